"""Allocation-algorithm plugins and their registry."""

from swarmbed.plugins.base import Allocator, LocalView, Message, TaskInfo
from swarmbed.plugins.registry import PluginError, make, names, register, resolve

__all__ = ["Allocator", "LocalView", "Message", "TaskInfo", "PluginError", "make", "names", "register", "resolve"]
