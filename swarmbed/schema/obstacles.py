"""Obstacles: the walls of a world (the ``obstacles:`` section) and the one test every part asks of
them, whether a straight line crosses a wall.

An experiment declares wall segments and closed polygons in world coordinates; a polygon is the
walls along its edges and its inside. Motion (robots never cross a wall), sight (a robot sees what
no wall hides) and the radio (``network.walls``: each wall a copy's straight path crosses costs
its material's loss in dB; with the disc model, ``line_of_sight`` drops such copies) all read the
same segments through :class:`Walls`. Left out, a world has no obstacles and every result file is
what it was before they existed.

A line *crosses* a wall when the two segments share a point, their ends included (a line that
grazes a wall's end is blocked by it); two segments on one line cross only where they overlap.
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import Annotated

import numpy as np
from numpy.typing import ArrayLike
from pydantic import BaseModel, ConfigDict, Field, model_validator

#: the most walls (segments and polygon edges together) a world may have: each copy of a tick's
#: messages and each sight line is tested against every wall
MAX_WALLS = 2000
#: the most vertices one polygon may have
MAX_VERTICES = 256

Point = tuple[float, float]
#: a point as an experiment writes it: [x, y]
XY = Annotated[list[float], Field(min_length=2, max_length=2)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class WallEntry(_Strict):
    start: XY = Field(description="one end [x, y]")
    end: XY = Field(description="the other end [x, y]")
    material: str = Field("heavy", description="its material: a key of network.walls.loss_db")

    @model_validator(mode="after")
    def _has_length(self) -> WallEntry:
        if math.dist(self.start, self.end) <= 1e-9:
            raise ValueError("a wall's start and end must differ")
        return self


class PolygonEntry(_Strict):
    points: list[XY] = Field(description="its vertices [[x, y], ...] in order; the last joins the first")
    material: str = Field("heavy", description="its edges' material: a key of network.walls.loss_db")

    @model_validator(mode="after")
    def _simple(self) -> PolygonEntry:
        n = len(self.points)
        if not 3 <= n <= MAX_VERTICES:
            raise ValueError(f"a polygon needs 3 to {MAX_VERTICES} vertices, not {n}")
        p = np.asarray(self.points, dtype=float)
        d = p - p[0]
        if np.all(np.abs(d[:, 0] * d[:, None, 1] - d[:, 1] * d[:, None, 0]) <= 1e-9):  # every pair in line
            raise ValueError("a polygon must enclose an area (its vertices are on one line)")
        q = np.roll(p, -1, axis=0)
        if np.any(np.hypot(*(q - p).T) <= 1e-9):
            raise ValueError("a polygon's consecutive vertices must differ")
        # a simple polygon: no two edges meet but neighbours, and those only at their shared vertex
        hit = segments_cross(
            p[:, None, 0], p[:, None, 1], q[:, None, 0], q[:, None, 1], p[:, 0], p[:, 1], q[:, 0], q[:, 1]
        )
        i, j = np.nonzero(np.triu(hit, 1))
        neighbours = (j == i + 1) | ((i == 0) & (j == n - 1))
        if np.any(~neighbours):
            raise ValueError(f"a polygon's edges {int(i[~neighbours][0])} and {int(j[~neighbours][0])} cross")
        if abs(_signed_area(p)) <= 1e-9:
            raise ValueError("a polygon must enclose an area")
        return self


class ObstaclesSection(_Strict):
    """Walls and closed polygons that block motion, sight and (``network.walls``) the radio."""

    walls: list[WallEntry] = Field(default_factory=list, description="wall segments")
    polygons: list[PolygonEntry] = Field(default_factory=list, description="closed obstacles (rubble, pillars)")
    clearance: float = Field(
        1.0,
        gt=0,
        description="how far a planned path keeps from a wall's corner, and the least distance of a spawned robot, "
        "task or victim from any wall (arena units)",
    )

    @model_validator(mode="after")
    def _bounded(self) -> ObstaclesSection:
        n = len(self.walls) + sum(len(p.points) for p in self.polygons)
        if n > MAX_WALLS:
            raise ValueError(f"{n} walls (segments and polygon edges), more than the {MAX_WALLS} a world may have")
        return self

    def materials(self) -> list[str]:
        """Every material named, in first-use order."""
        return list(dict.fromkeys([w.material for w in self.walls] + [p.material for p in self.polygons]))

    def points(self) -> list[tuple[str, Point]]:
        """Every vertex with where it is written (``walls[3].end``), for the arena check."""
        out = [
            (f"walls[{i}].{end}", (getattr(w, end)[0], getattr(w, end)[1]))
            for i, w in enumerate(self.walls)
            for end in ("start", "end")
        ]
        out += [
            (f"polygons[{i}].points[{k}]", (v[0], v[1]))
            for i, p in enumerate(self.polygons)
            for k, v in enumerate(p.points)
        ]
        return out

    def compile(self, loss_db: dict[str, float] | None = None) -> Walls:
        """The segments as arrays; ``loss_db``: each material's loss (absent ones cost 0 dB)."""
        ends: list[list[float]] = [[*w.start, *w.end] for w in self.walls]
        materials = [w.material for w in self.walls]
        for poly in self.polygons:
            ring = poly.points + poly.points[:1]
            ends += [[*a, *b] for a, b in zip(ring, ring[1:])]
            materials += [poly.material] * len(poly.points)
        table = loss_db or {}
        xy = np.array(ends, dtype=float).reshape(-1, 4)
        loss = np.array([table.get(m, 0.0) for m in materials], dtype=float)
        rings = [np.asarray(p.points, dtype=float) for p in self.polygons]
        return Walls(xy, loss, rings, self.clearance)


