"""Allocation-algorithm plugins and their registry."""

from plugins.base import Allocator, LocalView, Message, TaskInfo
from plugins.registry import PluginError, make, names, register, resolve

__all__ = ["Allocator", "LocalView", "Message", "TaskInfo", "PluginError", "make", "names", "register", "resolve"]
