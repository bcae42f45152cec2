"""What authentication and access control cost: lock-step ticks per second with the hub's
user/password authentication and access-control rules on, and with an open hub, in the same run.

    python benchmarks/access.py             # 50 agents, 3 pairs
    python benchmarks/access.py --n 100 --pairs 2

The no-op allocator, each agent messaging 5 peers per tick (benchmarks/lockstep.py's case); the two
settings alternate so that drift of the machine falls on both.
"""

from __future__ import annotations

import argparse
import statistics

from lockstep import swarmbed_run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--ticks", type=int, default=600)
    args = ap.parse_args()
    rates: dict[bool, list[float]] = {True: [], False: []}
    startup: dict[bool, list[float]] = {True: [], False: []}
    for _ in range(args.pairs):
        for auth in (False, True):
            r = swarmbed_run(args.n, args.ticks, auth=auth)
            rates[auth].append(r["ticks_per_s"])
            startup[auth].append(r["startup_s"])
            print(
                f"  auth {'on ' if auth else 'off'}: {r['ticks_per_s']:.1f} ticks/s, start-up {r['startup_s']:.1f} s",
                flush=True,
            )
    on, off = statistics.median(rates[True]), statistics.median(rates[False])
    print(
        f"N={args.n}: open hub {off:.1f} ticks/s, authenticated with access control {on:.1f} ticks/s "
        f"(ratio {on / off:.3f}); start-up {statistics.median(startup[False]):.1f} s vs "
        f"{statistics.median(startup[True]):.1f} s (medians of {args.pairs})"
    )


if __name__ == "__main__":
    main()
