"""Centralized allocators through a leader, over the emulated radio: the baselines reviewers ask for.

Every agent runs the same allocator; one of them is the leader. Each tick a follower sends the leader
a report (its position and the tasks it sees, as packed rows) and the leader, from the reports that
reached it and what it sees itself, solves the assignment of the agents it heard from to the tasks
it knows, and broadcasts it (packed (agent, task) pairs). Reports and assignments are radio messages
like any other: range, loss, rates, queues and the ledger apply to both directions, so what the
leader decides on is only what reached it. A follower works on its last assignment for ``hold_for``
simulated seconds without a fresh one, then explores (its tree's exploration), or, with
``fallback`` (a registered allocator, e.g. ``fcg``, with its own ``fallback_params``), lets that
allocator decide, which observes and talks over the radio all along; until an assignment reaches it
again.

Who leads (``leader``): a fixed agent id, or ``lowest_alive``: the lowest id among this agent and
those it heard from in the last ``heard_within`` simulated seconds. At the first tick every agent
has heard no one and leads itself; their assignments reach each other and from the next tick the
lowest id leads. When the leader is lost (its robot, its process) its followers stop hearing it,
and ``heard_within`` seconds later the lowest id that they still hear (themselves, at worst) takes
over by the same rule.

What the leader knows of a task: its position and remaining workload from the latest report that
named it. A task it knew that a fresh report leaves out although the reporter stood within the
awareness range of it is done (forgotten); so is one nobody reported for ``heard_within`` seconds.

The solvers (:meth:`Centralized.solve`): sequential greedy assignment (``sga``: the pair of agent
and task with the best score, again and again; a task's score is CBBA's path-independent one,
``discount ** (d / v) * R``) and the Hungarian method (``hungarian``: the assignment of least total
travel time, by :func:`scipy.optimize.linear_sum_assignment`), where each agent gets at most one
task and each task at most one agent, as CBBA's single-task robots do; and GRAPE's game solved in
one place (``central-grape``: a Nash-stable partition, several agents to a task as GRAPE allows).

Team tasks (ST-MR, a task that needs k robots at once): reports also carry each task's k; SGA and
the Hungarian method solve over the tasks' slots (k copies of a team task, each with 1/k of its
workload) and drop a team they leave short, solving again without it (:func:`~swarmbed.plugins.teams.by_slots`); a
kept team's open places are solved for; central GRAPE uses the utility that peaks at k members.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from typing import Literal

import numpy as np
from pydantic import BaseModel, Field

from swarmbed import kernels
from swarmbed.extension import LocalView
from swarmbed.plugins.external import FallbackParams, WithFallback
from swarmbed.plugins.grape import utility as grape_utility
from swarmbed.plugins.packed import read_tuples
from swarmbed.plugins.teams import by_slots
from swarmbed.schema.experiment import Experiment

REPORT, ASSIGN = "report", "assign"

#: a report's task rows: id, position and remaining workload as a robot would send them (float32)
TASK_ROW = np.dtype([("task", "<i4"), ("x", "<f4"), ("y", "<f4"), ("remaining", "<f4")])
#: the rows of a report that names a team task (ST-MR): also the robots each task needs; such a
#: report is ``[x, y, rows, 1]``, so that runs without team tasks send the bytes they did
TEAM_TASK_ROW = np.dtype([("task", "<i4"), ("x", "<f4"), ("y", "<f4"), ("remaining", "<f4"), ("needed", "u1")])
#: the same rows where a task needs more than 255 robots (``[x, y, rows, 2]``): a run of small teams
#: keeps its one-byte rows and its bytes
WIDE_TEAM_TASK_ROW = np.dtype([("task", "<i4"), ("x", "<f4"), ("y", "<f4"), ("remaining", "<f4"), ("needed", "<u2")])
TEAM_ROWS = {1: TEAM_TASK_ROW, 2: WIDE_TEAM_TASK_ROW}
#: how far from the follower a task it never saw may be, for its assignment to be taken (farther:
#: a leader naming a place no run has, e.g. (1e30, 1e30), is not followed)
MAX_GOAL_DISTANCE = 1e6
#: an assignment's rows: the agent, its task and where the task is (a goal, as a leader would send it)
ASSIGN_ROW = np.dtype([("agent", "<i2"), ("task", "<i4"), ("x", "<f4"), ("y", "<f4")])


class CentralParams(FallbackParams):
    leader: int | Literal["lowest_alive"] = Field(
        "lowest_alive",
        description="who solves the assignment: an agent id, or the lowest id this agent heard from in the last "
        "heard_within seconds (itself included), which also chooses the next leader when one is lost",
    )
    heard_within: float = Field(
        5.0, gt=0, description="simulated seconds after which an agent (or a task) not heard of counts as gone"
    )
    hold_for: float = Field(
        10.0, ge=0, description="simulated seconds a follower works on its last assignment without a fresh one"
    )
    discount: float = Field(0.999, gt=0, le=1, description="sga: lambda of the score discount ** (d / v) * R")
    max_phantoms: int = Field(
        3,
        ge=1,
        description="goals in a row at which a follower found no task it had ever seen: past it, the follower "
        "treats the leader as failed and follows the next (a leader that lies sends robots after tasks no run has)",
    )
    commit: bool = Field(
        True,
        description="the leader keeps an agent on its task until the task is done or the agent is gone, and "
        "solves for the others (a task's score falls as it is worked on: re-solving every tick would pull "
        "agents off half-done tasks); false: solve for everyone every tick",
    )


class Centralized(WithFallback):
    """The leader and follower roles every agent of a centralized allocator plays; subclasses say how
    the leader assigns (:meth:`solve`)."""

    Params = CentralParams
    params: CentralParams
    message_kinds = (REPORT, ASSIGN)
    event_names = ("assignments_sent", "reports_sent", "phantom_goals")
    version = "2"  # 2: a follower never takes again a goal it found empty, and leaves a leader of phantom goals

    @classmethod
    def check(cls, exp: Experiment, params: BaseModel) -> list[str]:
        leader = getattr(params, "leader", "lowest_alive")
        if isinstance(leader, int) and not 0 <= leader < exp.agents.count:
            return [f"allocator.leader: agent {leader} is not one of this run's agents 0..{exp.agents.count - 1}"]
        return []

    def __init__(self, agent_id: int, params: BaseModel, rng: np.random.Generator, run_seed: int = 0) -> None:
        super().__init__(agent_id, params, rng, run_seed)
        self.heard: dict[int, float] = {}  # agent -> simulated time it was last heard from
        self.positions: dict[int, tuple[float, float]] = {}  # agent -> its reported position (the leader's)
        self.tasks: dict[int, tuple[float, float, float, float]] = {}  # task -> x, y, remaining, time (leader's)
        self.assigned: tuple[int, float, float, float] | None = None  # (task, x, y, time the assignment came)
        self.plan: dict[int, int] = {}  # agent -> task, the leader's last assignment
        self.needed: dict[int, int] = {}  # team tasks (ST-MR) the leader knows: task -> robots it needs
        self.seen: set[int] = set()  # every task this agent has had in view
        self.empty: set[int] = set()  # goals this follower reached and found without their task: never again
        self.phantoms = 0  # goals in a row whose task this agent never saw
        self.distrusted: set[int] = set()  # leaders that sent it after phantoms, max_phantoms times in a row

    # -- the roles ------------------------------------------------------------------------------
    def leader(self, now: float) -> int:
        """Who leads as this agent sees it at ``now``."""
        if self.params.leader != "lowest_alive" and int(self.params.leader) not in self.distrusted:
            return int(self.params.leader)
        recent = [a for a, t in self.heard.items() if now - t <= self.params.heard_within and a not in self.distrusted]
        return min([self.agent_id, *recent])

    def decide(self, view: LocalView) -> int | None:
        now = view.time
        self.seen.update(view.tasks)
        self._read(view, now)
        leader = self.leader(now)
        teams = view.coalitions()
        seen: list[tuple]
        if teams:
            seen = [(t.id, t.x, t.y, t.remaining, teams.get(t.id, (1, 0))[0]) for t in view.tasks.values()]
        else:
            seen = [(t.id, t.x, t.y, t.remaining) for t in view.tasks.values()]
        if leader == self.agent_id:
            self._learn(self.agent_id, view.x, view.y, seen, view)
            self._forget(now)
            fresh = self.params.heard_within
            agents = {a: p for a, p in self.positions.items() if a == self.agent_id or now - self.heard[a] <= fresh}
            plan = self._plan(agents, view.max_speed)
            goals = [(a, j, *self.tasks[j][:2]) for a, j in sorted(plan.items())]
            view.broadcast(ASSIGN, _pack(goals, ASSIGN_ROW))
            self.count("assignments_sent")
            mine = plan.get(self.agent_id)
            self.assigned = None if mine is None else (mine, *self.tasks[mine][:2], now)
            return mine
        if teams:
            wide = 2 if any(row[4] > 255 for row in seen) else 1
            report = [view.x, view.y, _pack(seen, TEAM_ROWS[wide]), wide]
        else:
            report = [view.x, view.y, _pack(seen, TASK_ROW)]
        view.send(leader, REPORT, report)
        self.count("reports_sent")
        if self.assigned is None or now - self.assigned[3] > self.params.hold_for:
            # nothing fresh enough from the leader: the fallback allocator decides, or the tree explores
            return self.fallback_decide(view)
        task, x, y, _ = self.assigned
        if task not in view.tasks and math.hypot(x - view.x, y - view.y) < view.awareness_range:
            self._found_empty(task, now)  # in sight of where it stood, and gone: done, or never there
            return self.fallback_decide(view)
        if task in view.tasks:
            self.phantoms = 0
        return task

    def _found_empty(self, task: int, now: float) -> None:
        """The goal of ``task`` is in sight and holds no task: it is never taken again, and where this
        agent never saw that task at all, it counts as a phantom of the leader's; ``max_phantoms`` in
        a row and the leader is treated as failed (the next lowest id leads, as when one is lost)."""
        self.assigned = None
        self.empty.add(task)
        if task in self.seen:
            self.phantoms = 0
            return
        self.phantoms += 1
        self.count("phantom_goals")
        if self.phantoms >= self.params.max_phantoms:
            self.distrusted.add(self.leader(now))
            self.phantoms = 0

    def _read(self, view: LocalView, now: float) -> None:
        """Note who was heard; keep a report (as the leader would use it) and the leader's assignment."""
        for msg in view.inbox:
            if msg.sender == self.agent_id or not 0 <= msg.sender < view.n_agents:
                continue
            self.heard[msg.sender] = now
            data = msg.data
            if msg.kind == REPORT and isinstance(data, list) and (len(data) == 3 or data[3:] in ([1], [2])):
                x, y, packed = data[:3]
                if isinstance(x, (int, float)) and isinstance(y, (int, float)) and math.isfinite(x + y):
                    rows = read_tuples(packed, TASK_ROW if len(data) == 3 else TEAM_ROWS[data[3]])
                    self._learn(msg.sender, float(x), float(y), rows, view)
            elif msg.kind == ASSIGN and msg.sender == self.leader(now):
                for agent, task, x, y in read_tuples(data, ASSIGN_ROW):
                    if int(task) in self.empty:
                        continue  # a goal it found empty: left out, as the leader should have
                    if agent == self.agent_id and self._plausible(int(task), float(x), float(y), view):
                        self.assigned = (int(task), float(x), float(y), now)
                        break
                else:
                    self.assigned = None  # the leader left this agent out

    def _plausible(self, task: int, x: float, y: float, view: LocalView) -> bool:
        """Whether a follower takes the leader's goal: a finite place within :data:`MAX_GOAL_DISTANCE`,
        and, for a task it sees, where it sees it (float32 rounding apart). A leader can still send
        it to a real task, or to a place within that distance: the followers trust their leader, as
        the centralized solvers the baselines stand for do."""
        if not math.isfinite(x + y) or math.hypot(x - view.x, y - view.y) > MAX_GOAL_DISTANCE:
            return False
        seen = view.tasks.get(task)
        return seen is None or math.hypot(seen.x - x, seen.y - y) <= 1e-3 * (1 + abs(seen.x) + abs(seen.y))

    def _learn(self, reporter: int, x: float, y: float, rows: list[tuple], view: LocalView) -> None:
        """A report (or the leader's own view): where ``reporter`` is, the tasks it sees, and the
        tasks it should see but does not (done)."""
        now = view.time
        self.positions[reporter] = (x, y)
        named = set()
        for task, tx, ty, remaining, *needed in rows:
            if math.isfinite(tx + ty + remaining):
                self.tasks[int(task)] = (float(tx), float(ty), float(remaining), now)
                named.add(int(task))
                if needed and needed[0] > 1:
                    self.needed[int(task)] = int(needed[0])
        reach = view.awareness_range
        for task, (tx, ty, _r, _t) in list(self.tasks.items()):
            if task not in named and math.hypot(tx - x, ty - y) < reach:
                del self.tasks[task]
                self.needed.pop(task, None)

    def _plan(self, agents: dict[int, tuple[float, float]], speed: float) -> dict[int, int]:
        """The leader's assignment: the committed pairs that still stand, and the solver's for the rest."""
        kept = {a: j for a, j in self.plan.items() if a in agents and j in self.tasks} if self.params.commit else {}
        free = {a: p for a, p in agents.items() if a not in kept}
        if not self.needed:
            taken = set(kept.values())
            plan = kept | self.solve(free, {j: v[:3] for j, v in self.tasks.items() if j not in taken}, speed)
        else:  # team tasks: the places a kept team leaves open are solved for, as slots
            on = Counter(kept.values())
            need = {j: self.needed.get(j, 1) - on[j] for j in self.tasks}
            open_tasks = {j: v[:3] for j, v in self.tasks.items() if need[j] > 0}
            plan = kept | by_slots(lambda a, t: self.solve(a, t, speed), free, open_tasks, need)
        self.plan = plan
        return plan

    def _forget(self, now: float) -> None:
        for task, (_x, _y, _r, seen) in list(self.tasks.items()):
            if now - seen > self.params.heard_within:
                del self.tasks[task]
                self.needed.pop(task, None)

    # -- the assignment -------------------------------------------------------------------------
    def solve(
        self, agents: dict[int, tuple[float, float]], tasks: dict[int, tuple[float, float, float]], speed: float
    ) -> dict[int, int]:
        """Agent -> task for the agents and tasks the leader knows (each at most once)."""
        raise NotImplementedError


