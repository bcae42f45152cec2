"""One lock-step tick, for any transport.

Tick k: record where every live agent is; draw the robots the scenario loses at k+1 (the radio
must not deliver to them then); hand the transport the world sample and every live agent's
observation with its inbox of tick k; take back the step (every action of tick k, the inboxes of
k+1, the radio's counters); apply the actions the scenario declares; record. What a way of running
adds around the tick is a list of :class:`~swarmbed.engine.hooks.TickHook`; who the run's agents
are (which processes were started again, lost or retired) is its :class:`Membership`.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

from swarmbed.engine.hooks import POINTS as _POINTS
from swarmbed.engine.hooks import TickHook, handlers
from swarmbed.engine.recorder import Membership as RecordedMembership
from swarmbed.engine.recorder import Recorder
from swarmbed.extension.actions import admit
from swarmbed.extension.scenario import Scenario, World
from swarmbed.schema.experiment import Experiment
from swarmbed.wire.codec import NetemStep, WorldSample
from swarmbed.wire.control import RestartRecord, SwapRecord
from swarmbed.wire.observation import Observation
from swarmbed.wire.stages import Stages


class Transport(Protocol):
    """What carries a tick to the agents and back: one call a tick."""

    def exchange(
        self,
        k: int,
        sample: WorldSample,
        observed: Mapping[int, Observation],
        inboxes: Mapping[int, bytes],
        decisions: Mapping[int, int],
    ) -> NetemStep:
        """Carry tick ``k`` to the agents ``observed`` names (with ``decisions``, agent -> task id,
        for an allocator that takes them from outside) and return the step: their actions (those
        the transport gives the world), the inboxes of tick k+1 and the radio's counters."""


class Membership(RecordedMembership, Protocol):
    """Who the run's agents are: the coordinator's
    :class:`~swarmbed.coordinator.lifecycle.AgentLifecycle` (processes that start, swap, restart
    and die), or :class:`OneProcess`. The results read ``lost`` and the two logs."""

    def incarnations(self) -> dict[int, int]:
        """Agent -> its current process's incarnation, for those started again (0s left out)."""

    def gone(self, agent: int, k: int) -> None:
        """``agent``'s process was found gone during tick ``k``."""

    def retire(self, agent: int, tick: int) -> None:
        """The scenario lost ``agent``'s robot from ``tick`` on."""


class OneProcess:
    """The membership of a run whose agents all step in this process: none is ever swapped,
    restarted or found gone; the scenario's losses are the only ones."""

    def __init__(self, world: World) -> None:
        self.world = world
        self.lost: dict[int, int] = {}
        self.swap_log: list[SwapRecord] = []
        self.restart_log: list[RestartRecord] = []

    def incarnations(self) -> dict[int, int]:
        return {}

    def gone(self, agent: int, k: int) -> None:
        raise AssertionError(f"agent {agent} found gone at tick {k} in a run of one process")

    def retire(self, agent: int, tick: int) -> None:
        self.lost[agent] = tick
        self.world.kill(agent)


@dataclass(frozen=True)
class TickInHand:
    """A tick between :meth:`TickLoop.begin` and :meth:`TickLoop.complete`."""

    k: int
    sample: WorldSample
    observed: Mapping[int, Observation]
    doomed: Collection[int]  # robots the scenario loses at tick k+1
    live: int  # agents alive at tick k


