"""Message schemas and the msgpack codec.

Messages are msgpack arrays (compact and fast to pack). Every decoder checks the shape it reads
and raises :class:`WireError` on anything else, so a malformed sample is dropped and counted by
the receiver instead of crashing it.

A radio message's *size* is ``len(payload)``: the bytes of the encoded payload exactly as they
cross Zenoh. The agent measures it when it encodes; the proxy measures it again when it receives.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import msgpack
import msgspec
import numpy as np

from swarmbed.wire.errors import WireError

BROADCAST = -1

TAG_TICK = 0
TAG_STOP = 1
# swap orders, each for one incarnation of the agent (the other process of a swap ignores it)
TAG_SNAPSHOT, TAG_RESUME, TAG_RETIRE = 2, 3, 4
# a checkpoint: the agent reports its state and goes on (kept to restart it after a crash)
TAG_CHECKPOINT = 5
CONTROLS = {TAG_SNAPSHOT: "snapshot", TAG_RESUME: "resume", TAG_RETIRE: "retire", TAG_CHECKPOINT: "checkpoint"}


# The largest sample an agent may send, or receive in one tick (its observation and inbox); a
# larger one is malformed (dropped and counted) before it is unpacked, so that junk cannot make a
# process allocate without bound.
MAX_AGENT_SAMPLE_BYTES = 16 * 2**20


_packers = threading.local()


def pack(obj: Any) -> bytes:
    """msgpack bytes of ``obj``, from a packer kept per thread. ``msgpack.packb`` makes a packer
    with a fresh 256 KB buffer on every call: at every tick and in every process that is a large
    block allocated and freed, which costs 14 times the packing itself where large blocks are
    mapped on their own (:func:`~swarmbed.wire.child_process.tune_malloc`)."""
    packer = getattr(_packers, "packer", None)
    if packer is None:
        packer = _packers.packer = msgpack.Packer(use_bin_type=True)
    return packer.pack(obj)  # its buffer is reset after each call, and after an error too


def unpack(data: bytes, max_bytes: int | None = None) -> Any:
    if max_bytes is not None and len(data) > max_bytes:
        raise WireError(f"oversized: {len(data):,} bytes, more than the {max_bytes:,} a sample may have")
    try:
        return msgpack.unpackb(data, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated exception types
        raise WireError(f"not msgpack: {exc}") from exc


def _expect(cond: bool, what: str) -> None:
    if not cond:
        raise WireError(what)


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


# --- radio messages -------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RadioMessage:
    """One message an agent hands to the radio. ``dest`` is BROADCAST, one id, or a tuple of ids."""

    dest: int | tuple[int, ...]
    kind: str
    payload: bytes

    def to_wire(self) -> list:
        dest = list(self.dest) if isinstance(self.dest, tuple) else self.dest
        return [dest, self.kind, self.payload]


def _radio_from_wire(item: Any) -> RadioMessage:
    _expect(isinstance(item, list) and len(item) == 3, "radio message must be [dest, kind, payload]")
    dest, kind, payload = item
    if isinstance(dest, list):
        _expect(all(_is_int(d) and d >= 0 for d in dest), "multicast dest must be agent ids")
        dest = tuple(dest)
    else:
        _expect(_is_int(dest) and dest >= BROADCAST, "dest must be -1 (broadcast) or an agent id")
    _expect(isinstance(kind, str) and 0 < len(kind) <= 64, "kind must be a short string")
    _expect(isinstance(payload, bytes), "payload must be bytes")
    return RadioMessage(dest, kind, payload)


class Delivered(NamedTuple):
    """One message as it arrives in an inbox."""

    sender: int
    kind: str
    payload: bytes


def encode_inbox(items: list[list]) -> bytes:
    """``items``: ``[sender, kind, payload]`` triples, in delivery order."""
    return pack(items)


EMPTY_INBOX = encode_inbox([])
_INBOX = msgspec.msgpack.Decoder(list[Delivered])  # what the loop below accepts, in one C pass


def decode_inbox(data: bytes) -> list[Delivered]:
    try:
        return _INBOX.decode(data)
    except msgspec.MsgspecError:
        return decode_inbox_checked(data)  # malformed: its checks name what


def delivered_in(data: bytes | None) -> list[Delivered]:
    """The copies of an inbox the proxy made, for a view of it (ROS 2 topics, a live view, an
    environment's observation): none for an empty one, and none where it does not decode (never
    expected; the agent it goes to counts it)."""
    if not data or data == EMPTY_INBOX:
        return []
    try:
        return decode_inbox(data)
    except WireError:
        return []


def decode_inbox_checked(data: bytes) -> list[Delivered]:
    """The inbox checked one entry at a time in Python: what ``decode_inbox`` accepts, and the
    error that names what is wrong where it does not."""
    items = unpack(data)
    _expect(isinstance(items, list), "inbox must be a list")
    out = []
    for it in items:
        _expect(isinstance(it, list) and len(it) == 3, "inbox entry must be [sender, kind, payload]")
        sender, kind, payload = it
        _expect(_is_int(sender) and isinstance(kind, str) and isinstance(payload, bytes), "bad inbox entry")
        out.append(Delivered(sender, kind, payload))
    return out


# --- coordinator -> agent -------------------------------------------------------------------

#: the tasks of an observation travel as one binary table of these records (little-endian)
TASK_DTYPE = np.dtype([("id", "<i4"), ("x", "<f8"), ("y", "<f8"), ("remaining", "<f8"), ("color", "i1")])


def encode_task_table(table: np.ndarray) -> bytes:
    return np.ascontiguousarray(table, dtype=TASK_DTYPE).tobytes()


def decode_task_table(data: object) -> np.ndarray:
    if not isinstance(data, bytes) or len(data) % TASK_DTYPE.itemsize:
        raise WireError(f"task table must be bytes, a multiple of {TASK_DTYPE.itemsize}")
    return np.frombuffer(data, dtype=TASK_DTYPE)


#: the most proxies a radio may be split over (``radio_split.shards``)
MAX_SHARDS = 64


def encode_tick(tick: int, obs: dict, inbox: bytes, decision: int | None = None, shard: int | None = None) -> bytes:
    """A tick's input; ``decision``: what an outside decision maker chose for this agent's tick
    (only for allocators that take their decisions from outside); ``shard``: the proxy of a radio
    split by region that reads this agent's output of the tick (docs/machines.md). The sample is
    unchanged where they are None."""
    if shard is not None:
        return pack([TAG_TICK, tick, obs, inbox, decision, shard])
    if decision is None:
        return pack([TAG_TICK, tick, obs, inbox])
    return pack([TAG_TICK, tick, obs, inbox, decision])


# --- coordinator -> a host daemon: its agents' inputs of one tick, in one sample ----------------

# A host's tick sample holds the inputs of every agent it carries: bounded for the same reason as
# an agent's, with room for a few thousand agents.
MAX_HOST_SAMPLE_BYTES = 256 * 2**20


@dataclass(frozen=True, slots=True)
class HostTick:
    """The inputs of tick ``tick`` for the agents ``agents`` of one host, column by column: agent
    ``agents[j]`` gets ``obs[j]``, ``inboxes[j]`` and ``decisions[j]`` (None: no outside decision)."""

    tick: int
    agents: list[int]
    obs: list[dict]
    inboxes: list[bytes]
    decisions: list[int | None]
    shards: list[int] | None = None  # each agent's proxy, in a radio split by region

    def samples(self) -> list[tuple[int, bytes]]:
        """Each agent's own tick sample, the bytes :func:`encode_tick` makes of its column entries."""
        tick = self.tick
        shards = self.shards if self.shards is not None else [None] * len(self.agents)
        return [
            (agent, encode_tick(tick, obs, inbox, decision, shard))
            for agent, obs, inbox, decision, shard in zip(
                self.agents, self.obs, self.inboxes, self.decisions, shards, strict=True
            )
        ]


