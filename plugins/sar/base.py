"""What every search-and-rescue strategy shares: the robot's memory of victims, the colours it
knows, the victims it found incompatible, and the cycle around its target (approach, inspect,
then rescue or abandon).

Memory is updated in :meth:`SARStrategy.observe`, every tick before the tree: victims seen, the
results of the robot's own inspections, and victims gone (no longer there although in view, or
past the lifetime the robot saw them with). Subclasses add their messages in :meth:`receive` and
their way of choosing a target in :meth:`acquire`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import ClassVar

from pydantic import BaseModel, ConfigDict, Field

from swarmbed.extension import Allocator, LocalView, TaskInfo
from swarmbed.scenarios.sar import SARObservation

TREES = Path(__file__).resolve().parent / "trees"


class StrategyParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    incompatible_for: float = Field(60.0, ge=0, description="seconds a mismatched victim is not retried")
    monitor: bool | None = Field(
        None,
        description="whether the robot watches its target while it inspects or rescues it, and turns to something "
        "else once the target is gone or no longer its own (with scenario.interrupt: on_change that stops the "
        "action); None: as the text has it, the behavior-tree strategies do (their condition nodes watch the "
        "target), cbba and c-cbba, state machines, do not; true: every strategy watches",
    )


class SARStrategy(Allocator):
    Params = StrategyParams
    params: StrategyParams
    #: what ``monitor: None`` means for this strategy (CBBA-ETC paper, Section 4: the tree's condition
    #: nodes "continuously monitor the status of the assigned target" and may interrupt the action)
    MONITORS: ClassVar[bool] = True

    def __init__(self, agent_id, params, rng, run_seed=0):
        super().__init__(agent_id, params, rng, run_seed)
        self.victims: dict[int, TaskInfo] = {}  # seen and not known to be gone
        self.expires: dict[int, float] = {}  # victim -> time its lifetime ends, as seen
        self.colors: dict[int, int] = {}  # victim -> colour, where known
        self.inspected: set[int] = set()  # victims this robot inspected
        self.incompatible: dict[int, float] = {}  # victim -> until when it is not retried
        self.gone: set[int] = set()  # victims known to be rescued or expired (their ids are never reused)
        self.target: int | None = None
        self.busy = False  # inspecting or rescuing
        self.holding = False  # busy with its target and not watching it (monitor off)
        self.my_color = -1
        self.reach = 5.0  # the scenario's inspection distance, as observed
        self.now = 0.0

    # -- memory -------------------------------------------------------------------------------------
    def observe(self, view: LocalView[SARObservation]) -> None:
        obs = view.obs
        self.now, self.my_color = view.time, obs.color
        self.reach = obs.reach
        self.busy = obs.busy > 0
        self.holding = not self.monitoring and self.busy and self.target is not None
        for v, info in view.tasks.items():
            self.victims[v] = info
            self.expires[v] = view.time + info.remaining
            if info.color >= 0:
                self.colors[v] = info.color
        for v, color in obs.inspected:
            self.inspected.add(v)
            self.colors[v] = color
        rescued = set(obs.rescued)
        gone = [
            v
            for v, info in self.victims.items()
            if (v in rescued or (v not in view.tasks and (view.sees(info.x, info.y) or self.expires[v] <= view.time)))
            and not (self.holding and v == self.target)  # learnt once the action it holds to ends
        ]
        for v in gone:  # what was known of it goes too: a gone victim is never a candidate again
            del self.victims[v]
            del self.expires[v]
            self.colors.pop(v, None)
            self.inspected.discard(v)
            self.incompatible.pop(v, None)
            self.gone.add(v)
            self.forget(v)
        self.receive(view)

    def forget(self, victim: int) -> None:
        """A victim is gone (rescued or expired)."""
        if self.target == victim:
            self.target = None

    def receive(self, view: LocalView) -> None:
        """Handle this tick's inbox (default: no messages)."""

    def compatible(self, v: int) -> bool:
        return self.incompatible.get(v, -math.inf) <= self.now

    def candidates(self) -> list[int]:
        """Victims worth choosing: remembered, alive as far as known, not found incompatible."""
        return sorted(v for v in self.victims if self.compatible(v))

    def distance(self, view: LocalView, v: int) -> float:
        info = self.victims[v]
        return math.hypot(info.x - view.x, info.y - view.y)

    # -- the target ----------------------------------------------------------------------------------
    def holds(self, v: int) -> bool:
        """Whether this robot is still entitled to its target (consensus strategies: it wins it)."""
        return True

    @property
    def monitoring(self) -> bool:
        return self.MONITORS if self.params.monitor is None else self.params.monitor

    def target_valid(self, view: LocalView) -> bool:
        if self.holding:
            return True  # it does not look while it holds to its action
        t = self.target
        return t is not None and t in self.victims and self.compatible(t) and self.holds(t)

    def needs_inspection(self) -> bool:
        return self.target not in self.inspected

    def color_match(self) -> bool:
        return self.target is not None and self.colors.get(self.target) == self.my_color

    def in_reach(self, view: LocalView) -> bool:
        t = self.target
        return t is not None and t in self.victims and self.distance(view, t) <= self.reach

    def abandon(self, view: LocalView) -> None:
        """The colours do not match: remember the victim as incompatible for a while, let it go."""
        v = self.target
        assert v is not None, "abandon() without a target"
        self.incompatible[v] = self.now + self.params.incompatible_for
        self.target = None
        self.released(v, view)

    def released(self, victim: int, view: LocalView) -> None:
        """Hook: the robot gave up ``victim`` (after abandoning it)."""

    def acquire(self, view: LocalView) -> bool:
        """Choose a new target; True if there is one."""
        raise NotImplementedError

    def execute(self, view: LocalView) -> list | None:
        """One step of the target cycle as a plain action (None: no valid target, wander)."""
        if not self.target_valid(view):
            return None
        t = self.target
        if not self.in_reach(view):
            return ["goto_task", t]
        if self.needs_inspection():
            return ["inspect", t]
        if self.color_match():
            return ["rescue", t]
        self.abandon(view)
        return ["abandon", t]

    def decide(self, view: LocalView) -> int | None:
        if not self.target_valid(view):
            self.acquire(view)
        return self.target
