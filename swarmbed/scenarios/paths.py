"""Getting around walls: a visibility-graph planner, the waypoints each robot follows, and free
places to spawn in. A world with obstacles (``obstacles:``) uses all three; one without never
builds them, so its draws and moves are what they were.

The graph's nodes stand off every convex corner of the walls by the clearance (at a wall's free
end, beyond it; where walls meet, in each open angle wider than a half turn, along its bisector);
two nodes are joined when the straight line between them crosses no wall. SciPy's shortest paths
over that graph are computed once per world; a query joins the start and the goal to the nodes
they see and takes the cheapest combination, so a plan costs two sight tests against the nodes and
no graph search. A plan is made when a robot's target changes, never every tick.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from swarmbed.schema.obstacles import Point, Walls

#: tries per point before a spawn gives up (the map leaves almost no free room)
MAX_TRIES = 10_000
#: the most sight tests (node pairs x walls) the planner's graph may take: each costs about
#: :data:`SECONDS_PER_SIGHT_TEST` (3e9: about a minute and a half); a map past it is refused by --check
MAX_SIGHT_TESTS = 3_000_000_000
#: measured on a 2-core machine, built a slice at a time (400 random one-unit walls, 1.3e8 tests:
#: 3.9 s; all at once it took 17 s and 7.4 GB)
SECONDS_PER_SIGHT_TEST = 3.5e-8
#: sight tests per slice of the graph's build: its memory stays about 200 MB whatever the map
SIGHT_TESTS_PER_SLICE = 2_000_000


def corner_nodes(walls: Walls) -> np.ndarray:
    """The planner's nodes (V x 2): a point the clearance off each convex corner of the walls."""
    ends: dict[tuple[float, float], list[float]] = {}
    for x1, y1, x2, y2 in walls.xy.tolist():
        ends.setdefault((round(x1, 9), round(y1, 9)), []).append(math.atan2(y2 - y1, x2 - x1))
        ends.setdefault((round(x2, 9), round(y2, 9)), []).append(math.atan2(y1 - y2, x1 - x2))
    nodes = []
    for (x, y), angles in ends.items():
        a = sorted(angles)
        gaps = [(a[(k + 1) % len(a)] - a[k]) % (2 * math.pi) or 2 * math.pi for k in range(len(a))]
        for k, gap in enumerate(gaps):
            if gap > math.pi + 1e-9:
                mid = a[k] + gap / 2
                nodes.append((x + walls.clearance * math.cos(mid), y + walls.clearance * math.sin(mid)))
    return np.array(nodes, dtype=float).reshape(-1, 2)


def sight_tests(walls: Walls) -> int:
    """The sight tests (node pairs x walls) the planner's graph of ``walls`` takes, at most (nodes
    outside the arena or inside a polygon are dropped before it is built)."""
    v = len(corner_nodes(walls))
    return v * (v - 1) // 2 * len(walls.xy)


def _visible_pairs(walls: Walls, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i < j) of ``nodes`` that see each other, tested a slice of rows at a time so that
    memory stays bounded by :data:`SIGHT_TESTS_PER_SLICE` (in order: the same pairs as all at once)."""
    v = len(nodes)
    per_slice = max(1, SIGHT_TESTS_PER_SLICE // max(1, len(walls.xy)))
    found_i, found_j = [], []
    row = 0
    while row < v - 1:
        rows: list[int] = []
        pairs = 0
        while row < v - 1 and (not rows or pairs + (v - 1 - row) <= per_slice):
            rows.append(row)
            pairs += v - 1 - row
            row += 1
        i = np.concatenate([np.full(v - 1 - r, r) for r in rows])
        j = np.concatenate([np.arange(r + 1, v) for r in rows])
        seen = walls.clear(nodes[i, 0], nodes[i, 1], nodes[j, 0], nodes[j, 1])
        found_i.append(i[seen])
        found_j.append(j[seen])
    if not found_i:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    return np.concatenate(found_i), np.concatenate(found_j)


def planner_problems(walls: Walls) -> list[str]:
    """Why the planner's graph of ``walls`` is too large to build (none: it is not)."""
    tests = sight_tests(walls)
    if tests <= MAX_SIGHT_TESTS:
        return []
    return [
        f"obstacles: the path planner's graph would take {tests:,} sight tests (corner nodes x pairs x walls; "
        f"about {tests * SECONDS_PER_SIGHT_TEST / 60:,.0f} min), more than the {MAX_SIGHT_TESTS:,} a world may "
        "have: fewer walls, or polygons instead of many short walls"
    ]