def encode_host_tick(
    tick: int,
    agents: list[int],
    obs: list[dict],
    inboxes: list[bytes],
    decisions: list,
    shards: list[int] | None = None,
) -> bytes:
    """One sample for a host instead of one per agent: the per-agent encoding and puts are the
    host's work (:mod:`swarmbed.hosts.relay`), the hub packs one list per host."""
    if shards is None:
        return pack([tick, agents, obs, inboxes, decisions])
    return pack([tick, agents, obs, inboxes, decisions, shards])


def decode_host_tick(data: bytes) -> HostTick:
    msg = unpack(data, MAX_HOST_SAMPLE_BYTES)
    _expect(
        isinstance(msg, list) and len(msg) in (5, 6),
        "host tick must be [tick, agents, obs, inboxes, decisions] or [..., shards]",
    )
    tick, agents, obs, inboxes, decisions = msg[:5]
    shards = msg[5] if len(msg) == 6 else None
    _expect(_is_int(tick) and tick >= 0, "host tick: tick must be a non-negative int")
    _expect(
        all(isinstance(c, list) for c in (agents, obs, inboxes, decisions))
        and len(agents) == len(obs) == len(inboxes) == len(decisions),
        "host tick: agents, obs, inboxes and decisions must be lists of one length",
    )
    _expect(all(_is_int(a) and a >= 0 for a in agents), "host tick: agents must be non-negative ints")
    _expect(
        shards is None
        or (
            isinstance(shards, list)
            and len(shards) == len(agents)
            and all(_is_int(s) and 0 <= s < MAX_SHARDS for s in shards)
        ),
        f"host tick: shards must be one int in 0..{MAX_SHARDS - 1} per agent",
    )
    _expect(len(set(agents)) == len(agents), "host tick: an agent named twice")
    _expect(all(isinstance(o, dict) for o in obs), "host tick: each obs must be a map")
    _expect(all(isinstance(b, bytes) for b in inboxes), "host tick: each inbox must be bytes")
    _expect(
        all(d is None or (_is_int(d) and -(2**31) <= d < 2**31) for d in decisions),
        "host tick: a decision must be a 32-bit int or nil",
    )
    return HostTick(tick, agents, obs, inboxes, decisions, shards)


