"""SPACE's own code against swarmbed, side by side, on the same cells, the same machine, the same hour.

For each allocator (CBBA, GRAPE, FCG: SPACE's ``cbba``, ``grape``, ``greedy``) and radio range, one
run of SPACE's code headless through ``../shared/tools/space-bench`` (its example config at that
range, the agent count and horizon set), then the same cell in swarmbed on the in-process engine and
in processes (``experiments/space_mtsr_code.yaml``), interleaved cell by cell, and the ratios:
SPACE's wall seconds over ours (above 1: ours is faster).

    SPACE_DIR=/tmp/space SPACE_PY=/tmp/spacevenv/bin/python python benchmarks/space_side_by_side.py
    python benchmarks/space_side_by_side.py --alg cbba --range 300 --agents 50 --horizon 600

Set up SPACE once with ``../shared/tools/space-bench/setup.sh`` (it prints the two variables). Run
from a non-editable install on an otherwise idle machine. Each figure is one run, or with
``--repeat N`` the median of N runs of each side, interleaved (a run's wall time on a shared
virtual machine moves by up to a quarter from one run to the next: take N >= 3 for a table).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BENCH = ROOT.parent / "shared" / "tools" / "space-bench"
OURS = {"cbba": "cbba", "grape": "grape", "greedy": "fcg"}


def space_run(alg: str, agents: int, comm: int, seed: int, horizon: int, out: Path) -> dict:
    """SPACE's run of one cell, headless: its ``bench.json`` (wall seconds, peak RSS)."""
    env = {**os.environ, "SPACE_DIR": os.environ.get("SPACE_DIR", "/tmp/space")}
    env.setdefault("SPACE_PY", "/tmp/spacevenv/bin/python")
    args = [str(BENCH / "one.sh"), alg, str(agents), str(comm), str(seed), str(horizon), str(out)]
    subprocess.run(args, env=env, check=True, capture_output=True, text=True)
    return json.loads((out / "bench.json").read_text())


def space_seconds(alg: str, agents: int, comm: int, seed: int, horizon: int, out: Path) -> float:
    """Wall seconds of SPACE's run (its loop and set-up, as bench.json reports them)."""
    return float(space_run(alg, agents, comm, seed, horizon, out)["total_wall_s"])


def our_command(alg: str, agents: int, comm: int, seed: int, horizon: int, engine: str, out: Path) -> list[str]:
    """``swarmbed run --engine ENGINE`` on the same cell as SPACE's, in a fresh interpreter."""
    sets = [
        f"allocator.name={OURS[alg]}",
        f"agents.count={agents}",
        f"network.range={comm}",
        f"run.seed={seed}",
        f"run.duration={horizon}",
    ]
    cmd = [sys.executable, "-m", "swarmbed", "run", str(ROOT / "experiments" / "space_mtsr_code.yaml")]
    return cmd + [a for s in sets for a in ("--set", s)] + ["--engine", engine, "--out", str(out), "--no-progress"]


def our_seconds(alg: str, agents: int, comm: int, seed: int, horizon: int, engine: str, out: Path) -> float:
    """Wall seconds of :func:`our_command`."""
    started = time.perf_counter()
    subprocess.run(our_command(alg, agents, comm, seed, horizon, engine, out), check=True, capture_output=True)
    return time.perf_counter() - started


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--alg", nargs="+", default=["greedy", "grape", "cbba"], choices=list(OURS))
    ap.add_argument("--range", nargs="+", type=int, default=[100, 300], dest="ranges")
    ap.add_argument("--agents", type=int, default=50)
    ap.add_argument("--horizon", type=int, default=600)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--engines", nargs="+", default=["inprocess", "processes"], choices=["inprocess", "processes"])
    ap.add_argument("--repeat", type=int, default=1, help="runs of each side per cell, interleaved; medians shown")
    args = ap.parse_args()
    if not (Path(os.environ.get("SPACE_DIR", "/tmp/space")) / "main.py").exists():
        sys.exit("SPACE's code is not set up: run ../shared/tools/space-bench/setup.sh and export what it prints")
    head = f"{'range':>5} {'allocator':>9} {'SPACE s':>8}" + "".join(
        f" {e + ' s':>12} {'x SPACE':>8}" for e in args.engines
    )
    print(head)
    with tempfile.TemporaryDirectory() as tmp:
        for comm in args.ranges:
            for alg in args.alg:
                base = Path(tmp) / f"{alg}_{comm}"
                seconds: dict[str, list[float]] = {}
                for r in range(args.repeat):  # SPACE, then each engine, then again: a slow minute falls on all
                    cell = (alg, args.agents, comm, args.seed, args.horizon)
                    seconds.setdefault("space", []).append(space_seconds(*cell, base / f"space{r}"))
                    for engine in args.engines:
                        seconds.setdefault(engine, []).append(our_seconds(*cell, engine, base / f"{engine}{r}"))
                space = statistics.median(seconds["space"])
                line = f"{comm:>5} {OURS[alg]:>9} {space:>8.1f}"
                for engine in args.engines:
                    ours = statistics.median(seconds[engine])
                    line += f" {ours:>12.1f} {space / ours:>8.2f}"
                print(line, flush=True)


if __name__ == "__main__":
    main()
