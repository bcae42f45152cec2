"""Which behavior-tree nodes and which tree an agent runs, from its scenario and its allocator.

One function for the agent runtime and for the CLI (``swarmbed bt palette`` / ``bt check``), so a
tree that loads in ``bt check`` loads in a run and the palette Groot2 gets is the set a run uses.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from swarmbed.bt import NodeRegistry
from swarmbed.extension.space_nodes import SPACE_TREE


def node_registry(owners: Iterable[type]) -> NodeRegistry:
    """The built-in BT.CPP nodes plus every ``bt_nodes`` of ``owners`` (scenario and allocator classes)."""
    registry = NodeRegistry()
    for owner in owners:
        for node in getattr(owner, "bt_nodes", ()):
            registry.register(node)
    return registry


def tree_path(behavior_tree: str, scenario: type, allocator: type) -> Path:
    """``agents.behavior_tree`` as a path: a file the user named, else the allocator's default tree,
    else the scenario's, else SPACE's."""
    if behavior_tree != "default":
        return Path(behavior_tree)
    return Path(getattr(allocator, "default_tree", None) or getattr(scenario, "default_tree", None) or SPACE_TREE)
