"""Bytes the consensus allocators send: whole-state messages against messages of what changed
between whole ones (``full_every``), side by side in one run, with the outcome of each run so that
a change in results shows next to the bytes saved.

    python benchmarks/messages.py                        # MT-SR (30 agents) and SAR (20 robots)
    python benchmarks/messages.py --agents 100 --duration 500 --scenarios mtsr
    python benchmarks/messages.py --scenarios mtsr --allocators grape

Rows: allocator, full_every, messages sent, payload bytes, bytes per message, the ratio of bytes
to the whole-state row's, simulated seconds per wall second, and the outcome (MT-SR: tasks
completed; SAR: victims rescued). GRAPE's rows are its partition messages, whole against deltas;
FCG, which sends only its claims, is listed once for scale.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent
EXPERIMENTS = {"mtsr": ROOT / "experiments" / "space_mtsr.yaml", "sar": ROOT / "experiments" / "sar" / "_base.yaml"}
ROWS = {
    "mtsr": [("cbba", 1), ("cbba", 10), ("grape", 1), ("grape", 10), ("fcg", None)],
    "sar": [
        ("cbba", 1),
        ("cbba", 10),
        ("cbba-tree", 1),
        ("cbba-tree", 10),
        ("cbba-etc", 1),
        ("cbba-etc", 10),
        ("c-cbba", 1),
        ("c-cbba", 10),
    ],
}


def measure(scenario: str, allocator: str, full_every: int | None, agents: int, duration: float) -> dict:
    sets = [f"allocator.name={allocator}", f"run.duration={duration}", "run.stop_when_done=false"]
    if scenario == "mtsr":
        sets += [f"agents.count={agents}", "network.range=200"]
    if full_every is not None:
        sets.append(f"allocator.full_every={full_every}")
    exp = cfg.load(EXPERIMENTS[scenario], sets)
    with tempfile.TemporaryDirectory() as out:
        result = run_experiment(exp, Path(out), progress=False)
    s, net = result.summary, result.summary["network"]
    outcome = s["tasks_completed"] if scenario == "mtsr" else s["rescued"]
    return {
        "messages": net["messages_sent"],
        "bytes": net["bytes_sent"],
        "outcome": outcome,
        "sim_per_wall": exp.run.dt * s["ticks"] / result.timings["run_s"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenarios", nargs="+", choices=sorted(EXPERIMENTS), default=["mtsr", "sar"])
    ap.add_argument("--allocators", nargs="+", help="only these allocators' rows (default: all)")
    ap.add_argument("--agents", type=int, default=30, help="MT-SR agents (SAR keeps its 20 robots)")
    ap.add_argument("--duration", type=float, default=1000.0, help="simulated seconds per run")
    args = ap.parse_args()
    print(
        f"{'scenario':>8} {'allocator':>9} {'full_every':>10} {'messages':>9} {'payload MB':>10} {'B/message':>9} "
        f"{'bytes x':>7} {'sim s/wall s':>12} {'outcome':>8}"
    )
    for scenario in args.scenarios:
        whole: dict[str, int] = {}
        for allocator, full_every in ROWS[scenario]:
            if args.allocators and allocator not in args.allocators:
                continue
            m = measure(scenario, allocator, full_every, args.agents, args.duration)
            if full_every == 1:
                whole[allocator] = m["bytes"]
            ratio = f"{m['bytes'] / whole[allocator]:7.3f}" if allocator in whole else f"{'-':>7}"
            print(
                f"{scenario:>8} {allocator:>9} {full_every or '-':>10} {m['messages']:>9} {m['bytes'] / 1e6:>10.2f} "
                f"{m['bytes'] / max(m['messages'], 1):>9.1f} {ratio} {m['sim_per_wall']:>12.1f} "
                f"{m['outcome']!s:>8}",
                flush=True,
            )


if __name__ == "__main__":
    main()
