"""A lock-step run in this one process, on the in-process engine (:mod:`swarmbed.engine`).

For tests, checks and calibration: the same result files as ``swarmbed run`` writes for the same
configuration and seed (``summary.json``, ``timeseries.csv``, ``agents.csv``, the ledger,
``config.yaml``), byte for byte, without Zenoh, the proxy or agent processes. It records no
behavior-tree log and measures no TCP; runs of the mission stay processes.
"""

from __future__ import annotations

import time
from pathlib import Path

from swarmbed.coordinator.recorder import Recorder
from swarmbed.engine import InProcess, TickLoop
from swarmbed.experiments.launch.runner import RunResult, plan_run, start_result_dir
from swarmbed.wire.schema import Experiment
from swarmbed.wire.seeds import WORLD, component_rng


def run_in_process(exp: Experiment, out_dir: Path) -> RunResult:
    """Run ``exp`` (lock-step) in this process and write its result files to ``out_dir``."""
    t0 = time.perf_counter()
    plan = plan_run(exp, out_dir)
    resolved = plan.resolved
    if exp.run.clock != "lockstep":
        raise ValueError("the in-process engine steps lock-step runs only (run.clock: lockstep)")
    if resolved.allocator_cls.decision_source is not None:
        raise ValueError(
            f"allocator {exp.allocator.name!r} takes its decisions from outside "
            f"({resolved.allocator_cls.decision_source}): the in-process engine has no one to ask"
        )
    start_result_dir(plan)
    scenario = resolved.scenario()
    world = scenario.make_world(component_rng(exp.run.seed, WORLD), resolved.allocator_cls)
    recorder = Recorder(exp, world, out_dir, list(resolved.allocator_cls.event_names))
    engine = InProcess(exp, resolved.targets, world, out_dir)
    try:
        last = TickLoop(exp, scenario, world, recorder, engine).run()
        reports, netem = engine.reports(), engine.finish(last)
    except BaseException:
        recorder.abandon()
        raise
    summary = recorder.summary(last + 1, engine, reports, netem, malformed=0, clock=None)
    timings = {"engine": "in-process", "run_s": time.perf_counter() - t0}
    recorder.write(summary, timings, engine, reports, netem)
    return RunResult(out_dir, summary.document, timings)
