"""Where First-Claimed Greedy's robots stood when they claimed their tasks: one run of the central
baselines' `unlimited` cell (everyone in radio reach, robots see 300 m) and the same seed with the
`oracle` cell's vision (2000 m: the whole arena), docs/baselines.md.

    python docs/scripts/fcg_claims.py 7        # run seed 7, both cells, about 3 minutes

Each run goes through the in-process engine (results under a temporary folder); the allocator's
``decide`` is wrapped to note every new claim (time, agent, task, distance to it), nothing else
changes. Prints the mission time, the claims, how far robots were from the tasks they claimed, over
all and after 4000 s (the last tenth of the tasks), and how many claims were beyond 300 m.
"""

from __future__ import annotations

import math
import statistics
import sys
import tempfile
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.launch.inprocess import run_in_process
from swarmbed.plugins import fcg

BASE = Path(__file__).resolve().parents[2] / "experiments" / "space_mtsr_code.yaml"
CELLS = {"unlimited": [], "oracle": ["agents.awareness_range=2000"]}
LATE_S = 4000.0


def claims_of(cell: str, seed: int, out: Path) -> tuple[dict, list[tuple[float, int, int, float]]]:
    """The run's summary and its claims as (time, agent, task, distance)."""
    noted: list[tuple[float, int, int, float]] = []
    decide = fcg.FirstClaimedGreedy.decide

    def noting(self, view):
        before = self.task
        choice = decide(self, view)
        if self.task is not None and self.task != before and self.task in view.tasks:
            task = view.tasks[self.task]
            noted.append((view.time, self.agent_id, self.task, math.hypot(task.x - view.x, task.y - view.y)))
        return choice

    sets = ["agents.count=30", "network.range=null", "allocator={name: fcg}", f"run.seed={seed}", *CELLS[cell]]
    fcg.FirstClaimedGreedy.decide = noting
    try:
        result = run_in_process(cfg.load(BASE, sets), out / cell)
    finally:
        fcg.FirstClaimedGreedy.decide = decide
    return result.summary, noted


def main(seed: int) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for cell in CELLS:
            summary, noted = claims_of(cell, seed, Path(tmp))
            far = [d for *_, d in noted]
            late = [d for t, *_, d in noted if t > LATE_S]
            print(
                f"{cell}: mission {summary['mission_time']:.0f} s, 95 % at {summary['time_95']:.0f} s, "
                f"{summary['distance_total'] / 1000:.1f} km driven; {len(noted)} claims, "
                f"{statistics.mean(far):.0f} m away on average (largest {max(far):.0f}), "
                f"{len(late)} after {LATE_S:.0f} s at {statistics.mean(late) if late else math.nan:.0f} m, "
                f"{sum(d > 300 for d in far)} beyond 300 m"
            )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 7)