def encode_host_out(agents: list[int], outputs: list[bytes]) -> bytes:
    """A host's relay -> the proxy: the outputs its agents put (each as the agent encoded it)."""
    return pack([agents, outputs])


def decode_host_out(data: bytes) -> list[tuple[int, bytes]]:
    """(agent, its output's bytes) of a host's gathered outputs; each output is decoded and checked
    as one an agent put itself (:func:`decode_agent_out`)."""
    msg = unpack(data, MAX_HOST_SAMPLE_BYTES)
    _expect(
        isinstance(msg, list)
        and len(msg) == 2
        and all(isinstance(c, list) for c in msg)
        and len(msg[0]) == len(msg[1]),
        "host output must be [agents, outputs], two lists of one length",
    )
    agents, outputs = msg
    _expect(len(agents) == len(outputs), "host output must be [agents, outputs], two lists of one length")
    _expect(all(_is_int(a) and a >= 0 for a in agents), "host output: agents must be non-negative ints")
    _expect(all(isinstance(o, bytes) for o in outputs), "host output: each output must be bytes")
    return list(zip(agents, outputs, strict=True))


# --- launcher -> netem proxy: the radio's parameters changed (chaos) --------------------------

NETEM_OVERRIDABLE = ("loss", "rate", "range", "latency")


@dataclass(frozen=True, slots=True)
class NetemControl:
    """From tick ``from_tick`` on, the radio's parameters are the run's with ``overrides`` (an empty
    map: the run's own again); ``label`` names the cause in the proxy's log."""

    from_tick: int
    overrides: dict[str, Any]
    label: str


def encode_netem_control(control: NetemControl) -> bytes:
    return pack([control.from_tick, control.overrides, control.label])


def decode_netem_control(data: bytes) -> NetemControl:
    msg = unpack(data)
    _expect(isinstance(msg, list) and len(msg) == 3, "netem control must be [from_tick, overrides, label]")
    tick, overrides, label = msg
    _expect(_is_int(tick) and tick >= 0, "from_tick must be a non-negative int")
    _expect(
        isinstance(overrides, dict) and all(k in NETEM_OVERRIDABLE for k in overrides),
        f"overrides must be a map of {', '.join(NETEM_OVERRIDABLE)}",
    )
    _expect(isinstance(label, str), "label must be a string")
    return NetemControl(tick, overrides, label)


def encode_stop(reason: str) -> bytes:
    return pack([TAG_STOP, reason])


def encode_control(tag: int, incarnation: int, ticket: bytes = b"") -> bytes:
    """An order for one incarnation; ``ticket``: what the answer must carry (snapshot, checkpoint)."""
    return pack([tag, incarnation, ticket] if ticket else [tag, incarnation])


@dataclass(frozen=True, slots=True)
class TickIn:
    tick: int
    obs: Any  # the observation's wire map, or the typed observation (``swarmbed.wire.tickdecode``)
    inbox: bytes
    decision: int | None = None  # a decision made outside the agent (the ``ros2`` allocator's), if any
    shard: int | None = None  # the proxy that reads this tick's output (a radio split by region), if any


@dataclass(frozen=True, slots=True)
class StopIn:
    reason: str


@dataclass(frozen=True, slots=True)
class ControlIn:
    """An order for one ``incarnation``: snapshot, resume or retire (a swap), or checkpoint."""

    order: str
    incarnation: int
    ticket: bytes = b""  # to send back with the state asked for (coordinator.tickets)


