"""Snapshots of Python state as msgpack, for moving a running agent to another process.

Plain values travel as msgpack does; the rest as extension types that restore to the same type:
tuples (named ones too), sets, numpy arrays and scalars, integers past 64 bits, numpy random
generators (their bit generator's state), enum members, and instances of dataclasses and plain
classes. Anything else raises :class:`StateError` naming the value's type and where it was, so that
a plugin whose state cannot move says so instead of moving wrongly.

A snapshot crosses the network, so restoring one must never do more than rebuild data. A class
may appear in a snapshot only when its module declared it with :func:`state_type`; a snapshot
names a class by its exact ``module:qualname`` and restoring looks that name up in the registry of
declared types, nothing else: no import, no attribute walk, no call of anything the snapshot names
except a declared enum's value lookup and a declared named tuple's constructor. Objects are rebuilt
without calling ``__init__``, and only attributes that are ordinary names (no dunders; for a
dataclass, only its fields) are set. Random generators restore only numpy's own bit generators.

Shared references are not preserved: an object reached twice is restored as two equal objects.
"""

from __future__ import annotations

import dataclasses
import enum
from typing import Any, TypeVar

import msgpack
import numpy as np

from swarmbed.wire.codec import pack

EXT_TUPLE, EXT_SET, EXT_ARRAY, EXT_SCALAR, EXT_BIGINT, EXT_RNG, EXT_OBJECT, EXT_FROZENSET, EXT_ENUM = range(1, 10)

#: numpy's bit generators, the only ones a snapshot may name (by their class name)
BIT_GENERATORS: dict[str, type] = {
    c.__name__: c for c in (np.random.PCG64, np.random.PCG64DXSM, np.random.MT19937, np.random.Philox, np.random.SFC64)
}

T = TypeVar("T", bound=type)
_DECLARED: dict[str, type] = {}  # "module:qualname" -> the class


class StateError(ValueError):
    """State that cannot be snapshotted or restored; the message says what and where."""


