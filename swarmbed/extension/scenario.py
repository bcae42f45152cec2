"""What a scenario is: one class that holds everything scenario-specific, registered by name.

A :class:`Scenario` declares its parameters (the ``scenario:`` section of an experiment), its typed
observation (part of the wire contract), the behavior-tree nodes and default tree its agents run,
the metrics that measure its outcome, and it builds the :class:`World` that the coordinator drives.
The coordinator, the agent runtime and the CLI know nothing else about scenarios, so a new one is
one module plus one registry line (``swarmbed.plugins.registry``) or a ``swarmbed.scenarios``
entry point in another package; ``swarmbed.checks.check_scenario`` checks it.

Agents build a scenario too (from the same resolved parameters) for its sensing range and its
helpers (``random_point``); they never build its world.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from pydantic import BaseModel

from swarmbed.extension.actions import MOVE_ACTIONS, ActionSpec
from swarmbed.extension.allocator import Allocator
from swarmbed.extension.figures import Figure
from swarmbed.schema.experiment import AgentsSection, Experiment
from swarmbed.schema.obstacles import ObstaclesSection, Walls
from swarmbed.wire.observation import Observation as BaseObservation

if TYPE_CHECKING:
    from swarmbed.bt import TreeNode


@dataclass(frozen=True)
class Sensing:
    """What an agent's sensors cover: tasks within ``range`` and inside a cone of ``angle``."""

    range: float
    angle: float = 2 * math.pi


def within(dx: np.ndarray, dy: np.ndarray, reach: float) -> np.ndarray:
    """``math.hypot(dx, dy) <= reach``, element for element, at a fraction of its cost: squared
    distances settle every pair but those within a relative 1e-9 of ``reach``, for which the
    standard library's hypot decides, as an agent's :meth:`LocalView.sees` does (numpy's hypot
    differs from it in the last bit now and then, which on the edge would make the world show a
    point the agent believes it cannot see, or the other way round)."""
    if not 1e-100 < reach < 1e100:  # squares would underflow or overflow: numpy's hypot, math's on the edge
        h = np.hypot(dx, dy)
        near, edge = h <= reach, (h == reach) if math.isinf(reach) else np.abs(h - reach) <= 1e-9 * reach
        if edge.any():
            near[edge] = _elementwise(lambda a, b: math.hypot(a, b) <= reach, dx[edge], dy[edge])
        return near
    d2 = dx * dx
    d2 += dy * dy
    r2 = reach * reach
    near = d2 < r2 * (1 - 1e-9)
    edge = (d2 <= r2 * (1 + 1e-9)) & ~near
    if edge.any():
        near[edge] = _elementwise(lambda a, b: math.hypot(a, b) <= reach, dx[edge], dy[edge])
    return near