def decode_agent_in(data: bytes) -> TickIn | StopIn | ControlIn:
    msg = unpack(data, MAX_AGENT_SAMPLE_BYTES)
    _expect(isinstance(msg, list) and bool(msg) and _is_int(msg[0]), "agent input must be [tag, ...]")
    if msg[0] == TAG_TICK:
        _expect(
            len(msg) in (4, 5, 6),
            "tick must be [0, tick, obs, inbox], [0, tick, obs, inbox, decision] or [..., decision, shard]",
        )
        tick, obs, inbox = msg[1:4]
        _expect(_is_int(tick) and tick >= 0, "tick must be a non-negative int")
        _expect(isinstance(obs, dict), "obs must be a map")
        _expect(isinstance(inbox, bytes), "inbox must be bytes")
        if len(msg) == 4:
            return TickIn(tick, obs, inbox)
        decision = msg[4]
        _expect(
            (decision is None and len(msg) == 6) or (_is_int(decision) and -(2**31) <= decision < 2**31),
            "a decision must be a 32-bit int",
        )
        if len(msg) == 5:
            return TickIn(tick, obs, inbox, decision)
        shard = msg[5]
        _expect(_is_int(shard) and 0 <= shard < MAX_SHARDS, f"a shard must be an int in 0..{MAX_SHARDS - 1}")
        return TickIn(tick, obs, inbox, decision, shard)
    if msg[0] == TAG_STOP:
        _expect(len(msg) == 2 and isinstance(msg[1], str), "stop must be [1, reason]")
        return StopIn(msg[1])
    if msg[0] in CONTROLS:
        _expect(
            len(msg) in (2, 3) and _is_int(msg[1]) and msg[1] >= 0,
            "a swap order must be [tag, incarnation] or [tag, incarnation, ticket]",
        )
        ticket = msg[2] if len(msg) == 3 else b""
        _expect(isinstance(ticket, bytes) and len(ticket) <= 64, "a ticket must be at most 64 bytes")
        return ControlIn(CONTROLS[msg[0]], msg[1], ticket)
    raise WireError(f"unknown agent input tag {msg[0]}")


# --- agent -> netem proxy -------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class AgentOut:
    tick: int
    agent_id: int
    action: list
    messages: list[RadioMessage]
    events: dict[str, int]  # what the allocator counted this tick (e.g. negotiations)


def encode_agent_out(
    tick: int, agent_id: int, action: list, messages: list[RadioMessage], events: dict[str, int] | None = None
) -> bytes:
    return pack([tick, agent_id, action, [m.to_wire() for m in messages], events or {}])


def decode_agent_out(data: bytes) -> AgentOut:
    msg = unpack(data, MAX_AGENT_SAMPLE_BYTES)
    _expect(isinstance(msg, list) and len(msg) == 5, "agent output must be [tick, id, action, messages, events]")
    tick, agent_id, action, messages, events = msg
    _expect(_is_int(tick) and tick >= 0, "tick must be a non-negative int")
    _expect(_is_int(agent_id) and agent_id >= 0, "agent id must be a non-negative int")
    _expect(isinstance(action, list) and bool(action) and isinstance(action[0], str), "action must be [name, ...]")
    _expect(isinstance(messages, list), "messages must be a list")
    _expect(
        isinstance(events, dict) and all(isinstance(k, str) and _is_int(v) for k, v in events.items()),
        "events must map names to counts",
    )
    return AgentOut(tick, agent_id, action, [_radio_from_wire(m) for m in messages], events)


# --- coordinator -> netem proxy -------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class WorldSample:
    """Positions of the agents alive at ``tick``; ``alive_next``: those still alive at tick+1."""

    tick: int
    ids: list[int]
    xs: list[float]
    ys: list[float]
    alive_next: list[int]
    incarnations: dict[int, int]  # the current process of each agent that was swapped (others: 0)

    def incarnation(self, agent: int) -> int:
        return self.incarnations.get(agent, 0)


def encode_world(w: WorldSample) -> bytes:
    return pack([w.tick, w.ids, w.xs, w.ys, w.alive_next, w.incarnations])


def decode_world(data: bytes) -> WorldSample:
    msg = unpack(data)
    _expect(isinstance(msg, list) and len(msg) == 6, "world must be [tick, ids, xs, ys, alive_next, incarnations]")
    tick, ids, xs, ys, alive_next, incarnations = msg
    _expect(
        isinstance(incarnations, dict) and all(_is_int(k) and _is_int(v) for k, v in incarnations.items()),
        "incarnations must map agent ids to numbers",
    )
    _expect(_is_int(tick) and tick >= 0, "tick must be a non-negative int")
    _expect(all(isinstance(v, list) for v in (ids, xs, ys, alive_next)), "world fields must be lists")
    _expect(len(ids) == len(xs) == len(ys), "ids, xs and ys must have one entry per agent")
    return WorldSample(tick, ids, [float(x) for x in xs], [float(y) for y in ys], alive_next, incarnations)


