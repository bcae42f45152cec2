"""A sweep whose runs are stepped by the in-process engine (swarmbed.engine) instead of processes:
for calibration and long measurement campaigns on one machine. Each run's result files are byte
for byte those `swarmbed sweep` writes with processes (tests/test_engine.py; checked on a 3000 s
SAR cbba run in docs/reproduction.md, section 5); there is no TCP measure, no behavior-tree log
and no real-time clock. Resumable like `swarmbed sweep`, and into the same folders: runs
completed either way count.

    python docs/scripts/sweep_in_process.py experiments/sar/base_R20_V100.yaml --runs 10 \\
        --out runs/world3/base_R20_V100 [--set KEY=VALUE ...] [--jobs 2]

Run it from a non-editable install, away from the checkout (`cd /tmp`), as the benchmarks are.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from swarmbed.campaigns.sweep import load_sweep, run_sweep


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweep", type=Path)
    parser.add_argument("--runs", type=int, default=None)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--jobs", type=int, default=None, help="runs at once (default: one per core)")
    parser.add_argument("--set", action="append", default=[], help="an experiment override, KEY=VALUE")
    parser.add_argument("--grid", action="append", default=[], help="KEY=V1,V2 (as swarmbed sweep)")
    args = parser.parse_args()
    sweep = load_sweep(args.sweep, args.runs, args.grid, args.set)
    table = run_sweep(sweep, args.out, jobs=args.jobs, progress=False, in_process=True)
    print(f"{(table['status'] == 'ok').sum()} of {len(table)} runs complete in {args.out}")


if __name__ == "__main__":
    main()
