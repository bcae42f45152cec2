"""What an allocation plugin sees and returns.

SPACE's plugin shape: each tick the DecisionMakingNode calls :meth:`Allocator.decide` with the
agent's :class:`LocalView` (its own state, the tasks its sensors see, the messages that reached it
this tick). The plugin resolves conflicts using ``view.inbox``, decides, queues what it wants to
share with ``view.broadcast`` / ``view.send``, and returns the task id it commits to (or None).

A plugin never sees global truth: only what the view holds.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict

from swarmbed.wire.codec import BROADCAST, RadioMessage, pack


@dataclass(frozen=True, slots=True)
class TaskInfo:
    id: int
    x: float
    y: float
    remaining: float  # MT-SR: workload still to do; SAR: seconds the victim has left
    color: int = -1  # SAR: the victim's colour where known to this agent, else -1


@dataclass(frozen=True, slots=True)
class Message:
    sender: int
    kind: str
    data: Any  # the decoded payload


@dataclass(frozen=True, slots=True)
class Outgoing:
    dest: int | tuple[int, ...]
    kind: str
    data: Any

    def encode(self) -> RadioMessage:
        """The message as it goes on the wire; its size is ``len(payload)``."""
        return RadioMessage(self.dest, self.kind, pack(self.data))


@dataclass
class LocalView:
    agent_id: int
    n_agents: int
    tick: int
    time: float
    x: float
    y: float
    heading: float
    speed: float
    work_rate: float
    tasks: dict[int, TaskInfo]
    inbox: list[Message]
    max_speed: float = 1.0
    awareness_range: float = float("inf")  # tasks within it (and within the vision cone) are in ``tasks``
    vision_angle: float = 2 * math.pi  # full angle of the sensing cone around ``heading``
    color: int = -1  # SAR: this robot's colour
    obs: dict = field(default_factory=dict)  # the raw observation, for scenario-specific extras
    outbox: list[Outgoing] = field(default_factory=list)

    def sees(self, x: float, y: float) -> bool:
        """Whether a point is in the sensing region (an open task there would be in ``tasks``)."""
        dx, dy = x - self.x, y - self.y
        if math.hypot(dx, dy) > self.awareness_range:
            return False
        if self.vision_angle >= 2 * math.pi or (dx == 0 and dy == 0):
            return True
        off = (math.atan2(dy, dx) - self.heading + math.pi) % (2 * math.pi) - math.pi
        return abs(off) <= self.vision_angle / 2

    def distance_to(self, task: TaskInfo) -> float:
        return math.hypot(task.x - self.x, task.y - self.y)

    def broadcast(self, kind: str, data: Any) -> None:
        """Share ``data`` with every agent in radio range."""
        self.outbox.append(Outgoing(BROADCAST, kind, data))

    def send(self, to: int | list[int] | tuple[int, ...], kind: str, data: Any) -> None:
        """Send ``data`` to one agent, or to a list of agents (multicast)."""
        dest = to if isinstance(to, int) else tuple(to)
        self.outbox.append(Outgoing(dest, kind, data))


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

    def observe(self, view: LocalView) -> None:
        """Called every tick before the tree is ticked (default: nothing)."""

    @abc.abstractmethod
    def decide(self, view: LocalView) -> int | None:
        """Return the task to work on now, or None (the tree then explores)."""
