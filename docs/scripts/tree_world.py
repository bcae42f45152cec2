"""The non-communicating `tree` strategy in the search-and-rescue world, in one process: the world,
every robot's runtime and the radio stepped by the in-process engine (swarmbed.engine): a real
run's results for the same configuration and seed, without Zenoh. For the world's calibration
(docs/reproduction.md, section 2): a search over the action model is hundreds of trials; the
chosen model is then checked with real runs (`swarmbed sweep experiments/sar/calibration_tree.yaml`).

    python docs/scripts/tree_world.py --trials 3 --duration 1000 --set scenario.inspect_time=25

prints the mean rescued, failed rescues, their ratio and expired per trial, and the robots' time
budget (the share of robot time moving, inspecting, rescuing, in move penalties and idle), as JSON.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from statistics import mean

from swarmbed import config as cfg
from swarmbed.launch.inprocess import run_in_process

BASE = Path(__file__).resolve().parents[2] / "experiments" / "sar" / "_base.yaml"


def trial(overrides: list[str], seed: int) -> dict:
    """One trial's summary, from the in-process engine (the result files go to a temporary folder)."""
    exp = cfg.load(BASE, ["allocator.name=tree", f"run.seed={seed}", *overrides])
    with tempfile.TemporaryDirectory() as out:
        return run_in_process(exp, Path(out)).summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--duration", type=float, default=1000.0)
    parser.add_argument("--seed", type=int, default=1, help="trial t uses seed + t")
    parser.add_argument("--set", action="append", default=[], help="an experiment override, KEY=VALUE")
    args = parser.parse_args()
    runs = [trial([f"run.duration={args.duration}", *args.set], args.seed + t) for t in range(args.trials)]
    keys = ("rescued", "failed_rescues", "expired", "stale_actions", "inspections")
    out = {k: mean(r[k] for r in runs) for k in keys}
    out["failed_per_rescue"] = out["failed_rescues"] / max(out["rescued"], 1e-9)
    out["time_budget"] = {k: round(mean(r["time_budget"][k] for r in runs), 4) for k in runs[0]["time_budget"]}
    out["rescued_each"] = [r["rescued"] for r in runs]
    out["set"] = args.set
    print(json.dumps(out))


if __name__ == "__main__":
    main()