def _elementwise(test: Callable[[float, float], bool], a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``test`` of each pair of elements, in Python floats (what an agent computes), as a bool array."""
    a, b = np.broadcast_arrays(a, b)
    flat = [test(x, y) for x, y in zip(a.ravel().tolist(), b.ravel().tolist())]
    return np.array(flat, dtype=bool).reshape(a.shape)


def sight(
    ox: np.ndarray,
    oy: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    reach: float,
    heading: np.ndarray | None = None,
    angle: float = 2 * math.pi,
    walls: Walls | None = None,
) -> np.ndarray:
    """What a team sees, one row per observer at (ox, oy), one column per point (x, y): the point
    is within ``reach`` (:func:`within`), inside the observer's cone of full ``angle`` about its
    ``heading`` (a point where the observer stands counts as inside; the angle is taken only for
    pairs within reach) and, given ``walls``, no wall lies between them. One array operation for
    the whole team; on the edge of the range or of the cone (within 1e-9) the standard library
    decides, as an agent's :meth:`LocalView.sees` does, so world and agent agree on every pair."""
    dx, dy = x[None, :] - ox[:, None], y[None, :] - oy[:, None]
    seen = within(dx, dy, reach)
    if angle < 2 * math.pi:
        if heading is None:
            raise ValueError("sight: a cone narrower than a full turn needs the observers' headings")
        row, col = np.nonzero(seen)
        ddx, ddy, h = dx[row, col], dy[row, col], heading[row]
        off = np.abs((np.arctan2(ddy, ddx) - h + math.pi) % (2 * math.pi) - math.pi)
        edge = np.flatnonzero(np.abs(off - angle / 2) <= 1e-9)  # the standard library decides, as agents do
        if len(edge):
            off[edge] = [
                abs((math.atan2(b, a) - g + math.pi) % (2 * math.pi) - math.pi)
                for a, b, g in zip(ddx[edge].tolist(), ddy[edge].tolist(), h[edge].tolist())
            ]
        outside = (off > angle / 2) & ((ddx != 0) | (ddy != 0))
        seen[row[outside], col[outside]] = False
    if walls is not None and seen.any():
        row, col = np.nonzero(seen)
        seen[row, col] = ~walls.crossings_between(ox, oy, x, y, row, col).any(axis=1)
    return seen


#: the least share of the arena (on a grid) that must be free for spawns: below it a spawn could
#: miss in the 10,000 draws a placement gets (at 1 % free, (0.99)^10000 is about 2e-44)
MIN_FREE_SHARE = 0.01
#: the grid's points per side on which the free share is measured
FREE_GRID = 100


def obstacles_outside(
    exp: Experiment,
    inside: Callable[[float, float], bool],
    arena: str,
    box: tuple[float, float, float, float] | None = None,
) -> list[str]:
    """Problems of an experiment's obstacles with a scenario's arena: every vertex must lie in it
    (``inside(x, y)``; ``arena`` says what the arena is, for the message), and with ``box`` (the
    arena's bounding box x0, y0, x1, y1) at least :data:`MIN_FREE_SHARE` of the arena must be free
    for spawns (outside every polygon, ``clearance`` from every wall), so that no run dies placing
    a robot or a task."""
    if exp.obstacles is None:
        return []
    problems = [
        f"obstacles.{where}: [{x:g}, {y:g}] lies outside the arena ({arena})"
        for where, (x, y) in exp.obstacles.points()
        if not inside(x, y)
    ]
    if len(problems) > 10:
        problems = [*problems[:10], f"obstacles: {len(problems) - 10} more vertices lie outside the arena ({arena})"]
    if box is not None and not problems:
        share = free_share(exp.obstacles.compile(), inside, box)
        if share < MIN_FREE_SHARE:
            problems.append(
                f"obstacles: {share:.1%} of the arena is free for spawns (outside every polygon and "
                f"obstacles.clearance = {exp.obstacles.clearance:g} from every wall); at least "
                f"{MIN_FREE_SHARE:.0%} is needed to place robots and tasks"
            )
    return problems


def free_share(walls: Walls, inside: Callable[[float, float], bool], box: tuple[float, float, float, float]) -> float:
    """The share of a :data:`FREE_GRID` x :data:`FREE_GRID` grid over ``box`` inside the arena that
    ``walls`` leave free (cell centres; measured in chunks so memory stays a few MB)."""
    x0, y0, x1, y1 = box
    gx = x0 + (np.arange(FREE_GRID) + 0.5) * (x1 - x0) / FREE_GRID
    gy = y0 + (np.arange(FREE_GRID) + 0.5) * (y1 - y0) / FREE_GRID
    xs, ys = (a.ravel() for a in np.meshgrid(gx, gy))
    keep = np.fromiter((inside(float(x), float(y)) for x, y in zip(xs, ys, strict=True)), bool, len(xs))
    xs, ys = xs[keep], ys[keep]
    if not len(xs):
        return 0.0
    chunk = max(1, 1_000_000 // max(1, len(walls.xy)))
    free = sum(int(walls.free(xs[k : k + chunk], ys[k : k + chunk]).sum()) for k in range(0, len(xs), chunk))
    return free / len(xs)


class World(abc.ABC):
    """The ground truth of one run, advanced one tick at a time by the coordinator."""

    tick: int
    alive: np.ndarray  # bool per agent

    @property
    @abc.abstractmethod
    def time(self) -> float: ...

    @property
    @abc.abstractmethod
    def finished(self) -> bool:
        """Nothing is left to do (the run may stop early)."""

    @abc.abstractmethod
    def positions(self) -> tuple[list[int], list[float], list[float]]:
        """Ids and positions of the live agents, in id order."""

    @abc.abstractmethod
    def observations(self) -> Mapping[int, BaseObservation]:
        """What each live agent senses at this tick."""

    @abc.abstractmethod
    def apply(self, actions: dict[int, list]) -> None:
        """Advance one tick with every live agent's action (all act on the state of this tick)."""

    def draw_losses(self) -> list[int]:
        """Agents the scenario loses at the next tick (default: none)."""
        return []

    @abc.abstractmethod
    def kill(self, agent_id: int) -> None: ...

    @abc.abstractmethod
    def row(self) -> dict[str, Any]:
        """This tick's time-series row; the same keys every tick."""

    @abc.abstractmethod
    def summary(self) -> dict[str, Any]:
        """Outcome figures for ``summary.json`` (JSON values)."""

    @abc.abstractmethod
    def per_agent(self) -> dict[str, list]:
        """Columns of ``agents.csv``: one list per column, one entry per agent."""

    def markers(self) -> dict[int, tuple[float, float, str]]:
        """What stands on the map at this tick (tasks, victims): id -> (x, y, label), for replays.
        Recorded with ``run.record_trajectories`` only; the default draws nothing."""
        return {}

    def agent_labels(self) -> Mapping[int, str]:
        """A label per live agent for replays (its colour, its state); the default labels none."""
        return {}

    def invariants(self) -> list[str]:
        """Broken conservation laws (tasks or victims unaccounted), as sentences; empty when sound."""
        return []


class Scenario(abc.ABC):
    """A scenario, built from its resolved parameters and the run's agents section and tick length."""

    #: the ``scenario:`` section's own keys (pydantic; unknown keys are refused)
    Params: ClassVar[type[BaseModel]]
    #: the typed observation its world sends each agent every tick
    Observation: ClassVar[type[BaseObservation]] = BaseObservation
    #: the actions its agents may send (:mod:`swarmbed.extension.actions`); the coordinator hands
    #: the world ``["invalid"]`` for any other
    actions: ClassVar[ActionSpec] = MOVE_ACTIONS
    #: behavior-tree nodes its agents' trees may use
    bt_nodes: ClassVar[tuple[type[TreeNode], ...]] = ()
    #: the tree used when the allocator has none (None: SPACE's default tree,
    #: ``swarmbed.extension.space_nodes.SPACE_TREE``)
    default_tree: ClassVar[Path | None] = None
    #: summary keys that measure the outcome, first the headline (sweep tables, printed summaries)
    outcome_metrics: ClassVar[tuple[str, ...]] = ()
    #: the summary key that counts work done (tasks completed, victims rescued): what reports set
    #: against the bytes it cost; None where a scenario has no such count
    benefit_metric: ClassVar[str | None] = None
    #: every key ``World.summary()`` returns (checked by the scenario checker)
    summary_keys: ClassVar[tuple[str, ...]] = ()
    #: metrics that a run stopped by ``run.duration`` reports as the duration rather than as measured:
    #: metric -> the summary key that is true where the run got there (``swarmbed analyze`` counts
    #: such runs per cell and marks the metric's mean as a lower bound)
    capped_by: ClassVar[Mapping[str, str]] = {}
    #: what ``swarmbed analyze`` tabulates (per sweep scenario: n, mean, CI) and labels its axes
    #: with: summary metric -> label; empty: the outcome metrics under their own names
    metric_labels: ClassVar[Mapping[str, str]] = {}
    #: the figures ``swarmbed analyze`` draws (:mod:`swarmbed.extension.figures`); empty: one box
    #: per allocator for each outcome metric
    figures: ClassVar[tuple[Figure, ...]] = ()
    #: the allocator the others are compared with in ``statistics.csv`` (ANOVA, Dunnett, Cohen's d)
    #: when a sweep has it; None: no such table
    control_allocator: ClassVar[str | None] = None
    #: bump when a change makes the same configuration and seed give other results: every run records
    #: it (provenance.json) and ``swarmbed analyze`` refuses to pool runs of two versions
    version: ClassVar[str] = "1"

    def __init__(
        self, params: BaseModel, agents: AgentsSection, dt: float, obstacles: ObstaclesSection | None = None
    ) -> None:
        self.params = params
        self.agents = agents
        self.dt = dt
        #: the experiment's walls (the coordinator's copy; agents are built without them: the world
        #: decides what a wall hides and where a robot goes around one)
        self.obstacles = obstacles

    @classmethod
    def check(cls, exp: Experiment, params: BaseModel) -> list[str]:
        """Problems between this scenario's parameters and the rest of the experiment, as
        ``dotted.key: message`` (default: none)."""
        return []

    @abc.abstractmethod
    def make_world(self, rng: np.random.Generator, allocator: type[Allocator] | None = None) -> World:
        """The world of one run. ``allocator`` is the allocator class, for traits the scenario
        reads from it (e.g. :attr:`~swarmbed.extension.allocator.Allocator.bids_with_colors`)."""

    @abc.abstractmethod
    def sensing(self) -> Sensing: ...

    @abc.abstractmethod
    def random_point(self, rng: np.random.Generator) -> tuple[float, float]:
        """A uniformly random point of the arena (exploration waypoints)."""

    def blackboard(self) -> dict[str, Any]:
        """Entries the agents' trees find on their blackboard at start (ports default to them)."""
        return {"exploration_duration": self.agents.exploration_duration}

    def random_action(self, obs: BaseObservation, rng: np.random.Generator) -> list:
        """An action for the checker to drive the world with (default: go to a visible task or
        stop). Scenarios with more actions override it so that the checker exercises them."""
        if len(obs.tasks) and rng.random() < 0.8:
            return ["goto_task", int(obs.tasks["id"][int(rng.integers(len(obs.tasks)))])]
        return ["stop"]

    def summary_rows(self, summary: dict[str, Any]) -> list[tuple[str, Any]]:
        """(label, value) lines of the printed summary (default: the outcome metrics)."""
        return [(key.replace("_", " "), summary.get(key)) for key in self.outcome_metrics]
