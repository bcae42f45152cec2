"""Node base classes and ports, following BehaviorTree.CPP v4's semantics.

Leaves: :class:`SyncAction` and :class:`Condition` complete within their tick;
:class:`StatefulAction` has ``on_start`` / ``on_running`` / ``on_halted`` and may stay RUNNING.
Controls and decorators live in ``composites`` and ``decorators``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

from swarmbed.bt.blackboard import Blackboard
from swarmbed.bt.status import FAILURE, IDLE, RUNNING, SUCCESS, Status

StatusWatcher = Callable[["TreeNode", Status, Status], None]
"""Called with (node, previous status, new status) on every change, as BehaviorTree.CPP's
StatusChangeLogger hears them (transitions to IDLE included)."""


_WATCHED: dict[type, type] = {}  # a node class -> the same class with its status watched
_PLAIN: dict[type, type] = {}  # and back


def watch_node(node: TreeNode, watcher: StatusWatcher | None) -> None:
    """Hand ``node``'s status changes to ``watcher`` (None: to no one).

    A watched node becomes an instance of a subclass of its own class whose ``status`` is a property
    that tells the watcher; an unwatched node is an instance of its own class again, where ``status``
    is a plain attribute. So a tree nobody watches pays nothing per change, and the attribute stays
    ``status`` in the node's ``__dict__`` either way (snapshots do not see the difference)."""
    plain = _PLAIN.get(type(node), type(node))
    if watcher is None:
        node.__class__ = plain
        node.__dict__.pop("_watcher", None)
        return
    watched = _WATCHED.get(plain)
    if watched is None:

        def get(self: TreeNode) -> Status:
            return self.__dict__["status"]

        def put(self: TreeNode, new: Status) -> None:
            prev = self.__dict__["status"]
            if new is not prev:
                self.__dict__["status"] = new
                self.__dict__["_watcher"](self, prev, new)

        namespace = {"status": property(get, put), "__module__": plain.__module__, "__qualname__": plain.__qualname__}
        watched = _WATCHED[plain] = type(plain.__name__, (plain,), namespace)
        _PLAIN[watched] = plain
    node.__dict__["_watcher"] = watcher
    node.__class__ = watched


class BTError(Exception):
    """A tree that cannot be loaded or ticked; the message names the file, line and node."""


@dataclass(frozen=True)
class Port:
    direction: str  # "input", "output" or "inout"
    type: type = str
    default: str | None = None  # a literal or a "{key}" reference, as it would appear in XML
    description: str = ""

    @property
    def required(self) -> bool:
        return self.default is None and self.direction != "output"


def InputPort(type_: type = str, default: Any = None, description: str = "") -> Port:
    return Port("input", type_, None if default is None else str(default), description)


def OutputPort(type_: type = str, default: str | None = None, description: str = "") -> Port:
    return Port("output", type_, default, description)


def convert_port(raw: str, type_: type) -> Any:
    if type_ is bool:
        low = raw.strip().lower()
        if low in ("true", "1"):
            return True
        if low in ("false", "0"):
            return False
        raise ValueError(f"{raw!r} is not a boolean")
    if type_ is str:
        return raw
    return type_(raw)


def blackboard_key(raw: str, port_name: str) -> str | None:
    """The key of a ``{key}`` reference (``{=}`` means the port's own name), else None."""
    raw = raw.strip()
    if len(raw) >= 2 and raw[0] == "{" and raw[-1] == "}":
        key = raw[1:-1].strip()
        return port_name if key == "=" else key
    return None


@dataclass
class NodeConfig:
    blackboard: Blackboard
    ports: dict[str, str] = field(default_factory=dict)  # raw attribute values from XML
    path: str = ""  # e.g. "main.xml:12 <DecisionMakingNode name='decide'>"
    context: Any = None  # whatever the host hands to its nodes (the agent runtime, a test harness)


