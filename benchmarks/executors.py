"""What handing a sweep to an executor costs: the same SAR sweep (six strategies x RUNS runs of the
CBBA-ETC baseline) through the local process pool and through a Dask LocalCluster of as many
one-thread workers, wall time side by side, plus each executor's overhead per run.

    python benchmarks/executors.py                      # 6 x 5 runs of 300 simulated s, 2 at once
    python benchmarks/executors.py --runs 5 --duration 3000 --parallel 2

Overhead per run is read from each run's ``attempts.jsonl`` (written where the run executed): for
every worker, the gap from the end of its previous run (or from the sweep's submission, for its
first) to the start of its next run, i.e. the time a free slot waited for work. Submitit's local
stand-in for Slurm is measured the same way on a 2-run sweep (it starts every array task at once,
so it cannot share a machine's cores with the others for the wall-time comparison).
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from swarmbed.campaigns import executors
from swarmbed.campaigns.sweep import load_sweep, run_sweep
from swarmbed.results.campaign_folders import ATTEMPTS

SAR = Path(__file__).resolve().parent.parent / "experiments" / "sar" / "base_R20_V100.yaml"


def overheads(out: Path, submitted: float) -> list[float]:
    """Seconds each run waited between a free worker and its start (see the module's docstring)."""
    by_worker: dict[tuple[str, int], list[tuple[float, str]]] = defaultdict(list)
    for path in out.glob(f"*/run_*/{ATTEMPTS}"):
        for line in path.read_text().splitlines():
            a = json.loads(line)
            by_worker[(a["host"], a["pid"])].append((a["time"], a["event"]))
    gaps = []
    for events in by_worker.values():
        free = submitted
        for t, event in sorted(events):
            if event == "start":
                gaps.append(t - free)
            else:
                free = t
    return gaps


def timed(name: str, executor: executors.Executor, runs: int, duration: int, work: Path) -> tuple[float, list[float]]:
    sweep = load_sweep(SAR, runs=runs, extra=[f"run.duration={duration}"])
    out = work / name
    t0 = time.time()
    table = run_sweep(sweep, out, progress=False, executor=executor)
    wall = time.time() - t0
    assert (table["status"] == "ok").all(), table[table["status"] != "ok"]
    return wall, overheads(out, t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5, help="runs per strategy (default 5)")
    ap.add_argument("--duration", type=int, default=300, help="simulated seconds per run (default 300)")
    ap.add_argument("--parallel", type=int, default=2, help="runs at once in both executors (default 2)")
    args = ap.parse_args()
    import distributed

    rows = []
    with tempfile.TemporaryDirectory(prefix="swarmbed-bench-exec-") as tmp:
        work = Path(tmp)
        wall, gaps = timed("local", executors.get("local", jobs=args.parallel), args.runs, args.duration, work)
        rows.append(("local pool", wall, gaps))
        print(f"  local: {wall:.1f} s", flush=True)
        with distributed.LocalCluster(
            n_workers=args.parallel, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster:
            wall, gaps = timed(
                "dask", executors.get("dask", scheduler=cluster.scheduler_address), args.runs, args.duration, work
            )
        rows.append(("dask LocalCluster", wall, gaps))
        print(f"  dask: {wall:.1f} s", flush=True)
        slurm = executors.get("slurm", folder=work / "slurm" / ".submitit", cluster="local", time="30")
        _, gaps = timed("slurm", slurm, 1, args.duration, work)  # 6 x 1 runs, all at once
        rows.append(("submitit local (6 runs at once)", None, gaps))
    n = 6 * args.runs
    print(
        f"\nSAR base_R20_V100, 6 strategies x {args.runs} runs of {args.duration} simulated s, "
        f"{args.parallel} runs at once"
    )
    print(f"{'executor':<34}{'wall s':>9}{'vs local':>10}{'overhead/run s: median':>24}{'max':>8}")
    local_wall = rows[0][1]
    for name, wall, gaps in rows:
        w = f"{wall:9.1f}{wall / local_wall:10.2f}" if wall is not None else f"{'-':>9}{'-':>10}"
        print(f"{name:<34}{w}{statistics.median(gaps):24.2f}{max(gaps):8.2f}")
    print(f"({n} runs per executor; overhead: a free worker's wait for its next run's start)")


if __name__ == "__main__":
    main()
