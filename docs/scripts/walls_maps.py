"""Writes the obstacles of the shipped walls experiments (experiments/walls/*.yaml): an office
floor for MT-SR (two rows of rooms off a corridor, a door in each room's corridor wall) and a rubble
field for search and rescue (small polygons scattered by a fixed seed). Run it to regenerate them:

    python docs/scripts/walls_maps.py
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

OUT = Path(__file__).resolve().parents[2] / "experiments" / "walls"


def office(width: float = 1400, height: float = 1000, rooms: int = 7, corridor: float = 100, door: float = 60) -> dict:
    """Rooms of width / ``rooms`` below and above a corridor along the middle; each room's corridor
    wall (heavy) has a door in its middle; rooms are parted by light walls."""
    room = width / rooms
    low, high = (height - corridor) / 2, (height + corridor) / 2
    walls = []
    for k in range(rooms):
        x0, x1, mid = k * room, (k + 1) * room, (k + 0.5) * room
        for y in (low, high):
            walls.append({"start": [x0, y], "end": [mid - door / 2, y], "material": "heavy"})
            walls.append({"start": [mid + door / 2, y], "end": [x1, y], "material": "heavy"})
        if k:
            walls.append({"start": [x0, 0.0], "end": [x0, low], "material": "light"})
            walls.append({"start": [x0, high], "end": [x0, height], "material": "light"})
    return {"walls": walls, "clearance": 5.0}


def rubble(radius: float = 32.0, pieces: int = 14, seed: int = 2026) -> dict:
    """``pieces`` convex slabs of 1.5-4 m, at least 4 m apart and 3 m inside the arena's edge."""
    rng = np.random.default_rng(seed)
    centres: list[tuple[float, float]] = []
    polygons = []
    while len(polygons) < pieces:
        r, a = (radius - 7) * math.sqrt(rng.random()), rng.uniform(-math.pi, math.pi)
        c = (r * math.cos(a), r * math.sin(a))
        if any(math.dist(c, o) < 8.0 for o in centres):
            continue
        centres.append(c)
        sides = int(rng.integers(3, 7))
        size = rng.uniform(1.5, 4.0)
        turn = rng.uniform(0, 2 * math.pi)
        points = [
            [
                round(c[0] + size * math.cos(turn + 2 * math.pi * k / sides), 3),
                round(c[1] + size * math.sin(turn + 2 * math.pi * k / sides), 3),
            ]
            for k in range(sides)
        ]
        polygons.append({"points": points, "material": "heavy"})
    return {"polygons": polygons, "clearance": 0.5}


def main() -> None:
    for name, obstacles in (("office_obstacles.yaml", office()), ("rubble_obstacles.yaml", rubble())):
        text = yaml.safe_dump({"obstacles": obstacles}, sort_keys=False, default_flow_style=None)
        (OUT / name).write_text(f"# written by docs/scripts/walls_maps.py: do not edit by hand\n{text}")
        print(OUT / name)


if __name__ == "__main__":
    main()
