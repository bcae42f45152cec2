"""The base class of allocation plugins."""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict

from swarmbed.agent_runtime.view import LocalView


class NoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Allocator(abc.ABC):
    """Base class of allocation plugins. Subclasses declare ``Params`` (a pydantic model; unknown
    keys are refused when the experiment is loaded) and implement :meth:`decide`.

    Optional: ``observe(view)`` runs every tick before the tree; ``events`` counts what happened
    this tick (the runtime sends and clears it; names in ``event_names`` get a time-series column);
    ``bt_nodes`` and ``default_tree`` give the tree this algorithm needs."""

    Params: ClassVar[type[BaseModel]] = NoParams
    #: message kinds this plugin sends (documentation and conformance checks)
    message_kinds: ClassVar[tuple[str, ...]] = ()
    #: counters this plugin reports through ``events``
    event_names: ClassVar[tuple[str, ...]] = ()
    #: behavior-tree node classes this plugin's trees use, and its default tree (a path)
    bt_nodes: ClassVar[tuple[type, ...]] = ()
    default_tree: ClassVar[str | None] = None
    #: SAR: whether the scenario should show victims' colours to this algorithm when bidding
    bids_with_colors: ClassVar[bool] = False

    def __init__(self, agent_id: int, params: BaseModel, rng: np.random.Generator, run_seed: int = 0) -> None:
        self.agent_id = agent_id
        self.params = params
        self.rng = rng
        self.run_seed = run_seed  # the same for every agent: for randomness agents must share
        self.events: dict[str, int] = {}

    def count(self, event: str, n: int = 1) -> None:
        self.events[event] = self.events.get(event, 0) + n

    def observe(self, view: LocalView) -> None:  # noqa: B027 - optional hook, deliberately empty
        """Called every tick before the tree is ticked (default: nothing)."""

    @abc.abstractmethod
    def decide(self, view: LocalView) -> int | None:
        """Return the task to work on now, or None (the tree then explores)."""
