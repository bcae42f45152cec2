"""Allocators whose decisions are made outside the agent process and handed over with each tick.

The coordinator gathers one decision per robot before it sends a tick, puts it in that robot's tick
sample, and the agent's allocator answers with it, so the decision takes the path a plugin's
decision takes: the tree runs it, the world carries it out, the radio and the result files are
those of any run. A decision is a task id, or :data:`~swarmbed.extension.allocator.HOLD` / ``HALT``;
none (-1, or no decision yet) lets the tree explore. Where the decisions come from is the class's
``decision_source``: ROS 2 topics (``ros2``: ``docs/ros2.md``) or a driver in the launching process
(``external``: a learner through ``swarmbed.envs``, ``docs/learning.md``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from swarmbed.extension import Allocator, LocalView
from swarmbed.extension.allocator import DecisionSource
from swarmbed.wire.validation import validation_lines

NONE = -1  # a decision that chooses no task (the tree explores)
DEFER = -4  # a decision that asks the fallback allocator what it would do
#: a bit of a decision: choose the task ``decision - ANNOUNCE`` and broadcast a claim of it over the
#: radio (a ``claim`` message holding the task id), so that a learned policy can use the radio
ANNOUNCE = 1 << 30
CLAIM = "claim"


class FallbackParams(BaseModel):
    """The keys of an allocator that hosts a registered one beside its own decisions (``fallback``)."""

    model_config = ConfigDict(extra="forbid")
    fallback: str | None = Field(
        None,
        description="a registered allocator that runs beside this one (it observes, talks over the radio, and "
        "decides where this one leaves the decision to it)",
    )
    fallback_scenario: str = Field("mtsr", description="the scenario whose implementation of `fallback` runs")
    fallback_params: dict[str, Any] = Field(default_factory=dict, description="the fallback allocator's own keys")

    @model_validator(mode="after")
    def _fallback_is_an_allocator_with_these_keys(self) -> FallbackParams:
        """The fallback is resolved and its keys validated here, where the experiment is loaded
        (``swarmbed run``, ``--check``, the environment), not first inside each agent's process."""
        if self.fallback is None:
            if self.fallback_params:
                raise ValueError("allocator.fallback_params: given without a fallback allocator")
            return self
        from swarmbed.plugins import registry

        try:
            cls = registry.resolve(self.fallback, self.fallback_scenario)
        except registry.PluginError as exc:
            raise ValueError(f"allocator.fallback: {exc}") from None
        if cls.decision_source is not None:
            raise ValueError(
                f"allocator.fallback: {self.fallback!r} takes its decisions from outside too ({cls.decision_source})"
            )
        try:
            cls.Params.model_validate(self.fallback_params)
        except ValidationError as exc:
            raise ValueError("; ".join(validation_lines(exc, cls.Params, "allocator.fallback_params"))) from None
        return self


class ExternalParams(FallbackParams):
    fallback: str | None = Field(
        None,
        description="a registered allocator that runs beside the outside decisions (it observes, talks over "
        "the radio, and decides whenever the decision is DEFER = -4): a built-in allocator as a policy",
    )


class WithFallback(Allocator):
    """An allocator that hosts a registered one (its params' ``fallback``) with its own parameters
    and stream: shown every tick's view (``observe``), deciding where the host calls
    :meth:`fallback_decide` (and sending what its ``decide`` sends), its counters the host's."""

    CONSTRUCTED = (*Allocator.CONSTRUCTED, "inner")  # the fallback travels as its own snapshot

    def __init__(self, agent_id: int, params: BaseModel, rng: np.random.Generator, run_seed: int = 0) -> None:
        super().__init__(agent_id, params, rng, run_seed)
        self.inner: Allocator | None = None
        p = self.params
        assert isinstance(p, FallbackParams)
        if p.fallback is not None:
            from swarmbed.plugins import registry

            cls = registry.resolve(p.fallback, p.fallback_scenario)
            self.inner = cls(agent_id, cls.Params.model_validate(p.fallback_params), rng, run_seed)

    def observe(self, view: LocalView) -> None:
        if self.inner is not None:
            self.inner.observe(view)
            self._take_events()

    def fallback_decide(self, view: LocalView) -> int | None:
        """What the fallback decides (None without one: the tree explores)."""
        if self.inner is None:
            return None
        chosen = self.inner.decide(view)
        self._take_events()
        return chosen

    def _take_events(self) -> None:
        assert self.inner is not None
        for name, n in self.inner.events.items():
            self.count(name, n)
        self.inner.events = {}

    def snapshot(self) -> dict[str, Any]:
        state = super().snapshot()
        if self.inner is not None:
            state["inner"] = self.inner.snapshot()
        return state

    def restore(self, state: dict[str, Any]) -> None:
        inner = state.pop("inner", None)
        super().restore(state)
        if self.inner is not None and inner is not None:
            self.inner.restore(inner)
            self.inner.rng = self.rng  # one stream, as in the fallback's own run


class ExternalAllocator(WithFallback):
    """Decisions from a driver in the launching process (a PettingZoo environment's learner). With
    ``fallback``, a built-in allocator lives inside it with its own parameters and stream: it is
    shown every tick's view (``observe``) and, where the decision is :data:`DEFER`, it decides (and
    sends what its ``decide`` sends), so "CBBA as a policy" is DEFER at every tick and gives CBBA's
    run."""

    Params = ExternalParams
    params: ExternalParams
    decision_source: ClassVar[DecisionSource | None] = "env"

    def decide(self, view: LocalView) -> int | None:
        if view.decision == DEFER:
            return self.fallback_decide(view)
        if view.decision is not None and view.decision >= ANNOUNCE:
            task = view.decision - ANNOUNCE
            view.broadcast(CLAIM, task)
            return task
        return None if view.decision is None or view.decision == NONE else view.decision


class Ros2Allocator(ExternalAllocator):
    """Decisions from ``/robot_<i>/cmd`` (``swarmbed_msgs/msg/TaskCommand``), published by any ROS 2
    node that reads ``/robot_<i>/observation``. Needs the experiment's ``ros2:`` section."""

    decision_source: ClassVar[DecisionSource | None] = "ros2"
