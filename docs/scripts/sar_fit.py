"""The search-and-rescue action model against the facts it must meet (docs/reproduction.md, section 2;
issue 44 item 1): `tree` at 100 victims (about 430 rescues per 3000 s, failed / rescued about 2.0)
**and** the capacity the paper's strongest strategies show at 500 victims (about 2,900 rescues per
3000 s with 20 robots), with the robots' time budget beside each.

The capacity is measured with an oracle, not a strategy: every robot knows every victim's place and
colour and takes the nearest victim of its colour that no other robot holds; it still approaches,
inspects and rescues as the world demands. No strategy that must find victims and agree on them
does better, so a world whose oracle rescues fewer than 2,900 cannot show the paper's figure.

    python docs/scripts/sar_fit.py --inspect 10 15 20 30 --interrupt never on_change --trials 3

prints one JSON line per setting: tree's rescued, failed per rescue and budget at V100, and the
oracle's rescued and budget at V500, per 1000 s (a 3000 s trial rescues about 2.9 times as many).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from statistics import mean

import numpy as np
from tree_world import BASE, trial  # this folder is on sys.path when the script runs

from swarmbed import config as cfg
from swarmbed.config import resolve_experiment
from swarmbed.engine.session import run_world
from swarmbed.scenarios.sar import ALIVE


def oracle(overrides: list[str], seed: int) -> dict:
    """One trial of the colour-aware oracle on the world alone (see the module's docstring)."""
    exp = cfg.load(BASE, ["allocator.name=cbba-etc", f"run.seed={seed}", *overrides])
    resolved = resolve_experiment(exp)
    world = run_world(exp, resolved.scenario(), resolved.allocator_cls)  # the world a run of exp steps
    held: dict[int, int] = {}  # robot -> victim
    for _ in range(round(exp.run.duration / exp.run.dt)):
        alive = np.flatnonzero(world.vstatus == ALIVE)
        ids = alive + world.base
        taken = set(held.values())
        actions = {}
        for i in range(world.n):
            v = held.get(i)  # a victim gone meanwhile was let go after the last tick
            if v is None:
                mine = [(r, int(x)) for r, x in zip(alive, ids) if world.vcolor[r] == world.color[i] and x not in taken]
                if not mine:
                    continue
                r, v = min(mine, key=lambda p: math.hypot(world.vx[p[0]] - world.ax[i], world.vy[p[0]] - world.ay[i]))
                held[i] = v
                taken.add(v)
            if not world._in_reach(i, v):
                actions[i] = ["goto_task", v]
            elif i not in world.inspected.get(v, ()):
                actions[i] = ["inspect", v]
            else:
                actions[i] = ["rescue", v]
        world.apply(actions)
        for i, v in list(held.items()):
            if world._at(v) is None or world.vstatus[v - world.base] != ALIVE:
                del held[i]
    return world.summary()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inspect", type=float, nargs="+", default=[30.0], help="inspection times (s)")
    parser.add_argument("--interrupt", nargs="+", default=["never"], help="scenario.interrupt values")
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--duration", type=float, default=1000.0)
    parser.add_argument("--seed", type=int, default=11, help="trial t uses seed + t")
    parser.add_argument("--set", action="append", default=[], help="a further experiment override, KEY=VALUE")
    args = parser.parse_args()
    for interrupt in args.interrupt:
        for inspect in args.inspect:
            sets = [
                f"run.duration={args.duration}",
                f"scenario.inspect_time={inspect}",
                f"scenario.interrupt={interrupt}",
                *args.set,
            ]
            trees = [trial(sets, args.seed + t) for t in range(args.trials)]
            oracles = [oracle([*sets, "scenario.victims=500"], args.seed + t) for t in range(args.trials)]
            out = {
                "inspect_time": inspect,
                "interrupt": interrupt,
                "tree_rescued": mean(r["rescued"] for r in trees),
                "tree_failed_per_rescue": round(
                    sum(r["failed_rescues"] for r in trees) / max(1, sum(r["rescued"] for r in trees)), 3
                ),
                "tree_budget": _budget(trees),
                "oracle_v500_rescued": mean(r["rescued"] for r in oracles),
                "oracle_budget": _budget(oracles),
                "set": args.set,
            }
            print(json.dumps(out), flush=True)


def _budget(runs: list[dict]) -> dict[str, float]:
    keys = [k for k in runs[0]["time_budget"] if k != "robot_seconds"]
    return {k: round(mean(r["time_budget"][k] for r in runs), 3) for k in keys}


if __name__ == "__main__":
    assert Path(__file__).parent.name == "scripts"
    main()
