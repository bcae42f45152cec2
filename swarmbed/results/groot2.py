"""The Groot2 monitoring protocol, as BehaviorTree.CPP's Groot2Publisher speaks it: what Groot2 asks a
tree executor and what it is answered, from a tree's XML and its status changes.

Groot2 is a ZeroMQ request socket. Each request is one frame of 6 bytes (protocol 2, a request type
letter, a uint32 request id), sometimes with a second frame. Each answer repeats those 6 bytes and
adds the 16-byte identity of the tree (Groot2 reloads the tree when it changes), then a body:

- ``T``: the tree's XML, every node with its ``_uid``;
- ``S``: every node's status, 3 bytes each (uint16 uid, uint8 status), tree by tree in the order the
  XML lists them (main tree, then each SubTree instance), nodes in document order within each; a node
  back to IDLE shows 10 + the status it left, as BehaviorTree.CPP encodes it;
- ``B``: the blackboards named in the second frame (``;``-separated: the main tree's ID, a
  SubTree's ``_fullpath``), as a msgpack map of maps, names and entries sorted, unknown names left
  out, nil if none is known or a blackboard holds nothing; numbers are packed as nlohmann::json
  packs them (a double as float32 when that loses nothing), so the bytes are BehaviorTree.CPP's;
- ``r``: recording of status changes, ``start`` or ``stop``; on start the body is the first
  timestamp (microseconds since the epoch, as text);
- ``t``: the status changes recorded since the last ``t``, 9 bytes each (6 bytes of microseconds
  since the first timestamp, uint16 uid, uint8 status);
- ``D``: the breakpoints, always none (``[]``): an agent of a lock-step run never pauses.

A request that cannot be read is answered ``error`` and why. ``tests/test_groot.py`` asks
BehaviorTree.CPP's own publisher and ours the same questions about the same ticks.
"""

from __future__ import annotations

import hashlib
import math
import struct
import threading
from collections.abc import Mapping, Sequence
from xml.etree import ElementTree

import msgpack

from swarmbed.wire.btlog import EPOCH_US, BlackboardValue

PROTOCOL = 2
REQUEST = struct.Struct("<BBI")  # protocol, type, request id
IDLE = 0
HOOKS = frozenset(b"IRAXNU")  # breakpoint requests: insert, remove, remove all, disable all, reached, unlock


def pack_like_nlohmann(value: object) -> bytes:
    """msgpack as nlohmann::json's ``to_msgpack`` writes it (what BehaviorTree.CPP answers Groot2
    with): maps with their keys sorted, a finite double that float32 holds exactly as float32."""
    if isinstance(value, dict):
        head = _container_head(len(value), 0x80, 0xDE)
        return head + b"".join(pack_like_nlohmann(k) + pack_like_nlohmann(value[k]) for k in sorted(value))
    if isinstance(value, list):
        return _container_head(len(value), 0x90, 0xDC) + b"".join(map(pack_like_nlohmann, value))
    if isinstance(value, float) and math.isfinite(value):
        try:
            single = struct.pack(">f", value)
        except OverflowError:
            single = b""
        if single and struct.unpack(">f", single)[0] == value:
            return b"\xca" + single
    return msgpack.packb(value)


def _container_head(n: int, fixed: int, code16: int) -> bytes:
    """A msgpack map's or array's header: fixmap/fixarray, then the 16- and 32-bit forms."""
    if n < 16:
        return bytes([fixed | n])
    return struct.pack(">BH", code16, n) if n < 1 << 16 else struct.pack(">BI", code16 + 1, n)


def tree_identity(*names: object) -> bytes:
    """A tree's 16-byte identity, the same for the same names (a run, an agent, its process)."""
    return hashlib.blake2b(repr(names).encode(), digest_size=16).digest()


def buffer_order(xml: str) -> list[int]:
    """The uids of a tree's XML (as :func:`~swarmbed.bt.groot_tree.tree_xml` writes it) in
    the order BehaviorTree.CPP's status buffer lists them."""
    try:
        root = ElementTree.fromstring(xml)
    except ElementTree.ParseError:
        return []
    return [int(n.get("_uid", "0")) for tree in root.findall("BehaviorTree") for n in tree.iter() if n.get("_uid")]


#: the status changes a recording keeps until Groot2 asks for them with ``t`` (the newest; older
#: ones are dropped, as BehaviorTree.CPP's publisher bounds its transitions buffer): a client that
#: started a recording and went away must not grow the gateway by 9 bytes a change for ever
MAX_RECORDED_CHANGES = 1000
CHANGE_BYTES = 9  # 6 bytes of microseconds, a uint16 uid, a status byte


