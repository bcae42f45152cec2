"""Allocation-algorithm plugins. Write one against :mod:`swarmbed.extension`; register it in
:mod:`swarmbed.plugins.registry` (or through the ``swarmbed.allocators`` entry-point group)."""

from swarmbed.extension import Allocator, LocalView, Message, TaskInfo

__all__ = ["Allocator", "LocalView", "Message", "TaskInfo"]