def _signed_area(p: np.ndarray) -> float:
    q = np.roll(p, -1, axis=0)
    return float(0.5 * np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def segments_cross(px, py, qx, qy, ax, ay, bx, by) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Whether segment p-q and segment a-b share a point (arrays broadcast against each other):
    each segment's ends lie on opposite sides of (or on) the other's line; on one line, where
    their boxes overlap. Exact in floating point for the turn signs, with no tolerance."""
    ux, uy = qx - px, qy - py
    o1 = np.sign(ux * (ay - py) - uy * (ax - px))
    o2 = np.sign(ux * (by - py) - uy * (bx - px))
    crossing = o1 * o2 <= 0
    vx, vy = bx - ax, by - ay
    o3 = np.sign(vx * (py - ay) - vy * (px - ax))
    o4 = np.sign(vx * (qy - ay) - vy * (qx - ax))
    crossing &= o3 * o4 <= 0
    collinear = crossing & (o1 == 0) & (o2 == 0)
    if collinear.any():  # rare: test the boxes of those pairs only
        at = np.nonzero(collinear)
        shape = collinear.shape
        p_x, p_y, q_x, q_y, a_x, a_y, b_x, b_y = (
            np.broadcast_to(v, shape)[at] for v in (px, py, qx, qy, ax, ay, bx, by)
        )
        overlap = (
            np.maximum(np.minimum(p_x, q_x), np.minimum(a_x, b_x))
            <= np.minimum(np.maximum(p_x, q_x), np.maximum(a_x, b_x))
        ) & (
            np.maximum(np.minimum(p_y, q_y), np.minimum(a_y, b_y))
            <= np.minimum(np.maximum(p_y, q_y), np.maximum(a_y, b_y))
        )
        crossing[at] = overlap
    return crossing


def wall_lines(section: ObstaclesSection | None) -> list[tuple[Point, Point]]:
    """A run's walls as line segments for a view to draw (none without obstacles)."""
    return section.compile().lines if section is not None else []


class Walls:
    """A world's walls as arrays: ``xy`` (one row ``x1, y1, x2, y2`` per wall), each wall's
    ``loss_db``, the polygons' vertex rings (their insides are solid) and the clearance."""

    def __init__(self, xy: np.ndarray, loss_db: np.ndarray, rings: list[np.ndarray], clearance: float) -> None:
        self.xy, self.loss_db, self.rings, self.clearance = xy, loss_db, rings, clearance

    def __len__(self) -> int:
        return len(self.xy)

    def crossings(self, px: ArrayLike, py: ArrayLike, qx: ArrayLike, qy: ArrayLike) -> np.ndarray:
        """One row per line p-q, one column per wall: whether the line crosses it."""
        px, py, qx, qy = (np.asarray(v, dtype=float).reshape(-1) for v in (px, py, qx, qy))
        every = np.arange(len(px))
        return self.crossings_between(px, py, qx, qy, every, every)

    def crossings_among(self, x: np.ndarray, y: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """:meth:`crossings` for the lines from point ``i[k]`` to point ``j[k]`` of one set of points
        (the radio's agents)."""
        return self.crossings_between(x, y, x, y, i, j)

    def crossings_between(
        self, px: np.ndarray, py: np.ndarray, qx: np.ndarray, qy: np.ndarray, i: np.ndarray, j: np.ndarray
    ) -> np.ndarray:
        """:meth:`crossings` for the lines from point ``i[k]`` of P to point ``j[k]`` of Q (robots to
        the tasks they might see): which side of each wall's line every point lies on is computed
        once per point, and only the lines whose ends do not lie strictly on one side are tested in
        full."""
        out = np.zeros((len(i), len(self.xy)), dtype=bool)
        if not len(self.xy) or not len(i):
            return out
        ax, ay, bx, by = self.xy.T

        def sides(x: np.ndarray, y: np.ndarray) -> np.ndarray:
            return np.sign((bx - ax) * (y[:, None] - ay) - (by - ay) * (x[:, None] - ax)).astype(np.int8)

        side_p = sides(px, py)
        side_q = side_p if qx is px and qy is py else sides(qx, qy)
        rows, walls = np.nonzero(side_p[i] * side_q[j] <= 0)
        p, q = i[rows], j[rows]
        out[rows, walls] = segments_cross(px[p], py[p], qx[q], qy[q], ax[walls], ay[walls], bx[walls], by[walls])
        return out

    def clear(self, px, py, qx, qy) -> np.ndarray:  # type: ignore[no-untyped-def]
        """Whether each line p-q crosses no wall (line of sight)."""
        return np.asarray(~self.crossings(px, py, qx, qy).any(axis=1))

    def inside(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Whether each point is inside a polygon (even-odd rule; on an edge counts as inside)."""
        x, y = np.asarray(x, dtype=float).reshape(-1), np.asarray(y, dtype=float).reshape(-1)
        out = np.zeros(len(x), dtype=bool)
        for ring in self.rings:
            ax, ay = ring[:, 0], ring[:, 1]
            bx, by = np.roll(ax, -1), np.roll(ay, -1)
            straddle = (ay[None, :] > y[:, None]) != (by[None, :] > y[:, None])
            with np.errstate(divide="ignore", invalid="ignore"):
                at = ax + (y[:, None] - ay) * (bx - ax) / (by - ay)
            odd = np.count_nonzero(straddle & (x[:, None] < at), axis=1) % 2 == 1
            out |= odd | (self.distance(x, y, ring_only=ring) <= 1e-9)
        return out

    def distance(self, x: ArrayLike, y: ArrayLike, ring_only: np.ndarray | None = None) -> np.ndarray:
        """Each point's distance to the nearest wall (or to one ring's edges)."""
        x, y = np.asarray(x, dtype=float).reshape(-1), np.asarray(y, dtype=float).reshape(-1)
        if ring_only is not None:
            ax, ay = ring_only[:, 0], ring_only[:, 1]
            bx, by = np.roll(ax, -1), np.roll(ay, -1)
        else:
            ax, ay, bx, by = self.xy.T
        if not len(ax):
            return np.full(len(x), np.inf)
        dx, dy = bx - ax, by - ay
        t = np.clip(((x[:, None] - ax) * dx + (y[:, None] - ay) * dy) / np.maximum(dx * dx + dy * dy, 1e-300), 0, 1)
        return np.hypot(ax + t * dx - x[:, None], ay + t * dy - y[:, None]).min(axis=1)

    def free(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Whether each point may hold a robot, task or victim: outside every polygon and at least
        the clearance from every wall."""
        return ~self.inside(x, y) & (self.distance(x, y) >= self.clearance)

    @cached_property
    def lines(self) -> list[tuple[Point, Point]]:
        """Every wall as ((x1, y1), (x2, y2)), for the views to draw."""
        return [((float(a), float(b)), (float(c), float(d))) for a, b, c, d in self.xy]
