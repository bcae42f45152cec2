"""The observation: what one agent senses at one tick, as part of the wire contract.

Every scenario's observation has the same core (time, the agent's own pose and speed, the tasks it
sees as one binary table of :data:`~swarmbed.wire.codec.TASK_DTYPE` records) and adds typed fields
of its own by subclassing :class:`Observation` as a dataclass. On the wire it is a msgpack map:
``t``, ``me`` = ``[x, y, heading, speed]``, ``tasks`` and one entry per extra field.

Decoding checks the core and every extra field against its annotation (``int``, ``float``,
``bool``, ``str``, ``bytes``, ``list[X]``, ``tuple[X, Y, ...]``, ``X | None``), so a malformed
observation is a :class:`~swarmbed.wire.codec.WireError` that names the field, counted by the agent
like any malformed sample, and never an error blamed on a plugin.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any, ClassVar, TypeVar

import numpy as np

from swarmbed.wire.codec import TASK_DTYPE, WireError, decode_task_table, encode_task_table

ObsT = TypeVar("ObsT", bound="Observation")
_CORE = ("time", "x", "y", "heading", "speed", "tasks")


@dataclasses.dataclass(frozen=True, slots=True)
class Observation:
    time: float
    x: float
    y: float
    heading: float
    speed: float
    tasks: np.ndarray = dataclasses.field(repr=False)  # TASK_DTYPE records: id, x, y, remaining, color

    #: (name, annotation) of the extra fields, filled in per subclass on first use
    _extras: ClassVar[dict[type, list[tuple[str, Any]]]] = {}

    @classmethod
    def extra_fields(cls) -> list[tuple[str, Any]]:
        fields = Observation._extras.get(cls)
        if fields is None:
            hints = typing.get_type_hints(cls)
            fields = [(f.name, hints[f.name]) for f in dataclasses.fields(cls) if f.name not in _CORE]
            Observation._extras[cls] = fields
        return fields

    def to_wire(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "t": self.time,
            "me": [self.x, self.y, self.heading, self.speed],
            "tasks": encode_task_table(self.tasks),
        }
        for name, _ in self.extra_fields():
            value = getattr(self, name)
            if value is not None:
                out[name] = value
        return out

    @classmethod
    def from_wire(cls: type[ObsT], obj: Any) -> ObsT:
        if not isinstance(obj, dict):
            raise WireError("observation must be a map")
        t, me, table = obj.get("t"), obj.get("me"), obj.get("tasks")
        if not isinstance(t, (int, float)) or isinstance(t, bool):
            raise WireError("observation field t: must be a number")
        if not (isinstance(me, list) and len(me) == 4 and all(_is_number(v) for v in me)):
            raise WireError("observation field me: must be [x, y, heading, speed]")
        try:
            tasks = decode_task_table(table)
        except WireError as exc:
            raise WireError(f"observation field tasks: {exc}") from None
        extras = {}
        for name, annotation in cls.extra_fields():
            if name in obj:
                extras[name] = _check(obj[name], annotation, name)
            elif not _optional(annotation):
                raise WireError(f"observation field {name}: missing")
        unknown = set(obj) - {"t", "me", "tasks"} - {n for n, _ in cls.extra_fields()}
        if unknown:
            raise WireError(f"observation has unknown fields: {', '.join(sorted(map(str, unknown)))}")
        return cls(float(t), float(me[0]), float(me[1]), float(me[2]), float(me[3]), tasks, **extras)


def empty_tasks() -> np.ndarray:
    return np.empty(0, dtype=TASK_DTYPE)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _optional(annotation: Any) -> bool:
    return _is_union(annotation) and type(None) in typing.get_args(annotation)


def _is_union(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)


def _check(value: Any, annotation: Any, where: str) -> Any:
    """``value`` as ``annotation`` says (lists of tuples become tuples), or a WireError naming ``where``."""
    if annotation is float:
        if _is_number(value):
            return float(value)
    elif annotation is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif annotation in (bool, str, bytes):
        if isinstance(value, annotation):
            return value
    elif _is_union(annotation):
        args = typing.get_args(annotation)
        if value is None and type(None) in args:
            return None
        for arg in args:
            if arg is not type(None):
                try:
                    return _check(value, arg, where)
                except WireError:
                    pass
    else:
        origin, args = typing.get_origin(annotation), typing.get_args(annotation)
        if origin is list and isinstance(value, list):
            return [_check(v, args[0], f"{where}[{i}]") for i, v in enumerate(value)]
        if origin is tuple and isinstance(value, (list, tuple)):
            if len(args) == 2 and args[1] is Ellipsis:
                return tuple(_check(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
            if len(value) == len(args):
                return tuple(_check(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    raise WireError(f"observation field {where}: expected {_name(annotation)}, got {value!r:.60}")


def _name(annotation: Any) -> str:
    return getattr(annotation, "__name__", None) or str(annotation).replace("typing.", "")
