"""``swarmbed run --check`` and ``swarmbed sweep --check``: what a command would do, and roughly how
long it would take, without starting a process.

By the time a plan is described the experiment has been loaded the way a run loads it (files,
duplicate keys, plugins imported, parameters validated, behavior trees loaded with their port values
checked, at least one tick), so whatever would stop a run before its first tick has already been
said. The wall-time estimate comes from a short calibration: the allocator's own ``observe`` and
``decide`` timed in this process on a random instance of the experiment's size (capped), plus the
per agent-tick cost of swarmbed's processes measured in docs/benchmarks.md, spread over this
machine's cores. It is a guide, not a measurement.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.checks.allocator_kit import random_instance, simulate
from swarmbed.schema.experiment import Experiment, hosts_of
from swarmbed.wire.credentials import Identity

#: CPU seconds swarmbed's own processes spend per agent-tick with a no-op allocator (agent ~330 us,
#: hub and proxy ~70 us each: docs/benchmarks.md, 2026-11-26, 50-200 agents)
PROCESS_CPU_PER_AGENT_TICK = 470e-6
#: wall seconds to start a run's processes: a fixed part and one per agent (fork server, joins)
STARTUP_S, STARTUP_PER_AGENT_S = 3.0, 0.03
#: CPU seconds the in-process engine spends per agent-tick with a no-op allocator, on one core (the
#: quick start's world at 10 agents, 1000 ticks: 47 us, 2026-11-28); it starts in about a second
INPROCESS_CPU_PER_AGENT_TICK, INPROCESS_STARTUP_S = 50e-6, 1.0
CALIBRATION_AGENTS, CALIBRATION_TASKS, CALIBRATION_ROUNDS = 10, 40, 20


def allocator_seconds_per_agent_tick(exp: Experiment) -> float:
    """The allocator's own CPU per agent and tick, timed in this process on a small random instance."""
    kind = exp.scenario.kind if exp.scenario.kind in ("mtsr", "sar") else "mtsr"
    n = max(2, min(exp.agents.count, CALIBRATION_AGENTS))
    inst = random_instance(exp.run.seed, n, CALIBRATION_TASKS, scenario=kind)
    params = dict(exp.allocator.params())
    started = time.process_time()
    simulate(exp.allocator.name, params, inst, CALIBRATION_ROUNDS, exp.run.seed, scenario=kind)
    return (time.process_time() - started) / (n * CALIBRATION_ROUNDS)


def run_cost(exp: Experiment, engine: str = "processes") -> tuple[float, float, int]:
    """One run of ``exp``: its fixed wall seconds (start-up, the planner's graph), the CPU seconds of
    its ticks, and the most cores those can use at once (one in-process; agents + hub + proxy in
    processes). The one estimator behind ``run --check`` and ``sweep --check``."""
    try:
        allocator = allocator_seconds_per_agent_tick(exp)
    except Exception:  # an allocator the kit cannot drive (a scenario of its own): the engine's cost alone
        allocator = 0.0
    if exp.obstacles is not None:  # the planner's graph, built once per world (where the world is)
        from swarmbed.scenarios.paths import SECONDS_PER_SIGHT_TEST, sight_tests

        planning = sight_tests(exp.obstacles.compile()) * SECONDS_PER_SIGHT_TEST
    else:
        planning = 0.0
    agent_ticks = exp.ticks * exp.agents.count
    if engine == "inprocess":
        return planning + INPROCESS_STARTUP_S, agent_ticks * (INPROCESS_CPU_PER_AGENT_TICK + allocator), 1
    fixed = planning + STARTUP_S + STARTUP_PER_AGENT_S * exp.agents.count
    return fixed, agent_ticks * (PROCESS_CPU_PER_AGENT_TICK + allocator), exp.agents.count + 2


def estimate_wall_s(exp: Experiment, cores: int | None = None, engine: str = "processes") -> float:
    """Rough wall seconds of one run of ``exp`` alone on ``cores`` (this machine's by default)."""
    fixed, cpu, parallel = run_cost(exp, engine)
    return fixed + cpu / max(1, min(cores or os.cpu_count() or 1, parallel))


