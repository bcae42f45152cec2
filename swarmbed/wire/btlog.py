"""BehaviorTree.CPP's ``.btlog`` file (its FileLogger2), which Groot2 opens to replay a tree's run,
and the per-tick sample in which an agent hands its tree's status changes to the coordinator.

The file's layout, little-endian, as BehaviorTree.CPP v4 writes it:

- the 19-byte header ``BTCPP4-FileLogger2`` and a byte 1;
- a uint32 N, then N bytes of the tree as XML: every node with its ``_uid``, each SubTree instance
  as a ``<BehaviorTree ID=... _fullpath=...>`` of its own after the main tree, then the node models
  (:func:`swarmbed.bt.groot_tree.tree_xml` writes it);
- an int64: the first timestamp, in microseconds since the Unix epoch;
- then one 9-byte record per status change: 6 bytes of microseconds since the first timestamp,
  the node's uint16 uid, and its uint8 status (IDLE 0, RUNNING 1, SUCCESS 2, FAILURE 3).

BehaviorTree.CPP stamps records with the wall clock. Ours are stamped in simulated time from a
fixed epoch (:data:`EPOCH_US`), so a lock-step run's files are byte-identical on every rerun and
placement. ``tests/test_btlog.py`` runs the same trees through BehaviorTree.CPP's own FileLogger
and compares the trees, uids and status changes.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field

from swarmbed.wire.codec import pack, unpack
from swarmbed.wire.errors import WireError

HEADER = b"BTCPP4-FileLogger2\x01"
EPOCH_US = 946_684_800_000_000  # simulated time 0 is 2000-01-01T00:00:00Z
STATUS_CODES = 4  # IDLE, RUNNING, SUCCESS, FAILURE: BehaviorTree.CPP's NodeStatus values 0 to 3
_RECORD = 9
_MAX_OFFSET_US = 2**48 - 1
MAX_TREE_XML = 1 << 20  # bytes: a tree a person drew is far smaller
MAX_CHANGES = 1 << 16  # status changes of one agent in one tick
MAX_BLACKBOARDS = 256  # blackboards (the main tree and SubTree instances) in one sample
MAX_ENTRIES = 256  # entries of one blackboard
MAX_NAME = 256  # characters of a blackboard's or an entry's name
MAX_TEXT = 4096  # characters of a text value
MAX_ITEMS = 64  # items of a list value
_UID = re.compile(r'_uid="([^"]*)"')
MAX_NODES = 0xFFFF  # a record's uid is a uint16
Scalar = int | float | str | None
BlackboardValue = Scalar | list[Scalar]


class BtLogError(ValueError):
    """A .btlog that cannot be read; the message says where it stops making sense."""


def tree_size(xml: str) -> int:
    """The number of nodes of a tree's XML as :func:`file_head` takes it (uids run from 1 to it, each
    once). A WireError for any other numbering: the size is what a reader allocates for, so it is
    taken from the nodes the XML holds, never from a uid it claims."""
    uids = _UID.findall(xml)
    if len(uids) > MAX_NODES:
        raise WireError(f"tree: {len(uids)} nodes, more than a .btlog record can name ({MAX_NODES})")
    if any(not (u.isascii() and u.isdigit()) or len(u) > 5 for u in uids):
        raise WireError("tree: every _uid must be a number of at most 5 digits")
    if sorted(map(int, uids)) != list(range(1, len(uids) + 1)):
        raise WireError(f"tree: its {len(uids)} nodes' _uid are not 1 to {len(uids)}, each once")
    return len(uids)


def file_head(xml: str, first_us: int = EPOCH_US) -> bytes:
    """What a .btlog starts with: the header, the tree and the first timestamp."""
    data = xml.encode()
    return HEADER + struct.pack("<I", len(data)) + data + struct.pack("<q", first_us)


def records(offset_us: int, changes: Iterable[tuple[int, int]]) -> bytes:
    """The 9-byte records of status changes ``(uid, status code)`` at ``offset_us`` after the first
    timestamp."""
    if not 0 <= offset_us <= _MAX_OFFSET_US:
        raise BtLogError(f"a .btlog record's time must be 0 to {_MAX_OFFSET_US} us after the first, got {offset_us}")
    stamp = offset_us.to_bytes(6, "little")
    return b"".join(stamp + struct.pack("<HB", uid, code) for uid, code in changes)


def read_btlog(data: bytes) -> tuple[str, int, list[tuple[int, int, int]]]:
    """(tree XML, first timestamp in us, [(us after the first, uid, status code)]) of a .btlog."""
    if not data.startswith(HEADER):
        raise BtLogError("not a .btlog: it does not start with BTCPP4-FileLogger2")
    at = len(HEADER)
    if len(data) < at + 4:
        raise BtLogError(f"the file ends at byte {len(data)}, inside the tree's length")
    (n,) = struct.unpack_from("<I", data, at)
    at += 4
    if len(data) < at + n + 8:
        raise BtLogError(f"the file ends at byte {len(data)}, inside the tree ({n} bytes from byte {at})")
    xml = data[at : at + n].decode()
    at += n
    (first,) = struct.unpack_from("<q", data, at)
    at += 8
    if (len(data) - at) % _RECORD:
        raise BtLogError(f"{len(data) - at} bytes of records is not a whole number of {_RECORD}-byte records")
    out = []
    for i in range(at, len(data), _RECORD):
        uid, code = struct.unpack_from("<HB", data, i + 6)
        out.append((int.from_bytes(data[i : i + 6], "little"), uid, code))
    return xml, first, out


# -- agent -> coordinator and monitors: one tick's status changes ----------------------------------
@dataclass(frozen=True)
class TreeChanges:
    """An agent's status changes in one tick, ``(uid, status code)`` in the order they happened, at
    simulated time ``time_us``. The first sample a process sends, and the first after a monitor
    appears, carry its tree (``xml``, as :func:`file_head` takes it) and every node's status at the
    tick's end (``statuses``, the nodes not IDLE), from which a monitor starts.

    ``blackboards``, only while a monitor looks: each blackboard whose content changed in the tick
    (all of them with the tree), whole, by the name Groot2 asks for it (the main tree's ID, or a
    SubTree's ``_fullpath``); nil for one with nothing Groot2 can show. Values are numbers, text,
    nil, or lists of those."""

    tick: int
    time_us: int
    changes: list[tuple[int, int]]
    xml: str | None = None
    statuses: list[tuple[int, int]] = field(default_factory=list)
    blackboards: dict[str, dict[str, BlackboardValue] | None] = field(default_factory=dict)


def _flat(pairs: list[tuple[int, int]]) -> bytes:
    return b"".join(struct.pack("<HB", uid, code) for uid, code in pairs)


def _pairs(flat: object, what: str, n_nodes: int | None) -> list[tuple[int, int]]:
    if not (isinstance(flat, bytes) and len(flat) % 3 == 0 and len(flat) <= 3 * MAX_CHANGES):
        raise WireError(f"tree changes: {what} must be whole 3-byte (uid, status) records")
    pairs = [struct.unpack_from("<HB", flat, i) for i in range(0, len(flat), 3)]
    for uid, code in pairs:
        if code >= STATUS_CODES or uid == 0 or (n_nodes is not None and uid > n_nodes):
            raise WireError(f"tree changes: no node {uid} with status {code}")
    return pairs


def encode_tree_changes(sample: TreeChanges) -> bytes:
    return pack(
        [sample.tick, sample.time_us, _flat(sample.changes), sample.xml, _flat(sample.statuses), sample.blackboards]
    )


def decode_tree_changes(data: bytes, n_nodes: int | None = None) -> TreeChanges:
    """A sample of :func:`encode_tree_changes`; WireError names what is wrong. ``n_nodes``: the
    tree's size, once known (uids run from 1 to it)."""
    raw = unpack(data, max_bytes=MAX_TREE_XML + 6 * MAX_CHANGES + (1 << 20))
    if not (isinstance(raw, list) and len(raw) == 6):
        raise WireError("tree changes: not [tick, time_us, changes, xml, statuses, blackboards]")
    tick, time_us, changes, xml, statuses, blackboards = raw
    for name, value in (("tick", tick), ("time_us", time_us)):
        if not (isinstance(value, int) and not isinstance(value, bool) and 0 <= value < 2**48):
            raise WireError(f"tree changes: {name} must be a count, got {value!r}")
    if not (xml is None or (isinstance(xml, str) and xml.startswith("<root") and len(xml) <= MAX_TREE_XML)):
        raise WireError("tree changes: xml must be a tree's <root> element or nil")
    if xml is not None:
        n_nodes = tree_size(xml)  # its statuses are checked against the tree it comes with
    return TreeChanges(
        tick,
        time_us,
        _pairs(changes, "changes", n_nodes),
        xml,
        _pairs(statuses, "statuses", n_nodes),
        _blackboards(blackboards),
    )


def _blackboards(raw: object) -> dict[str, dict[str, BlackboardValue] | None]:
    if not (isinstance(raw, dict) and len(raw) <= MAX_BLACKBOARDS):
        raise WireError(f"tree changes: blackboards must be a map of at most {MAX_BLACKBOARDS}")
    out: dict[str, dict[str, BlackboardValue] | None] = {}
    for name, entries in raw.items():
        if not (isinstance(name, str) and len(name) <= MAX_NAME):
            raise WireError(f"tree changes: a blackboard's name must be text of at most {MAX_NAME} characters")
        if entries is None:
            out[name] = None
            continue
        if not (isinstance(entries, dict) and len(entries) <= MAX_ENTRIES):
            raise WireError(f"tree changes: blackboard {name!r} must be a map of at most {MAX_ENTRIES} entries or nil")
        for key, value in entries.items():
            if not (isinstance(key, str) and len(key) <= MAX_NAME):
                raise WireError(f"tree changes: blackboard {name!r} has an entry name that is not short text")
            listed = isinstance(value, list) and len(value) <= MAX_ITEMS and all(map(_scalar, value))
            if not (_scalar(value) or listed):
                raise WireError(f"tree changes: blackboard {name!r} entry {key!r} is not a number, text or a list")
        out[name] = entries
    return out


def _scalar(value: object) -> bool:
    if value is None or isinstance(value, float):
        return True
    if isinstance(value, int):
        return not isinstance(value, bool) and -(2**63) <= value < 2**64
    return isinstance(value, str) and len(value) <= MAX_TEXT