class Planner:
    """Shortest paths around a world's walls for a point robot, within an arena."""

    def __init__(self, walls: Walls, in_arena: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        # only a world with obstacles plans: agents import this module and never load SciPy
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import shortest_path

        self.walls = walls
        nodes = corner_nodes(walls)
        if len(nodes):
            nodes = nodes[in_arena(nodes[:, 0], nodes[:, 1]) & ~walls.inside(nodes[:, 0], nodes[:, 1])]
        self.nodes = nodes
        v = len(nodes)
        i, j = _visible_pairs(walls, nodes)
        length = np.hypot(nodes[i, 0] - nodes[j, 0], nodes[i, 1] - nodes[j, 1])
        graph = coo_matrix((length, (i, j)), shape=(v, v)).tocsr()
        self.dist, self.pred = shortest_path(graph, directed=False, return_predecessors=True)

    def path(self, start: Point, goal: Point) -> list[Point] | None:
        """The waypoints from ``start`` to ``goal`` (the goal last); None when no path exists."""
        (sx, sy), (gx, gy) = start, goal
        if self.walls.clear([sx], [sy], [gx], [gy])[0]:
            return [goal]
        n = self.nodes
        if not len(n):
            return None
        from_start = np.flatnonzero(self.walls.clear(np.full(len(n), sx), np.full(len(n), sy), n[:, 0], n[:, 1]))
        to_goal = np.flatnonzero(self.walls.clear(n[:, 0], n[:, 1], np.full(len(n), gx), np.full(len(n), gy)))
        if not len(from_start) or not len(to_goal):
            return None
        cost = (
            np.hypot(n[from_start, 0] - sx, n[from_start, 1] - sy)[:, None]
            + self.dist[np.ix_(from_start, to_goal)]
            + np.hypot(n[to_goal, 0] - gx, n[to_goal, 1] - gy)[None, :]
        )
        a, b = np.unravel_index(int(np.argmin(cost)), cost.shape)
        if not np.isfinite(cost[a, b]):
            return None
        first, last = int(from_start[a]), int(to_goal[b])
        chain = [last]
        while chain[-1] != first:
            chain.append(int(self.pred[first, chain[-1]]))
        return [(float(n[k, 0]), float(n[k, 1])) for k in reversed(chain)] + [goal]


class Navigator:
    """Each robot's plan toward its current target: made when the target changes, followed one
    waypoint at a time (the next once the robot is within ``reach`` of the one before)."""

    def __init__(self, planner: Planner, reach: float) -> None:
        self.planner = planner
        self.reach = reach
        self.plans: dict[int, tuple[Point, list[Point]]] = {}
        self.plans_made = 0

    def toward(self, robot: int, x: float, y: float, target: Point) -> Point:
        """Where ``robot``, at (x, y) and bound for ``target``, heads now. A target no path reaches
        is headed for straight (the walls stop the robot)."""
        plan = self.plans.get(robot)
        if plan is None or plan[0] != target:
            self.plans_made += 1
            plan = (target, self.planner.path((x, y), target) or [target])
            self.plans[robot] = plan
        waypoints = plan[1]
        while len(waypoints) > 1 and math.hypot(waypoints[0][0] - x, waypoints[0][1] - y) <= self.reach:
            waypoints.pop(0)
        return waypoints[0]

    def forget(self, robot: int) -> None:
        self.plans.pop(robot, None)


def free_places(
    walls: Walls, xs: np.ndarray, ys: np.ndarray, draw: Callable[[], tuple[float, float]]
) -> tuple[np.ndarray, np.ndarray]:
    """``xs``/``ys`` with every point that is not free (:meth:`Walls.free`) drawn again with
    ``draw`` until it is, in index order (the draws come after those that placed the points)."""
    xs, ys = np.array(xs, dtype=float), np.array(ys, dtype=float)
    for k in np.flatnonzero(~walls.free(xs, ys)).tolist():
        for _ in range(MAX_TRIES):
            x, y = draw()
            if walls.free([x], [y])[0]:
                xs[k], ys[k] = x, y
                break
        else:
            raise ValueError(f"no free place found in {MAX_TRIES} draws: the obstacles leave almost no room")
    return xs, ys


def blocked_moves(walls: Walls, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray) -> np.ndarray:
    """Which moves from (x0, y0) to (x1, y1) would cross a wall (a robot never does: it stays)."""
    moved = (x0 != x1) | (y0 != y1)
    out = np.zeros(len(x0), dtype=bool)
    if moved.any():
        out[moved] = ~walls.clear(x0[moved], y0[moved], x1[moved], y1[moved])
    return out
