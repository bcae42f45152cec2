"""The search-and-rescue scenario (CBBA-ETC paper, Section 5.1 and Table 1).

Circular arena; robots of colour RED/GREEN/BLUE (robot i has colour i mod 3) moving holonomically
at ``agents.max_speed``; victims at uniform random positions with a hidden wall colour and a
lifetime. A robot sees victims and robots in its vision cone (range and full angle around its
heading, the direction it last moved in), not their colours. Within ``inspect_range`` it can
inspect a victim (learns the colour: a mismatch counts as a failed rescue), then rescue it if the
colours match (a robot turns to the victim it inspects or rescues, and learns the outcome of its
own actions). Inspecting takes ``inspect_time`` seconds and rescuing ``rescue_time`` seconds: the
robot is busy meanwhile (its tree keeps ticking; an action other than going on with it stops it,
``interrupt: on_change``, or is ignored, ``never``), and the outcome
(the colour learnt, the victim rescued) happens when the action ends, if the victim is still there
(``rescue_saves: start`` saves it when the rescue starts instead); an action that ends within the
tick it began in takes effect in that tick. Durations are rounded up to whole ticks, so results
converge as ``run.dt`` shrinks (tests/test_world.py pins it).

Moves, inspections and rescues fail with their probabilities. A failed inspection or rescue is known
when it is tried and costs only that tick (``failure_known: start``; the paper gives failed moves a
time penalty and these none); ``failure_known: end`` charges its whole duration. A move is the run
of ticks a robot spends going toward one goal (a point, or a victim): it fails at its start and
leaves the robot stuck for ``move_penalty`` seconds, after which it tries again (``move_failure:
per_move``, which converges as dt shrinks); ``per_tick`` draws on every tick of moving. In steady
state a rescued or expired victim is replaced at once; in finite mode it is not. After
``agent_loss_grace`` seconds each robot is lost for good with probability ``agent_loss`` per step:
per tick, per simulated second
(``agent_loss_per: second``, one draw a tick at 1 - (1 - p)^dt), or per decision of the robot
(``decision``: one draw for each robot that chose, at the tick before, an action other than the one it
was doing, or chose anew once a timed action, a move penalty or an abandon ended).

For the consensus strategies colours are known when bidding ("bid-then-verify"): their
observations carry the victims' colours, but a rescue still needs the robot's own inspection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmbed.extension.actions import MOVE_ACTIONS
from swarmbed.extension.allocator import Allocator
from swarmbed.extension.figures import Figure
from swarmbed.extension.presets import Preset
from swarmbed.extension.scenario import Scenario, Sensing, World, obstacles_outside, sight
from swarmbed.extension.space_nodes import SPACE_NODES
from swarmbed.scenarios.budget import ACTIVITIES, IDLE, INSPECTING, MOVING, PENALTY, RESCUING, TimeBudget
from swarmbed.scenarios.paths import Navigator, Planner, blocked_moves, free_places, planner_problems
from swarmbed.scenarios.victims import ALIVE, EXPIRED, RESCUED, VictimRows
from swarmbed.schema.experiment import MAX_TASKS, Experiment
from swarmbed.wire.codec import TASK_DTYPE
from swarmbed.wire.observation import Observation
from swarmbed.wire.observation import Observation as AnyObservation

FORGET_AFTER = 2.0  # lifetimes after its spawn a victim's row may leave the world's arrays
COLOR_NAMES = ("red", "green", "blue")
# The paper gives no durations for inspecting and rescuing; they are calibrated on the
# non-communicating `tree` strategy alone, against three facts of its baseline (docs/reproduction.md,
# section 2), and then frozen for every strategy and scenario. The rescue is done in the tick it is
# started in (0 s): a matched victim must practically never expire between its inspection and its
# rescue (tree's failed rescues are twice its rescues); the inspection's length sets the pace.
INSPECT_TIME = 33.0
RESCUE_TIME = 0.0


class SARParams(BaseModel):
    """The ``scenario:`` section of a search-and-rescue experiment (CBBA-ETC paper, Table 1)."""

    presets: ClassVar[dict[str, Preset]] = {
        "cbba_etc_text": Preset(
            {
                "agent_loss_per": "second",
                "interrupt": "on_change",
                "failure_known": "start",
                "move_failure": "per_move",
            },
            "the CBBA-ETC paper's text: robot loss 'per step', a step read as a simulated second (Figure 3: 'a "
            "specific time step (233 seconds)'); behavior trees that 'can interrupt the current action sequence'; "
            "a time penalty for failed moves only (Table 1), a Move one action of the tree (docs/reproduction.md "
            "sections 1 and 10)",
        ),
    }

    model_config = ConfigDict(extra="forbid")
    arena_radius: float = Field(32.0, gt=0, description="radius of the circular arena (m)")
    victims: int = Field(100, ge=0, le=MAX_TASKS, description="victims at any time (steady state) or in all (finite)")
    lifetime: float = Field(100.0, gt=0, description="seconds a victim lives before it expires")
    replace: bool = Field(True, description="steady state: a rescued or expired victim is replaced")
    first_ages: Literal["new", "spread"] = Field(
        "spread",
        description="the first victims' ages: spread, uniform over a lifetime (a steady state from the start: "
        "expiries come one by one, not all at once every lifetime), or new, all born at time 0 "
        "(their replacements then expire in waves a lifetime apart for the whole run)",
    )
    colors: int = Field(3, ge=1, le=3, description="RED, GREEN, BLUE")
    vision_range: float = Field(12.0, gt=0, description="conical vision: range (m)")
    vision_angle: float = Field(math.pi / 2, gt=0, le=2 * math.pi, description="conical vision: full angle (rad)")
    inspect_range: float = Field(5.0, gt=0, description="distance within which a robot can inspect/rescue (m)")
    move_fail: float = Field(0.0, ge=0, le=1, description="probability that a move fails")
    inspect_fail: float = Field(0.0, ge=0, le=1, description="probability that an inspection fails")
    rescue_fail: float = Field(0.0, ge=0, le=1, description="probability that a rescue fails")
    move_penalty: float = Field(0.5, ge=0, description="seconds a robot is stuck after a failed move")
    abandon_time: float = Field(
        0.0,
        ge=0,
        description="seconds the 'abandon' action takes (the text: 'the robot executes an \"abandon\" action'; "
        "no duration given): the robot is busy for it, booked in the time budget as penalty; 0: instant "
        "(docs/reproduction.md section 9, M3)",
    )
    inspect_time: float = Field(
        INSPECT_TIME,
        ge=0,
        description="seconds an inspection takes; its result comes at "
        "the end (calibrated on tree: docs/reproduction.md)",
    )
    rescue_time: float = Field(
        RESCUE_TIME,
        ge=0,
        description="seconds a rescue takes (0: the tick it starts in); the victim is saved at the end "
        "(calibrated on tree: docs/reproduction.md)",
    )
    failure_known: Literal["end", "start"] = Field(
        "start",
        description="when a failed inspection or rescue is known: at its end, after its whole duration, or at its "
        "start, costing only the tick it was tried in (the paper gives failed moves a penalty and these none)",
    )
    move_failure: Literal["per_tick", "per_move"] = Field(
        "per_move",
        description="what a failed move is: any tick of moving (the loss grows as dt shrinks), or one move, the "
        "run of ticks toward one goal, failing at its start and tried again after the penalty",
    )
    rescue_saves: Literal["end", "start"] = Field(
        "end",
        description="when a rescue saves its victim: when it ends, if the victim is still there, or when it starts "
        "(the robot then stays busy for rescue_time)",
    )
    interrupt: Literal["never", "on_change"] = Field(
        "on_change",
        description="a robot busy inspecting or rescuing whose action this tick is not to go on with it: on_change "
        "stops the action and does the new one this tick (the paper's behavior trees 'can interrupt the current "
        "action sequence' when the target's status changes; allocator.monitor says who watches), never lets the "
        "action run its whole length",
    )
    agent_loss: float = Field(0.0, ge=0, le=1, description="probability per step that a robot is lost for good")
    agent_loss_grace: float = Field(500.0, ge=0, description="seconds before agent loss can happen")
    agent_loss_per: Literal["tick", "second", "decision"] = Field(
        "tick",
        description="the 'step' agent_loss is a probability per (the text: 'per step'; its SimPy world's steps "
        "are read as seconds by one caption, 'a specific time step (233 seconds)'): tick, "
        "second (per tick 1 - (1 - p)^dt: the same loss per simulated second at any run.dt) or "
        "decision (a step of the robot's own process in a process-based simulation: each time its tree or "
        "state machine chooses a new action, or chooses again after a timed action)",
    )
    colors_for_bidding: Literal["auto", "always", "never"] = Field(
        "auto", description="show victims' colours to bidders (auto: when the allocator bids with colours)"
    )


@dataclass(frozen=True, slots=True)
class SARObservation(Observation):
    """A robot's observation: the core, plus what search and rescue adds."""

    color: int  # this robot's colour
    reach: float  # the inspection distance
    robots: list[tuple[int, float, float]]  # other robots in the vision cone: id, x, y
    inspected: list[tuple[int, int]]  # results of this robot's inspections last tick: victim, colour
    rescued: list[int]  # victims this robot rescued last tick
    busy: int  # ticks this robot is still busy (a failed move, an inspection or a rescue)
    team: list[tuple[int, float, float]] | None = None  # at tick 0 only: every robot's start position


