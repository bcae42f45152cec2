"""CPU per agent-tick by process kind and by stage, measured live in a real lock-step run.

    python benchmarks/profile_tick.py                    # N = 50, no-op allocator, 5 peers each
    python benchmarks/profile_tick.py --n 100 --threads single --allocator cbba

Runs swarmbed's lock-step benchmark case (``benchmarks/lockstep.py``'s, no-op allocator messaging
5 peers per tick, unless ``--allocator`` names another) with ``SWARMBED_PROFILE_STAGES=1``: every
process charges the CPU of the thread that ticks to the stage that used it (``swarmbed.wire.stages``)
and logs it. This prints, per process kind, the whole process's CPU per agent-tick (from the run's
timings.json: every thread, Zenoh's included) and the stages' share of it; "other" is what no stage
holds (Zenoh's receive and send, the kernel, callback dispatch, and in the agent the thread state
handling around each callback). Run it alone on an idle machine from a non-editable install; read
the shares, and compare microseconds only between runs of the same day.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import tempfile
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.launch.hub import HubOptions
from swarmbed.launch.runner import run_experiment
from swarmbed.wire import stages

ROOT = Path(__file__).resolve().parent.parent


class _Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


def profile(n: int, ticks: int, threads: str, allocator: str) -> dict[str, dict[str, float]]:
    """{kind: {stage: us per agent-tick}} with ``total`` (the whole process) and ``other``."""
    name = "{name: noop, peers: 5}" if allocator == "noop" else allocator
    exp = cfg.load(
        ROOT / "experiments" / "quickstart.yaml",
        [
            f"agents.count={n}",
            f"allocator={name}" if allocator == "noop" else f"allocator.name={allocator}",
            *(["scenario.initial_tasks=0"] if allocator == "noop" else []),
            "run.stop_when_done=false",
            f"run.duration={ticks}",
            "network.range=null",
            "run.record_every=1000000",
            f"run.zenoh_threads={threads}",
        ],
    )
    os.environ[stages.ENV] = "1"
    heard = _Lines()  # the coordinator runs in this process: its line comes through logging
    hub_log = logging.getLogger("swarmbed.coordinator")
    hub_log.addHandler(heard)
    level, hub_log.level = hub_log.level, logging.INFO
    try:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "run"
            run_experiment(exp, out, progress=False, hub=HubOptions())
            timings = json.loads((out / "timings.json").read_text())
            logs = {p.name: p.read_text() for p in (out / "logs").glob("*.log")}
    finally:
        del os.environ[stages.ENV]
        hub_log.removeHandler(heard)
        hub_log.setLevel(level)
    logs["hub"] = "\n".join(heard.lines)
    totals = timings["per_agent_tick"]["cpu_us"]
    agent_stages = [
        stages.parse(line)
        for text in logs.values()
        for line in text.splitlines()
        if stages.PREFIX in line and " agent " in line
    ]
    out: dict[str, dict[str, float]] = {}
    if agent_stages:
        names = list(agent_stages[0])
        out["agents"] = {s: statistics.median(a.get(s, 0.0) for a in agent_stages) for s in names}
    for kind, tag in (("hub", "coordinator: "), ("netem", "netem: ")):
        for text in logs.values():
            for line in text.splitlines():
                if stages.PREFIX in line and tag in line:
                    out[kind] = stages.parse(line)
    for kind, found in out.items():
        total = float(totals.get(kind, 0.0))
        found["other"] = max(0.0, total - sum(found.values()))
        found["total"] = total
    return out


def table(profiled: dict[str, dict[str, float]]) -> str:
    lines = ["| process | stage | us per agent-tick | share |", "| --- | --- | ---: | ---: |"]
    for kind, found in profiled.items():
        total = found["total"] or 1.0
        for stage, us in found.items():
            if stage != "total":
                lines.append(f"| {kind} | {stage} | {us:.1f} | {100 * us / total:.0f} % |")
        lines.append(f"| {kind} | **whole process** | **{found['total']:.1f}** | |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=50, help="agents")
    ap.add_argument("--ticks", type=int, default=400)
    ap.add_argument("--threads", choices=("zenoh", "default", "single"), default="single")
    ap.add_argument("--allocator", default="noop")
    args = ap.parse_args()
    print(f"N = {args.n}, {args.ticks} ticks, zenoh_threads {args.threads}, allocator {args.allocator}")
    print(table(profile(args.n, args.ticks, args.threads, args.allocator)))


if __name__ == "__main__":
    main()
