"""Snapshots of Python state as msgpack, for moving a running agent to another process.

Plain values travel as msgpack does; the rest as extension types that restore to the same type:
tuples (named ones too), sets, numpy arrays and scalars, integers past 64 bits, numpy random generators (their bit
generator's state), enum members, and instances of dataclasses and plain classes defined in swarmbed or in the
module of a plugin (by ``module:qualname``, restored without calling ``__init__``). Anything else
raises :class:`StateError` naming the value's type and where it was, so that a plugin whose state
cannot move says so instead of moving wrongly.

Shared references are not preserved: an object reached twice is restored as two equal objects.
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
import sys
from typing import Any

import msgpack
import numpy as np

from swarmbed.wire.codec import pack

EXT_TUPLE, EXT_SET, EXT_ARRAY, EXT_SCALAR, EXT_BIGINT, EXT_RNG, EXT_OBJECT, EXT_FROZENSET, EXT_ENUM = range(1, 10)


class StateError(ValueError):
    """State that cannot be snapshotted or restored; the message says what and where."""


def _allowed(module: str, extra: tuple[str, ...]) -> bool:
    return module.startswith("swarmbed") or module in extra


def pack_state(obj: Any, modules: tuple[str, ...] = ()) -> bytes:
    """``obj`` as bytes; ``modules``: plugin modules (beside swarmbed's) whose classes may be stored."""

    def ext(code: int, value: Any, where: str) -> msgpack.ExtType:
        return msgpack.ExtType(code, pack(walk(value, where)))

    def walk(value: Any, where: str) -> Any:
        if value is None or isinstance(value, (bool, str, bytes, float)):
            return value
        if isinstance(value, int):
            return value if -(2**63) <= value < 2**64 else ext(EXT_BIGINT, str(value), where)
        if isinstance(value, list):
            return [walk(v, f"{where}[{i}]") for i, v in enumerate(value)]
        if isinstance(value, dict):
            return {walk(k, where): walk(v, f"{where}.{k}") for k, v in value.items()}
        if isinstance(value, tuple) and not hasattr(value, "_fields"):
            return ext(EXT_TUPLE, list(value), where)
        if isinstance(value, frozenset):
            return ext(EXT_FROZENSET, list(value), where)
        if isinstance(value, set):
            return ext(EXT_SET, list(value), where)
        if isinstance(value, np.ndarray):
            if value.dtype.hasobject:
                raise StateError(f"{where}: numpy array of Python objects")
            descr = value.dtype.descr if value.dtype.names else value.dtype.str
            return ext(EXT_ARRAY, [descr, list(value.shape), np.ascontiguousarray(value).tobytes()], where)
        if isinstance(value, np.generic):
            return ext(EXT_SCALAR, [value.dtype.str, value.tobytes()], where)
        if isinstance(value, np.random.Generator):
            return ext(EXT_RNG, value.bit_generator.state, where)
        cls = type(value)
        if _allowed(cls.__module__, modules):
            if isinstance(value, enum.Enum):
                return ext(EXT_ENUM, [f"{cls.__module__}:{cls.__qualname__}", value.value], where)
            if dataclasses.is_dataclass(value):
                fields = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
            elif isinstance(value, tuple) and hasattr(value, "_fields"):  # a named tuple
                fields = dict(zip(value._fields, value))
            elif hasattr(value, "__dict__"):
                fields = dict(vars(value))
            else:
                raise StateError(f"{where}: {cls.__qualname__} has neither dataclass fields nor attributes")
            return ext(EXT_OBJECT, [f"{cls.__module__}:{cls.__qualname__}", fields], where)
        raise StateError(f"{where}: cannot snapshot a {cls.__module__}.{cls.__qualname__}")

    return pack(walk(obj, "state"))


def _class(ref: str, modules: tuple[str, ...]) -> type:
    module_name, _, qualname = ref.partition(":")
    if not _allowed(module_name, modules):
        raise StateError(f"a snapshot names class {ref}, outside swarmbed and the plugin's module")
    module = sys.modules.get(module_name) or importlib.import_module(module_name)
    obj: Any = module
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def unpack_state(data: bytes, modules: tuple[str, ...] = ()) -> Any:
    """What :func:`pack_state` packed."""

    def hook(code: int, raw: bytes) -> Any:
        value = msgpack.unpackb(raw, raw=False, strict_map_key=False, ext_hook=hook)
        if code == EXT_TUPLE:
            return tuple(value)
        if code == EXT_SET:
            return set(value)
        if code == EXT_FROZENSET:
            return frozenset(value)
        if code == EXT_BIGINT:
            return int(value)
        if code == EXT_ARRAY:
            descr, shape, buf = value
            dtype = np.dtype([tuple(f) for f in descr]) if isinstance(descr, list) else np.dtype(descr)
            return np.frombuffer(buf, dtype=dtype).reshape(shape).copy()
        if code == EXT_SCALAR:
            return np.frombuffer(value[1], dtype=np.dtype(value[0]))[0]
        if code == EXT_RNG:
            bit_generator = getattr(np.random, value["bit_generator"])()
            bit_generator.state = value
            return np.random.Generator(bit_generator)
        if code == EXT_ENUM:
            return _class(value[0], modules)(value[1])
        if code == EXT_OBJECT:
            ref, fields = value
            cls: Any = _class(ref, modules)
            if issubclass(cls, tuple):  # a named tuple
                return cls(**fields)
            obj = cls.__new__(cls)
            for name, v in fields.items():
                object.__setattr__(obj, name, v)  # frozen dataclasses too
            return obj
        raise StateError(f"unknown extension type {code} in a snapshot")

    try:
        return msgpack.unpackb(data, raw=False, strict_map_key=False, ext_hook=hook)
    except StateError:
        raise
    except Exception as exc:
        raise StateError(f"not a snapshot: {exc}") from exc