class SAR(Scenario):
    """Search and rescue with heterogeneous robots (CBBA-ETC paper, Section 5.1)."""

    Params = SARParams
    Observation = SARObservation
    bt_nodes = SPACE_NODES
    actions = {**MOVE_ACTIONS, "inspect": (int,), "rescue": (int,), "abandon": (int,)}
    outcome_metrics = ("rescued", "expired", "failed_rescues")
    benefit_metric = "rescued"
    metric_labels = {
        "rescued": "victims rescued per trial",
        "expired": "victims expired per trial",
        "failed_rescues": "failed rescues (mismatch found) per trial",
        "negotiations": "negotiations per trial",
    }
    # CBBA-ETC Section 5.4: outcomes per strategy, their spread, the cost in messages, and the
    # victim-count, robot-count and failure series
    figures = (
        Figure("means", ("rescued", "expired"), label="victims per trial"),
        Figure(
            "boxes",
            ("rescued", "expired", "failed_rescues", "negotiations", "network.messages_sent", "network.bytes_sent"),
        ),
        Figure("scatter", ("rescued", "network.messages_sent")),
        Figure("against_count", ("network.messages_sent", "rescued"), over=("scenario.victims", "agents.count")),
        Figure("against_factor", ("rescued",)),
    )
    control_allocator = "cbba-etc"  # the paper's proposed strategy, which its tests compare the others with
    summary_keys = (
        "rescued",
        "expired",
        "failed_rescues",
        "inspections",
        "inspect_failures",
        "rescue_failures",
        "move_failures",
        "abandons",
        "interrupted",
        "spawned",
        "victims_alive",
        "victims_accounted",
        "distance_total",
        "distance_per_agent",
        "rescues_per_agent",
        "invalid_actions",
        "stale_actions",
        "time_budget",
    )
    params: SARParams

    @classmethod
    def check(cls, exp: Experiment, params: BaseModel) -> list[str]:
        assert isinstance(params, SARParams)
        r = params.arena_radius
        return obstacles_outside(
            exp, lambda x, y: math.hypot(x, y) <= r, f"a disc of radius {r:g} about [0, 0]", (-r, -r, r, r)
        ) + (planner_problems(exp.obstacles.compile()) if exp.obstacles is not None else [])

    def make_world(self, rng: np.random.Generator, allocator: type[Allocator] | None = None) -> SARWorld:
        return SARWorld(self, rng, bids_with_colors=allocator is not None and allocator.bids_with_colors)

    def sensing(self) -> Sensing:
        return Sensing(self.params.vision_range, self.params.vision_angle)

    def blackboard(self) -> dict:
        return {**super().blackboard(), "arrival_radius": self.params.inspect_range}

    def random_point(self, rng: np.random.Generator) -> tuple[float, float]:
        r = self.params.arena_radius * math.sqrt(float(rng.random()))
        a = float(rng.uniform(-math.pi, math.pi))
        return r * math.cos(a), r * math.sin(a)

    def random_action(self, obs: AnyObservation, rng: np.random.Generator) -> list:
        if len(obs.tasks) and rng.random() < 0.5:
            victim = int(obs.tasks["id"][int(rng.integers(len(obs.tasks)))])
            return [("inspect", "rescue", "abandon", "goto_task")[int(rng.integers(4))], victim]
        if rng.random() < 0.2:
            return ["goto", *self.random_point(rng)]
        return super().random_action(obs, rng)

    def summary_rows(self, summary: dict) -> list[tuple[str, object]]:
        return [
            ("rescued", summary["rescued"]),
            ("expired", summary["expired"]),
            ("failed rescues (mismatch found)", summary["failed_rescues"]),
            ("victims spawned / still alive", f"{summary['spawned']} / {summary['victims_alive']}"),
            ("negotiations", summary.get("negotiations", "-")),
            ("agents lost", len(summary["agents_lost"])),
            ("robot time", _budget_text(summary["time_budget"])),
        ]


