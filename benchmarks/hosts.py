"""Runs over several hosts, measured side by side with all-local runs in one go (needs root and
iproute2: the hosts are stand-ins, network namespaces on a bridge, one ``swarmbed host`` each).

    sudo python benchmarks/hosts.py                 # 50 agents; 50 swaps; 100 agents placed
    sudo python benchmarks/hosts.py --agents 20 --swaps 10 --placed 40

Prints lock-step ticks per second with the agents split over 2 hosts against all local (the no-op
allocator, each agent messaging 5 peers per tick), the pause and snapshot size of swaps of CBBA
agents between the hosts (median and max), and the start-up time of a run whose agents are placed
on 2 hosts against all local. Every pair of runs also checks that its result files are identical.
"""

from __future__ import annotations

import argparse
import csv
import statistics
import tempfile
from pathlib import Path

import numpy as np

from swarmbed import config as cfg
from swarmbed.hosts.netns import Lab, LabError, make_lab
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ("summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv")


def _exp(*sets: str) -> cfg.Experiment:
    return cfg.load(ROOT / "experiments" / "quickstart.yaml", list(sets))


def _pair(lab: Lab, out: Path, sets: list[str], placed: list[str]) -> tuple[dict, dict]:
    """The same experiment all local and placed over the lab's hosts; (local, placed) timings."""
    local = run_experiment(_exp(*sets), out / "local", progress=False)
    spread = run_experiment(_exp(*sets, *placed), out / "spread", progress=False, hub=lab.hub_options())
    same = all((out / "local" / f).read_bytes() == (out / "spread" / f).read_bytes() for f in RESULTS)
    return {**local.timings, "same": same}, {**spread.timings, "same": same}


def split(n: int) -> str:
    half = n // 2
    return f"placement={{a: '0-{half - 1}', b: '{half}-{n - 1}'}}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agents", type=int, default=50, help="agents in the throughput and swap runs")
    ap.add_argument("--ticks", type=int, default=600, help="ticks of the throughput runs")
    ap.add_argument("--swaps", type=int, default=50, help="swaps in the swap run")
    ap.add_argument("--placed", type=int, default=100, help="agents in the start-up runs")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        try:
            lab = make_lab(out / "hosts")
        except LabError as exc:
            raise SystemExit(f"cannot make stand-in hosts: {exc}") from None
        try:
            lab.add_host("a")
            lab.add_host("b")
            n = args.agents
            noop = [
                f"agents.count={n}",
                "allocator={name: noop, peers: 5}",
                "scenario.initial_tasks=0",
                "run.stop_when_done=false",
                f"run.duration={args.ticks}",
                "network.range=null",
                "run.record_every=1000000",
            ]
            local, spread = _pair(lab, out / "throughput", noop, [split(n)])
            ratio = spread["ticks_per_s"] / local["ticks_per_s"]
            print(
                f"lock-step, {n} agents, no-op + 5 messages each per tick: all local {local['ticks_per_s']:.1f} "
                f"ticks/s, over 2 hosts {spread['ticks_per_s']:.1f} ({ratio:.2f}x); identical files: {local['same']}",
                flush=True,
            )

            rng = np.random.default_rng(1)
            ticks = sorted(int(t) for t in rng.choice(np.arange(1, 10 * args.swaps), args.swaps, replace=False))
            swaps = ", ".join(
                f"{{agent: {int(rng.integers(n))}, tick: {t}, to: {'ab'[k % 2]}}}" for k, t in enumerate(ticks)
            )
            cbba = [
                f"agents.count={n}",
                "allocator={name: cbba}",
                "run.stop_when_done=false",
                f"run.duration={10 * args.swaps + 10}",
                "scenario.initial_tasks=60",
                "scenario.width=600",
                "scenario.height=400",
                "run.record_every=1000000",
            ]
            local, spread = _pair(lab, out / "swaps", cbba, [split(n), f"swaps=[{swaps}]"])
            with open(out / "swaps" / "spread" / "swaps.csv") as f:
                records = list(csv.DictReader(f))
            ok = [r for r in records if r["outcome"] == "ok"]
            pauses = [float(r["pause_ms"]) for r in ok]
            sizes = [int(r["snapshot_bytes"]) for r in ok]
            print(
                f"swaps of CBBA agents between 2 hosts, {n} agents: {len(ok)} of {len(records)} ok; pause median "
                f"{statistics.median(pauses):.0f} ms, max {max(pauses):.0f} ms; snapshot median "
                f"{statistics.median(sizes):,.0f} B, max {max(sizes):,} B; identical files: {spread['same']}",
                flush=True,
            )

            m = args.placed
            start = [
                f"agents.count={m}",
                "allocator={name: noop}",
                "scenario.initial_tasks=0",
                "run.stop_when_done=false",
                "run.duration=20",
            ]
            local, spread = _pair(lab, out / "startup", start, [split(m)])
            print(
                f"start-up, {m} agents: all local {local['startup_s']:.1f} s, placed on 2 hosts "
                f"{spread['startup_s']:.1f} s; identical files: {local['same']}",
                flush=True,
            )
        finally:
            lab.close()


if __name__ == "__main__":
    main()
