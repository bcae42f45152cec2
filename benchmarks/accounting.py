"""Bandwidth accounting measured: wire bytes against payload, report cost, and what a watcher costs.

    python benchmarks/accounting.py                      # defaults below
    python benchmarks/accounting.py --agents 20 --duration 600 --watch-agents 20

Prints, in one go:
- wire bytes against payload bytes (TCP bytes the agents sent / radio payload bytes) for FCG and
  CBBA on MT-SR and for cbba-etc on search and rescue;
- the time and size of a run's report (a CBBA run of ``--agents`` agents and ``--duration`` s, with
  the receiver-level ledger) and of a sweep's report (``--sweep-runs`` runs of two SAR strategies);
- lock-step ticks per second of the same run without and with a ``swarmbed watch`` attached
  (alternated, ``--repeats`` pairs), and whether their result files are identical.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.campaigns.sweep import load_sweep, run_sweep
from swarmbed.launch.hub import HubOptions
from swarmbed.launch.runner import run_experiment
from swarmbed.results.report import report
from swarmbed.wire.zenoh_session import free_loopback_endpoint

ROOT = Path(__file__).resolve().parent.parent
QUICKSTART = ROOT / "experiments" / "quickstart.yaml"
SAR_BASE = ROOT / "experiments" / "sar" / "_base.yaml"
RESULTS = ("summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv")


def overhead(out: Path, name: str, base: Path, sets: list[str]) -> None:
    run = run_experiment(cfg.load(base, sets), out / name, progress=False)
    t = json.loads((run.out_dir / "transport.json").read_text())["totals"]
    print(
        f"{name}: payload {t['radio_payload_bytes']:,} B, agents' samples {t['agent_sample_bytes_out']:,} B, "
        f"agents' TCP {t['agent_tcp_bytes_sent']:,} B: overhead {t['overhead_ratio']:.2f}x "
        f"({run.summary['ticks']:,} ticks, {run.summary['agents']} agents)",
        flush=True,
    )


def timed_report(folder: Path, what: str) -> None:
    t0 = time.perf_counter()
    page = report(folder)
    print(f"report of {what}: {time.perf_counter() - t0:.1f} s, {page.stat().st_size / 1e6:.1f} MB", flush=True)


def watched(out: Path, sets: list[str], watch: bool) -> dict:
    endpoint = free_loopback_endpoint()
    stop = threading.Event()
    watcher: list[subprocess.Popen] = []

    def attach() -> None:  # the watcher waits for the run to appear, as a user's would
        watcher.append(
            subprocess.Popen(
                [sys.executable, "-m", "swarmbed", "watch", "--connect", endpoint, "--wait", "60"],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
        stop.wait()

    thread = threading.Thread(target=attach)
    if watch:
        thread.start()
    try:
        run = run_experiment(cfg.load(QUICKSTART, sets), out, progress=False, hub=HubOptions(listen=[endpoint]))
    finally:
        stop.set()
        if watch:
            thread.join()
            for p in watcher:
                p.wait(timeout=30)
    return run.timings


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agents", type=int, default=100, help="agents of the CBBA run whose report is timed")
    ap.add_argument("--duration", type=float, default=3000, help="simulated seconds of that run")
    ap.add_argument("--sweep-runs", type=int, default=10, help="runs per strategy of the SAR sweep")
    ap.add_argument("--sweep-duration", type=float, default=600, help="simulated seconds of each sweep run")
    ap.add_argument("--watch-agents", type=int, default=50, help="agents of the watched runs")
    ap.add_argument("--watch-ticks", type=int, default=2000, help="ticks of the watched runs")
    ap.add_argument("--repeats", type=int, default=2, help="pairs of watched and unwatched runs")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        overhead(out, "FCG, MT-SR quickstart", QUICKSTART, [])
        overhead(out, "CBBA, MT-SR quickstart", QUICKSTART, ["allocator={name: cbba}"])
        overhead(out, "cbba-etc, SAR base (600 s)", SAR_BASE, ["allocator.name=cbba-etc", "run.duration=600"])

        n = args.watch_agents
        sets = [
            f"agents.count={n}",
            "allocator={name: noop, peers: 5}",
            "scenario.initial_tasks=0",
            "run.stop_when_done=false",
            f"run.duration={args.watch_ticks}",
            "network.range=null",
            "run.record_every=1000000",
        ]
        plain, seen = [], []
        for i in range(args.repeats):
            plain.append(watched(out / f"plain{i}", sets, watch=False))
            seen.append(watched(out / f"watched{i}", sets, watch=True))
        same = all(
            (out / "plain0" / f).read_bytes() == (out / f"watched{i}" / f).read_bytes()
            for i in range(args.repeats)
            for f in RESULTS
        )
        a = sum(t["ticks_per_s"] for t in plain) / len(plain)
        b = sum(t["ticks_per_s"] for t in seen) / len(seen)
        print(
            f"lock-step, {n} agents, no-op + 5 messages each per tick: {a:.1f} ticks/s unwatched, {b:.1f} "
            f"watched ({b / a:.2f}x; {args.repeats} pairs alternated); identical files: {same}",
            flush=True,
        )

        run = run_experiment(
            cfg.load(
                QUICKSTART,
                [
                    f"agents.count={args.agents}",
                    "allocator={name: cbba}",
                    f"run.duration={args.duration}",
                    "run.stop_when_done=false",
                    "scenario.initial_tasks=200",
                    "scenario.width=600",
                    "scenario.height=400",
                    "network.ledger=per_receiver",
                ],
            ),
            out / "big",
            progress=False,
        )
        timed_report(
            run.out_dir, f"a CBBA run, {args.agents} agents, {run.summary['ticks']:,} ticks, receiver-level ledger"
        )

        (out / "sweep.yaml").write_text(
            textwrap.dedent(f"""
            name: sar_costs
            base: {SAR_BASE}
            seed: 1
            runs: {args.sweep_runs}
            scenarios:
              - {{name: tree, set: {{allocator.name: tree}}}}
              - {{name: cbba-etc, set: {{allocator.name: cbba-etc}}}}
        """)
        )
        run_sweep(
            load_sweep(out / "sweep.yaml", extra=[f"run.duration={args.sweep_duration}"]),
            out / "sweep",
            jobs=2,
            progress=False,
        )
        timed_report(out / "sweep", f"a SAR sweep, 2 strategies x {args.sweep_runs} runs")


if __name__ == "__main__":
    main()
