"""Vectors of a message as packed little-endian arrays of declared dtypes: each vector goes in the
narrowest of a fixed, ordered list of dtypes that holds every entry exactly (ids in range, whole
numbers where the dtype is an integer), named by a key the receiver looks its dtype up by. A
receiver reads one with ``struct.iter_unpack`` and never makes more than a tuple per entry;
bytes that are not a whole number of entries are read as none (plugins' messages are data anyone in
range may have sent)."""

from __future__ import annotations

import functools
import struct
from collections.abc import Hashable, Sequence
from typing import Any, TypeVar

import numpy as np

Key = TypeVar("Key", bound=Hashable)

#: below this many rows a vector's dtype is chosen in Python (a few numpy calls cost more)
FEW_ROWS = 32


def _narrowest(wide: np.ndarray, keys: Sequence[tuple[Key, np.dtype]]) -> tuple[Key, np.ndarray]:
    """The first of ``keys`` whose dtype holds every entry of ``wide`` exactly, and the entries in it
    (ids: in range; stamps: whole numbers in range; a bid is always float64)."""
    seen: dict[str, tuple[Any, Any, bool]] = {}  # per field: least, greatest, all whole; looked at once
    for key, dtype in keys[:-1]:
        if all(_holds(wide, name, bound, dtype[name], seen) for name, bound in zip(dtype.names or (), _bounds(dtype))):
            return key, wide.astype(dtype)
    return keys[-1][0], wide


def _holds(
    wide: np.ndarray, name: str, bound: tuple[int, int] | None, dtype: np.dtype, seen: dict[str, tuple[Any, Any, bool]]
) -> bool:
    """Whether field ``name`` of ``wide`` fits ``dtype`` (of range ``bound``) exactly."""
    if bound is None or dtype == wide.dtype[name]:
        return True
    if name not in seen:
        values = wide[name]
        whole = values.dtype.kind != "f" or bool((values == np.floor(values)).all())
        seen[name] = (values.min(), values.max(), whole)
    least, greatest, whole = seen[name]
    return bool(bound[0] <= least and greatest <= bound[1]) and whole


@functools.lru_cache(maxsize=64)
def _bounds(dtype: np.dtype) -> tuple[tuple[int, int] | None, ...]:
    """Per field of ``dtype``: the range of an integer field, None for a float one."""
    return tuple(
        None if dtype[name].kind == "f" else (int(np.iinfo(dtype[name]).min), int(np.iinfo(dtype[name]).max))
        for name in dtype.names or ()
    )


def _narrowest_key(rows: Sequence[tuple], keys: Sequence[tuple[Key, np.dtype]]) -> Key:
    """:func:`_narrowest`'s key for a few rows, found without making arrays."""
    columns = list(zip(*rows))
    for key, dtype in keys[:-1]:
        if all(
            bound is None or (bound[0] <= min(column) and max(column) <= bound[1] and all(v == int(v) for v in column))
            for bound, column in zip(_bounds(dtype), columns)
        ):
            return key
    return keys[-1][0]


def pack_rows(rows: Sequence[tuple], keys: Sequence[tuple[Key, np.dtype]]) -> tuple[Key, bytes]:
    """``rows`` packed in the first of ``keys``' dtypes that holds every row exactly, and its key."""
    if len(rows) < FEW_ROWS:
        key = _narrowest_key(rows, keys)
        dtype = dict(keys)[key]
        entry = _struct(dtype)
        whole = [bound is not None for bound in _bounds(dtype)]
        return key, b"".join(entry.pack(*[int(v) if w else v for w, v in zip(whole, row)]) for row in rows)
    key, packed = _narrowest(np.array(rows, dtype=keys[-1][1]), keys)
    return key, packed.tobytes()


def pack_columns(columns: Sequence[np.ndarray], keys: Sequence[tuple[Key, np.dtype]]) -> tuple[Key, bytes]:
    """:func:`pack_rows` of the rows that ``columns`` (one array per field) hold, without making a
    Python tuple per row where there are many: the same key and bytes."""
    n = len(columns[0])
    if n < FEW_ROWS:
        return pack_rows(list(zip(*[c.tolist() for c in columns])), keys)
    wide = np.empty(n, dtype=keys[-1][1])
    for name, column in zip(wide.dtype.names or (), columns):
        wide[name] = column
    key, packed = _narrowest(wide, keys)
    return key, packed.tobytes()


_STRUCT = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "i8": "q", "f4": "f", "f8": "d"}


def struct_format(dtype: np.dtype) -> str:
    """The :mod:`struct` format of one entry of ``dtype`` (little-endian, no padding)."""
    return "<" + "".join(_STRUCT[dtype[name].str[1:]] for name in dtype.names or ())


@functools.lru_cache(maxsize=64)
def _struct(dtype: np.dtype) -> struct.Struct:
    return struct.Struct(struct_format(dtype))


def _packs(raw: Any, dtype: np.dtype) -> bool:
    """Whether ``raw`` is packed entries of ``dtype``: bytes, a whole number of entries."""
    return isinstance(raw, bytes) and len(raw) % dtype.itemsize == 0


def read_tuples(raw: Any, dtype: np.dtype) -> list[tuple]:
    """The entries ``raw`` packs in ``dtype`` as tuples (``struct.iter_unpack``: no array made, which
    for a message of a few entries costs more than reading them); none for anything else."""
    return list(_struct(dtype).iter_unpack(raw)) if _packs(raw, dtype) else []


def read_array(raw: Any, dtype: np.dtype) -> np.ndarray | None:
    """The entries ``raw`` packs in ``dtype`` as a read-only array over its bytes, or None for
    anything that is not such entries."""
    return np.frombuffer(raw, dtype) if _packs(raw, dtype) else None
