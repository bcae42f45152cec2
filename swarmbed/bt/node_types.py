"""Node types by ID. The built-in set mirrors the BehaviorTree.CPP nodes this engine supports."""

from __future__ import annotations

from collections.abc import Iterable

from swarmbed.bt.composites import CONTROLS
from swarmbed.bt.decorators import DECORATORS
from swarmbed.bt.leaves import LEAVES
from swarmbed.bt.node import TreeNode

BUILTIN_TYPES: tuple[type[TreeNode], ...] = CONTROLS + DECORATORS + LEAVES


class NodeRegistry:
    def __init__(self, types: Iterable[type[TreeNode]] = BUILTIN_TYPES) -> None:
        self._types: dict[str, type[TreeNode]] = {}
        self._builtin = {t.ID for t in BUILTIN_TYPES}
        for t in types:
            self.register(t)

    def register(self, node_type: type[TreeNode]) -> type[TreeNode]:
        """Register a node class under its ``ID`` (usable as a decorator)."""
        if not node_type.ID:
            raise ValueError(f"{node_type.__name__} has no ID")
        known = self._types.get(node_type.ID)
        if known is not None and known is not node_type:
            raise ValueError(f"node ID {node_type.ID!r} is already registered by {known.__module__}.{known.__name__}")
        self._types[node_type.ID] = node_type
        return node_type

    def get(self, node_id: str) -> type[TreeNode] | None:
        return self._types.get(node_id)

    def custom(self) -> list[type[TreeNode]]:
        """Registered types that BehaviorTree.CPP does not ship (what Groot2 needs a model for)."""
        return [t for i, t in sorted(self._types.items()) if i not in self._builtin]

    def ids(self) -> list[str]:
        """Every registered node ID, sorted."""
        return sorted(self._types)

    def __contains__(self, node_id: str) -> bool:
        return node_id in self._types
