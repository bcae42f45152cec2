"""The extension contract: what a scenario, an allocator and a behavior-tree node are written against.

``Scenario`` and ``World`` (:mod:`.scenario`), ``Allocator`` (:mod:`.allocator`), the agent's
``LocalView`` with its ``TaskInfo`` and ``Message`` (:mod:`.view`) and the node context
(:mod:`.context`) live here, below every process role: the coordinator, the agent runtime and the
plugins import this package, and it imports none of them (only the wire contract). A change here is
a change to every plugin and scenario, so it is kept small.
"""

from swarmbed.extension.actions import INVALID, MOVE_ACTIONS, ActionSpec, admit, conforms
from swarmbed.extension.allocator import HALT, HOLD, Allocator, NoParams
from swarmbed.extension.context import NodeContext
from swarmbed.extension.figures import Figure
from swarmbed.extension.scenario import Scenario, Sensing, World, sight, within
from swarmbed.extension.view import LocalView, Message, Outgoing, TaskInfo

__all__ = [
    "HALT",
    "HOLD",
    "INVALID",
    "MOVE_ACTIONS",
    "ActionSpec",
    "Allocator",
    "Figure",
    "LocalView",
    "Message",
    "NodeContext",
    "NoParams",
    "Outgoing",
    "Scenario",
    "Sensing",
    "TaskInfo",
    "World",
    "admit",
    "conforms",
    "sight",
    "within",
]
