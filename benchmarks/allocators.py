"""CBBA, GRAPE and FCG on the SPACE MT-SR scenario: simulated seconds per wall second, the peak
RSS of the largest process and the memory the agents hold, at 10, 50 and 100 agents over 3000
simulated seconds and at 200 and 500 over a shorter horizon (``--large-duration``).

    python benchmarks/allocators.py                          # N = 10, 50, 100 (about 10 minutes)
    python benchmarks/allocators.py --n 200 500 --allocators fcg cbba
    python benchmarks/allocators.py --n 10 --duration 500
    python benchmarks/allocators.py --n 200 --allocators grape --set allocator.full_every=10

Printed next to the public SPACE simulator's own figures, measured with SPACE's code on this
machine kind on 2026-11-27 (``../shared/tools/space-bench/``, its example configs at range 100,
300 simulated s, mean of seeds 11-13, idle): 50 agents CBBA 245, GRAPE 212, FCG 374; 100 agents
89, 83, 174 (docs/benchmarks.md; the figures printed here before, CBBA 19 at 100 agents among
them, were not what SPACE's code does on these cells). This machine kind's speed varies by a
quarter from day to day, so each N also gets the bare barrier measured in the same run
(``lockstep.py``'s floor: one sample in and one out per process per tick, no message, no Python
work). At 1 Hz its ticks per second are the most simulated seconds per wall second any design
with a process per agent can reach here today.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from lockstep import floor as barrier

from swarmbed import config as cfg
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent

SPACE_REFERENCE = {
    (50, "cbba"): 245,
    (50, "grape"): 212,
    (50, "fcg"): 374,
    (100, "cbba"): 89,
    (100, "grape"): 83,
    (100, "fcg"): 174,
}
LARGE = 200  # from this many agents on, the shorter horizon


def measure(n: int, allocator: str, duration: float, sets: tuple[str, ...] = ()) -> dict:
    exp = cfg.load(
        ROOT / "experiments" / "space_mtsr.yaml",
        [
            f"agents.count={n}",
            f"allocator.name={allocator}",
            f"run.duration={duration}",
            "run.stop_when_done=false",
            "run.join_timeout=600",
            *sets,
        ],
    )
    with tempfile.TemporaryDirectory() as out:
        result = run_experiment(exp, Path(out), progress=False)
    t = result.timings
    return {
        "sim_per_wall": exp.run.dt * (result.summary["ticks"]) / t["run_s"],
        "peak_rss_mb": max(t["peak_rss_mb"].values()),
        "startup_s": t["startup_s"],
        "agents_uss_gb": t["agent_uss_mb_mean"] * n / 1024,
        "bytes": result.summary["network"]["bytes_sent"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[10, 50, 100])
    ap.add_argument("--allocators", nargs="+", default=["cbba", "grape", "fcg"])
    ap.add_argument("--duration", type=float, default=3000.0)
    ap.add_argument("--large-duration", type=float, default=300.0, help=f"horizon from {LARGE} agents on")
    ap.add_argument(
        "--set",
        dest="sets",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a key of every run (repeatable), as `swarmbed run --set` does",
    )
    ap.add_argument("--floor-seconds", type=float, default=6.0, help="rough time measuring the barrier, per N")
    args = ap.parse_args()
    print(
        f"{'N':>4} {'allocator':>9} {'sim s':>6} {'sim s/wall s':>13} {'SPACE':>6} {'ratio':>6} {'barrier':>8} "
        f"{'/barrier':>8} {'peak RSS MB':>12} {'agents USS GB':>13} {'start-up s':>10} {'payload MB':>10}"
    )
    for n in args.n:
        duration = args.large_duration if n >= LARGE else args.duration
        floor = barrier("B0", n, max(50, int(max(20, 5000 // n) * args.floor_seconds)))["ticks_per_s"]
        for name in args.allocators:
            m = measure(n, name, duration, tuple(args.sets))
            ref = SPACE_REFERENCE.get((n, name))
            ratio = f"{m['sim_per_wall'] / ref:6.2f}" if ref else f"{'-':>6}"
            print(
                f"{n:>4} {name:>9} {duration:>6.0f} {m['sim_per_wall']:>13.1f} {ref or '-':>6} {ratio} "
                f"{floor:>8.1f} {m['sim_per_wall'] / floor:>8.2f} {m['peak_rss_mb']:>12.0f} "
                f"{m['agents_uss_gb']:>13.2f} {m['startup_s']:>10.1f} {m['bytes'] / 1e6:>10.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
