"""How well the real-time clock is kept: tick start lag and missed ticks at several speeds and sizes.

    python benchmarks/realtime.py                                  # speeds 1 10 50 x N 20 50 100, noop and cbba
    python benchmarks/realtime.py --speeds 10 --n 20 --allocators noop --seconds 10

Each case is the quickstart world on the real-time clock (dt 1 s, so speed s asks for s ticks per
wall second) for about ``--seconds`` of wall time. Prints, per case, the tick start lag p50/p99/max,
the share of ticks that started late (more than a tenth of a tick period after their wall time), and
the share of agent-ticks missed because an answer crossed the deadline.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent

ALLOCATORS = {"noop": "{name: noop, peers: 5}", "cbba": "{name: cbba}"}


def realtime_case(n: int, speed: float, allocator: str, seconds: float) -> dict:
    ticks = max(20, int(seconds * speed))
    exp = cfg.load(
        ROOT / "experiments" / "quickstart.yaml",
        [
            f"agents.count={n}",
            f"allocator={ALLOCATORS[allocator]}",
            f"scenario.initial_tasks={4 * n}",
            "run.stop_when_done=false",
            f"run.duration={ticks}",
            "run.clock=realtime",
            f"run.speed={speed}",
            "run.record_every=1000000",
        ],
    )
    with tempfile.TemporaryDirectory() as out:
        summary = run_experiment(exp, Path(out), progress=False).summary
    clock = summary["realtime"]
    return {
        "ticks": ticks,
        "lag": clock["start_lag_ms"],
        "started_late": clock["ticks_started_late"] / ticks,
        "missed": clock["late_ticks_total"] / (ticks * n),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--speeds", type=float, nargs="+", default=[1, 10, 50])
    ap.add_argument("--n", type=int, nargs="+", default=[20, 50, 100])
    ap.add_argument("--allocators", nargs="+", choices=sorted(ALLOCATORS), default=["noop", "cbba"])
    ap.add_argument("--seconds", type=float, default=30.0, help="wall time per case, start-up aside")
    args = ap.parse_args()
    print(
        f"{'alloc':>5} {'N':>4} {'speed':>6} {'ticks':>6} {'lag p50 ms':>11} {'p99 ms':>8} {'max ms':>8} "
        f"{'ticks late':>11} {'agent-ticks missed':>19}"
    )
    for allocator in args.allocators:
        for n in args.n:
            for speed in args.speeds:
                r = realtime_case(n, speed, allocator, args.seconds)
                lag = r["lag"]
                print(
                    f"{allocator:>5} {n:>4} {speed:>6g} {r['ticks']:>6} {lag['p50']:>11.2f} {lag['p99']:>8.2f} "
                    f"{lag['max']:>8.1f} {r['started_late']:>10.1%} {r['missed']:>18.2%}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
