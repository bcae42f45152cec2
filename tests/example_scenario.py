"""A third scenario written the way a user would: pickup and delivery (SPACE's stated future work),
in this one file and nowhere else in swarmbed. Items wait at random points of a rectangle; a robot
that reaches an item picks it up, carries it to the depot and drops it there.

Experiments name it by target, with no change to swarmbed:

    scenario: {kind: tests/example_scenario.py:PickupDelivery, items: 12}
    allocator: {name: tests/example_scenario.py:NearestItem}

(an installed package would add a ``swarmbed.scenarios`` entry point instead).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmbed.extension import Allocator, Figure, LocalView, Scenario, Sensing, World
from swarmbed.extension.space_nodes import SPACE_NODES
from swarmbed.wire.codec import TASK_DTYPE
from swarmbed.wire.observation import Observation

WAITING, CARRIED, DELIVERED = 0, 1, 2


class PickupParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    width: float = Field(100.0, gt=0, description="area width")
    height: float = Field(60.0, gt=0, description="area height")
    items: int = Field(10, ge=0, description="items to deliver")
    depot: tuple[float, float] = Field((0.0, 0.0), description="where items are delivered")
    reach: float = Field(2.0, gt=0, description="distance at which an item is picked up or dropped")


@dataclass(frozen=True, slots=True)
class PickupObservation(Observation):
    carrying: int  # the item this robot carries, or -1
    depot: tuple[float, float]


class PickupDelivery(Scenario):
    """Pickup and delivery: carry every item to the depot."""

    Params = PickupParams
    Observation = PickupObservation
    bt_nodes = SPACE_NODES
    outcome_metrics = ("delivered", "items")
    benefit_metric = "delivered"
    summary_keys = ("delivered", "items", "carried", "distance_total", "invalid_actions")
    # what ``swarmbed analyze`` tabulates and draws for its sweeps: named here, drawn by swarmbed
    metric_labels = {"delivered": "items delivered per run", "distance_total": "distance driven by all robots"}
    figures = (
        Figure("means", ("delivered",), label="items per run"),
        Figure("boxes", ("delivered", "distance_total")),
    )
    params: PickupParams

    def make_world(self, rng: np.random.Generator, allocator: type | None = None) -> PickupWorld:
        return PickupWorld(self, rng)

    def sensing(self) -> Sensing:
        return Sensing(math.inf)

    def blackboard(self) -> dict:
        return {**super().blackboard(), "arrival_radius": self.params.reach}  # the SPACE tree's exploration reads it

    def random_point(self, rng: np.random.Generator) -> tuple[float, float]:
        return float(rng.uniform(0, self.params.width)), float(rng.uniform(0, self.params.height))


class PickupWorld(World):
    def __init__(self, scenario: PickupDelivery, rng: np.random.Generator) -> None:
        p = scenario.params
        self.p, self.dt, self.speed = p, scenario.dt, scenario.agents.max_speed
        n = scenario.agents.count
        self.ax, self.ay = rng.uniform(0, p.width, n), rng.uniform(0, p.height, n)
        self.ix, self.iy = rng.uniform(0, p.width, p.items), rng.uniform(0, p.height, p.items)
        self.status = np.full(p.items, WAITING)
        self.carrying = np.full(n, -1)
        self.alive = np.ones(n, dtype=bool)
        self.distance = np.zeros(n)
        self.invalid = np.zeros(n, dtype=np.int64)
        self.tick = 0

    @property
    def time(self) -> float:
        return self.tick * self.dt

    @property
    def finished(self) -> bool:
        return bool((self.status == DELIVERED).all())

    def positions(self) -> tuple[list[int], list[float], list[float]]:
        ids = [int(i) for i in np.flatnonzero(self.alive)]
        return ids, [float(self.ax[i]) for i in ids], [float(self.ay[i]) for i in ids]

    def observations(self) -> dict[int, PickupObservation]:
        waiting = np.flatnonzero(self.status == WAITING)
        table = np.zeros(len(waiting), dtype=TASK_DTYPE)
        table["id"], table["x"], table["y"], table["remaining"], table["color"] = (
            waiting,
            self.ix[waiting],
            self.iy[waiting],
            1.0,
            -1,
        )
        return {
            i: PickupObservation(
                self.time,
                float(self.ax[i]),
                float(self.ay[i]),
                0.0,
                0.0,
                table,
                carrying=int(self.carrying[i]),
                depot=self.p.depot,
            )
            for i in self.positions()[0]
        }

    def _move(self, i: int, x: float, y: float) -> bool:
        """Toward (x, y) at full speed; whether it is within reach afterwards."""
        dx, dy = x - self.ax[i], y - self.ay[i]
        dist = math.hypot(dx, dy)
        step = min(self.speed * self.dt, dist)
        if dist > 0:
            self.ax[i] += dx / dist * step
            self.ay[i] += dy / dist * step
            self.distance[i] += step
        return dist - step <= self.p.reach

    def apply(self, actions: dict[int, list]) -> None:
        for i in self.positions()[0]:
            action = actions.get(i, ["stop"])
            if self.carrying[i] >= 0:  # a robot with an item heads for the depot whatever it asks
                if self._move(i, *self.p.depot):
                    self.status[self.carrying[i]] = DELIVERED
                    self.carrying[i] = -1
            elif (
                len(action) == 2
                and action[0] == "goto_task"
                and isinstance(action[1], int)
                and 0 <= action[1] < len(self.status)
            ):
                item = action[1]
                if self.status[item] == WAITING and self._move(i, float(self.ix[item]), float(self.iy[item])):
                    self.status[item], self.carrying[i] = CARRIED, item
            elif len(action) == 3 and action[0] == "goto" and all(isinstance(v, (int, float)) for v in action[1:]):
                self._move(i, float(action[1]), float(action[2]))
            elif action != ["stop"]:
                self.invalid[i] += 1
        self.tick += 1

    def kill(self, agent_id: int) -> None:
        self.alive[agent_id] = False
        if self.carrying[agent_id] >= 0:  # its item is dropped where it died, to be picked up again
            item = self.carrying[agent_id]
            self.ix[item], self.iy[item], self.status[item] = self.ax[agent_id], self.ay[agent_id], WAITING
            self.carrying[agent_id] = -1

    def row(self) -> dict:
        return {
            "tick": self.tick,
            "time": self.time,
            "delivered": int((self.status == DELIVERED).sum()),
            "carried": int((self.status == CARRIED).sum()),
        }

    def summary(self) -> dict:
        return {
            "delivered": int((self.status == DELIVERED).sum()),
            "items": int(len(self.status)),
            "carried": int((self.status == CARRIED).sum()),
            "distance_total": float(self.distance.sum()),
            "invalid_actions": int(self.invalid.sum()),
        }

    def per_agent(self) -> dict[str, list]:
        return {"distance": [float(d) for d in self.distance], "invalid_actions": [int(v) for v in self.invalid]}

    def invariants(self) -> list[str]:
        carried = sorted(int(c) for c in self.carrying if c >= 0)
        if carried != sorted(int(i) for i in np.flatnonzero(self.status == CARRIED)):
            return [f"items carried by robots {carried} != items marked carried"]
        return []


class NearestItem(Allocator):
    """Go for the nearest waiting item; tell the others which one (they avoid it)."""

    message_kinds = ("claim",)

    def __init__(self, agent_id, params, rng, run_seed=0):
        super().__init__(agent_id, params, rng, run_seed)
        self.claimed: dict[int, int] = {}  # item -> robot that claimed it

    def decide(self, view: LocalView[PickupObservation]) -> int | None:
        for msg in view.inbox:
            self.claimed[int(msg.data)] = msg.sender
        free = [t for t in view.tasks.values() if self.claimed.get(t.id, self.agent_id) == self.agent_id]
        if view.obs.carrying >= 0 or not free:
            return None
        best = min(free, key=lambda t: (view.distance_to(t), t.id))
        if self.claimed.get(best.id) != self.agent_id:
            self.claimed[best.id] = self.agent_id
            view.broadcast("claim", best.id)
        return best.id