class MonitoredTree:
    """What Groot2 sees of one tree: its XML and identity, each node's status, and the status changes
    recorded while Groot2 asks for them. Fed by :meth:`reset` and :meth:`apply` (from any thread);
    :meth:`answer` serves one request."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.xml = ""
        self.identity = bytes(16)
        self.raw: list[int] = [IDLE]  # index: uid (0 unused)
        self.shown: list[int] = [IDLE]
        self.order: list[int] = []  # the uids in the order the status buffer lists them
        self.now_us = EPOCH_US  # the last tick's time
        self.recording_from: int | None = None
        self.recorded = bytearray()
        self.blackboards: dict[str, dict[str, BlackboardValue] | None] = {}

    def reset(
        self,
        xml: str,
        identity: bytes,
        n_nodes: int,
        statuses: Sequence[tuple[int, int]] = (),
        blackboards: Mapping[str, dict[str, BlackboardValue] | None] | None = None,
    ) -> None:
        """Show another tree (or the same tree's state afresh): every node IDLE unless ``statuses``,
        the blackboards as ``blackboards`` has them."""
        with self.lock:
            self.blackboards = dict(blackboards or {})
            self.xml, self.identity = xml, identity
            self.order = [u for u in buffer_order(xml) if 0 < u <= n_nodes]
            self.raw = [IDLE] * (n_nodes + 1)
            self.shown = [IDLE] * (n_nodes + 1)
            for uid, code in statuses:
                if 0 < uid <= n_nodes:
                    self.raw[uid] = self.shown[uid] = code
            self.recorded.clear()

    def apply(
        self,
        time_us: int,
        changes: list[tuple[int, int]],
        blackboards: Mapping[str, dict[str, BlackboardValue] | None] | None = None,
    ) -> None:
        """One tick's status changes ``(uid, status code)`` at ``time_us`` (since the epoch), and the
        blackboards that changed in it."""
        with self.lock:
            self.now_us = time_us
            self.blackboards.update(blackboards or {})
            for uid, code in changes:
                if not 0 < uid < len(self.raw):
                    continue
                prev, self.raw[uid] = self.raw[uid], code
                self.shown[uid] = code if code != IDLE else 10 + prev
                if self.recording_from is not None:
                    offset = max(0, time_us - self.recording_from)
                    self.recorded += offset.to_bytes(6, "little") + struct.pack("<HB", uid, code)
            if len(self.recorded) > MAX_RECORDED_CHANGES * CHANGE_BYTES:  # nobody asked ("t") for a while
                del self.recorded[: len(self.recorded) - MAX_RECORDED_CHANGES * CHANGE_BYTES]

    def answer(self, frames: list[bytes]) -> list[bytes]:
        if not frames or len(frames[0]) != REQUEST.size:
            return [b"error", b"wrong request header"]
        _protocol, kind, _request_id = REQUEST.unpack(frames[0])
        payload = frames[1] if len(frames) > 1 else b""
        with self.lock:
            head = bytes([PROTOCOL]) + frames[0][1:] + self.identity
            if kind == ord("T"):
                return [head, self.xml.encode()]
            if kind == ord("S"):
                return [head, b"".join(struct.pack("<HB", uid, self.shown[uid]) for uid in self.order)]
            if kind == ord("B"):
                if len(frames) < 2:
                    return [b"error", b"must be 2 parts message"]
                names = set(payload.decode(errors="replace").split(";"))
                shown = {n: self.blackboards[n] for n in sorted(names) if n in self.blackboards}
                return [head, pack_like_nlohmann(shown or None)]
            if kind == ord("r"):
                if payload == b"start":
                    self.recording_from = self.now_us
                    self.recorded.clear()
                    return [head, str(self.recording_from).encode()]
                if payload == b"stop":
                    self.recording_from = None
                    self.recorded.clear()
                return [head]
            if kind == ord("t"):
                out, self.recorded = bytes(self.recorded), bytearray()
                return [head, out]
            if kind == ord("D"):
                return [head, b"[]"]
            if kind in HOOKS:
                return [b"error", b"breakpoints are not available: an agent of a lock-step run never pauses"]
        return [b"error", b"Request not recognized"]


def serve(tree: MonitoredTree, port: int, stop: threading.Event, bind: str = "127.0.0.1") -> None:
    """Answer Groot2 on ``port`` (and hold ``port + 1``, where BehaviorTree.CPP publishes breakpoint
    notices, so that Groot2 finds both) until ``stop`` is set."""
    import zmq

    context = zmq.Context()
    replies = context.socket(zmq.REP)
    notices = context.socket(zmq.PUB)
    try:
        replies.setsockopt(zmq.MAXMSGSIZE, 1 << 16)  # a request is a header and a few names
        replies.setsockopt(zmq.LINGER, 0)
        notices.setsockopt(zmq.LINGER, 0)
        replies.bind(f"tcp://{bind}:{port}")
        notices.bind(f"tcp://{bind}:{port + 1}")
        while not stop.is_set():
            if replies.poll(100):
                replies.send_multipart(tree.answer(replies.recv_multipart()))
    finally:
        replies.close()
        notices.close()
        context.term()
