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
import operator
from collections.abc import Callable, Iterable, Iterator, MutableMapping, Sequence
from typing import Any

import numpy as np

from swarmbed import kernels
from swarmbed.plugins.packed import pack_columns, pack_rows, read_array, read_tuples
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


def _first_vector(data: dict, keys: tuple[tuple[str, np.dtype], ...]) -> tuple[int, Any]:
    """Which of ``keys`` (its index) a message carries a vector under, the first it has, and that
    vector as it came; (-1, None) where it has none."""
    for n, (key, _dtype) in enumerate(keys):
        if key in data:
            return n, data[key]
    return -1, None


def _read(data: dict, keys: tuple[tuple[str, np.dtype], ...]) -> list[tuple]:
    """The entries under the first of ``keys`` the message has, or none for anything that is not a
    packed vector (a torn or crafted message)."""
    n, raw = _first_vector(data, keys)
    return read_tuples(raw, keys[n][1]) if n >= 0 else []


def consensus_message(
    t: float,
    winners: Sequence[tuple] = (),
    stamps: Sequence[tuple] = (),
    delta: bool = False,
    stamp_columns: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict:
    """A message as it goes out: ``winners`` as (task, winner, bid), ``stamps`` as (agent, stamp)
    rows, or ``stamp_columns`` as (agents, stamps) arrays."""
    out: dict[str, Any] = {"t": _compact(t)}
    if delta:
        out["d"] = 1
    if winners:  # an empty vector is left out
        compiled = kernels.pack_winners(winners) if kernels.pack_winners is not None else None
        key, packed = compiled or pack_rows(winners, WINNER_KEYS)
        out[key] = packed
    if stamp_columns is not None and len(stamp_columns[0]):
        compiled = kernels.pack_stamps(*stamp_columns) if kernels.pack_stamps is not None else None
        key, packed = compiled or pack_columns(stamp_columns, STAMP_KEYS)
        out[key] = packed
    elif stamps:
        key, packed = pack_rows(stamps, STAMP_KEYS)
        out[key] = packed
    return out


def read_message(data: Any) -> tuple[float, list[tuple[int, int, float]], list[tuple[int, float]], bool]:
    """(stamp, winners, stamps, is a delta) of a message, as Python values."""
    return data["t"], _read(data, WINNER_KEYS), _read(data, STAMP_KEYS), bool(data.get("d"))


def _compact(t: float) -> float | int:
    """A whole-second timestamp travels as an int (1-5 msgpack bytes instead of 9); same value."""
    return int(t) if float(t).is_integer() else t


def winners_of(z: dict[int, int], y: dict[int, float]) -> dict[int, tuple[int, float]]:
    """The map task -> (winner, bid) of ``z`` and ``y``, in ``z``'s order."""
    return {t: (z[t], y[t]) for t in z}


def winners_changed(
    z: dict[int, int], y: dict[int, float], told: dict[int, tuple[int, float]]
) -> tuple[dict[int, tuple[int, float]], list[tuple[int, int, float]]]:
    """The map task -> (winner, bid) of ``z`` and ``y``, in ``z``'s order, and the (task, winner,
    bid) entries that differ from ``told``'s (the last message's); ``swarmbed.kernels`` has it
    compiled."""
    winners = winners_of(z, y)
    return winners, [(t, w, b) for t, (w, b) in winners.items() if told.get(t) != (w, b)]


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


def better_masks(y1: np.ndarray, z1: Any, y2: np.ndarray, z2: Any) -> np.ndarray:
    """:func:`better` over arrays."""
    return (y1 > y2) | ((y1 == y2) & (z1 < z2))


def table_masks(
    i: int,
    k: int,
    zk: np.ndarray,
    yk: np.ndarray,
    zi: np.ndarray,
    yi: np.ndarray,
    newer_m: np.ndarray,
    older_m: np.ndarray,
    newer_n: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`table` over many tasks at once: (update, reset) as masks. ``newer_m``/``older_m``:
    ``compare(zk)`` > 0 / < 0 per task; ``newer_n``: ``compare(zi)`` > 0. The cases are tested in
    :func:`table`'s order, so that each task takes the action :func:`table` gives it; an update to
    nobody (``zk`` NONE) comes back as the reset it is."""
    a = zk == k  # sender thinks it wins
    b = ~a & (zk == i)  # sender thinks the receiver wins
    c = ~a & ~b & (zk == NONE)  # sender thinks nobody wins
    d = ~(a | b | c)  # a third agent m = zk
    zi_i, zi_k, zi_none = zi == i, zi == k, zi == NONE
    fourth = ~zi_i & ~zi_none  # zi not in (i, NONE)
    update = a & np.where(zi_i, better_masks(yk, k, yi, i), zi_k | zi_none | newer_n | better_masks(yk, k, yi, zi))
    reset = (b | c) & (zi_k | (fourth & newer_n))  # 6, 7; 15, 16 (an update to nobody is a reset)
    d_i = d & zi_i  # 9
    d_k = d & ~zi_i & zi_k  # 10
    d_m = d & ~zi_i & ~zi_k & ((zi == zk) | zi_none)  # 11, 13
    d_n = d & ~(zi_i | zi_k | (zi == zk) | zi_none)  # 12
    up_n = newer_m & (newer_n | better_masks(yk, zk, yi, zi))
    update |= (d_i & newer_m & better_masks(yk, zk, yi, i)) | ((d_k | d_m) & newer_m) | (d_n & up_n)
    reset |= (d_k & ~newer_m) | (d_n & ~up_n & newer_n & older_m)
    return update, reset


#: below this many tasks to decide, the Python receive runs Table 1 task by task (building arrays
#: for numpy's masks costs more than it saves); the compiled receive (``kernels.receive``)
#: decides every task in C
FEW_TASKS = 24


class Stamps(MutableMapping):
    """A consensus state's information timestamps as a map agent -> stamp, over its array (for
    tests and plugins that read or set a few; the state itself works on the array)."""

    def __init__(self, state: ConsensusState) -> None:
        self._state = state

    def __getitem__(self, agent: int) -> float:
        s = self._state.stamps
        if not (isinstance(agent, (int, np.integer)) and 0 <= agent < len(s)) or s[agent] == _NEVER:
            raise KeyError(agent)
        return float(s[agent])

    def __setitem__(self, agent: int, stamp: float) -> None:
        self._state.hear(np.array([agent]), np.array([stamp], dtype=float))

    def __delitem__(self, agent: int) -> None:
        self[agent]  # noqa: B018 (KeyError where it is unknown)
        self._state.stamps[agent] = _NEVER

    def __iter__(self) -> Iterator[int]:
        return iter(np.flatnonzero(self._state.stamps > _NEVER).tolist())

    def __len__(self) -> int:
        return int(np.count_nonzero(self._state.stamps > _NEVER))


def _stamp_array(data: dict) -> tuple[np.ndarray, np.ndarray]:
    """(agents, stamps) a message names, as arrays; an agent named twice keeps its last stamp (a
    map of them would), a negative agent id (no agent has one: a crafted message) is no news."""
    n, raw = _first_vector(data, STAMP_KEYS)
    rows = read_array(raw, STAMP_KEYS[n][1]) if n >= 0 else None
    if rows is None:
        return np.zeros(0, np.int64), np.zeros(0)
    agents, stamps = rows["agent"].astype(np.int64), rows["stamp"].astype(float)
    if len(agents) > 1 and not (agents[1:] > agents[:-1]).all():  # ours are sorted, each once
        last = len(agents) - 1 - np.unique(agents[::-1], return_index=True)[1]
        agents, stamps = agents[last], stamps[last]
    keep = agents >= 0
    return (agents, stamps) if keep.all() else (agents[keep], stamps[keep])


@state_type
class ConsensusState:
    """One agent's CBBA knowledge and bundle. Winners and bids are maps over the tasks it knows of;
    the information timestamps an array over agent ids (``-inf``: never heard of), as every
    message names every agent heard of and a receiver compares and merges them all."""

    def __init__(self, agent_id: int, full_every: int = 1) -> None:
        self.agent_id = agent_id
        self.full_every = full_every
        self.y: dict[int, float] = {}
        self.z: dict[int, int] = {}
        #: agent -> simulated time of the latest information from it (never its own: that is ``now``)
        self.stamps = np.full(agent_id + 1, _NEVER)
        self.bundle: list[int] = []
        self.path: list[int] = []
        self.now = 0.0
        self.sent = 0  # messages made
        self.told: dict[int, tuple[int, float]] = {}  # task -> (winner, bid) as the last message had it
        self.told_s = np.full(0, _NEVER)  # the timestamps as the last message had them
        self.bid_on: set[int] = set()  # tasks this agent bid on since its knowledge was last cleared

    @property
    def s(self) -> Stamps:
        """The timestamps as a map agent -> stamp."""
        return Stamps(self)

    def _cover(self, top: int) -> None:
        """Grow the timestamps to hold agent ids up to ``top``."""
        if top >= len(self.stamps):
            self.stamps = np.concatenate([self.stamps, np.full(top + 1 - len(self.stamps), _NEVER)])

    def hear(self, agents: np.ndarray, stamps: np.ndarray) -> None:
        """Take each stamp newer than the one known (never one of this agent's own)."""
        if len(agents):
            self._cover(int(agents.max()))
            known = self.stamps[agents]
            newer = (stamps > known) & (agents != self.agent_id)
            self.stamps[agents[newer]] = stamps[newer]

    def _known_stamps(self) -> tuple[np.ndarray, np.ndarray]:
        agents = np.flatnonzero(self.stamps > _NEVER)
        return agents, self.stamps[agents]

    def message(self) -> dict:
        """The state for neighbours: whole, or (``full_every`` > 1) what changed since the last one."""
        due_whole = self.sent % self.full_every == 0
        self.sent += 1
        if self.full_every == 1:
            return self._whole()
        delta = None
        if due_whole:  # what it tells becomes the base of the next deltas; nothing to compare
            winners = winners_of(self.z, self.y)
        else:
            winners, changed = (kernels.winners_changed or winners_changed)(self.z, self.y, self.told)
            told = self.told
            dropped = [(t, NONE, 0.0) for t in told.keys() - winners.keys()]
            told_s = np.full(len(self.stamps), _NEVER)
            told_s[: len(self.told_s)] = self.told_s[: len(self.stamps)]
            agents = np.flatnonzero((self.stamps > _NEVER) & (self.stamps != told_s))
            if len(changed) + len(dropped) + len(agents) < len(winners) + len(self.s):
                delta = consensus_message(
                    self.now, sorted(changed + dropped), delta=True, stamp_columns=(agents, self.stamps[agents])
                )
        self.told, self.told_s = winners, self.stamps.copy()
        return delta or self._whole()

    def _whole(self) -> dict:
        z, y = self.z, self.y
        return consensus_message(self.now, [(t, z[t], y[t]) for t in sorted(z)], stamp_columns=self._known_stamps())

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
        tasks = [e[0] for e in entries]
        if not all(map(operator.lt, tasks, tasks[1:])):  # ours are sorted, each task once
            first: dict[int, tuple] = {}
            for entry in entries:
                first.setdefault(entry[0], entry)  # a task named twice: the first entry counts
            entries = [first[t] for t in sorted(first)]
            tasks = [e[0] for e in entries]
        skip = ignore if isinstance(ignore, (set, frozenset)) else set(ignore)
        if kernels.receive is not None:  # compiled: the same steps as below, in C
            layout, raw = _first_vector(data, STAMP_KEYS)
            self.stamps = kernels.receive(
                i, k, self.now, float(data["t"]), delta, self.stamps, raw, layout, self.z, self.y, entries, skip, within
            )
            return
        # the sender's timestamps over agent ids: every agent it names, itself at the message's time;
        # an agent a delta leaves out is no news (its stamp as ours), one a whole message leaves out never heard of
        agents, stamps = _stamp_array(data)
        self._cover(max(k, int(agents.max()) if len(agents) else 0))
        mine = np.append(self.stamps, _NEVER)  # the last entry: any id we hold no stamp for
        mine[i] = self.now
        their = mine.copy() if delta else np.full(len(mine), _NEVER)
        their[agents] = stamps
        their[k] = data["t"]
        their[-1] = mine[-1] = _NEVER
        self._receive_tasks(entries, tasks, delta, skip, within, mine, their, k)
        their[i] = _NEVER  # never news of ourselves
        their = their[:-1]
        self.stamps = np.where(their > self.stamps, their, self.stamps)  # a NaN stamp is no news

    def _receive_tasks(
        self,
        entries: list[tuple],
        tasks: list[int],
        delta: bool,
        skip: set[int] | frozenset[int],
        within: set[int] | None,
        mine: np.ndarray,
        their: np.ndarray,
        k: int,
    ) -> None:
        """Table 1 on the tasks of a message (``entries``: sorted, each task once) whose belief
        differs from ours; the Python that ``swarmbed.kernels.receive`` is compared with."""
        z, y = self.z, self.y
        # the tasks whose belief differs from ours (identical entries leave every table case unchanged):
        # a delta names only the tasks it changes (NONE: a winner the sender dropped); a whole message
        # also differs on every task we hold that it does not name
        zget, yget = z.get, y.get
        theirs = {t: (wk, bk) for t, wk, bk in entries if zget(t, NONE) != wk or yget(t, 0.0) != bk}
        differing = set(theirs)
        if not delta:
            named = set(tasks)
            differing.update(t for t in z if t not in named)
        if within is not None:
            differing = {t for t in differing if t in within and t in theirs}
        order = [j for j in sorted(differing) if j not in skip]
        if order:
            self._decide(order, theirs, mine, their, k)

    def _decide(
        self, order: list[int], theirs: dict[int, tuple[int, float]], mine: np.ndarray, their: np.ndarray, k: int
    ) -> None:
        """Table 1 on each task of ``order`` (sorted), with the sender's belief ``theirs`` (a task it
        does not name: nobody wins) and both sides' timestamps over agent ids (``mine``, ``their``:
        the last entry stands for any agent either holds none for)."""
        i, z, y = self.agent_id, self.z, self.y
        out = len(mine) - 1
        if len(order) >= FEW_TASKS:
            self._decide_over_arrays(order, theirs, mine, their, k)
            return
        m_list, t_list = mine.tolist(), their.tolist()

        def compare(m: int) -> int:
            at = m if 0 <= m < out else out
            return (t_list[at] > m_list[at]) - (t_list[at] < m_list[at])

        for j in order:
            zk, yk = theirs.get(j, (NONE, 0.0))
            zi, yi = z.get(j, NONE), y.get(j, 0.0)
            if zk == zi and yk == yi:
                continue
            action = table(i, k, zk, yk, zi, yi, compare)
            if action == "update" and zk != NONE:
                z[j], y[j] = zk, yk
            elif action != "leave":
                self.reset(j)

    def _decide_over_arrays(
        self, order: list[int], theirs: dict[int, tuple[int, float]], mine: np.ndarray, their: np.ndarray, k: int
    ) -> None:
        """:meth:`_decide` for many tasks, Table 1 as numpy masks (:func:`table_masks`)."""
        i, z, y, out = self.agent_id, self.z, self.y, len(mine) - 1
        beliefs = [theirs.get(j, (NONE, 0.0)) for j in order]
        wk = np.array([w for w, _ in beliefs], dtype=np.int64)
        bk = np.array([b for _, b in beliefs], dtype=float)
        wi = np.array([z.get(j, NONE) for j in order], dtype=np.int64)
        bi = np.array([y.get(j, 0.0) for j in order], dtype=float)
        at_m = np.where((wk >= 0) & (wk < out), wk, out)
        at_n = np.where((wi >= 0) & (wi < out), wi, out)
        newer_m, older_m = their[at_m] > mine[at_m], their[at_m] < mine[at_m]
        newer_n = their[at_n] > mine[at_n]
        update, reset = table_masks(i, k, wk, bk, wi, bi, newer_m, older_m, newer_n)
        same = (wk == wi) & (bk == bi)
        update &= ~same
        reset = (reset | (update & (wk == NONE))) & ~same
        update &= wk != NONE
        for n in np.flatnonzero(update | reset).tolist():
            j = order[n]
            if update[n]:
                z[j], y[j] = int(wk[n]), float(bk[n])
            else:
                self.reset(j)

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
        heard, out = self.stamps, len(self.stamps)
        stale = {
            w
            for w in set(self.z.values())
            if w != self.agent_id and (heard[w] if 0 <= w < out else _NEVER) < older_than
        }
        if stale:
            for task in [t for t, w in self.z.items() if w in stale]:
                self.reset(task)
