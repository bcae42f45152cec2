"""CBBA's consensus state, shared by every CBBA-family allocator: winning bids ``y``, winners ``z``,
information timestamps ``s`` (simulated time), the receiver action table (Choi, Brunet, How 2009,
Table 1, all 17 cases), and the bundle release of Eqs. 6-7.

Messages carry the whole state (every winner, bid and timestamp the agent knows) unless
``full_every`` > 1: then every ``full_every``-th message does, and those between carry only what
changed since the message before (``"d": 1``; a winner dropped travels as ``NONE``), unless that
names as many entries as the whole state (rounds far apart: everything changed), which then goes.
A receiver applies Table 1 to the tasks a delta names and takes an agent a delta does not name as no news
about it. A neighbour that missed a message, or came into range, is whole again at the next full
one. The full messages are byte for byte those of ``full_every = 1``.

On the wire a message is ``{"t": stamp, WINNERS, STAMPS}`` (``"d": 1`` for a delta), its vectors
packed arrays of declared little-endian dtypes, each under the key of the narrowest that holds it
exactly (an empty one left out) (:data:`WINNER_KEYS`: task uint16 or uint32, winner int8 or int16, bid float64;
:data:`STAMP_KEYS`: agent int8 or int16, stamp uint16 or int32 where every stamp is whole, else
float64), as a robot would send them: a receiver reads them without a Python
object per entry, and anything that is not such an array (a torn or crafted message) is read as
naming nothing. :func:`consensus_message` and
:func:`read_message` build and read one."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np

from swarmbed.plugins.packed import pack_rows, read_tuples
from swarmbed.wire.state import state_type

NONE = -1
_NEVER = -math.inf

#: one winner entry of a message: the task, the agent believed to win it (NONE: a winner dropped,
#: in a delta), its winning bid (float64 always: a bid is compared exactly)
WINNER_DTYPE = np.dtype([("task", "<u4"), ("winner", "<i2"), ("bid", "<f8")])
#: one information timestamp of a message: the agent, the simulated time of the latest news of it
STAMP_DTYPE = np.dtype([("agent", "<i2"), ("stamp", "<f8")])
#: each vector's keys and declared dtypes, narrowest first: a message carries a vector under the
#: first key whose dtype holds every entry exactly (ids below 128 or 65,536, whole-second stamps), and
#: leaves an empty one out; one-letter keys, as every byte of a message is counted
WINNER_KEYS = (
    ("w", np.dtype([("task", "<u2"), ("winner", "i1"), ("bid", "<f8")])),
    ("v", np.dtype([("task", "<u2"), ("winner", "<i2"), ("bid", "<f8")])),
    ("u", WINNER_DTYPE),
)
STAMP_KEYS = (
    ("s", np.dtype([("agent", "i1"), ("stamp", "<u2")])),
    ("r", np.dtype([("agent", "<i2"), ("stamp", "<u2")])),
    ("q", np.dtype([("agent", "<i2"), ("stamp", "<i4")])),
    ("p", STAMP_DTYPE),
)


def _read(data: dict, keys: tuple[tuple[str, np.dtype], ...]) -> list[tuple]:
    """The entries under the first of ``keys`` the message has, or none for anything that is not a
    packed vector (a torn or crafted message)."""
    for key, dtype in keys:
        if key in data:
            return read_tuples(data[key], dtype)
    return []


def consensus_message(
    t: float, winners: Sequence[tuple] = (), stamps: Sequence[tuple] = (), delta: bool = False
) -> dict:
    """A message as it goes out: ``winners`` as (task, winner, bid), ``stamps`` as (agent, stamp)."""
    out: dict[str, Any] = {"t": _compact(t)}
    if delta:
        out["d"] = 1
    for rows, keys in ((winners, WINNER_KEYS), (stamps, STAMP_KEYS)):
        if rows:  # an empty vector is left out
            key, packed = pack_rows(rows, keys)
            out[key] = packed
    return out


def read_message(data: Any) -> tuple[float, list[tuple[int, int, float]], list[tuple[int, float]], bool]:
    """(stamp, winners, stamps, is a delta) of a message, as Python values."""
    return data["t"], _read(data, WINNER_KEYS), _read(data, STAMP_KEYS), bool(data.get("d"))


def _compact(t: float) -> float | int:
    """A whole-second timestamp travels as an int (1-5 msgpack bytes instead of 9); same value."""
    return int(t) if float(t).is_integer() else t


def better(y1: float, z1: int, y2: float, z2: int) -> bool:
    """Bid (y1 by z1) beats bid (y2 by z2): higher, or equal and by the lower agent id."""
    return y1 > y2 or (y1 == y2 and z1 < z2)


def table(i: int, k: int, zk: int, yk: float, zi: int, yi: float, compare: Callable[[int], int]) -> str:
    """Receiver i's action on one task, given sender k's belief (zk, yk) and its own (zi, yi):
    "update", "reset" or "leave". ``compare(m)`` > 0 when k's information about agent m is newer
    than i's (s_km > s_im), < 0 when older."""

    def newer(m: int) -> bool:
        return compare(m) > 0

    if zk == k:  # sender thinks it wins
        if zi == i:
            return "update" if better(yk, k, yi, i) else "leave"  # 1
        if zi in (k, NONE):
            return "update"  # 2, 4
        return "update" if newer(zi) or better(yk, k, yi, zi) else "leave"  # 3
    if zk == i:  # sender thinks the receiver wins
        if zi == k:
            return "reset"  # 6
        if zi not in (i, NONE) and newer(zi):
            return "reset"  # 7
        return "leave"  # 5, 7, 8
    if zk == NONE:  # sender thinks nobody wins
        if zi == k:
            return "update"  # 15
        if zi not in (i, NONE) and newer(zi):
            return "update"  # 16
        return "leave"  # 14, 16, 17
    m = zk  # sender thinks a third agent m wins
    if zi == i:
        return "update" if newer(m) and better(yk, m, yi, i) else "leave"  # 9
    if zi == k:
        return "update" if newer(m) else "reset"  # 10
    if zi in (m, NONE):
        return "update" if newer(m) else "leave"  # 11, 13
    n = zi  # 12: receiver thinks a fourth agent n wins
    if newer(m) and (newer(n) or better(yk, m, yi, n)):
        return "update"
    if newer(n) and compare(m) < 0:
        return "reset"
    return "leave"


