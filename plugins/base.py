"""The plugin author's API: subclass :class:`Allocator`, read a :class:`LocalView`, return a task.

Defined in the extension contract (``swarmbed.extension``, below every process role) and gathered
here, where plugin authors look for it.
"""

from swarmbed.extension.allocator import HALT, HOLD, Allocator, NoParams
from swarmbed.extension.view import LocalView, Message, Outgoing, TaskInfo

__all__ = ["HALT", "HOLD", "Allocator", "LocalView", "Message", "NoParams", "Outgoing", "TaskInfo"]
