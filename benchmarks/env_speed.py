"""swarmbed.envs: environment steps per second and reset time, beside a plain run of the same
configuration (the quick start's MT-SR with the built-in nearest allocator, whose policy the
environment's greedy policy plays, so both runs do the same work).

    python benchmarks/env_speed.py                    # 10 and 50 agents, 300 ticks, both engines
    python benchmarks/env_speed.py --n 10 --ticks 1000 --engine inprocess

The floor beside each: a plain run of the same configuration on the same engine (ticks/s).

Run from a non-editable install on an idle machine.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.envs import SwarmbedParallelEnv
from swarmbed.launch.inprocess import run_in_process
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[10, 50])
    ap.add_argument("--ticks", type=int, default=300)
    ap.add_argument("--engine", nargs="+", default=["inprocess", "processes"], choices=["inprocess", "processes"])
    args = ap.parse_args()
    print(
        f"{'engine':>10} {'N':>4} {'reset s':>8} {'env steps/s':>12} {'run ticks/s':>12} {'env / run':>9} "
        f"{'CPU us/step':>12}"
    )
    for engine in args.engine:
        for n in args.n:
            measure(engine, n, args.ticks)


def measure(engine: str, n: int, ticks: int) -> None:
    """One line: the environment's steps on ``engine`` at ``n`` agents, beside a plain run's ticks."""
    sets = [f"agents.count={n}", f"run.duration={ticks}", "run.stop_when_done=false"]
    env = SwarmbedParallelEnv(ROOT / "experiments" / "quickstart.yaml", sets, engine=engine)
    try:
        t0 = time.perf_counter()
        obs, _ = env.reset(seed=1)
        reset_s = time.perf_counter() - t0
        steps, t1, c1 = 0, time.perf_counter(), time.process_time()
        while env.agents:
            obs, *_ = env.step({a: 1 if obs[a]["task_mask"][0] else 0 for a in env.agents})
            steps += 1
        env_rate = steps / (time.perf_counter() - t1)
        cpu_us = 1e6 * (time.process_time() - c1) / steps  # this process's: all of it in-process
    finally:
        env.close()
    exp = cfg.load(ROOT / "experiments" / "quickstart.yaml", [*sets, "allocator.name=nearest", "run.seed=1"])
    with tempfile.TemporaryDirectory() as out:
        if engine == "inprocess":
            result = run_in_process(exp, Path(out) / "run")
        else:
            result = run_experiment(exp, Path(out), progress=False)
    run_rate = result.summary["ticks"] / result.timings["run_s"]
    print(
        f"{engine:>10} {n:>4} {reset_s:>8.2f} {env_rate:>12.1f} {run_rate:>12.1f} {env_rate / run_rate:>9.2f} "
        f"{cpu_us:>12.0f}",
        flush=True,
    )


if __name__ == "__main__":
    main()
