"""One lock-step tick, for any transport.

Tick k: record where every live agent is; draw the robots the scenario loses at k+1 (the radio
must not deliver to them then); hand the transport the world sample and every live agent's
observation with its inbox of tick k; take back the step (every action of tick k, the inboxes of
k+1, the radio's counters); apply the actions the scenario declares; record.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

from swarmbed.coordinator.recorder import Recorder
from swarmbed.extension.actions import admit
from swarmbed.extension.scenario import Scenario, World
from swarmbed.wire.codec import NetemStep, WorldSample
from swarmbed.wire.observation import Observation
from swarmbed.wire.schema import Experiment
from swarmbed.wire.stages import Stages


class TickTransport(Protocol):
    """What carries a tick to the agents and back. Every method but :meth:`exchange` may do
    nothing (the in-process transport has no wall clock, no restarts and no watchers)."""

    def run_starts(self) -> None:
        """The first tick is about to start."""

    def tick_starts(self, k: int) -> None:
        """Tick ``k`` is about to start (a real-time clock waits for its wall time here)."""

    def before_world(self, k: int) -> None:
        """Positions of tick ``k`` are recorded; what falls due before its world sample (swaps,
        restarts, checkpoints) happens now."""

    def incarnations(self) -> dict[int, int]:
        """Agent -> its current process's incarnation, for those started again (0s left out)."""

    def world_ready(self, sample: WorldSample) -> None:
        """Tick ``k``'s world sample, before the observations are made (a proxy may route with it
        while the coordinator makes them)."""

    def exchange(
        self, k: int, sample: WorldSample, observed: Mapping[int, Observation], inboxes: Mapping[int, bytes]
    ) -> NetemStep:
        """Carry tick ``k`` to the agents ``observed`` names and return the step: their actions
        (those the transport gives the world), the inboxes of tick k+1 and the counters."""

    def lose(self, agent: int, k: int) -> None:
        """``agent``'s process was found gone during tick ``k``."""

    def retire(self, agent: int, tick: int) -> None:
        """The scenario lost ``agent``'s robot from ``tick`` on."""

    def clock_columns(self) -> Sequence[float]:
        """The real-time clock's columns of this tick's time-series row (none in lock-step)."""

    def tick_done(self, k: int, admitted: Mapping[int, list]) -> None:
        """Tick ``k`` is applied and recorded (``admitted``: the actions the world took)."""

    def should_stop(self) -> bool:
        """Whether to end the run before the next tick (a soak's duration is over)."""

    def run_ends(self) -> None:
        """The ticks are over (the last one, or the one before a stop)."""


@dataclass(frozen=True)
class TickInHand:
    """A tick between :meth:`TickLoop.begin` and :meth:`TickLoop.complete`."""

    k: int
    sample: WorldSample
    observed: Mapping[int, Observation]
    doomed: Collection[int]  # robots the scenario loses at tick k+1
    live: int  # agents alive at tick k


class TickLoop:
    """The world, its recorder and a transport; :meth:`run` steps them to the end of the run."""

    def __init__(
        self,
        exp: Experiment,
        scenario: Scenario,
        world: World,
        recorder: Recorder,
        transport: TickTransport,
        stages: Stages | None = None,
    ) -> None:
        self.exp, self.scenario, self.world, self.recorder = exp, scenario, world, recorder
        self.transport = transport
        self.stages = stages  # benchmarks/profile_tick.py
        self.last_tick = -1

    def start(self) -> None:
        """Open the result tables and tell the transport the first tick is about to start."""
        self.recorder.open()
        self.transport.run_starts()

    def over(self, k: int) -> bool:
        """Whether the run ends before tick ``k``: its duration, a finished world where the run says
        to stop then, or a transport that asks to stop (a soak's duration)."""
        w = self.world
        return k >= self.exp.ticks or (w.finished and self.exp.run.stop_when_done) or self.transport.should_stop()

    def run(self, on_tick: Callable[[int, float], None] | None = None) -> int:
        """Step every tick of the run (or until the world is finished, where the run says to stop
        then); return the last tick stepped."""
        w, t = self.world, self.transport
        self.start()
        inboxes: dict[int, bytes] = {}
        k = 0
        while not self.over(k):
            t.tick_starts(k)
            inboxes = self.tick(k, inboxes)
            if on_tick:
                on_tick(w.tick, w.time)
            k += 1
        t.run_ends()
        return self.last_tick

    def tick(self, k: int, inboxes: Mapping[int, bytes]) -> dict[int, bytes]:
        """Tick ``k`` with the inboxes delivered for it; return the inboxes of tick k+1."""
        return self.complete(self.begin(k), inboxes)

    def begin(self, k: int) -> TickInHand:
        """The first half of tick ``k``: positions recorded, losses drawn, the world sample made and
        every live agent's observation. Between :meth:`begin` and :meth:`complete` a caller that owns
        the loop (a learner) reads the observations and sets its decisions."""
        w, rec, t, st = self.world, self.recorder, self.transport, self.stages
        ids, xs, ys = w.positions()
        rec.positions(k, ids, xs, ys)
        if k > 0:
            t.before_world(k)
        doomed = w.draw_losses()  # lost at tick k+1: the radio must not deliver to them then
        alive_next = [i for i in ids if i not in doomed]
        sample = WorldSample(k, ids, xs, ys, alive_next, t.incarnations())
        t.world_ready(sample)
        observed = w.observations()
        if st is not None:
            st.mark("observations")
        return TickInHand(k, sample, observed, doomed, len(ids))

    def complete(self, hand: TickInHand, inboxes: Mapping[int, bytes]) -> dict[int, bytes]:
        """The second half of a tick: the transport carries it, the world applies the actions its
        scenario declares, the recorder books it; return the inboxes of the next tick."""
        w, rec, t, st, k = self.world, self.recorder, self.transport, self.stages, hand.k
        step = t.exchange(k, hand.sample, hand.observed, inboxes)
        for j in step.lost:
            t.lose(j, k)
        declared = self.scenario.actions  # a world sees only actions of the shapes its scenario declares
        admitted = {a: admit(act, declared) for a, act in step.actions.items() if w.alive[a]}
        w.apply(admitted)
        rec.step(step)
        for j in hand.doomed:
            t.retire(j, k + 1)
        self.last_tick = k
        if w.tick % self.exp.run.record_every == 0 or w.finished:
            rec.row(t.clock_columns())
        if st is not None:
            st.mark("apply and record")
            st.ticks += hand.live  # per agent-tick, as the other processes count
        t.tick_done(k, admitted)
        return step.inboxes
