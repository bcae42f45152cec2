"""The SPACE MT-SR workload scenario (SPACE paper, Table I).

Rectangular area; tasks with a workload that agents reduce at their work rate; initial tasks plus
periodic generations; point-mass agents. An agent works on a task while within ``arrival_radius``
(plus ``work_radius_per_workload`` x the task's initial workload, SPACE's code)
of it; the work rates of agents on one task add, and the workload never goes below zero (work
beyond what was left is not counted). A task is done when its workload reaches zero.

Single-task multi-robot (ST-MR) tasks (``robots_needed``, SPACE's ST-MR setting and GRAPE's home): a
task that needs k robots progresses only while at least k of them are on it (within its work radius
and acting on it); fewer wait there, braking, and do no work. Each agent's observation then lists,
for the tasks it sees that need more than one robot, how many they need and how many were on them at
the last tick (:class:`MTSRObservation` ``coalitions``); with every task needing one robot the field
is left out and the run is byte for byte what it was. A range [lo, hi] draws each task's k uniformly
from a stream spawned off the world's (``Generator.spawn``, which leaves the world's own draws as
they were), so the tasks' places and workloads are those of the same seed with k = 1.

Agents act on the state of tick k, all at once: no agent sees another's move of the same tick.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from swarmbed.extension.allocator import Allocator
from swarmbed.extension.figures import Figure
from swarmbed.extension.presets import Preset
from swarmbed.extension.scenario import Scenario, Sensing, World, obstacles_outside, sight
from swarmbed.extension.space_nodes import SPACE_NODES
from swarmbed.scenarios.kinematics import Limits, step
from swarmbed.scenarios.paths import Navigator, Planner, blocked_moves, free_places, planner_problems
from swarmbed.schema.experiment import MAX_TASKS, Experiment, QuietDefaults
from swarmbed.wire.codec import TASK_DTYPE
from swarmbed.wire.observation import Observation
from swarmbed.wire.observation import Observation as AnyObservation


@dataclasses.dataclass(frozen=True, slots=True)
class MTSRObservation(Observation):
    """An MT-SR observation; ``coalitions`` only where some task needs a team: (task, robots it
    needs, robots on it at the last tick) for each task in view that needs more than one."""

    coalitions: list[tuple[int, int, int]] | None = None


class Generations(BaseModel):
    model_config = ConfigDict(extra="forbid")
    interval: float = Field(1000.0, gt=0, description="simulated seconds between task generations")
    count: int = Field(3, ge=0, le=MAX_TASKS, description="how many generations")
    tasks: int = Field(50, ge=0, le=MAX_TASKS, description="tasks per generation")


class MTSRParams(QuietDefaults):
    """The ``scenario:`` section of an MT-SR experiment."""

    #: tasks that need one robot write the config.yaml (and the sweep digests) they did before teams
    QUIET: ClassVar[dict[str, Any]] = {"robots_needed": 1, "work_motion": "brake"}
    #: SPACE's code's task geometry and motion (its config.yaml and TaskExecutingNode)
    presets: ClassVar[dict[str, Preset]] = {
        "space_code": Preset(
            {"work_radius_per_workload": 1 / 3, "approach_radius": 50.0, "work_motion": "close_in"},
            "SPACE's code: task radius amount / task_visualisation_factor (3) added to "
            "threshold_done_by_arrival, target_approaching_radius 50, TaskExecutingNode keeps heading for "
            "the task's centre while working",
        ),
    }

    model_config = ConfigDict(extra="forbid")
    width: float = Field(1400.0, gt=0, description="area width")
    height: float = Field(1000.0, gt=0, description="area height")
    initial_tasks: int = Field(250, ge=0, le=MAX_TASKS, description="tasks at time 0")
    workload: tuple[float, float] = Field((6.0, 60.0), description="task workload range [min, max]")
    arrival_radius: float = Field(10.0, gt=0, description="distance within which an agent works on a task")
    work_radius_per_workload: float = Field(
        0.0,
        ge=0,
        description="a task's work radius grows by this much per unit of its initial workload "
        "(SPACE's code: 1/3, its task radius amount / task_visualisation_factor added to the arrival threshold)",
    )
    approach_radius: float = Field(
        0.0,
        ge=0,
        description="within this distance of its target an agent's speed is at most max_speed x distance / "
        "approach_radius (SPACE's code: target_approaching_radius 50); 0: no such slow-down",
    )
    work_motion: Literal["brake", "close_in"] = Field(
        "brake",
        description="an agent within a task's work radius, working (or waiting for its team): brakes (brake) or "
        "keeps heading for the task's centre (close_in: SPACE's TaskExecutingNode calls follow() on every tick "
        "it works, so its agents drive on, slowing within approach_radius)",
    )
    generations: Generations = Field(Generations(), description="tasks added during the run")
    agent_positions: list[tuple[float, float]] | None = Field(None, description="fixed start positions (else uniform)")
    task_positions: list[tuple[float, float]] | None = Field(None, description="fixed initial task positions")
    robots_needed: int | tuple[int, int] = Field(
        1,
        description="robots a task needs at once to progress (ST-MR coalition tasks): a number, or [min, max] "
        "drawn per task from a stream spawned off the world's; 1: every task is worked by whoever is on it",
    )

    @model_validator(mode="after")
    def _check(self):
        lo, hi = self.workload
        if not 0 < lo <= hi:
            raise ValueError("workload must be [min, max] with 0 < min <= max")
        k_lo, k_hi = self.needed_range
        if not 1 <= k_lo <= k_hi:
            raise ValueError("robots_needed must be a number >= 1 or [min, max] with 1 <= min <= max")
        if self.task_positions is not None and len(self.task_positions) != self.initial_tasks:
            raise ValueError("task_positions needs one [x, y] per initial task")
        total = self.initial_tasks + self.generations.count * self.generations.tasks
        if total > MAX_TASKS:
            raise ValueError(
                f"initial_tasks + generations.count x generations.tasks = {total:,} tasks, more than the "
                f"{MAX_TASKS:,} a run may have"
            )
        return self

    @property
    def needed_range(self) -> tuple[int, int]:
        k = self.robots_needed
        return (k, k) if isinstance(k, int) else k

    @property
    def teamwork(self) -> bool:
        """Whether a task may need more than one robot."""
        return self.needed_range[1] > 1


class MTSR(Scenario):
    """SPACE's multi-task single-robot workload scenario."""

    Params = MTSRParams
    Observation = MTSRObservation
    bt_nodes = SPACE_NODES
    outcome_metrics = ("mission_time", "time_95", "time_99", "tasks_completed", "all_tasks_completed")
    benefit_metric = "tasks_completed"
    metric_labels = {
        "mission_time": "mission completion time (s)",
        "time_95": "time to 95 % of tasks (s)",
        "time_99": "time to 99 % of tasks (s)",
        "distance_per_agent_mean": "average distance per agent",
        "work_per_agent_mean": "average work per agent",
        # SPACE's Monte Carlo analysis: the Gini coefficient of the per-agent values, one per run
        "distance_per_agent_gini": "Gini coefficient of distance per agent",
        "work_per_agent_gini": "Gini coefficient of work per agent",
        "tasks_completed": "tasks completed",
        "team_wait_total": "robot-seconds waiting for a team (team tasks)",
        # one value per agent, pooled over a scenario's runs (SPACE's per-agent panels): a run's mean
        # work per agent is its total work over N, the same for every allocator that completes the
        # mission; how the work is shared out is what tells allocators apart
        "distance_per_agent": "travel distance per agent",
        "work_per_agent": "workload per agent",
    }
    # one value per run in every panel, as SPACE's Monte Carlo analysis plots them (the per-agent
    # values pooled over runs stay available: "distance_per_agent", "work_per_agent")
    figures = (
        Figure(
            "by_range",
            (
                "mission_time",
                "time_95",
                "time_99",
                "distance_per_agent_mean",
                "work_per_agent_gini",
                "distance_per_agent_gini",
            ),
        ),
    )
    capped_by = {"mission_time": "all_tasks_completed"}
    summary_keys = (
        "mission_time",
        "all_tasks_completed",
        "time_95",
        "time_99",
        "tasks_total",
        "tasks_spawned",
        "tasks_completed",
        "distance_total",
        "distance_per_agent",
        "work_total",
        "work_per_agent",
        "invalid_actions",
    )
    params: MTSRParams

    @classmethod
    def check(cls, exp: Experiment, params: BaseModel) -> list[str]:
        assert isinstance(params, MTSRParams)
        if params.agent_positions is not None and len(params.agent_positions) != exp.agents.count:
            return [f"scenario.agent_positions: needs one [x, y] per agent ({exp.agents.count})"]
        if params.needed_range[1] > exp.agents.count:
            return [
                f"scenario.robots_needed: a task may need {params.needed_range[1]} robots, "
                f"the run has {exp.agents.count} agents"
            ]
        return obstacles_outside(
            exp,
            lambda x, y: 0 <= x <= params.width and 0 <= y <= params.height,
            f"[0, {params.width:g}] x [0, {params.height:g}]",
            (0.0, 0.0, params.width, params.height),
        ) + (planner_problems(exp.obstacles.compile()) if exp.obstacles is not None else [])

    def make_world(self, rng: np.random.Generator, allocator: type[Allocator] | None = None) -> MTSRWorld:
        return MTSRWorld(self, rng)

    def sensing(self) -> Sensing:
        return Sensing(self.agents.awareness_range)

    def blackboard(self) -> dict:
        return {**super().blackboard(), "arrival_radius": self.params.arrival_radius}

    def random_point(self, rng: np.random.Generator) -> tuple[float, float]:
        return float(rng.uniform(0, self.params.width)), float(rng.uniform(0, self.params.height))

    def random_action(self, obs: AnyObservation, rng: np.random.Generator) -> list:
        if rng.random() < 0.2:
            return ["goto", *self.random_point(rng)]
        return super().random_action(obs, rng)

    def summary_rows(self, summary: dict) -> list[tuple[str, object]]:
        return [
            ("mission time (sim s)", summary["mission_time"]),
            ("all tasks completed", summary["all_tasks_completed"]),
            ("time to 95% of tasks", summary["time_95"]),
            ("time to 99% of tasks", summary["time_99"]),
            ("tasks completed / total", f"{summary['tasks_completed']} / {summary['tasks_total']}"),
            ("distance, all agents", summary["distance_total"]),
            ("work, all agents", summary["work_total"]),
        ]


