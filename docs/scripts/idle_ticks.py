"""How many agent-ticks could a step that skips idle agents spare? (issue 43, item 5)

    python docs/scripts/idle_ticks.py                       # every shipped experiment and sweep scenario
    python docs/scripts/idle_ticks.py --duration 600 --only sar/base_R20_V100
    python docs/scripts/idle_ticks.py --only radio/sar_bursts --scenario ge_

An agent-tick is *idle* when the agent's answer equals its answer of the tick before (the same
action, and it sends no radio message), it received nothing, and the tasks in its view are the
same: exactly the ticks whose skipping could not change what the agent does next, for an agent whose
decision depends only on what it received and sees (a timer inside a node or an allocator would
still need its tick). A *quiet* tick is the looser upper bound: the same answer and nothing
received, whatever changed in view (what declared events could spare at most). Each experiment
runs with ``SWARMBED_PROFILE_STAGES=1``: every agent counts
its idle ticks and logs them (``swarmbed.wire.stages``); this sums them per experiment. Sweep files
contribute each of their scenarios (the first run's seed), so every strategy is counted.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

from swarmbed import config as cfg
from swarmbed.campaigns.sweep import experiment_for, load_sweep, plan
from swarmbed.wire import stages

ROOT = Path(__file__).resolve().parents[2]


def cases(only: str | None, scenario: str | None = None) -> list[tuple[str, cfg.Experiment]]:
    """(name, experiment) of every shipped experiment file and every scenario of every sweep file."""
    out: list[tuple[str, cfg.Experiment]] = []
    seen: set[str] = set()
    for path in sorted((ROOT / "experiments").rglob("*.yaml")):
        data = yaml.safe_load(path.read_text()) or {}
        name = str(path.relative_to(ROOT))
        if "events" in data or set(data) == {"obstacles"} or (only and only not in name):
            continue
        if "base" not in data:
            out.append((name, cfg.load(path)))
            continue
        sweep = load_sweep(path)
        for spec in plan(sweep, Path("unused")):
            if spec.index == 0 and (scenario is None or scenario in spec.scenario.name):
                exp = experiment_for(spec.base, spec.scenario, spec.seed, spec.extra)
                key = cfg.to_yaml(exp.model_copy(update={"name": "x"}))
                if key not in seen:  # sweeps share scenarios (the density series, the baselines)
                    seen.add(key)
                    out.append((f"{name} {spec.scenario.name}", exp))
    return out


def count(exp: cfg.Experiment, duration: float) -> tuple[int, int, int]:
    """(agent-ticks, idle agent-ticks, quiet agent-ticks) of one run of ``exp``."""
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "exp.yaml"
        config.write_text(cfg.to_yaml(exp))
        sets = ["--set", f"run.duration={min(duration, exp.run.duration)}"] if duration else []
        done = subprocess.run(
            [sys.executable, "-m", "swarmbed", "run", str(config), "--out", f"{tmp}/run", "--no-progress", *sets],
            capture_output=True,
            text=True,
            env={**os.environ, stages.ENV: "1"},
        )
        if done.returncode != 0:
            raise RuntimeError(done.stderr.strip().splitlines()[-1])
        ticks = idle = quiet = 0
        for log in (Path(tmp) / "run" / "logs").glob("agent_*.log"):
            for line in log.read_text().splitlines():
                if stages.PREFIX in line:
                    t, i, q = stages.counts(line)
                    ticks, idle, quiet = ticks + t, idle + i, quiet + q
        return ticks, idle, quiet


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=600.0, help="simulated seconds per run (0: the file's own)")
    ap.add_argument("--only", help="only files whose path contains this")
    ap.add_argument("--scenario", help="of sweep files, only scenarios whose name contains this")
    ap.add_argument("--json", help="also write the counts here")
    args = ap.parse_args()
    rows = []
    print("| experiment | allocator | agents | agent-ticks | idle | share | quiet (view may change) |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
    for name, exp in cases(args.only, args.scenario):
        try:
            ticks, idle, quiet = count(exp, args.duration)
        except RuntimeError as exc:
            print(f"| {name} | {exp.allocator.name} | {exp.agents.count} | failed: {exc} | | | |", flush=True)
            continue
        share = idle / ticks if ticks else 0.0
        rows.append({"experiment": name, "allocator": exp.allocator.name, "ticks": ticks, "idle": idle, "quiet": quiet})
        print(
            f"| {name} | {exp.allocator.name} | {exp.agents.count} | {ticks:,} | {idle:,} | {100 * share:.0f} % "
            f"| {100 * quiet / max(ticks, 1):.0f} % |",
            flush=True,
        )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