class TickLoop:
    """The world, its recorder, a transport, the run's membership and the hooks around a tick;
    :meth:`run` steps them to the end of the run, or a caller owns the loop with :meth:`begin`
    and :meth:`complete`."""

    def __init__(
        self,
        exp: Experiment,
        scenario: Scenario,
        world: World,
        recorder: Recorder,
        transport: Transport,
        membership: Membership,
        hooks: Sequence[TickHook] = (),
        stages: Stages | None = None,
    ) -> None:
        self.exp, self.scenario, self.world, self.recorder = exp, scenario, world, recorder
        self.transport, self.membership = transport, membership
        self.hooks = list(hooks)
        self._on = {point: handlers(self.hooks, point) for point in _POINTS}
        self.stages = stages  # benchmarks/profile_tick.py: the loop's own stages
        self.last_tick = -1
        self.ended = False

    def _call(self, point: str, *args: object) -> None:
        for handler in self._on[point]:
            handler(*args)

    def start(self) -> None:
        """Open the result tables and tell the hooks the first tick is about to start."""
        self.recorder.open()
        self._call("run_starts")

    def over(self, k: int) -> bool:
        """Whether the run ends before tick ``k``: its duration, a finished world where the run says
        to stop then, or a hook that asks to stop (a soak's duration)."""
        w = self.world
        return (
            k >= self.exp.ticks
            or (w.finished and self.exp.run.stop_when_done)
            or any(stop() for stop in self._on["should_stop"])
        )

    def run(self, on_tick: Callable[[int, float], None] | None = None) -> int:
        """Step every tick of the run (or until the world is finished, where the run says to stop
        then); return the last tick stepped."""
        w = self.world
        self.start()
        inboxes: dict[int, bytes] = {}
        k = 0
        while not self.over(k):
            self._call("tick_starts", k)
            inboxes = self.tick(k, inboxes)
            if on_tick:
                on_tick(w.tick, w.time)
            k += 1
        self.end()
        return self.last_tick

    def end(self) -> None:
        """The ticks are over: tell the hooks (once, however often the end is reached)."""
        if not self.ended:
            self.ended = True
            self._call("run_ends")

    def tick(
        self, k: int, inboxes: Mapping[int, bytes], decisions: Mapping[int, int] | None = None
    ) -> dict[int, bytes]:
        """Tick ``k`` with the inboxes delivered for it; return the inboxes of tick k+1."""
        return self.complete(self.begin(k), inboxes, decisions)

    def begin(self, k: int) -> TickInHand:
        """The first half of tick ``k``: positions recorded, losses drawn, the world sample made and
        every live agent's observation. Between :meth:`begin` and :meth:`complete` a caller that owns
        the loop (a learner) reads the observations and sets its decisions."""
        w, rec, st = self.world, self.recorder, self.stages
        ids, xs, ys = w.positions()
        rec.positions(k, ids, xs, ys)
        if k > 0:
            self._call("before_world", k)
        doomed = w.draw_losses()  # lost at tick k+1: the radio must not deliver to them then
        alive_next = [i for i in ids if i not in doomed]
        sample = WorldSample(k, ids, xs, ys, alive_next, self.membership.incarnations())
        self._call("world_ready", sample)
        observed = w.observations()
        if st is not None:
            st.mark("observations")
        return TickInHand(k, sample, observed, doomed, len(ids))

    def complete(
        self, hand: TickInHand, inboxes: Mapping[int, bytes], decisions: Mapping[int, int] | None = None
    ) -> dict[int, bytes]:
        """The second half of a tick: the transport carries it, the world applies the actions its
        scenario declares, the recorder books it; return the inboxes of the next tick."""
        w, rec, st, k, members = self.world, self.recorder, self.stages, hand.k, self.membership
        self._call("exchange_starts", k, hand.sample, hand.observed, inboxes)
        step = self.transport.exchange(k, hand.sample, hand.observed, inboxes, decisions or {})
        for j in step.lost:
            members.gone(j, k)
        declared = self.scenario.actions  # a world sees only actions of the shapes its scenario declares
        admitted = {a: admit(act, declared) for a, act in step.actions.items() if w.alive[a]}
        w.apply(admitted)
        rec.step(step)
        for j in hand.doomed:
            members.retire(j, k + 1)
        self.last_tick = k
        if w.tick % self.exp.run.record_every == 0 or w.finished:
            rec.row([c for columns in self._on["row_columns"] for c in columns()])
        if st is not None:
            st.mark("apply and record")
            st.ticks += hand.live  # per agent-tick, as the other processes count
        self._call("tick_done", k, admitted)
        return step.inboxes