class MTSRWorld(World):
    def __init__(self, scenario: MTSR, rng: np.random.Generator) -> None:
        self.sc = scenario.params
        self.dt = scenario.dt
        self.rng = rng
        a = scenario.agents
        self.limits = Limits(a.max_speed, a.max_accel, a.max_turn_rate, self.sc.approach_radius)
        self.n = a.count
        self.work_rate = a.work_rate
        self.awareness = a.awareness_range
        self.ax = rng.uniform(0, self.sc.width, self.n)
        self.ay = rng.uniform(0, self.sc.height, self.n)
        if self.sc.agent_positions is not None:
            self.ax, self.ay = (np.array(c, dtype=float) for c in zip(*self.sc.agent_positions))
        # with obstacles: a start inside one is drawn again (after the first draws), and moves plan around them
        self.walls = scenario.obstacles.compile() if scenario.obstacles is not None else None
        self.navigator: Navigator | None = None
        if self.walls is not None:
            if self.sc.agent_positions is None:
                self.ax, self.ay = free_places(self.walls, self.ax, self.ay, lambda: self._point())
            w, h = self.sc.width, self.sc.height
            planner = Planner(self.walls, lambda x, y: (x >= 0) & (x <= w) & (y >= 0) & (y <= h))
            self.navigator = Navigator(planner, reach=self.walls.clearance / 2)
        self.heading = rng.uniform(-math.pi, math.pi, self.n)
        self.speed = np.zeros(self.n)
        self.alive = np.ones(self.n, dtype=bool)
        self.distance = np.zeros(self.n)
        self.work = np.zeros(self.n)
        self.invalid_actions = np.zeros(self.n, dtype=np.int64)
        self.team_wait = np.zeros(self.n)  # seconds each agent stood at a team task short of its team
        # tasks (grown by generations)
        self.tx = np.zeros(0)
        self.ty = np.zeros(0)
        self.workload = np.zeros(0)
        self.work_radius = np.zeros(0)
        self.remaining = np.zeros(0)
        self.spawned_at = np.zeros(0)
        self.done_at = np.full(0, np.nan)
        self.needed = np.zeros(0, dtype=np.int64)  # robots each task needs at once
        self.present = np.zeros(0, dtype=np.int64)  # robots on each task at the last tick
        k_lo, k_hi = self.sc.needed_range
        self.team_rng = rng.spawn(1)[0] if k_lo < k_hi else None  # spawning draws nothing from rng
        self.tick = 0
        self.finished_tick: int | None = None  # the tick at whose start every task was done
        self._generations_done = 0
        self._spawn(self.sc.initial_tasks)
        if self.sc.task_positions is not None and self.sc.initial_tasks:
            self.tx, self.ty = (np.array(c, dtype=float) for c in zip(*self.sc.task_positions))

    # -- tasks ---------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.tick * self.dt

    def _point(self) -> tuple[float, float]:
        return float(self.rng.uniform(0, self.sc.width)), float(self.rng.uniform(0, self.sc.height))

    @property
    def tasks_total_planned(self) -> int:
        g = self.sc.generations
        return self.sc.initial_tasks + g.count * g.tasks

    def _spawn(self, count: int) -> None:
        if count <= 0:
            return
        lo, hi = self.sc.workload
        self.tx = np.concatenate([self.tx, self.rng.uniform(0, self.sc.width, count)])
        self.ty = np.concatenate([self.ty, self.rng.uniform(0, self.sc.height, count)])
        w = self.rng.uniform(lo, hi, count)
        if self.walls is not None:  # a task inside an obstacle is placed again, after the draws above
            new = slice(len(self.tx) - count, len(self.tx))
            self.tx[new], self.ty[new] = free_places(self.walls, self.tx[new], self.ty[new], self._point)
        self.workload = np.concatenate([self.workload, w])
        # SPACE's code: arrival threshold + initial amount / 3; a factor of 0 leaves arrival_radius
        self.work_radius = np.concatenate(
            [self.work_radius, self.sc.arrival_radius + self.sc.work_radius_per_workload * w]
        )
        self.remaining = np.concatenate([self.remaining, w])
        self.spawned_at = np.concatenate([self.spawned_at, np.full(count, self.time)])
        self.done_at = np.concatenate([self.done_at, np.full(count, np.nan)])
        k_lo, k_hi = self.sc.needed_range
        k = np.full(count, k_lo) if self.team_rng is None else self.team_rng.integers(k_lo, k_hi + 1, count)
        self.needed = np.concatenate([self.needed, k])
        self.present = np.concatenate([self.present, np.zeros(count, dtype=np.int64)])

    def _maybe_generate(self) -> None:
        g = self.sc.generations
        while self._generations_done < g.count and self.time + 1e-9 >= (self._generations_done + 1) * g.interval:
            self._generations_done += 1
            self._spawn(g.tasks)

    @property
    def tasks_completed(self) -> int:
        return int(np.count_nonzero(~np.isnan(self.done_at)))

    @property
    def finished(self) -> bool:
        """Every task there will ever be is done."""
        return self._generations_done == self.sc.generations.count and self.tasks_completed == len(self.remaining)

    def markers(self) -> dict[int, tuple[float, float, str]]:
        """Tasks spawned and not yet done."""
        return {int(j): (float(self.tx[j]), float(self.ty[j]), "task") for j in np.flatnonzero(np.isnan(self.done_at))}

    # -- agents --------------------------------------------------------------------------------
    def positions(self) -> tuple[list[int], list[float], list[float]]:
        ids = [int(i) for i in np.flatnonzero(self.alive)]
        return ids, [float(self.ax[i]) for i in ids], [float(self.ay[i]) for i in ids]

    def kill(self, agent_id: int) -> None:
        self.alive[agent_id] = False
        self.speed[agent_id] = 0.0

    def observations(self) -> dict[int, MTSRObservation]:
        """What each live agent senses at this tick: itself and the open tasks within awareness range
        (as a binary task table, see ``wire.codec.TASK_DTYPE``)."""
        open_idx = np.flatnonzero(np.isnan(self.done_at))
        table = np.empty(len(open_idx), dtype=TASK_DTYPE)
        table["id"], table["x"], table["y"] = open_idx, self.tx[open_idx], self.ty[open_idx]
        table["remaining"] = self.remaining[open_idx]
        table["color"] = -1
        alive = np.flatnonzero(self.alive)
        # within awareness range, and no wall between (a full circle: no cone)
        ax, ay, tx, ty = self.ax[alive], self.ay[alive], self.tx[open_idx], self.ty[open_idx]
        near = sight(ax, ay, tx, ty, self.awareness, walls=self.walls)
        # every agent's visible tasks in one gather (of raw records: a structured gather is ~3x slower);
        # each agent's table is a slice of it
        rows, cols = np.nonzero(near)
        seen = table.view(np.uint8).reshape(len(table), TASK_DTYPE.itemsize)[cols].view(TASK_DTYPE).reshape(-1)
        bounds = np.searchsorted(rows, np.arange(len(alive) + 1)).tolist()
        t = self.time
        coalitions = self._coalitions(seen["id"], bounds) if self.sc.teamwork else [None] * len(alive)
        return {
            int(i): MTSRObservation(
                t,
                float(self.ax[i]),
                float(self.ay[i]),
                float(self.heading[i]),
                float(self.speed[i]),
                seen[bounds[row] : bounds[row + 1]],
                coalitions[row],
            )
            for row, i in enumerate(alive)
        }

    def _coalitions(self, seen: np.ndarray, bounds: list[int]) -> list[list[tuple[int, int, int]] | None]:
        """Per agent (a slice of ``seen``, the ids of the tasks it sees): (task, needed, on it) for the
        tasks that need a team; None where it sees none."""
        team = self.needed[seen] > 1
        rows = np.stack([seen, self.needed[seen], self.present[seen]], axis=1)[team].tolist()
        cuts = np.concatenate([[0], np.cumsum(team)])[bounds].tolist()
        return [[tuple(r) for r in rows[a:b]] or None for a, b in zip(cuts, cuts[1:])]

    def _target(self, i: int, action: list) -> tuple[tuple[float, float] | None, int | None]:
        """Where agent i moves to and which task it may work on, from its action."""
        name = action[0] if action else None
        if name == "goto_task" and len(action) == 2 and isinstance(action[1], int):
            t = action[1]
            if 0 <= t < len(self.remaining):  # head there even if done: the agent learns it on arrival
                return (float(self.tx[t]), float(self.ty[t])), (t if np.isnan(self.done_at[t]) else None)
        elif name == "goto" and len(action) == 3 and all(isinstance(v, (int, float)) for v in action[1:]):
            return (float(action[1]), float(action[2])), None
        elif name in ("stop", "halt") and len(action) == 1:
            if name == "halt":
                self.speed[i] = 0.0  # SPACE's reset_movement: no braking distance
            return None, None
        self.invalid_actions[i] += 1
        return None, None

    def apply(self, actions: dict[int, list]) -> None:
        """Advance one tick: every live agent moves or works on the state of this tick."""
        dt = self.dt
        working: dict[int, list[int]] = {}
        live = np.flatnonzero(self.alive)
        before = (self.ax[live].copy(), self.ay[live].copy(), self.distance[live].copy())
        for i in map(int, live):
            target, task = self._target(i, actions.get(i, ["stop"]))
            if (
                task is not None
                and math.hypot(self.tx[task] - self.ax[i], self.ty[task] - self.ay[i]) <= self.work_radius[task]
                and (
                    self.walls is None
                    or self.walls.clear([self.ax[i]], [self.ay[i]], [self.tx[task]], [self.ty[task]])[0]
                )
            ):
                working.setdefault(task, []).append(i)
                if self.sc.work_motion == "brake":
                    target = None
            if target is not None and self.navigator is not None:
                target = self.navigator.toward(i, float(self.ax[i]), float(self.ay[i]), target)
            x, y, h, v = step(
                float(self.ax[i]),
                float(self.ay[i]),
                float(self.heading[i]),
                float(self.speed[i]),
                target,
                self.limits,
                dt,
            )
            self.distance[i] += math.hypot(x - self.ax[i], y - self.ay[i])
            self.ax[i], self.ay[i], self.heading[i], self.speed[i] = x, y, h, v
        if self.walls is not None:  # a move that would cross a wall does not happen: the robot stops short
            stopped = live[blocked_moves(self.walls, before[0], before[1], self.ax[live], self.ay[live])]
            back = np.searchsorted(live, stopped)
            self.ax[stopped], self.ay[stopped], self.distance[stopped] = (b[back] for b in before)
            self.speed[stopped] = 0.0
        self.present[:] = 0
        for task in sorted(working):
            agents = working[task]
            self.present[task] = len(agents)
            if len(agents) < self.needed[task]:
                self.team_wait[agents] += dt  # a team task waits for its team: no work
                continue
            capacity = self.work_rate * dt * len(agents)
            done = min(capacity, float(self.remaining[task]))
            for i in agents:
                self.work[i] += done / len(agents)
            self.remaining[task] -= done
            if self.remaining[task] <= 1e-12:
                self.remaining[task] = 0.0
                self.done_at[task] = self.time + dt
        self.tick += 1
        self._maybe_generate()
        if self.finished_tick is None and self.finished:
            self.finished_tick = self.tick

    # -- metrics -------------------------------------------------------------------------------
    def row(self) -> dict:
        return {
            "tick": self.tick,
            "time": round(self.time, 9),
            "tasks_spawned": len(self.remaining),
            "tasks_completed": self.tasks_completed,
            "distance_total": float(self.distance.sum()),
            "work_total": float(self.work.sum()),
            "agents_alive": int(self.alive.sum()),
        }

    def summary(self) -> dict:
        times = np.sort(self.done_at[~np.isnan(self.done_at)])

        def time_to(share: float) -> float | None:
            # when the ceil(share x planned)-th task was done (SPACE's Fig. 3 discussion reads times
            # to 95 % and 99 % of the tasks beside mission time); None if the run never got there
            need = math.ceil(share * self.tasks_total_planned)
            return float(times[need - 1]) if need and len(times) >= need else None

        return {
            # the time every task was done; the run's length where it went on (stop_when_done: false)
            # or never got there (then all_tasks_completed is false)
            "mission_time": (self.finished_tick if self.finished_tick is not None else self.tick) * self.dt,
            "all_tasks_completed": bool(self.finished),
            "time_95": time_to(0.95),
            "time_99": time_to(0.99),
            "tasks_total": self.tasks_total_planned,
            "tasks_spawned": len(self.remaining),
            "tasks_completed": self.tasks_completed,
            "distance_total": float(self.distance.sum()),
            "distance_per_agent": [float(d) for d in self.distance],
            "work_total": float(self.work.sum()),
            "work_per_agent": [float(x) for x in self.work],
            "invalid_actions": int(self.invalid_actions.sum()),
            **self._team_summary(),
        }

    def _team_summary(self) -> dict:
        """With team tasks: the robot-seconds spent at a team task waiting for the rest of its team
        (in all, and per agent); nothing otherwise, so that a run without teams writes what it did."""
        if not self.sc.teamwork:
            return {}
        return {"team_wait_total": float(self.team_wait.sum()), "team_wait_per_agent": self.team_wait.tolist()}

    def per_agent(self) -> dict[str, list]:
        return {
            "distance": [float(d) for d in self.distance],
            "work": [float(x) for x in self.work],
            "invalid_actions": [int(v) for v in self.invalid_actions],
        }

    def invariants(self) -> list[str]:
        problems = []
        if np.any(self.remaining < 0) or np.any(self.remaining > self.workload):
            problems.append("a task's remaining workload left [0, workload]")
        done = float((self.workload - self.remaining).sum())
        if not math.isclose(done, float(self.work.sum()), rel_tol=1e-9, abs_tol=1e-6):
            problems.append(f"work done by agents {float(self.work.sum())} != workload removed from tasks {done}")
        if self.tasks_completed > len(self.remaining):
            problems.append("more tasks completed than spawned")
        return problems