# --- netem proxy -> coordinator -------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class NetemStep:
    """What the proxy took at ``tick``: every agent's action, the inboxes of tick+1, counters."""

    tick: int
    actions: dict[int, list]
    inboxes: dict[int, bytes]
    counters: list[int]  # messages_sent, bytes_sent, copies, delivered, dropped (this tick)
    lost: list[int]  # agents whose process vanished while the proxy waited for them
    events: dict[str, int]  # the agents' event counts of this tick, summed
    drops: dict[str, int]  # copies dropped at this tick, by reason (those that had any)
    late: list[int]  # real-time clock: agents whose output missed this tick's deadline
    # a radio split over proxies (swarmbed.netem.radio_split): which proxy sent the step, and per
    # receiver the send tick of each item of its inbox (what the merge orders by)
    shard: int = 0
    order: dict[int, list[int]] = field(default_factory=dict)


def encode_netem_step(s: NetemStep) -> bytes:
    fields = [s.tick, s.actions, s.inboxes, s.counters, s.lost, s.events, s.drops, s.late]
    return pack(fields + [s.shard, s.order] if s.shard or s.order else fields)


def decode_netem_step(data: bytes) -> NetemStep:
    msg = unpack(data)
    _expect(
        isinstance(msg, list) and len(msg) in (8, 10),
        "netem step must be [tick, actions, inboxes, counters, lost, events, drops, late(, shard, order)]",
    )
    tick, actions, inboxes, counters, lost, events, drops, late = msg[:8]
    shard, order = msg[8:] if len(msg) == 10 else (0, {})
    _expect(_is_int(shard) and 0 <= shard < 64 and isinstance(order, dict), "bad netem step: shard or order")
    for receiver, ticks in order.items():
        _expect(_is_int(receiver) and isinstance(ticks, list) and all(map(_is_int, ticks)), "bad netem step order")
    _expect(_is_int(tick) and isinstance(actions, dict) and isinstance(inboxes, dict), "bad netem step")
    _expect(isinstance(counters, list) and len(counters) == 5 and isinstance(lost, list), "bad netem step")
    _expect(isinstance(events, dict) and isinstance(drops, dict) and isinstance(late, list), "bad netem step")
    return NetemStep(tick, actions, inboxes, counters, lost, events, drops, late, shard, order)


def encode_traffic(totals: dict[int, list[int]]) -> bytes:
    """Proxy -> watchers: agent -> [messages, payload bytes] it sent since the proxy began counting."""
    return pack(totals)


def decode_traffic(data: bytes, max_agents: int = 100_000) -> dict[int, tuple[int, int]]:
    msg = unpack(data, max_bytes=32 * max_agents)
    _expect(isinstance(msg, dict) and len(msg) <= max_agents, "traffic must be a map of agents")
    out: dict[int, tuple[int, int]] = {}
    for agent, pair in msg.items():
        _expect(
            _is_int(agent) and agent >= 0 and isinstance(pair, list) and len(pair) == 2 and all(map(_is_int, pair)),
            "traffic must map agent ids to [messages, bytes]",
        )
        out[agent] = (pair[0], pair[1])
    return out


# --- reports (maps: rare, and read by people too) ---------------------------------------------


def encode_netem_stop(last_tick: int) -> bytes:
    """Coordinator -> proxy: the run is over after ``last_tick`` (-1: before any tick)."""
    return pack([last_tick])


def decode_netem_stop(data: bytes) -> int:
    msg = unpack(data)
    _expect(
        isinstance(msg, list) and len(msg) == 1 and _is_int(msg[0]) and msg[0] >= -1, "a stop order must be [last tick]"
    )
    return msg[0]


def encode_handover(ticket: bytes, state: bytes) -> bytes:
    """A swap's snapshot as the old process hands it over: the order's ticket, then the state."""
    return pack([ticket, state])


def decode_handover(data: bytes) -> tuple[bytes, bytes]:
    msg = unpack(data, MAX_AGENT_SAMPLE_BYTES)
    _expect(
        isinstance(msg, list) and len(msg) == 2 and all(isinstance(m, bytes) for m in msg),
        "a snapshot handover must be [ticket, state]",
    )
    return msg[0], msg[1]
