"""A lock-step run in this one process, on the in-process engine (:mod:`swarmbed.engine`):
``swarmbed run --engine inprocess``, ``swarmbed sweep --engine inprocess`` and the learning
environment's ``engine="inprocess"``.

The same result files as a run of processes writes for the same configuration and seed
(``summary.json``, ``timeseries.csv``, ``agents.csv``, the ledgers, ``config.yaml``,
``provenance.json``), byte for byte, without Zenoh, the proxy or agent processes: the agents'
runtimes and the radio step in this process. What needs processes is refused before anything
starts (:func:`refusals`): the real-time clock, other hosts and swaps, decisions from ROS 2,
ROS 2 topics, behavior-tree logs, and a hub others join. ``timings.json`` and ``deployment.json``
say which engine ran.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path

from swarmbed.coordinator import results
from swarmbed.coordinator.recorder import Recorder
from swarmbed.engine import InProcess, TickLoop
from swarmbed.engine.loop import TickInHand
from swarmbed.experiments.launch.runner import RunResult, plan_run, start_result_dir
from swarmbed.wire.rundir import DEPLOYMENT
from swarmbed.wire.schema import Experiment
from swarmbed.wire.seeds import WORLD, component_rng

#: the engines a run can be stepped by
ENGINES = ("processes", "inprocess")


def refusals(exp: Experiment, decision_source: str | None = None, env: bool = False) -> list[str]:
    """Why ``exp`` cannot run on the in-process engine, one reason a line (none: it can).
    ``decision_source``: the allocator's (``ros2``, ``env``); ``env``: the learning environment
    drives the run and supplies the ``env`` decisions itself."""
    why = []
    if exp.run.clock != "lockstep":
        why.append("run.clock is realtime: the in-process engine steps lock-step runs only")
    if exp.placement or exp.swaps or exp.may_carry:
        why.append("placement, swaps or may_carry name other hosts: agents on hosts are processes")
    if decision_source == "ros2" or (decision_source == "env" and not env):
        why.append(
            f"allocator {exp.allocator.name!r} takes its decisions from outside ({decision_source}): "
            "the in-process engine has no one to ask"
        )
    if exp.ros2 is not None:
        why.append("ros2: ROS 2 topics are published from a run's hub, which the in-process engine has none of")
    if exp.run.record_bt:
        why.append("run.record_bt: behavior-tree logs are written by agent processes")
    return why


class InProcessRun:
    """One run on the in-process engine, from its result folder made to its files written. The
    caller may own the loop (:meth:`observe`, :meth:`advance`: a learner, one tick a step) or let
    :meth:`run` step it to the end."""

    def __init__(self, exp: Experiment, out_dir: Path, env: bool = False) -> None:
        self.t0 = time.perf_counter()
        plan = plan_run(exp, out_dir)
        resolved = plan.resolved
        why = refusals(exp, resolved.allocator_cls.decision_source, env)
        if why:
            raise ValueError(f"--engine inprocess: {why[0]}")
        self.exp, self.out_dir = exp, Path(out_dir)
        start_result_dir(plan)
        self.scenario = resolved.scenario()
        self.world = self.scenario.make_world(component_rng(exp.run.seed, WORLD), resolved.allocator_cls)
        self.recorder = Recorder(exp, self.world, out_dir, list(resolved.allocator_cls.event_names))
        self.engine = InProcess(exp, resolved.targets, self.world, out_dir)
        self.loop = TickLoop(exp, self.scenario, self.world, self.recorder, self.engine)
        self.k = 0
        self.inboxes: dict[int, bytes] = {}
        self.hand: TickInHand | None = None
        self.result: RunResult | None = None
        self.loop.start()

    @property
    def over(self) -> bool:
        return self.result is not None or self.loop.over(self.k)

    def observe(self) -> TickInHand:
        """The tick in hand's first half (its observations), made once."""
        if self.hand is None or self.hand.k != self.k:
            self.hand = self.loop.begin(self.k)
        return self.hand

    def advance(self, decisions: Mapping[int, int] | None = None) -> None:
        """Complete the tick in hand with ``decisions`` (agent -> task id, for an ``external``
        allocator) and move to the next one; write the result files when the run is over."""
        self.engine.decisions = decisions or {}
        try:
            hand = self.observe()
            self.inboxes = self.loop.complete(hand, self.inboxes)
        except BaseException:
            self.recorder.abandon()
            raise
        self.k += 1
        if self.loop.over(self.k):
            self.finish()

    def run(self, on_tick: Callable[[int, float], None] | None = None) -> RunResult:
        """Step every tick of the run to its end and write the result files."""
        while not self.over:
            self.advance()
            if on_tick:
                on_tick(self.world.tick, self.world.time)
        return self.finish()

    def finish(self) -> RunResult:
        """Write the result files of the ticks stepped so far (once)."""
        if self.result is not None:
            return self.result
        self.engine.run_ends()
        last = self.loop.last_tick
        try:
            reports, netem = self.engine.reports(), self.engine.finish(last)
            summary = self.recorder.summary(last + 1, self.engine, reports, netem, malformed=0, clock=None)
            timings = {"engine": "inprocess", "run_s": time.perf_counter() - self.t0}
            self.recorder.write(summary, timings, self.engine, reports, netem)
        except BaseException:
            self.recorder.abandon()
            raise
        results.write_json(self.out_dir / DEPLOYMENT, {"engine": "inprocess", "agents": "this process"})
        self.result = RunResult(self.out_dir, summary.document, timings)
        return self.result


def run_in_process(exp: Experiment, out_dir: Path) -> RunResult:
    """Run ``exp`` (lock-step) in this process and write its result files to ``out_dir``."""
    return InProcessRun(exp, out_dir).run()