def _pack(rows: Sequence[tuple], dtype: np.dtype) -> bytes:
    return np.array(rows, dtype=dtype).tobytes() if rows else b""


def sequential_greedy(
    agents: dict[int, tuple[float, float]], tasks: dict[int, tuple[float, float, float]], speed: float, discount: float
) -> dict[int, int]:
    """Sequential greedy assignment: the (agent, task) pair of the best score ``discount ** (d / v) *
    R`` (CBBA's path-independent score, computed as CBBA computes it), again and again over the agents
    and tasks left; equal scores to the lower agent id, then the lower task id."""
    if not agents or not tasks:
        return {}
    ids, tids = sorted(agents), sorted(tasks)
    tx = np.array([tasks[t][0] for t in tids], dtype=float)
    ty = np.array([tasks[t][1] for t in tids], dtype=float)
    rem = np.array([tasks[t][2] for t in tids], dtype=float)
    log_l = math.log(discount)
    score = np.array([kernels.distance_gains(*agents[a], speed, log_l, tx, ty, rem) for a in ids])
    plan: dict[int, int] = {}
    live = score > 0
    for _ in range(min(len(ids), len(tids))):
        masked = np.where(live, score, -np.inf)
        best = masked.max()
        if not np.isfinite(best):
            break
        i, j = np.argwhere(masked == best)[0]  # row-major: the lower agent, then the lower task
        plan[ids[i]] = tids[j]
        live[i, :] = False
        live[:, j] = False
    return plan


