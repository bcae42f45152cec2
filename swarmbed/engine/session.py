"""A run, owned by the engine: its world and recorder built once, whatever carries its ticks.

Every way of running goes through a :class:`Session`: ``swarmbed run`` over processes (the
coordinator is its Zenoh transport), the in-process engine (``--engine inprocess``, sweeps, the
learning environment) and the conformance checks. The session builds the world from the run seed
and the recorder once, is connected to a transport, the run's membership and the hooks around a
tick, and offers :meth:`Session.run` (to the end), :meth:`Session.step` (the caller owns the loop,
as a learner does) and :meth:`Session.write` (the result files). Which combinations a run may not
ask for is :func:`refusals`, read by the launcher, ``config.validate`` and ``--check`` alike.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from swarmbed.engine.hooks import TickHook
from swarmbed.engine.loop import Membership, TickInHand, TickLoop, Transport
from swarmbed.engine.recorder import Recorder
from swarmbed.extension.allocator import Allocator
from swarmbed.extension.scenario import Scenario, World
from swarmbed.records.summary import RunSummary
from swarmbed.schema.experiment import Experiment
from swarmbed.wire.control import Final, NetemFinal
from swarmbed.wire.seeds import WORLD, component_rng
from swarmbed.wire.stages import Stages

#: the engines a run can be stepped by
ENGINES = ("processes", "inprocess")


def refusals(
    exp: Experiment, decision_source: str | None, engine: str = "processes", driven: bool = False
) -> list[str]:
    """Why ``exp`` cannot run as asked, one reason a line (none: it can). ``decision_source``: the
    allocator's (``ros2``, ``env``, or None); ``engine``: one of :data:`ENGINES`; ``driven``: a
    learner in this process supplies the ``env`` decisions."""
    why = []
    if decision_source == "ros2" and exp.ros2 is None:
        why.append(
            f"allocator.name: {exp.allocator.name!r} takes its decisions from ROS 2 topics: the experiment "
            "needs a ros2: section (docs/ros2.md)"
        )
    if decision_source == "env" and not driven:
        why.append(
            f"allocator.name: {exp.allocator.name!r} takes its decisions from a driver in the launching "
            "process (swarmbed.envs): swarmbed run cannot drive it"
        )
    if engine != "inprocess":
        return why
    if exp.run.clock != "lockstep":
        why.append("run.clock is realtime: the in-process engine steps lock-step runs only")
    if exp.placement or exp.swaps or exp.may_carry:
        why.append("placement, swaps or may_carry name other hosts: agents on hosts are processes")
    if decision_source == "ros2":
        why.append(
            f"allocator {exp.allocator.name!r} takes its decisions from outside (ros2): "
            "the in-process engine has no one to ask"
        )
    if exp.ros2 is not None:
        why.append("ros2: ROS 2 topics are published from a run's hub, which the in-process engine has none of")
    if exp.run.record_bt:
        why.append("run.record_bt: behavior-tree logs are written by agent processes")
    return why


def run_world(exp: Experiment, scenario: Scenario, allocator: type[Allocator] | None = None) -> World:
    """The world a run of ``exp`` steps: ``scenario``'s, drawn from the run seed's world stream
    (``wire.seeds.WORLD``); the one way a run's world is made, for a run and for a study that drives
    the world itself (docs/scripts/sar_fit.py's oracle)."""
    return scenario.make_world(component_rng(exp.run.seed, WORLD), allocator)


class Session:
    """One run: the world (from the run seed's world stream), the recorder of its result files,
    and, once :meth:`connect` gave it a transport, the tick loop."""

    def __init__(self, exp: Experiment, scenario: Scenario, allocator: type[Allocator], out_dir: Path) -> None:
        self.exp, self.scenario, self.out_dir = exp, scenario, Path(out_dir)
        self.world = run_world(exp, scenario, allocator)
        self.recorder = Recorder(exp, self.world, self.out_dir, list(allocator.event_names))
        self._loop: TickLoop | None = None
        self.k = 0  # the next tick to step, where the caller owns the loop
        self.inboxes: dict[int, bytes] = {}
        self.hand: TickInHand | None = None

    def connect(
        self, transport: Transport, membership: Membership, hooks: Sequence[TickHook] = (), stages: Stages | None = None
    ) -> TickLoop:
        """The tick loop over ``transport``, with the run's ``membership`` and the ``hooks`` around a tick."""
        self._loop = TickLoop(self.exp, self.scenario, self.world, self.recorder, transport, membership, hooks, stages)
        self.membership = membership
        return self._loop

    @property
    def loop(self) -> TickLoop:
        if self._loop is None:
            raise RuntimeError("Session.connect() first: the session has no transport")
        return self._loop

    @property
    def last_tick(self) -> int:
        return self._loop.last_tick if self._loop is not None else -1

    # -- the session owns the loop ------------------------------------------------------------------
    def run(self, on_tick: Callable[[int, float], None] | None = None) -> int:
        """Step every tick of the run to its end; return the last tick stepped."""
        return self.loop.run(on_tick)

    # -- the caller owns the loop ------------------------------------------------------------------
    def start(self) -> None:
        """Open the result tables; the first :meth:`observe` may follow."""
        self.loop.start()

    @property
    def over(self) -> bool:
        """Whether the run has no tick left to step."""
        return self.loop.over(self.k)

    def observe(self) -> TickInHand:
        """The first half of the next tick (its world sample and observations), made once."""
        if self.hand is None or self.hand.k != self.k:
            self.hand = self.loop.begin(self.k)
        return self.hand

    def step(self, decisions: Mapping[int, int] | None = None) -> None:
        """Complete the tick in hand with ``decisions`` (agent -> task id, for an allocator that takes
        them from outside) and move to the next one; the hooks hear the run end after the last."""
        self.inboxes = self.loop.complete(self.observe(), self.inboxes, decisions)
        self.k += 1
        if self.loop.over(self.k):
            self.loop.end()

    # -- the end -------------------------------------------------------------------------------------
    def write(
        self,
        reports: dict[int, Final],
        netem: NetemFinal,
        malformed: int,
        clock: dict | None,
        timings: dict,
    ) -> RunSummary:
        """The result files of the ticks stepped, from every agent's and the radio's final report;
        ``summary.json`` last."""
        summary = self.recorder.summary(self.last_tick + 1, self.membership, reports, netem, malformed, clock)
        self.recorder.write(summary, timings, self.membership, reports, netem)
        return summary

    def abandon(self) -> list[Path]:
        """The run did not complete: keep the rows streamed so far as ``partial_*`` files."""
        return self.recorder.abandon()
