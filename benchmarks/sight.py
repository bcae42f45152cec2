"""What a team sees, per tick: ``swarmbed.extension.sight`` for the whole team in one array
operation, against the floor measured in the same run, the same function called one robot at a time
(the shape of the SAR world's loop before 2026-11-29, whose own per-robot code was leaner: the
whole-run figures are in docs/benchmarks.md). Both are asked the same questions (robots' cones over
the live victims, and over the other robots); their answers are checked equal before anything is
timed.

    python benchmarks/sight.py                       # 20 robots x 100 victims (the CBBA-ETC baseline), 50 x 500
    python benchmarks/sight.py --team 20 --points 100 --walls

Microseconds per tick, median of interleaved repeats (team, one by one, team, ...); the ratio is
what to compare between days. Run from a non-editable install on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from swarmbed.extension.scenario import sight
from swarmbed.schema.obstacles import ObstaclesSection, Walls

RADIUS, REACH, ANGLE = 32.0, 12.0, math.pi / 2  # the CBBA-ETC arena and vision (experiments/sar/_base.yaml)


def _disc(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    r, a = RADIUS * np.sqrt(rng.random(n)), rng.uniform(-math.pi, math.pi, n)
    return r * np.cos(a), r * np.sin(a)


def _rubble(rng: np.random.Generator, pieces: int = 14) -> Walls:
    x, y = _disc(rng, pieces)
    turn = rng.uniform(0, math.pi, pieces)
    walls = [
        {
            "start": [float(a - 3 * math.cos(t)), float(b - 3 * math.sin(t))],
            "end": [float(a + 3 * math.cos(t)), float(b + 3 * math.sin(t))],
        }
        for a, b, t in zip(x, y, turn)
    ]
    return ObstaclesSection(walls=walls).compile()


def case(team: int, points: int, walls: bool, repeats: int, ticks: int) -> tuple[float, float]:
    rng = np.random.default_rng(7)
    obstacles = _rubble(rng) if walls else None
    ox, oy = _disc(rng, team)
    heading = rng.uniform(-math.pi, math.pi, team)
    x, y = _disc(rng, points)

    def whole() -> list[np.ndarray]:
        return [sight(ox, oy, px, py, REACH, heading, ANGLE, obstacles) for px, py in ((x, y), (ox, oy))]

    def one_by_one() -> list[np.ndarray]:
        return [
            np.vstack(
                [
                    sight(ox[i : i + 1], oy[i : i + 1], px, py, REACH, heading[i : i + 1], ANGLE, obstacles)
                    for i in range(team)
                ]
            )
            for px, py in ((x, y), (ox, oy))
        ]

    assert all(np.array_equal(a, b) for a, b in zip(whole(), one_by_one())), "the two ways disagree"
    timed: dict[str, list[float]] = {"team": [], "one": []}
    for _ in range(repeats):
        for name, fn in (("team", whole), ("one", one_by_one)):
            start = time.perf_counter()
            for _ in range(ticks):
                fn()
            timed[name].append((time.perf_counter() - start) / ticks * 1e6)
    return statistics.median(timed["team"]), statistics.median(timed["one"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--team", type=int, nargs="+", default=[20, 50])
    ap.add_argument("--points", type=int, nargs="+", default=[100, 500], help="victims, one count per team size")
    ap.add_argument("--walls", action="store_true", help="a rubble field of 14 slabs, line of sight")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--ticks", type=int, default=200)
    args = ap.parse_args()
    print(f"{'robots':>6} {'victims':>7} {'walls':>5} {'team us/tick':>13} {'one by one':>11} {'ratio':>6}")
    for team, points in zip(args.team, args.points):
        whole, one = case(team, points, args.walls, args.repeats, args.ticks)
        print(
            f"{team:>6} {points:>7} {'yes' if args.walls else 'no':>5} {whole:>13.1f} {one:>11.1f} {whole / one:>6.2f}"
        )


if __name__ == "__main__":
    main()