class SGA(Centralized):
    """Sequential greedy assignment by a leader (the centralized counterpart of CBBA: with the same
    path-independent score, CBBA's converged assignment with one task per bundle is this one)."""

    def solve(
        self, agents: dict[int, tuple[float, float]], tasks: dict[int, tuple[float, float, float]], speed: float
    ) -> dict[int, int]:
        return sequential_greedy(agents, tasks, speed, self.params.discount)


def least_travel(
    agents: dict[int, tuple[float, float]], tasks: dict[int, tuple[float, float, float]], speed: float
) -> dict[int, int]:
    """The assignment of min(agents, tasks) pairs of least total travel time (SciPy's
    ``linear_sum_assignment``, the Hungarian method's problem)."""
    from scipy.optimize import linear_sum_assignment

    if not agents or not tasks:
        return {}
    ids, tids = sorted(agents), sorted(tasks)
    ax = np.array([agents[a] for a in ids])
    tx = np.array([tasks[t][:2] for t in tids])
    cost = np.hypot(tx[None, :, 0] - ax[:, None, 0], tx[None, :, 1] - ax[:, None, 1]) / speed
    rows, cols = linear_sum_assignment(cost)
    return {ids[i]: tids[j] for i, j in zip(rows, cols)}


class Hungarian(Centralized):
    """The Hungarian method by a leader: the agents it heard from matched to the tasks it knows with
    the least total travel time."""

    def solve(
        self, agents: dict[int, tuple[float, float]], tasks: dict[int, tuple[float, float, float]], speed: float
    ) -> dict[int, int]:
        return least_travel(agents, tasks, speed)