@state_type
class ConsensusState:
    """One agent's CBBA knowledge and bundle."""

    def __init__(self, agent_id: int, full_every: int = 1) -> None:
        self.agent_id = agent_id
        self.full_every = full_every
        self.y: dict[int, float] = {}
        self.z: dict[int, int] = {}
        self.s: dict[int, float] = {}  # agent -> simulated time of the latest information from it
        self.bundle: list[int] = []
        self.path: list[int] = []
        self.now = 0.0
        self.sent = 0  # messages made
        self.told: dict[int, tuple[int, float]] = {}  # task -> (winner, bid) as the last message had it
        self.told_s: dict[int, float] = {}  # agent -> timestamp as the last message had it
        self.bid_on: set[int] = set()  # tasks this agent bid on since its knowledge was last cleared

    def message(self) -> dict:
        """The state for neighbours: whole, or (``full_every`` > 1) what changed since the last one."""
        due_whole = self.sent % self.full_every == 0
        self.sent += 1
        if self.full_every == 1:
            return self._whole()
        winners = {t: (self.z[t], self.y[t]) for t in self.z}
        delta = None
        if not due_whole:
            told, told_s = self.told, self.told_s
            changed = [(t, w, b) for t, (w, b) in winners.items() if told.get(t) != (w, b)]
            dropped = [(t, NONE, 0.0) for t in told.keys() - winners.keys()]
            stamps = [(a, ts) for a, ts in sorted(self.s.items()) if told_s.get(a) != ts]
            if len(changed) + len(dropped) + len(stamps) < len(winners) + len(self.s):  # else whole is smaller
                delta = consensus_message(self.now, sorted(changed + dropped), stamps, delta=True)
        self.told, self.told_s = winners, dict(self.s)
        return delta or self._whole()

    def _whole(self) -> dict:
        z, y = self.z, self.y
        return consensus_message(self.now, [(t, z[t], y[t]) for t in sorted(z)], sorted(self.s.items()))

    def receive(self, sender: int, data: dict, ignore: Iterable[int] = (), within: set[int] | None = None) -> None:
        """Apply Table 1 to every task in a neighbour's message, then merge its timestamps.

        ``within`` (SPACE's code's scope, CBBA's ``consensus_scope: local_bids``): apply it only to
        the tasks in ``within`` that the message names, leaving alone those the sender holds no
        winner for."""
        i, k = self.agent_id, sender
        if not isinstance(data, dict) or not isinstance(data.get("t"), (int, float)):
            return  # not a message of ours: nothing in it
        delta = bool(data.get("d"))
        entries = _read(data, WINNER_KEYS)
        if any(a[0] >= b[0] for a, b in zip(entries, entries[1:])):  # ours are sorted, each task once
            first: dict[int, tuple] = {}
            for entry in entries:
                first.setdefault(entry[0], entry)  # a task named twice: the first entry counts
            entries = [first[t] for t in sorted(first)]
        z, y = self.z, self.y
        # the tasks whose belief differs from ours (identical entries leave every table case unchanged):
        # a delta names only the tasks it changes (NONE: a winner the sender dropped); a whole message
        # also differs on every task we hold that it does not name
        zget, yget = z.get, y.get
        theirs = {t: (wk, bk) for t, wk, bk in entries if zget(t, NONE) != wk or yget(t, 0.0) != bk}
        differing = set(theirs)
        if not delta:
            named = {e[0] for e in entries}
            differing.update(t for t in z if t not in named)
        if within is not None:
            differing = {t for t in differing if t in within and t in theirs}
        sk: dict[int, float] = dict(_read(data, STAMP_KEYS))
        sk[k] = data["t"]
        skip = ignore if isinstance(ignore, (set, frozenset)) else set(ignore)

        def compare(m: int) -> int:
            mine = self.now if m == i else self.s.get(m, _NEVER)
            their = sk.get(m, mine if delta else _NEVER)  # a delta says nothing new of an agent it leaves out
            return (their > mine) - (their < mine)

        for j in sorted(differing):
            if j in skip:
                continue
            zk, yk = theirs.get(j, (NONE, 0.0))
            zi, yi = z.get(j, NONE), y.get(j, 0.0)
            if zk == zi and yk == yi:
                continue
            action = table(i, k, zk, yk, zi, yi, compare)
            if action == "update":
                if zk == NONE:
                    self.reset(j)
                else:
                    self.z[j], self.y[j] = zk, yk
            elif action == "reset":
                self.reset(j)
        known = self.s.get
        newer = {m: ts for m, ts in sk.items() if ts > known(m, _NEVER)}
        newer.pop(i, None)
        self.s.update(newer)

    def reset(self, task: int) -> None:
        self.z.pop(task, None)
        self.y.pop(task, None)

    def forget(self, task: int) -> None:
        """The task is gone (done): drop it everywhere."""
        self.reset(task)
        self.bid_on.discard(task)
        if task in self.bundle:
            self.bundle.remove(task)
            self.path.remove(task)

    def release(self) -> int:
        """Eqs. 6-7: from the first task this agent no longer wins, the bundle is cut; the tasks
        after that one had bids that depended on it, so their bids and winners are reset.
        Returns how many bundle tasks were lost to other agents' bids."""
        for n, task in enumerate(self.bundle):
            if self.z.get(task) != self.agent_id:
                for later in self.bundle[n + 1 :]:
                    if self.z.get(later) == self.agent_id:
                        self.reset(later)
                cut = set(self.bundle[n:])
                self.bundle = self.bundle[:n]
                self.path = [t for t in self.path if t not in cut]
                return 1
        return 0

    def add(self, task: int, bid: float, position: int | None = None) -> None:
        self.bundle.append(task)
        self.bid_on.add(task)
        self.path.insert(len(self.path) if position is None else position, task)
        self.y[task] = bid
        self.z[task] = self.agent_id

    def eligible(self, task: int, bid: float) -> bool:
        """Algorithm 3's h_ij: the bid beats the known winning bid (ties to the lower id)."""
        known = self.y.get(task, 0.0)
        return bid > known or (bid == known and self.agent_id < self.z.get(task, self.agent_id + 1))

    def drop_stale_winners(self, older_than: float) -> None:
        """Forget wins by agents not heard from since ``older_than`` (lost agents stop mattering).
        Called every tick over every known win: the few distinct winners are checked first, and the
        wins are walked only when one of them has gone quiet."""
        heard = self.s.get
        stale = {w for w in set(self.z.values()) if w != self.agent_id and heard(w, _NEVER) < older_than}
        if stale:
            for task in [t for t, w in self.z.items() if w in stale]:
                self.reset(task)