def _budget_text(budget: dict) -> str:
    """``moving 1 %, inspecting 98 % (25 % lost), ...``: the time budget as the run's printout shows it."""
    parts = [f"{name} {100 * budget[name]:.0f} %" for name in ACTIVITIES]
    parts[INSPECTING] += f" ({100 * budget['inspecting_lost']:.0f} % lost)"
    return ", ".join(parts)


class Decisions:
    """The robots' decisions, for ``agent_loss_per: decision``: a decision is a free tick whose action
    differs from the robot's last choice; a timed action forgets the last choice, so the choice after
    it is one too. ``last_tick`` lists, in id order, the robots that decided at the last tick applied."""

    def __init__(self) -> None:
        self.chosen: dict[int, list] = {}  # robot -> the action it chose at its last free tick
        self.last_tick: list[int] = []

    def note(self, robot: int, action: list) -> None:
        if self.chosen.get(robot) != action:
            self.last_tick.append(robot)
            self.chosen[robot] = action

    def forget(self, robot: int) -> None:
        self.chosen.pop(robot, None)


class SARWorld(VictimRows, World):
    def __init__(self, scenario: SAR, rng: np.random.Generator, bids_with_colors: bool) -> None:
        sc = scenario.params
        self.scenario, self.sc, self.dt = scenario, sc, scenario.dt
        self.spawn_rng, self.fail_rng, self.loss_rng = rng.spawn(3)
        self.n = scenario.agents.count
        self.speed = scenario.agents.max_speed
        self.show_colors = {"always": True, "never": False}.get(sc.colors_for_bidding, bids_with_colors)
        start = [scenario.random_point(self.spawn_rng) for _ in range(self.n)]
        self.ax = np.array([p[0] for p in start])
        self.ay = np.array([p[1] for p in start])
        # with obstacles: a start inside one is drawn again (after the first draws); moves plan around them
        self.walls = scenario.obstacles.compile() if scenario.obstacles is not None else None
        self.navigator: Navigator | None = None
        if self.walls is not None:
            self.ax, self.ay = free_places(self.walls, self.ax, self.ay, self._random_point)
            r = sc.arena_radius
            planner = Planner(self.walls, lambda x, y: np.hypot(x, y) <= r)
            self.navigator = Navigator(planner, reach=self.walls.clearance / 2)
        self.heading = self.spawn_rng.uniform(-math.pi, math.pi, self.n)
        self.color = np.arange(self.n) % sc.colors
        self.alive = np.ones(self.n, dtype=bool)
        self.busy_until = np.zeros(self.n, dtype=np.int64)
        self.distance = np.zeros(self.n)
        self.rescues = np.zeros(self.n, dtype=np.int64)
        self.invalid_actions = np.zeros(self.n, dtype=np.int64)
        self.stale_actions = np.zeros(self.n, dtype=np.int64)  # aimed at a victim already gone
        self.budget = TimeBudget(self.n)
        self.counts = {
            "rescued": 0,
            "expired": 0,
            "failed_rescues": 0,
            "inspections": 0,
            "inspect_failures": 0,
            "rescue_failures": 0,
            "move_failures": 0,
            "abandons": 0,
            "interrupted": 0,
        }
        self._init_victims()  # rows of victims born more than FORGET_AFTER lifetimes ago leave
        self.inspected: dict[int, set[int]] = {}  # victim -> robots that inspected it
        self.results: dict[int, list[list[int]]] = {}  # robot -> inspection results for its next observation
        self.rescued_by: dict[int, list[int]] = {}  # robot -> victims it rescued, for its next observation
        # robot -> (inspect|rescue, victim, tick it ends in, tick it began in)
        self.pending: dict[int, tuple[str, int, int, int]] = {}
        self.goal: dict[int, tuple] = {}  # robot -> the goal of the move it is making (move_failure: per_move)
        self.decisions = Decisions()  # agent_loss_per: decision
        self.tick = 0
        self._spawn(sc.victims, first=True)

    # -- victims ---------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.tick * self.dt

    def _spawn(self, count: int, first: bool = False) -> None:
        """``count`` new victims; the first ones, with ``first_ages: spread``, of ages drawn uniform
        over a lifetime after every place and colour, oldest first so that ids stay in birth order."""
        for _ in range(count):
            v = self._next_row(keep_after=self.time - FORGET_AFTER * self.sc.lifetime)
            self.vx[v], self.vy[v] = self.scenario.random_point(self.spawn_rng)
            if self.walls is not None:  # not inside an obstacle: drawn again before its colour
                (x,), (y,) = free_places(self.walls, self.vx[v : v + 1], self.vy[v : v + 1], self._random_point)
                self.vx[v], self.vy[v] = x, y
            self.vcolor[v] = int(self.spawn_rng.integers(self.sc.colors))
            self.vspawn[v] = self.time
            self.vstatus[v] = ALIVE
            self.nv += 1
        if first and self.sc.first_ages == "spread" and count:
            ages = np.sort(self.spawn_rng.uniform(0.0, self.sc.lifetime, count))[::-1]
            self.vspawn[self.nv - self.base - count : self.nv - self.base] = self.time - ages

    def _random_point(self) -> tuple[float, float]:
        return self.scenario.random_point(self.spawn_rng)

    def _end(self, victim: int, status: int) -> None:
        self.vstatus[victim - self.base] = status
        self.inspected.pop(victim, None)  # read only while it is there: a soak would keep every one
        self.counts["rescued" if status == RESCUED else "expired"] += 1
        if self.sc.replace:
            self._spawn(1)

    @property
    def finished(self) -> bool:
        return not self.sc.replace and self.victims_alive == 0

    def markers(self) -> dict[int, tuple[float, float, str]]:
        """Victims alive, labelled with their (hidden) wall colour."""
        return {
            int(v) + self.base: (float(self.vx[v]), float(self.vy[v]), COLOR_NAMES[int(self.vcolor[v])])
            for v in np.flatnonzero(self.vstatus == ALIVE)
        }

    def agent_labels(self) -> dict[int, str]:
        return {int(i): COLOR_NAMES[int(self.color[i])] for i in np.flatnonzero(self.alive)}

    # -- agents ----------------------------------------------------------------------------------
    def positions(self) -> tuple[list[int], list[float], list[float]]:
        ids = [int(i) for i in np.flatnonzero(self.alive)]
        return ids, [float(self.ax[i]) for i in ids], [float(self.ay[i]) for i in ids]

    def kill(self, agent_id: int) -> None:
        self.alive[agent_id] = False
        self.pending.pop(agent_id, None)  # what it was doing dies with it
        self.goal.pop(agent_id, None)
        self.decisions.forget(agent_id)
        if self.navigator is not None:
            self.navigator.forget(agent_id)

    def draw_losses(self) -> list[int]:
        """Robots lost at the next tick (one draw per live robot once the grace period is over)."""
        p = self.sc.agent_loss
        if p <= 0 or self.time < self.sc.agent_loss_grace:
            return []
        if self.sc.agent_loss_per == "decision":  # one draw per decision, in id order (apply went in id order)
            return [i for i in self.decisions.last_tick if self.alive[i] and self.loss_rng.random() < p]
        if self.sc.agent_loss_per == "second":  # the same draws, each at the chance of a tick's share of a second
            p = -math.expm1(self.dt * math.log1p(-p)) if p < 1 else 1.0
        return [int(i) for i in np.flatnonzero(self.alive) if self.loss_rng.random() < p]

    def _cones(self, robots: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Which of the points (x, y) each of ``robots`` sees (range, cone, walls), a row a robot."""
        ax, ay, heading = self.ax[robots], self.ay[robots], self.heading[robots]
        return sight(ax, ay, x, y, self.sc.vision_range, heading, self.sc.vision_angle, self.walls)

    def observations(self) -> dict[int, SARObservation]:
        live = np.flatnonzero(self.vstatus == ALIVE)
        lx, ly = self.vx[live], self.vy[live]
        left = self.vspawn[live] + self.sc.lifetime - self.time
        robots = np.flatnonzero(self.alive)
        ids = robots.tolist()
        # every (robot, victim) pair in view, robot by robot, each robot's victims in index order
        by, seen = np.nonzero(self._cones(robots, lx, ly))
        rows = live[seen]
        tables = np.empty(len(seen), dtype=TASK_DTYPE)
        tables["id"], tables["x"], tables["y"], tables["remaining"] = rows + self.base, lx[seen], ly[seen], left[seen]
        if self.show_colors:
            tables["color"] = self.vcolor[rows]
        else:  # a colour is known to the robots that inspected the victim
            tables["color"] = [
                c if ids[k] in self.inspected.get(v, ()) else -1
                for k, v, c in zip(by.tolist(), tables["id"].tolist(), self.vcolor[rows].tolist())
            ]
        cut = np.searchsorted(by, np.arange(len(robots) + 1)).tolist()
        sees_robots = self._cones(robots, self.ax[robots], self.ay[robots])
        np.fill_diagonal(sees_robots, False)  # a robot is not among the others it sees
        team = [(int(j), float(self.ax[j]), float(self.ay[j])) for j in robots]
        out = {}
        for k, i in enumerate(ids):
            out[i] = SARObservation(
                self.time,
                team[k][1],
                team[k][2],
                float(self.heading[i]),
                float(self.speed),
                tables[cut[k] : cut[k + 1]].copy(),
                color=int(self.color[i]),
                reach=self.sc.inspect_range,
                robots=[team[m] for m in np.flatnonzero(sees_robots[k]).tolist()],
                inspected=[(v, c) for v, c in self.results.pop(i, [])],
                rescued=self.rescued_by.pop(i, []),
                busy=int(max(0, self.busy_until[i] - self.tick)),
                team=self._team() if self.tick == 0 else None,  # where the team starts: known before deployment
            )
        return out

    def _team(self) -> list[tuple[int, float, float]]:
        return [(int(j), float(self.ax[j]), float(self.ay[j])) for j in range(self.n)]

    def _victim(self, action: list) -> int | None:
        if len(action) == 2 and isinstance(action[1], int) and 0 <= action[1] < self.nv:
            return action[1]
        return None

    def _ticks(self, seconds: float) -> int:
        """Whole ticks that ``seconds`` of activity starting now occupy (at least this one)."""
        return max(1, math.ceil(seconds / self.dt - 1e-9))

    def _busy(self, i: int, seconds: float) -> None:
        """The robot is occupied from this tick for ``seconds`` (whole ticks, rounded up); what it
        chooses once free is a decision, whatever it was doing before."""
        self.busy_until[i] = self.tick + self._ticks(seconds)
        self.decisions.forget(i)

    def _begin(self, i: int, name: str, v: int, seconds: float) -> None:
        """Start a timed action; it ends (and takes effect) in the last tick it occupies. With
        ``failure_known: start`` a failed one ends here, costing this tick only; with
        ``rescue_saves: start`` a rescue saves its victim here and the robot stays busy."""
        self.budget.doing(i, INSPECTING if name == "inspect" else RESCUING)  # a failed try too: its tick
        if self.sc.failure_known == "start" and self._failed(name):
            self._busy(i, 0.0)
            return
        self._busy(i, seconds)
        if name == "rescue" and self.sc.rescue_saves == "start":
            self._rescue(i, v)
            return
        self.pending[i] = (name, v, int(self.busy_until[i]) - 1, self.tick)
        if self.busy_until[i] - 1 == self.tick:
            self._finish(i)

    def _failed(self, name: str) -> bool:
        """Whether this try of an inspection or a rescue fails (one draw, counted if it does)."""
        if self.fail_rng.random() < (self.sc.inspect_fail if name == "inspect" else self.sc.rescue_fail):
            self.counts[f"{name}_failures"] += 1
            return True
        return False

    def _rescue(self, i: int, v: int) -> None:
        self.rescues[i] += 1
        self.rescued_by.setdefault(i, []).append(v)
        self._end(v, RESCUED)

    def _finish(self, i: int) -> None:
        """The end of robot i's inspection or rescue: the outcome, if the victim is still there."""
        name, v, end, began = self.pending.pop(i)
        at_end = self.sc.failure_known == "end"
        if not self._in_reach(i, v):
            self.stale_actions[i] += 1  # it expired, or another robot rescued it, meanwhile
            if name == "inspect":
                self.budget.inspection_lost(i, end - began + 1)
        elif name == "inspect":
            if at_end and self._failed(name):
                return
            self.counts["inspections"] += 1
            if i not in self.inspected.setdefault(v, set()):
                self.inspected[v].add(i)
                if self.vcolor[v - self.base] != self.color[i]:
                    self.counts["failed_rescues"] += 1
            self.results.setdefault(i, []).append([v, int(self.vcolor[v - self.base])])
        elif not (at_end and self._failed(name)):
            self._rescue(i, v)

    def _move(self, i: int, tx: float, ty: float, goal: tuple) -> None:
        new_move = self.sc.move_failure == "per_tick" or self.goal.get(i) != goal
        if new_move and self.fail_rng.random() < self.sc.move_fail:
            self.counts["move_failures"] += 1
            self.budget.doing(i, PENALTY)
            self._busy(i, self.sc.move_penalty)
            self.goal.pop(i, None)  # it tries this move again once the penalty is over
            return
        self.goal[i] = goal
        if self.navigator is not None:
            tx, ty = self.navigator.toward(i, float(self.ax[i]), float(self.ay[i]), (tx, ty))
        dx, dy = tx - self.ax[i], ty - self.ay[i]
        dist = math.hypot(dx, dy)
        if dist < 1e-12:
            return
        self.budget.doing(i, MOVING)
        step = min(self.speed * self.dt, dist)
        self.heading[i] = math.atan2(dy, dx)
        self.ax[i] += dx / dist * step
        self.ay[i] += dy / dist * step
        self.distance[i] += step

    def _face(self, i: int, v: int) -> None:
        """A robot that inspects or rescues a victim turns to it (its vision cone covers it)."""
        r = self._at(v)
        if r is None:
            return
        dx, dy = self.vx[r] - self.ax[i], self.vy[r] - self.ay[i]
        if dx or dy:
            self.heading[i] = math.atan2(dy, dx)

    def _in_reach(self, i: int, v: int) -> bool:
        r = self._at(v)
        return (
            r is not None
            and self.vstatus[r] == ALIVE
            and math.hypot(self.vx[r] - self.ax[i], self.vy[r] - self.ay[i]) <= self.sc.inspect_range + 1e-9
            and (
                self.walls is None or bool(self.walls.clear([self.ax[i]], [self.ay[i]], [self.vx[r]], [self.vy[r]])[0])
            )
        )

    def apply(self, actions: dict[int, list]) -> None:
        """Advance one tick; robots act in id order on the state of this tick."""
        live = np.flatnonzero(self.alive)
        before = (self.ax[live].copy(), self.ay[live].copy(), self.distance[live].copy())
        by_decision = self.sc.agent_loss_per == "decision"
        self.decisions.last_tick = []
        for i in map(int, live):
            action = actions.get(i, ["stop"])
            if self.busy_until[i] > self.tick and self._interrupted(i, action):
                self.busy_until[i] = self.tick
            if self.busy_until[i] > self.tick:
                self.budget.book(i)
                if i in self.pending and self.pending[i][2] == self.tick:
                    self._finish(i)
                continue
            self.budget.doing(i, IDLE)  # unless what it does now says otherwise
            if by_decision:
                self.decisions.note(i, action)
            self._act(i, action)
            self.budget.book(i)
        if self.walls is not None:  # a move that would cross a wall does not happen: the robot stays
            stopped = live[blocked_moves(self.walls, before[0], before[1], self.ax[live], self.ay[live])]
            back = np.searchsorted(live, stopped)
            self.ax[stopped], self.ay[stopped], self.distance[stopped] = (b[back] for b in before)
        self.tick += 1
        expired = (self.vstatus == ALIVE) & (self.vspawn + self.sc.lifetime <= self.time + 1e-9)
        for v in [int(r) + self.base for r in np.flatnonzero(expired)]:  # ids: _end may move the rows
            self._end(v, EXPIRED)

    def _interrupted(self, i: int, action: list) -> bool:
        """With ``interrupt: on_change``, whether busy robot i's action stops its inspection or
        rescue (anything but going on with it); what it spent on it is booked lost if an inspection."""
        if self.sc.interrupt == "never" or i not in self.pending:
            return False
        name, v, _, began = self.pending[i]
        if len(action) == 2 and action[0] == name and action[1] == v:
            return False
        del self.pending[i]
        self.counts["interrupted"] += 1
        if name == "inspect":
            self.budget.inspection_lost(i, self.tick - began)
        return True

    def _act(self, i: int, action: list) -> None:
        """Robot i, free this tick, does ``action`` (an admitted one: its shape is not trusted)."""
        name = action[0] if action else None
        v = self._victim(action)
        r = None if v is None else self._at(v)
        if name in ("inspect", "rescue") and v is not None:
            self._face(i, v)  # it looks where the victim is (or was)
        if name not in ("goto", "goto_task"):
            self.goal.pop(i, None)  # the move it was making, if any, is over
        if name == "goto" and len(action) == 3 and all(isinstance(c, (int, float)) for c in action[1:]):
            self._move(i, float(action[1]), float(action[2]), ("point", action[1], action[2]))
        elif name == "goto_task" and r is not None:
            self._move(i, float(self.vx[r]), float(self.vy[r]), ("victim", v))
        elif name == "inspect" and v is not None and self._in_reach(i, v):
            self._begin(i, "inspect", v, self.sc.inspect_time)
        elif (
            name == "rescue"
            and v is not None
            and r is not None
            and self._in_reach(i, v)
            and i in self.inspected.get(v, ())
            and self.vcolor[r] == self.color[i]
        ):
            self._begin(i, "rescue", v, self.sc.rescue_time)
        elif name == "abandon" and v is not None:
            self.counts["abandons"] += 1
            if self.sc.abandon_time > 0:  # it takes time: busy, and booked as time lost
                self.budget.doing(i, PENALTY)
                self._busy(i, self.sc.abandon_time)
        elif name in ("inspect", "rescue", "goto_task") and v is not None and (r is None or self.vstatus[r] != ALIVE):
            self.stale_actions[i] += 1  # someone was faster, or it expired: not the robot's fault
        elif name not in ("stop", "halt"):  # robots here move at a set speed: halting is stopping
            self.invalid_actions[i] += 1

    # -- metrics -----------------------------------------------------------------------------------
    def row(self) -> dict:
        return {
            "tick": self.tick,
            "time": round(self.time, 9),
            "spawned": self.nv,
            "rescued": self.counts["rescued"],
            "expired": self.counts["expired"],
            "failed_rescues": self.counts["failed_rescues"],
            "victims_alive": self.victims_alive,
            "agents_alive": int(self.alive.sum()),
        }

    def invariants(self) -> list[str]:
        c, spawned, alive = self.counts, self.nv, self.victims_alive
        if c["rescued"] + c["expired"] + alive != spawned:
            return [
                f"victims unaccounted: rescued {c['rescued']} + expired {c['expired']} + alive {alive} "
                f"!= spawned {spawned}"
            ]
        return []

    def summary(self) -> dict:
        spawned, alive = self.nv, self.victims_alive
        c = self.counts
        problems = self.invariants()
        if problems:
            raise AssertionError(problems[0])
        return {
            **c,
            "spawned": spawned,
            "victims_alive": alive,
            "victims_accounted": True,
            "distance_total": float(self.distance.sum()),
            "distance_per_agent": [float(d) for d in self.distance],
            "rescues_per_agent": [int(r) for r in self.rescues],
            "invalid_actions": int(self.invalid_actions.sum()),
            "stale_actions": int(self.stale_actions.sum()),
            "time_budget": self.budget.summary(self.dt),
        }

    def per_agent(self) -> dict[str, list]:
        return {
            "color": [int(c) for c in self.color],
            "distance": [float(d) for d in self.distance],
            "rescues": [int(r) for r in self.rescues],
            "invalid_actions": [int(v) for v in self.invalid_actions],
            "stale_actions": [int(v) for v in self.stale_actions],
        }