class CentralGRAPEParams(CentralParams):
    cost_weight: float = Field(1.0, ge=0, description="GRAPE's weight of the distance cost (SPACE Eq. 1)")
    social_inhibition: float = Field(100.0, ge=0, description="GRAPE's f_s: exponent on the coalition size")


def nash_stable_partition(
    agents: dict[int, tuple[float, float]],
    tasks: dict[int, tuple[float, float, float]],
    cost_weight: float,
    social_inhibition: float,
    start: dict[int, int] | None = None,
    max_passes: int = 1000,
    needed: dict[int, int] | None = None,
) -> dict[int, int]:
    """GRAPE's game solved in one place: from ``start`` (else every agent on its nearest task), each
    agent in id order joins the coalition of highest utility (SPACE's Eq. 1, :func:`grape.utility`)
    where it beats its own, until a whole pass moves no one: a Nash-stable partition (GRAPE's
    anonymous hedonic game with SPAO preferences converges, Jang et al. 2018, Theorem 1). ``needed``:
    the team tasks' k (ST-MR), whose utility peaks at k members (:func:`grape.utility`); the theorem
    does not cover those, and ``max_passes`` bounds the search where no stable partition is met."""
    if not tasks:
        return {}
    tids = sorted(tasks)

    def dist(a: int, j: int) -> float:
        return math.hypot(tasks[j][0] - agents[a][0], tasks[j][1] - agents[a][1])

    k = needed or {}

    part = {a: j for a, j in (start or {}).items() if a in agents and j in tasks}
    for a in sorted(agents):
        if a not in part:
            part[a] = min(tids, key=lambda j: (dist(a, j), j))
    size = dict.fromkeys(tids, 0)
    for j in part.values():
        size[j] += 1
    for _ in range(max_passes):
        moved = False
        for a in sorted(agents):
            here = part[a]
            u_here = grape_utility(
                tasks[here][2], dist(a, here), size[here], cost_weight, social_inhibition, k.get(here, 1)
            )
            best, u_best = here, u_here
            for j in tids:
                if j != here:
                    u = grape_utility(tasks[j][2], dist(a, j), size[j] + 1, cost_weight, social_inhibition, k.get(j, 1))
                    if u > u_best:
                        best, u_best = j, u
            if best != here:
                size[here] -= 1
                size[best] += 1
                part[a] = best
                moved = True
        if not moved:
            break
    return part


