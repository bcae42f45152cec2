"""The plugin author's API: subclass :class:`Allocator`, read a :class:`LocalView`, return a task.

Defined in ``swarmbed.agent_runtime`` (plugins build on the agent runtime, not the reverse) and
gathered here, where plugin authors look for it.
"""

from swarmbed.agent_runtime.allocator import HOLD, Allocator, NoParams
from swarmbed.agent_runtime.view import LocalView, Message, Outgoing, TaskInfo

__all__ = ["HOLD", "Allocator", "LocalView", "Message", "NoParams", "Outgoing", "TaskInfo"]
