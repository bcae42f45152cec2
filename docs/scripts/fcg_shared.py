"""How much of First-Claimed Greedy's work is doubled up: the share of agent-steps spent on a task
another agent holds at that step, in our FCG and in SPACE's own (docs/reproduction.md section 7).
SPACE's code on the 30-agent configuration (its config/example/greedy_a50_c<RANGE>.yaml with 30
agents, 10,000 s), ours on experiments/space_mtsr_code.yaml with 30 agents.

    python docs/scripts/fcg_shared.py ours SEED RANGE [unseen|id_order]   # allocator.same_tick_claims
    SPACE_DIR=... SPACE_PY=... python docs/scripts/fcg_shared.py space SEED RANGE

Ours goes through the in-process engine (results in a temporary folder), with the allocator's
``decide`` wrapped to note each agent's task each tick; the line also counts the agent-ticks whose
task another agent claimed at the same tick. SPACE's runs in its own environment
(``../shared/tools/space-bench``'s setup.sh prints SPACE_DIR and SPACE_PY): this script re-runs itself
there (``_space``), seeds ``random`` as space-bench does, and wraps SPACE's ``FirstClaimGreedy.decide``
the same way, its code unchanged; a step is every agent's decide once, in SPACE's id order.
"""

from __future__ import annotations

import collections
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
AGENTS = 30
MARK = "fcg_shared"  # the line SPACE's run prints its count on


def shared_line(who: str, held: collections.Counter, same_tick: int | None = None) -> str:
    """``held``: (step, task) -> agents on it."""
    total = sum(held.values())
    shared = sum(v for v in held.values() if v > 1)
    line = f"{who}: agent-steps on a task {total:,}; on a task another agent holds {shared / total:.1%}"
    if same_tick is not None:
        line += f"; of them claimed at the same tick as another's {same_tick / total:.1%}"
    return line


def ours(seed: int, radio_range: int, same_tick_claims: str) -> None:
    from swarmbed import config as cfg
    from swarmbed.launch.inprocess import run_in_process
    from swarmbed.plugins import fcg

    noted: dict[tuple[int, int], list[int]] = collections.defaultdict(list)  # (tick, task) -> claim ticks
    decide = fcg.FirstClaimedGreedy.decide

    def noting(self, view):
        task = decide(self, view)
        if task is not None:
            noted[(view.tick, task)].append(self.claimed_at)
        return task

    sets = [f"agents.count={AGENTS}", f"network.range={radio_range}", f"run.seed={seed}"]
    sets.append(f"allocator={{name: fcg, same_tick_claims: {same_tick_claims}}}")
    fcg.FirstClaimedGreedy.decide = noting
    try:
        with tempfile.TemporaryDirectory() as tmp:
            summary = run_in_process(
                cfg.load(ROOT / "experiments" / "space_mtsr_code.yaml", sets), Path(tmp) / "run"
            ).summary
    finally:
        fcg.FirstClaimedGreedy.decide = decide
    held = collections.Counter({key: len(v) for key, v in noted.items()})
    same = sum(len(v) for v in noted.values() if len(v) > 1 and len(set(v)) < len(v))
    print(shared_line(f"ours ({same_tick_claims}), seed {seed}, range {radio_range}", held, same))
    print(f"  time to 95 % {summary['time_95']:.0f} s, mission {summary['mission_time']:.0f} s")


def space(seed: int, radio_range: int) -> None:
    space_dir, space_py = os.environ["SPACE_DIR"], os.environ["SPACE_PY"]
    mkcfg = Path(os.environ.get("SPACE_BENCH", ROOT.parent / "shared" / "tools" / "space-bench")) / "mkcfg.py"
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "cfg.yaml"
        example = Path(space_dir) / "config" / "example" / f"greedy_a50_c{radio_range}.yaml"
        subprocess.run([space_py, str(mkcfg), str(example), str(config), "10000", tmp, str(AGENTS)], check=True)
        env = {**os.environ, "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}
        argv = [space_py, __file__, "_space", str(seed), str(config), space_dir]
        out = subprocess.run(argv, env=env, cwd=space_dir, capture_output=True, text=True, check=True)
    line = next(x for x in out.stderr.splitlines() if x.startswith(MARK))
    print(line.replace(MARK, f"SPACE, seed {seed}, range {radio_range}", 1))


def _space(seed: int, config: str, space_dir: str) -> None:
    """Inside SPACE's environment: its main.py with ``decide`` noted (stdout is SPACE's)."""
    import atexit
    import random
    import runpy

    random.seed(seed)
    os.chdir(space_dir)
    sys.path.insert(0, space_dir)
    sys.argv = ["main.py", f"--config={config}"]
    import modules.utils as space_utils

    space_utils.set_config(config)
    import plugins.greedy.greedy as greedy

    calls, held = [0], collections.Counter()
    decide = greedy.FirstClaimGreedy.decide

    def noting(self, blackboard):
        task = decide(self, blackboard)
        if task is not None:
            held[(calls[0] // AGENTS, task)] += 1
        calls[0] += 1
        return task

    greedy.FirstClaimGreedy.decide = noting
    atexit.register(lambda: print(shared_line(MARK, held), file=sys.stderr))
    runpy.run_path("main.py", run_name="__main__")


if __name__ == "__main__":
    mode, *args = sys.argv[1:]
    if mode == "ours":
        ours(int(args[0]), int(args[1]), args[2] if len(args) > 2 else "unseen")
    elif mode == "space":
        space(int(args[0]), int(args[1]))
    elif mode == "_space":
        _space(int(args[0]), args[1], args[2])
    else:
        raise SystemExit("usage: fcg_shared.py ours SEED RANGE [unseen|id_order] | space SEED RANGE")