class CentralGRAPE(Centralized):
    """GRAPE's game solved by a leader: a Nash-stable partition of the agents it heard from over the
    tasks it knows (several agents may share a task), warm-started from its last one."""

    Params = CentralGRAPEParams
    params: CentralGRAPEParams

    def _plan(self, agents: dict[int, tuple[float, float]], speed: float) -> dict[int, int]:
        p = self.params
        tasks = {j: v[:3] for j, v in self.tasks.items()}
        start = self.plan if p.commit else None
        fixed: dict[int, int] = {}
        if start and self.needed:
            # a full coalition stays on its task until it is done (commit): the task's workload falls as
            # it is worked, and re-solving would pull the robots off it for fuller tasks, again and
            # again (GRAPE's own agents re-decide only when the partition they hold changes); in worlds
            # without team tasks the warm start alone is kept, as published (docs/baselines.md)
            on = Counter(j for a, j in start.items() if a in agents and j in tasks)
            fixed = {a: j for a, j in start.items() if a in agents and j in tasks and on[j] >= self.needed.get(j, 1)}
            agents = {a: xy for a, xy in agents.items() if a not in fixed}
            tasks = {j: v for j, v in tasks.items() if j not in set(fixed.values())}
        free = nash_stable_partition(agents, tasks, p.cost_weight, p.social_inhibition, start, needed=self.needed)
        self.plan = fixed | free
        return self.plan


__all__ = [
    "SGA",
    "CentralGRAPE",
    "CentralParams",
    "Centralized",
    "Hungarian",
    "least_travel",
    "nash_stable_partition",
    "sequential_greedy",
]
