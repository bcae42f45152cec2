"""Policies through swarmbed.envs beside the built-in allocators, on the same seeds and radio.

    python docs/scripts/env_policies.py                          # quick start, 5 seeds, 10 % loss
    python docs/scripts/env_policies.py --agents 10 --seeds 10 --set network.range=150

`random` (a uniform action) and `greedy` (always row 1: the nearest task in view) play through the
environment, and so do FCG and CBBA as policies (the environment's ``fallback``, deferred to at
every tick); FCG, CBBA and GRAPE also play as swarmbed runs them, which the policies must equal.
Every row is the mean over the same seeds: tasks completed, the mission time where every task was
done, and the radio's messages.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

import numpy as np

from swarmbed import config as cfg
from swarmbed.envs import SwarmbedParallelEnv
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent.parent
POLICIES = {
    "random": lambda obs, rng: int(rng.integers(0, len(obs["task_mask"]) + 1)),
    "greedy": lambda obs, rng: 1 if obs["task_mask"][0] else 0,
}


def through_env(policy, sets: list[str], seed: int) -> dict:
    fallback = policy if policy not in POLICIES else None
    env = SwarmbedParallelEnv(ROOT / "experiments" / "quickstart.yaml", sets, fallback=fallback)
    rng = np.random.default_rng(seed)
    try:
        obs, _ = env.reset(seed=seed)
        while env.agents:
            if fallback is not None:
                obs, *_ = env.step(dict.fromkeys(env.agents, env.defer))
            else:
                obs, *_ = env.step({a: POLICIES[policy](obs[a], rng) for a in env.agents})
        return env.results[-1].summary
    finally:
        env.close()


def built_in(name: str, sets: list[str], seed: int) -> dict:
    exp = cfg.load(ROOT / "experiments" / "quickstart.yaml", [*sets, f"allocator.name={name}", f"run.seed={seed}"])
    with tempfile.TemporaryDirectory() as out:
        return run_experiment(exp, Path(out), progress=False).summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agents", type=int, default=5)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--loss", type=float, default=0.1)
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    sets = [f"agents.count={args.agents}", f"network.loss={args.loss}", *args.sets]
    print(f"quick start, {args.agents} agents, loss {args.loss}, seeds 0-{args.seeds - 1}: means")
    print("| policy | via | tasks completed | all done | mission time (s) | messages |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    rows = [(p, "swarmbed.envs", lambda s, p=p: through_env(p, sets, s)) for p in (*POLICIES, "fcg", "cbba")]
    rows += [(a, "built-in", lambda s, a=a: built_in(a, sets, s)) for a in ("nearest", "fcg", "cbba", "grape")]
    for name, via, play in rows:
        runs = [play(seed) for seed in range(args.seeds)]
        done = [r for r in runs if r["all_tasks_completed"]]
        mission = statistics.mean(r["mission_time"] for r in done) if done else float("nan")
        print(
            f"| {name} | {via} | {statistics.mean(r['tasks_completed'] for r in runs):.1f} | {len(done)}/{len(runs)} "
            f"| {mission:.0f} | {statistics.mean(r['network']['messages_sent'] for r in runs):.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
