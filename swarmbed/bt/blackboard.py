"""Blackboards with BehaviorTree.CPP's SubTree remapping rules.

A SubTree gets its own blackboard. A key it reads or writes that is not stored locally is looked up
in the parent: under the remapped name if the SubTree element remaps it (``port="{parent_key}"``),
under the same name if the SubTree has ``_autoremap="true"`` and the key is not private (``_x``).
A key written for the first time follows the same rule, so a remapped output lands in the parent.
``@key`` always means the root blackboard.
"""

from __future__ import annotations

from typing import Any

_MISSING = object()


class Blackboard:
    def __init__(
        self, parent: Blackboard | None = None, remap: dict[str, str] | None = None, autoremap: bool = False
    ) -> None:
        self._store: dict[str, Any] = {}
        self.parent = parent
        self.remap = dict(remap or {})
        self.autoremap = autoremap

    def root(self) -> Blackboard:
        bb = self
        while bb.parent is not None:
            bb = bb.parent
        return bb

    def _owner(self, key: str) -> tuple[Blackboard, str]:
        """Where ``key`` lives (or would be created)."""
        if key.startswith("@"):
            return self.root(), key[1:]
        bb = self
        while True:
            parent = bb.parent
            if key in bb._store or parent is None:
                return bb, key
            if key in bb.remap:
                bb, key = parent, bb.remap[key]
            elif bb.autoremap and not key.startswith("_"):
                bb = parent
            else:
                return bb, key

    def get(self, key: str, default: Any = _MISSING) -> Any:
        bb, k = self._owner(key)
        value = bb._store.get(k, _MISSING)
        if value is _MISSING:
            if default is _MISSING:
                raise KeyError(key)
            return default
        return value

    def __contains__(self, key: str) -> bool:
        bb, k = self._owner(key)
        return k in bb._store

    def set(self, key: str, value: Any) -> None:
        bb, k = self._owner(key)
        bb._store[k] = value

    def unset(self, key: str) -> None:
        bb, k = self._owner(key)
        bb._store.pop(k, None)

    def keys(self) -> list[str]:
        return sorted(self._store)

    def items(self) -> dict[str, Any]:
        return dict(self._store)
