"""What an allocation plugin sees each tick, and what it hands back.

SPACE's plugin shape: each tick the DecisionMakingNode calls the allocator's ``decide`` with the
agent's :class:`LocalView`: its own state, the tasks its sensors see, the messages that reached it
this tick, and ``obs``, the scenario's typed observation (``swarmbed.wire.observation``) for the
fields a scenario adds. The plugin queues what it wants to share with ``broadcast`` / ``send``.

A plugin never sees global truth: only what the view holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Generic, NamedTuple, TypeVar

from swarmbed.wire.codec import BROADCAST, RadioMessage, pack
from swarmbed.wire.observation import Observation
from swarmbed.wire.state import state_type

ObsT = TypeVar("ObsT", bound=Observation)


def coalitions_of(obs: Any) -> dict[int, tuple[int, int]]:
    """An observation's team tasks, task -> (robots it needs, robots on it at the last tick): its
    ``coalitions`` field where it has one (MT-SR with ``robots_needed``), else none."""
    rows = getattr(obs, "coalitions", None)
    return {t: (k, on) for t, k, on in rows} if rows else {}


@state_type
class TaskInfo(NamedTuple):
    """A task as an agent sees it. A named tuple, not a frozen dataclass: an agent builds one per
    visible task per tick, and a frozen dataclass's ``__init__`` took 4-5 times as long (at 200
    agents that was about 40 % of an agent's CPU)."""

    id: int
    x: float
    y: float
    remaining: float  # MT-SR: workload still to do; SAR: seconds the victim has left
    color: int = -1  # SAR: the victim's colour where known to this agent, else -1


@state_type
class Message(NamedTuple):
    """A message that reached this agent. A named tuple, as TaskInfo and for the same reason: an
    agent builds one per message it hears, every tick."""

    sender: int
    kind: str
    data: Any  # the decoded payload


@state_type
@dataclass(frozen=True, slots=True)
class Outgoing:
    dest: int | tuple[int, ...]
    kind: str
    data: Any

    def encode(self) -> RadioMessage:
        """The message as it goes on the wire; its size is ``len(payload)``."""
        return RadioMessage(self.dest, self.kind, pack(self.data))


@dataclass
class LocalView(Generic[ObsT]):
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
    obs: ObsT = None  # type: ignore[assignment]  # the scenario's typed observation (its extra fields)
    outbox: list[Outgoing] = field(default_factory=list)
    #: a decision made outside the agent for this tick (a ROS 2 node's, a learner's), for allocators
    #: that take their decisions from outside (:class:`~swarmbed.plugins.external.Ros2Allocator`)
    decision: int | None = None

    def sees(self, x: float, y: float) -> bool:
        """Whether a point is in the sensing region (an open task there would be in ``tasks``)."""
        dx, dy = x - self.x, y - self.y
        if math.hypot(dx, dy) > self.awareness_range:
            return False
        if self.vision_angle >= 2 * math.pi or (dx == 0 and dy == 0):
            return True
        off = (math.atan2(dy, dx) - self.heading + math.pi) % (2 * math.pi) - math.pi
        return abs(off) <= self.vision_angle / 2

    def coalitions(self) -> dict[int, tuple[int, int]]:
        """Task -> (robots it needs at once, robots on it at the last tick) for the tasks in view that
        need a team (an ST-MR observation's ``coalitions``); empty where every task needs one robot."""
        return coalitions_of(self.obs)

    def distance_to(self, task: TaskInfo) -> float:
        return math.hypot(task.x - self.x, task.y - self.y)

    def broadcast(self, kind: str, data: Any) -> None:
        """Share ``data`` with every agent in radio range."""
        self.outbox.append(Outgoing(BROADCAST, kind, data))

    def send(self, to: int | list[int] | tuple[int, ...], kind: str, data: Any) -> None:
        """Send ``data`` to one agent, or to a list of agents (multicast)."""
        dest = to if isinstance(to, int) else tuple(to)
        self.outbox.append(Outgoing(dest, kind, data))
