"""Start-up time and memory per agent: agents forked from the fork server next to fresh interpreters.

    python benchmarks/startup.py                 # N = 50, 100, 200
    python benchmarks/startup.py --n 500 --only fork

The no-op allocator (5 messages per agent per tick), 100 ticks. Prints, per N and way of starting:
start-up (until every process joined) with its parts (fork server ready, processes spawned,
sessions opened and joined), memory per agent process (RSS counts every page it maps, shared or
not; PSS shares each shared page among its users; USS is what only it holds: what the machine
gives up per extra agent), and lock-step ticks per second.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent


def case(n: int, fork: bool, ticks: int) -> dict:
    exp = cfg.load(
        ROOT / "experiments" / "quickstart.yaml",
        [
            f"agents.count={n}",
            "allocator={name: noop, peers: 5}",
            "scenario.initial_tasks=0",
            "run.stop_when_done=false",
            f"run.duration={ticks}",
            "network.range=null",
            "run.record_every=1000000",
            "run.join_timeout=600",
        ],
    )
    with tempfile.TemporaryDirectory() as out:
        return run_experiment(exp, Path(out), progress=False, fork_agents=fork).timings


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[50, 100, 200])
    ap.add_argument("--only", choices=["fork", "exec"], help="one way of starting only")
    ap.add_argument("--ticks", type=int, default=100)
    args = ap.parse_args()
    ways = [args.only == "fork"] if args.only else [False, True]
    print(
        f"{'N':>4} {'start':>5} {'start-up s':>10} {'server s':>8} {'spawn s':>8} {'join s':>7} "
        f"{'RSS MB':>7} {'PSS MB':>7} {'USS MB':>7} {'ticks/s':>8}"
    )
    for n in args.n:
        for fork in ways:
            t = case(n, fork, args.ticks)
            s = t["startup"]
            server = f"{s['fork_server_s']:.2f}" if s["fork_server_s"] is not None else "-"
            print(
                f"{n:>4} {'fork' if fork else 'exec':>5} {t['startup_s']:>10.2f} {server:>8} {s['spawn_s']:>8.2f} "
                f"{s['join_s']:>7.2f} {t['agent_rss_mb_mean']:>7.1f} {t['agent_pss_mb_mean']:>7.1f} "
                f"{t['agent_uss_mb_mean']:>7.1f} {t['ticks_per_s']:>8.1f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