class TreeNode:
    ID: ClassVar[str] = ""
    KIND: ClassVar[str] = "Action"  # Action | Condition | Control | Decorator | SubTree

    def __init__(self, name: str, config: NodeConfig) -> None:
        self.name = name
        self.config = config
        self.status = IDLE
        self.uid = 0  # BehaviorTree.CPP's UID: 1, 2, ... in the order the tree's nodes were built
        self._literals: dict[str, Any] = {}
        # a port's blackboard key, resolved once: the ports are fixed when the tree is built, and
        # resolving them (``provided_ports`` builds its Port objects) each tick was ~10 % of an idle agent's CPU
        self._keys: dict[str, str] = {}

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {}

    # -- ports -----------------------------------------------------------------------------
    def _raw_port(self, port: str) -> str:
        raw = self.config.ports.get(port)
        if raw is None:
            spec = self.provided_ports().get(port)
            raw = spec.default if spec else None
        if raw is None:
            raise BTError(f"{self.config.path}: port '{port}' has no value")
        return raw

    def get_input(self, port: str) -> Any:
        if port in self._literals:
            return self._literals[port]
        key = self._keys.get(port)
        if key is not None:
            return self._blackboard_value(port, key)
        raw = self._raw_port(port)
        spec = self.provided_ports().get(port, Port("input"))
        key = blackboard_key(raw, port)
        if key is None:
            try:
                value = convert_port(raw, spec.type)
            except ValueError as exc:
                raise BTError(f"{self.config.path}: port '{port}': {exc}") from None
            self._literals[port] = value
            return value
        self._keys[port] = key
        return self._blackboard_value(port, key)

    def _blackboard_value(self, port: str, key: str) -> Any:
        try:
            return self.config.blackboard.get(key)
        except KeyError:
            raise BTError(f"{self.config.path}: port '{port}' reads blackboard key '{key}', which is not set") from None

    def set_output(self, port: str, value: Any) -> None:
        key = self._keys.get(port)
        if key is None:
            raw = self._raw_port(port)
            key = blackboard_key(raw, port)
            if key is None:
                raise BTError(f"{self.config.path}: output port '{port}' must name a blackboard key, not {raw!r}")
            self._keys[port] = key
        self.config.blackboard.set(key, value)

    # -- ticking -----------------------------------------------------------------------------
    def execute_tick(self) -> Status:
        status = self.tick()
        self.status = status
        return status

    def tick(self) -> Status:
        raise NotImplementedError

    def halt(self) -> None:
        self.status = IDLE

    def reset_status(self) -> None:
        self.status = IDLE

    def children(self) -> list[TreeNode]:
        return []


class SyncAction(TreeNode):
    """An action that completes within one tick (SUCCESS or FAILURE)."""

    def execute_tick(self) -> Status:
        status = self.tick()
        if status not in (SUCCESS, FAILURE):
            raise BTError(f"{self.config.path}: a synchronous action must return SUCCESS or FAILURE, not {status.name}")
        self.status = status
        return status


class Condition(SyncAction):
    KIND = "Condition"


class StatefulAction(TreeNode):
    """An action that may take several ticks: on_start, then on_running while RUNNING."""

    def tick(self) -> Status:
        if self.status is IDLE:
            status = self.on_start()
        elif self.status is RUNNING:
            status = self.on_running()
        else:
            return self.status
        if status is IDLE:
            raise BTError(f"{self.config.path}: on_start/on_running must not return IDLE")
        return status

    def on_start(self) -> Status:
        raise NotImplementedError

    def on_running(self) -> Status:
        raise NotImplementedError

    def on_halted(self) -> None:
        pass

    def halt(self) -> None:
        if self.status is RUNNING:
            self.on_halted()
        self.status = IDLE


class ControlNode(TreeNode):
    KIND = "Control"
    MIN_CHILDREN: ClassVar[int] = 1

    def __init__(self, name: str, config: NodeConfig) -> None:
        super().__init__(name, config)
        self._children: list[TreeNode] = []

    def add_child(self, child: TreeNode) -> None:
        self._children.append(child)

    def children(self) -> list[TreeNode]:
        return self._children

    def halt_child(self, i: int) -> None:
        child = self._children[i]
        status = child.status
        if status is IDLE:  # nothing to halt; resetting an idle node changes nothing (as BT.CPP's resetStatus)
            return
        if status is RUNNING:
            child.halt()
        child.reset_status()

    def reset_children(self) -> None:
        for i, child in enumerate(self._children):
            if child.status is not IDLE:
                self.halt_child(i)

    def halt(self) -> None:
        self.reset_children()
        self.status = IDLE


class DecoratorNode(TreeNode):
    KIND = "Decorator"
    child: TreeNode  # set by add_child; the loader refuses a decorator without exactly one child

    def add_child(self, child: TreeNode) -> None:
        self.child = child

    def children(self) -> list[TreeNode]:
        return [self.child] if hasattr(self, "child") else []

    def reset_child(self) -> None:
        status = self.child.status
        if status is IDLE:
            return
        if status is RUNNING:
            self.child.halt()
        self.child.reset_status()

    def halt(self) -> None:
        self.reset_child()
        self.status = IDLE
