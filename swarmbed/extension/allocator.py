"""The base class of allocation plugins."""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict

from swarmbed.extension.view import LocalView

if TYPE_CHECKING:
    from swarmbed.bt import TreeNode
    from swarmbed.schema.experiment import Experiment


class DecisionError(ValueError):
    """``decide`` returned what is not a task id, None, HOLD or HALT; the message names the agent,
    the tick and the value."""


#: what :meth:`Allocator.decide` returns to keep the agent still this tick (no task, no exploring):
#: SPACE's GRAPE holds its agents while their partition converges. Task ids are never negative.
HOLD = -2
#: the same, and stop at once (speed to zero this tick), as SPACE's GRAPE resets an agent's movement
#: on every tick its partition has not converged; a scenario without the ``halt`` action brakes instead.
HALT = -3


#: where an allocator's decisions come from when not from its own ``decide`` (see ``decision_source``)
DecisionSource = Literal["env", "ros2"]


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
    bt_nodes: ClassVar[tuple[type[TreeNode], ...]] = ()
    default_tree: ClassVar[str | None] = None
    #: whether a running instance can move to another process (snapshot / restore); a plugin that
    #: holds what cannot move (open files, threads, sockets) sets False, and swaps are refused
    snapshottable: ClassVar[bool] = True
    #: bump when a change makes the same configuration and seed give other results (provenance.json)
    version: ClassVar[str] = "1"
    #: whether it bids knowing the tasks' colours: a scenario with coloured tasks (search and rescue,
    #: ``colors_for_bidding: auto``) shows them to such an allocator before any inspection
    bids_with_colors: ClassVar[bool] = False
    #: where its decisions come from when not from its own ``decide``: a driver in the launching
    #: process (``env``: swarmbed.envs) or ROS 2 topics (``ros2``); None for every other allocator
    decision_source: ClassVar[DecisionSource | None] = None

    @classmethod
    def check(cls, exp: Experiment, params: BaseModel) -> list[str]:
        """Problems between this allocator's parameters and the rest of the experiment, as
        ``dotted.key: message`` (default: none), found where the experiment is loaded."""
        return []

    def __init__(self, agent_id: int, params: BaseModel, rng: np.random.Generator, run_seed: int = 0) -> None:
        self.agent_id = agent_id
        self.params = params
        self.rng = rng
        self.run_seed = run_seed  # the same for every agent: for randomness agents must share
        self.events: dict[str, int] = {}

    def count(self, event: str, n: int = 1) -> None:
        self.events[event] = self.events.get(event, 0) + n

    #: attributes that ``snapshot`` leaves out: the constructor sets them again
    CONSTRUCTED: ClassVar[tuple[str, ...]] = ("agent_id", "params", "run_seed")

    def snapshot(self) -> dict[str, Any]:
        """This instance's state, to continue in another process: by default every attribute but
        those the constructor sets from the run (``CONSTRUCTED``). Override both this and
        :meth:`restore` for state that is not plain data (see ``swarmbed.wire.state``). Instances
        of the plugin's own classes travel only when the class is declared with
        ``@swarmbed.wire.state.state_type``."""
        return {k: v for k, v in vars(self).items() if k not in self.CONSTRUCTED}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from ``state`` (what :meth:`snapshot` returned, restored in a fresh instance
        built with the same arguments)."""
        self.__dict__.update(state)

    def observe(self, view: LocalView) -> None:  # noqa: B027 - optional hook, deliberately empty
        """Called every tick before the tree is ticked (default: nothing)."""

    @abc.abstractmethod
    def decide(self, view: LocalView) -> int | None:
        """Return the task to work on now, None (the tree then explores), :data:`HOLD` (stay put) or
        :data:`HALT` (stay put, stopping at once)."""
