"""What splitting the radio over K netem proxies (``radio_split``) costs and saves per tick.

    python benchmarks/radio_split.py                         # 100 agents, K = 1, 2 and 4
    python benchmarks/radio_split.py --agents 200 --ticks 60 --shards 1 3

For each K, the same lock-step run in processes: the no-op allocator, every agent messaging every
other a tick (so the copies, N x (N - 1) a tick, are the proxies' work), range 60 and loss 0.1 on
the quick start's 200 x 150 arena, per-copy draws, regions as bands of equal shares of the agents
(``--regions strips --strip-width 50`` for strips). Printed per K: ticks per second; the proxies'
CPU per tick, all of them together and the busiest one (the critical path once each proxy has its
own core); and whether the result files equal K = 1's. Run it from a
separate non-editable install on an otherwise idle machine; on a machine with fewer cores than
K + 1 the proxies share cores with the agents, and ticks per second say little.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ("summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv")


def measure(agents: int, ticks: int, shards: int, out: Path, regions: str = "bands", strip_width: float = 50.0) -> dict:
    sets = [
        f"agents.count={agents}",
        f"allocator={{name: noop, peers: {agents - 1}}}",
        f"run.duration={ticks}",
        "run.stop_when_done=false",
        "network.range=60",
        "network.loss=0.1",
        "network.draws=per_copy",
        f"radio_split.regions={regions}",
        f"radio_split.strip_width={strip_width}",
        f"radio_split.shards={shards}",
    ]
    run_experiment(cfg.load(ROOT / "experiments" / "quickstart.yaml", sets), out, progress=False)
    t = json.loads((out / "timings.json").read_text())
    cpu = t["cpu_s"]
    return {
        "ticks_per_s": t["ticks_per_s"],
        "proxies_cpu_ms_per_tick": cpu["netem"] * 1000 / ticks,
        "busiest_proxy_cpu_ms_per_tick": cpu.get("netem_max", cpu["netem"]) * 1000 / ticks,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--agents", type=int, default=100)
    ap.add_argument("--ticks", type=int, default=100)
    ap.add_argument("--shards", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument(
        "--regions", choices=["bands", "strips"], default="bands", help="radio_split.regions (default bands)"
    )
    ap.add_argument(
        "--strip-width", type=float, default=50.0, help="the strips' width, with --regions strips (default 50)"
    )
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        first: Path | None = None
        print(
            f"{args.agents} agents, {args.ticks} ticks, {args.agents * (args.agents - 1):,} copies a tick, regions: "
            + ("bands of equal shares" if args.regions == "bands" else f"strips {args.strip_width:g} wide")
        )
        print(f"{'K':>3} {'ticks/s':>8} {'proxies ms/tick':>16} {'busiest ms/tick':>16}  results")
        for k in args.shards:
            out = Path(tmp) / f"k{k}"
            m = measure(args.agents, args.ticks, k, out, args.regions, args.strip_width)
            first = first or out
            same = all((first / f).read_bytes() == (out / f).read_bytes() for f in RESULTS)
            print(
                f"{k:>3} {m['ticks_per_s']:>8.1f} {m['proxies_cpu_ms_per_tick']:>16.2f} "
                f"{m['busiest_proxy_cpu_ms_per_tick']:>16.2f}  {'identical' if same else 'DIFFER'}"
            )


if __name__ == "__main__":
    main()