def type_ref(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def state_type(cls: T) -> T:
    """Declare ``cls`` (a dataclass, a named tuple, an enum or a plain class) as a type agent
    snapshots may hold; use it as a class decorator in the module that defines the class. Only
    declared types are packed or restored: a plugin whose state holds its own classes declares them."""
    if not isinstance(cls, type):
        raise TypeError(f"state_type declares classes, not {cls!r}")
    if "<locals>" in cls.__qualname__:
        raise TypeError(f"{cls.__qualname__}: a class defined inside a function cannot be a state type")
    ref = type_ref(cls)
    known = _DECLARED.get(ref)
    if known is not None and known is not cls:
        raise TypeError(f"state type {ref} is declared twice, by two different classes")
    _DECLARED[ref] = cls
    return cls


def declared_state_types() -> dict[str, type]:
    """Every declared type by its ``module:qualname`` (a copy)."""
    return dict(_DECLARED)


def _declared(ref: object, where: str) -> type:
    cls = _DECLARED.get(ref) if isinstance(ref, str) else None
    if cls is None:
        raise StateError(f"{where}: the snapshot names {ref!r}, which is not a declared state type")
    return cls


def _attribute_names(cls: type, fields: object, where: str) -> dict[str, Any]:
    if not isinstance(fields, dict):
        raise StateError(f"{where}: the attributes of {type_ref(cls)} are not a map")
    allowed = {f.name for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else None
    for name in fields:
        if not isinstance(name, str) or not name.isidentifier() or name.startswith("__"):
            raise StateError(f"{where}: {type_ref(cls)} cannot have an attribute named {name!r}")
        if allowed is not None and name not in allowed:
            raise StateError(f"{where}: {type_ref(cls)} has no field {name!r}")
    return fields


def pack_state(obj: Any) -> bytes:
    """``obj`` as bytes; instances of classes are packed only where their class is declared."""

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
            if type(value.bit_generator).__name__ not in BIT_GENERATORS:
                raise StateError(f"{where}: a random generator over {type(value.bit_generator).__name__}")
            return ext(EXT_RNG, value.bit_generator.state, where)
        cls = type(value)
        ref = type_ref(cls)
        if _DECLARED.get(ref) is not cls:
            raise StateError(
                f"{where}: cannot snapshot a {cls.__module__}.{cls.__qualname__}: not a declared state "
                "type (decorate the class with swarmbed.wire.state.state_type)"
            )
        if isinstance(value, enum.Enum):
            return ext(EXT_ENUM, [ref, value.value], where)
        if dataclasses.is_dataclass(value):
            fields = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
        elif isinstance(value, tuple):  # a named tuple
            fields = dict(zip(value._fields, value))  # type: ignore[attr-defined]
        elif hasattr(value, "__dict__"):
            fields = dict(vars(value))
        else:
            raise StateError(f"{where}: {cls.__qualname__} has neither dataclass fields nor attributes")
        return ext(EXT_OBJECT, [ref, fields], where)

    return pack(walk(obj, "state"))


def _array(value: Any, where: str) -> np.ndarray:
    descr, shape, buf = value
    dtype = np.dtype([tuple(f) for f in descr]) if isinstance(descr, list) else np.dtype(descr)
    if dtype.hasobject:
        raise StateError(f"{where}: an array of Python objects")
    if not isinstance(buf, bytes) or not isinstance(shape, list) or not all(isinstance(n, int) for n in shape):
        raise StateError(f"{where}: a malformed array")
    return np.frombuffer(buf, dtype=dtype).reshape(shape).copy()


def _scalar(value: Any, where: str) -> np.generic:
    dtype = np.dtype(value[0])
    if dtype.hasobject or not isinstance(value[1], bytes):
        raise StateError(f"{where}: a malformed numpy scalar")
    return np.frombuffer(value[1], dtype=dtype)[0]


def _generator(value: Any, where: str) -> np.random.Generator:
    name = value.get("bit_generator") if isinstance(value, dict) else value
    if not isinstance(name, str) or name not in BIT_GENERATORS:
        raise StateError(f"{where}: a random generator over {name!r}, not one of numpy's {', '.join(BIT_GENERATORS)}")
    bit_generator = BIT_GENERATORS[value["bit_generator"]]()
    bit_generator.state = value
    return np.random.Generator(bit_generator)


def _object(value: Any, where: str) -> Any:
    ref, fields = value
    cls = _declared(ref, where)
    fields = _attribute_names(cls, fields, where)
    if issubclass(cls, enum.Enum):
        raise StateError(f"{where}: enum {ref} as an object")
    if issubclass(cls, tuple):
        if not hasattr(cls, "_fields") or set(fields) != set(cls._fields):
            raise StateError(f"{where}: the fields of named tuple {ref} do not match")
        return cls(**fields)
    obj = cls.__new__(cls)
    for name, v in fields.items():
        object.__setattr__(obj, name, v)  # frozen dataclasses too
    return obj


def _enum(value: Any, where: str) -> enum.Enum:
    ref, member = value
    cls = _declared(ref, where)
    if not issubclass(cls, enum.Enum):
        raise StateError(f"{where}: {ref} is not an enum")
    return cls(member)  # a lookup of a member by its value


_DECODERS = {
    EXT_TUPLE: lambda v, w: tuple(v),
    EXT_SET: lambda v, w: set(v),
    EXT_FROZENSET: lambda v, w: frozenset(v),
    EXT_ARRAY: _array,
    EXT_SCALAR: _scalar,
    EXT_RNG: _generator,
    EXT_OBJECT: _object,
    EXT_ENUM: _enum,
}


def unpack_state(data: bytes, max_bytes: int = 256 * 2**20) -> Any:
    """What :func:`pack_state` packed. Anything else, however crafted, raises :class:`StateError`
    after building nothing but declared types (see the module's docstring)."""
    if len(data) > max_bytes:
        raise StateError(f"a snapshot of {len(data)} bytes, over the limit of {max_bytes}")

    def hook(code: int, raw: bytes) -> Any:
        value = msgpack.unpackb(raw, raw=False, strict_map_key=False, ext_hook=hook)
        if code == EXT_BIGINT:
            if not isinstance(value, str) or len(value) > 4000:
                raise StateError("a malformed big integer")
            return int(value)
        decode = _DECODERS.get(code)
        if decode is None:
            raise StateError(f"unknown extension type {code} in a snapshot")
        return decode(value, "snapshot")

    try:
        return msgpack.unpackb(data, raw=False, strict_map_key=False, ext_hook=hook)
    except StateError:
        raise
    except Exception as exc:
        raise StateError(f"not a snapshot: {type(exc).__name__}: {exc}") from exc
