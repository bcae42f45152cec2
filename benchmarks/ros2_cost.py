"""What publishing a run as ROS 2 topics costs: space_mtsr with and without ``ros2:``, in pairs,
reading each run's CPU per agent-tick by process kind and its ticks per second.

    python benchmarks/ros2_cost.py                  # 50 agents, FCG, 300 s, two pairs
    python benchmarks/ros2_cost.py --n 100 --pairs 3 --allocator cbba

Run from a non-editable install on an idle machine (docs/benchmarks.md, "ROS 2 publishing").
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--allocator", default="fcg")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--pairs", type=int, default=2)
    args = ap.parse_args()
    print(f"{'N':>4} {'ros2':>4} {'ticks/s':>8} {'hub us':>7} {'agents us':>9} {'netem us':>8} {'wake-ups':>8}")
    for _ in range(args.pairs):
        for on in (False, True):
            sets = [
                f"agents.count={args.n}",
                f"run.duration={args.duration}",
                "run.stop_when_done=false",
                f"allocator.name={args.allocator}",
            ]
            if on:
                sets.append("ros2={domain: 9}")
            exp = cfg.load(ROOT / "experiments" / "space_mtsr.yaml", sets)
            with tempfile.TemporaryDirectory() as out:
                result = run_experiment(exp, Path(out), progress=False)
            t = result.timings
            cpu, wake = t["per_agent_tick"]["cpu_us"], t["per_agent_tick"]["wakeups"]
            print(
                f"{args.n:>4} {'on' if on else 'off':>4} {result.summary['ticks'] / t['run_s']:>8.1f} "
                f"{cpu['hub']:>7.0f} {cpu['agents']:>9.0f} {cpu['netem']:>8.0f} {wake['total']:>8.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
