"""How swarmbed scales against SPACE's own code: wall seconds and peak memory from 50 to 1,000 robots.

For each agent count and allocator (CBBA, GRAPE, FCG: SPACE's ``cbba``, ``grape``, ``greedy``) at
one radio range, one run of SPACE's code headless (``../shared/tools/space-bench``) and the same
cell in swarmbed (``experiments/space_mtsr_code.yaml``) on each engine asked for, interleaved cell by
cell so that a machine's slow minute falls on both. Printed per cell: wall seconds, peak RSS (MB)
and SPACE's wall seconds over ours (above 1: ours is faster). Peak RSS is the largest single
process's (``wait4``'s ``ru_maxrss``): for the in-process engine the whole run, for processes the
launcher's, not the sum over the agents (docs/benchmarks.md has PSS per agent).

    SPACE_DIR=/tmp/space SPACE_PY=/tmp/spacevenv/bin/python python benchmarks/scale.py
    python benchmarks/scale.py --agents 50 200 --alg cbba --engines inprocess --horizon 60

The horizon shrinks with the team so that a cell takes about as long at every size (``--horizon``
is the horizon at 50 agents; at N agents it is ``horizon x 50 / N``, at least 10 s: 600 s at 50,
30 s at 1,000 with the default). Set up SPACE once with ``../shared/tools/space-bench/setup.sh``.
Run from a non-editable install on an otherwise idle machine; ``--repeat N`` runs each side N
times, interleaved, and shows the medians (take N >= 3 for a table: one run's wall time moves by up
to a quarter on a shared virtual machine).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from space_side_by_side import OURS, our_command, space_run  # this folder is on sys.path when the script runs


def timed(cmd: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of ``cmd``, run to its end (its stderr kept in a file, so
    that a full pipe never stalls it)."""
    with tempfile.TemporaryFile() as err:
        started = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - started
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
        if proc.returncode != 0:
            err.seek(0)
            raise RuntimeError(f"{' '.join(cmd[:4])} ... failed: {err.read().decode(errors='replace')[-400:]}")
    return seconds, usage.ru_maxrss / 1024


def median_run(runs: list[tuple[float, float]]) -> tuple[float, float]:
    """The median wall seconds of a side's runs, and the largest peak RSS among them."""
    return statistics.median(s for s, _ in runs), max(mb for _, mb in runs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agents", nargs="+", type=int, default=[50, 200, 500, 1000])
    ap.add_argument("--alg", nargs="+", default=["cbba", "grape", "greedy"], choices=list(OURS))
    ap.add_argument("--range", type=int, default=100, dest="comm", choices=[100, 200, 300])
    ap.add_argument("--horizon", type=int, default=600, help="simulated seconds at 50 agents")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--engines", nargs="+", default=["inprocess", "processes"], choices=["inprocess", "processes"])
    ap.add_argument("--repeat", type=int, default=1, help="runs of each side per cell, interleaved; medians shown")
    args = ap.parse_args()
    if not (Path(os.environ.get("SPACE_DIR", "/tmp/space")) / "main.py").exists():
        sys.exit("SPACE's code is not set up: run ../shared/tools/space-bench/setup.sh and export what it prints")
    head = f"{'agents':>6} {'horizon':>7} {'allocator':>9} {'SPACE s':>8} {'MB':>6}"
    head += "".join(f" {e + ' s':>12} {'MB':>6} {'x SPACE':>8}" for e in args.engines)
    print(head, flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.agents:
            horizon = max(10, round(args.horizon * 50 / n))
            for alg in args.alg:
                base = Path(tmp) / f"{alg}_{n}"
                runs: dict[str, list[tuple[float, float]]] = {}
                for r in range(args.repeat):  # SPACE, then each engine, then again: a slow minute falls on all
                    bench = space_run(alg, n, args.comm, args.seed, horizon, base / f"space{r}")
                    runs.setdefault("space", []).append((float(bench["total_wall_s"]), float(bench["peak_rss_mb"])))
                    for engine in args.engines:
                        cmd = our_command(alg, n, args.comm, args.seed, horizon, engine, base / f"{engine}{r}")
                        runs.setdefault(engine, []).append(timed(cmd))
                space_s, space_mb = median_run(runs["space"])
                line = f"{n:>6} {horizon:>7} {OURS[alg]:>9} {space_s:>8.1f} {space_mb:>6.0f}"
                for engine in args.engines:
                    ours_s, ours_mb = median_run(runs[engine])
                    line += f" {ours_s:>12.1f} {ours_mb:>6.0f} {space_s / ours_s:>8.2f}"
                print(line, flush=True)


if __name__ == "__main__":
    main()