def _upto(exps: Sequence[Experiment]) -> str:
    """ "about", or "up to" where a run stops once its tasks are done (its ticks are a ceiling)."""
    return "up to about" if any(e.run.stop_when_done for e in exps) else "about"


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def describe_plan(exp: Experiment, out: Path, admitted: Sequence[Identity] = (), engine: str = "processes") -> str:
    """What ``swarmbed run`` would do with ``exp``, in a few lines; nothing is started or written."""
    resolved = cfg.resolve_experiment(exp)
    hosts = sorted({h for h in hosts_of(exp.placement, exp.agents.count).values() if h != "local"})
    admitted_hosts = {i.host_name for i in admitted if i.role == "host"}
    lines = [
        f"check: {exp.name} is valid; nothing was started",
        f"  scenario {exp.scenario.kind} ({resolved.targets.scenario}), allocator {exp.allocator.name} "
        f"({resolved.targets.allocator})",
        f"  {exp.agents.count} agents, {exp.ticks:,} ticks of {exp.run.dt:g} s ({exp.run.duration:g} simulated s), "
        f"seed {exp.run.seed}, clock {exp.run.clock}",
        f"  results into {out}"
        + (" (not empty: give --force to clear it)" if out.exists() and any(out.iterdir()) else ""),
    ]
    for host in hosts:
        if host in admitted_hosts:
            lines.append(f"  host {host}: admitted; it must be up and reach this machine when the run starts")
        else:
            lines.append(f"  host {host}: NOT admitted (give --admit with its credentials file)")
    if engine == "inprocess":
        lines.append("  engine: in-process (every agent and the radio in this process; the same result files)")
        lines.append(
            f"  estimated wall time: {_upto([exp])} {_duration(estimate_wall_s(exp, engine=engine))} on one core"
        )
    else:
        lines.append(
            f"  estimated wall time: {_upto([exp])} {_duration(estimate_wall_s(exp))} on {os.cpu_count()} cores"
        )
    if exp.allocator.name == "ros2" and exp.run.clock == "lockstep" and exp.ros2 is not None:
        timeout = exp.ros2.command_timeout
        lines.append(
            f"  plus the ROS 2 node's answers: each tick waits up to {timeout:g} s (ros2.command_timeout) for every "
            f"robot's command; a node that never answers makes the run last about {_duration(exp.ticks * timeout)}"
        )
    return "\n".join(lines)


def describe_sweep(
    n_runs: int, runs_left: int, per_run: dict[str, Experiment], jobs: int, engine: str = "processes"
) -> str:
    """What ``swarmbed sweep`` would do: runs planned and left, and a wall-time estimate. The runs
    go ``min(jobs, runs_left)`` at a time, the cores shared among them; the whole takes at least
    its longest run."""
    lines = [f"check: the sweep is valid; nothing was started ({n_runs} runs planned, {runs_left} still to run)"]
    at_once, cores = max(1, min(jobs, runs_left)), os.cpu_count() or 1
    costs = []
    for name, exp in per_run.items():
        cost = run_cost(exp, engine)
        alone = cost[0] + cost[1] / max(1, min(cores, cost[2]))
        lines.append(f"  {name}: {exp.agents.count} agents, {exp.ticks:,} ticks, about {_duration(alone)} a run alone")
        costs.append((alone, cost))
    if per_run and runs_left:
        # the runs share the cores: the whole is the CPU of every run left over the cores it can use,
        # plus each run's fixed part, `at_once` of them overlapping; never less than its longest run
        mean_fixed = sum(c[1][0] for c in costs) / len(costs)
        mean_cpu = sum(c[1][1] for c in costs) / len(costs)
        usable = min(cores, at_once * max(c[1][2] for c in costs))
        whole = max(max(c[0] for c in costs), runs_left * (mean_fixed / at_once + mean_cpu / usable))
        lines.append(
            f"  estimated wall time: {_upto(list(per_run.values()))} {_duration(whole)} with --jobs {jobs}"
            f" ({runs_left} run{'s' if runs_left != 1 else ''}, {at_once} at a time)"
        )
    return "\n".join(lines)
