"""The radio model: decides, per message and per intended receiver, what happens to each copy.

Pure and deterministic: given the same parameters, seed, positions and messages, it books the same
ledger and delivers the same inboxes. The proxy process drives it; tests drive it directly too.

Order of the checks for one message sent at tick k (a copy gets the first reason that applies):

1. addressing: a receiver that is not an agent of the run (or is the sender) -> ``no_such_receiver``;
   one that is not alive at tick k -> ``receiver_dead``.
2. sender queue (tc-netem ``limit``): if ``limit`` messages already wait behind the rate cap, the
   whole message is tail-dropped -> ``queue_full`` for every copy.
3. range: distance between sender and receiver at tick k greater than ``range`` -> ``out_of_range``.
4. loss: an independent Bernoulli draw per copy -> ``loss``.

On the real-time clock a sample that reaches the proxy after its tick's deadline is not routed:
every copy of its messages is ``late`` (:meth:`Radio.late`).

A message that survives is scheduled. With a ``rate`` cap it is transmitted after the ones queued
before it, taking ``size / rate`` seconds; idle time earns no credit (tc-netem ``rate``). It is
delivered at the first tick at or after the end of its transmission, never before k+1, plus
``latency`` ticks. At delivery, a receiver that died meanwhile -> ``receiver_dead``.
"""

from __future__ import annotations

import math
from collections import defaultdict, deque
from collections.abc import Iterable, Mapping, Sequence
from typing import NamedTuple

import numpy as np

from swarmbed.netem.ledger import DELIVERED, Ledger
from swarmbed.wire.codec import BROADCAST, RadioMessage
from swarmbed.wire.schema import NetworkSection

_EPS = 1e-9


def _per_segment(flags: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """How many of ``flags[bounds[i]:bounds[i + 1]]`` are set, for every i (empty segments too)."""
    total = np.concatenate(([0], np.cumsum(flags, dtype=np.int64)))
    return total[bounds[1:]] - total[bounds[:-1]]


class _Send(NamedTuple):
    """One message on its way through :meth:`Radio.route`."""

    sender: int
    sender_row: int
    msg: RadioMessage
    intended: int  # copies: one per intended receiver
    drops: list[tuple[str, np.ndarray]]  # copies dropped before range and loss: (reason, receivers)
    rows: np.ndarray  # the receivers (rows of the sorted alive ids) still in play
    end: float  # end of its transmission, in seconds


class Radio:
    def __init__(
        self, params: NetworkSection, n_agents: int, dt: float, rng: np.random.Generator, ledger: Ledger | None = None
    ) -> None:
        self.params = params
        self.n_agents = n_agents
        self.dt = dt
        self.rng = rng
        self.ledger = ledger if ledger is not None else Ledger()
        self._busy_until: dict[int, float] = defaultdict(float)
        self._in_queue: dict[int, deque[float]] = defaultdict(deque)  # transmission end times
        # delivery tick -> [(receivers, sender, kind, payload, send_tick)]
        self._pending: dict[int, list[tuple[np.ndarray, int, str, bytes, int]]] = defaultdict(list)
        # (tick, sender, kind, size, receivers delivered to, receivers found dead)
        self._unconfirmed: list[tuple[int, int, str, int, np.ndarray, np.ndarray]] = []

    @property
    def pending_copies(self) -> int:
        """Copies scheduled or handed out but not yet booked."""
        scheduled = sum(len(r) for entries in self._pending.values() for r, *_ in entries)
        return scheduled + sum(len(d) + len(x) for *_, d, x in self._unconfirmed)

    def route(
        self,
        tick: int,
        ids: Sequence[int],
        xs: Sequence[float],
        ys: Sequence[float],
        outs: Mapping[int, Iterable[RadioMessage]],
    ) -> None:
        """Take every message sent at ``tick``. ``ids``/``xs``/``ys``: agents alive at ``tick``.

        Three passes: each message is addressed and queued (Python, per message); range and loss
        are decided for every copy of the tick at once (arrays; the loss draws come from ``rng``
        in message order, then receiver order, as one message at a time would draw them); then
        each message is booked, in order, and what survives is scheduled."""
        order = np.argsort(np.asarray(ids, dtype=np.int64), kind="stable")
        alive = np.asarray(ids, dtype=np.int64)[order]
        every_row = np.arange(len(alive))
        row_of = dict(zip(alive.tolist(), every_row.tolist()))
        sends: list[_Send] = []
        for sender in sorted(outs):
            sender_row = row_of.get(sender)
            for msg in outs[sender]:
                if sender_row is None:
                    raise KeyError(f"agent {sender} sent at tick {tick} but is not alive then")
                sends.append(self._address(tick, sender, sender_row, msg, alive, row_of, every_row))
        if not sends:
            return
        counts = np.fromiter((len(s.rows) for s in sends), dtype=np.int64, count=len(sends))
        rows = np.concatenate([s.rows for s in sends])
        in_range = np.ones(len(rows), dtype=bool)
        if self.params.range is not None and len(rows):
            x = np.asarray(xs, dtype=float)[order]
            y = np.asarray(ys, dtype=float)[order]
            from_rows = np.repeat(np.fromiter((s.sender_row for s in sends), dtype=np.int64, count=len(sends)), counts)
            reach = self.params.range + _EPS
            in_range = np.hypot(x[from_rows] - x[rows], y[from_rows] - y[rows]) <= reach
        kept = in_range.copy()
        if self.params.loss > 0.0:
            kept[in_range] = self.rng.random(int(np.count_nonzero(in_range))) >= self.params.loss
        self._book_and_schedule(tick, sends, counts, alive, rows, in_range, kept)

    def _address(
        self,
        tick: int,
        sender: int,
        sender_row: int,
        msg: RadioMessage,
        alive: np.ndarray,
        row_of: dict[int, int],
        every_row: np.ndarray,
    ) -> _Send:
        """A message's intended receivers (as rows of ``alive``, the sorted ids; ``row_of`` maps an
        id to its row) that may still get a copy, the copies already dropped (addressing, the
        sender's queue) and the end of its transmission."""
        drops: list[tuple[str, np.ndarray]] = []
        if msg.dest == BROADCAST:
            rows = np.concatenate((every_row[:sender_row], every_row[sender_row + 1 :]))
            intended = len(rows)
        else:
            wanted = msg.dest if isinstance(msg.dest, tuple) else (msg.dest,)
            intended = len(wanted)
            ok = []
            for r in wanted:
                if r == sender or not 0 <= r < self.n_agents:
                    drops.append(("no_such_receiver", np.array([r], dtype=np.int64)))
                elif (row := row_of.get(r)) is None:
                    drops.append(("receiver_dead", np.array([r], dtype=np.int64)))
                else:
                    ok.append(row)
            rows = np.asarray(ok, dtype=np.int64)
        p = self.params
        end = t_now = tick * self.dt
        if p.rate is not None:
            queue = self._in_queue[sender]
            while queue and queue[0] <= t_now + _EPS:
                queue.popleft()
            if p.limit is not None and len(queue) >= p.limit:
                drops.append(("queue_full", alive[rows]))
                return _Send(sender, sender_row, msg, intended, drops, rows[:0], end)
            end = max(t_now, self._busy_until[sender]) + len(msg.payload) / p.rate
            self._busy_until[sender] = end
            queue.append(end)
        return _Send(sender, sender_row, msg, intended, drops, rows, end)

    def _book_and_schedule(
        self,
        tick: int,
        sends: list[_Send],
        counts: np.ndarray,
        alive: np.ndarray,
        rows: np.ndarray,
        in_range: np.ndarray,
        kept: np.ndarray,
    ) -> None:
        ledger, per_receiver = self.ledger, self.ledger.per_receiver
        bounds = np.concatenate(([0], np.cumsum(counts)))
        n_far, n_kept = _per_segment(~in_range, bounds), _per_segment(kept, bounds)
        kept_ids = np.split(alive[rows[kept]], np.cumsum(n_kept)[:-1])
        starts, copies, fars, keeps = bounds.tolist(), counts.tolist(), n_far.tolist(), n_kept.tolist()
        for i, send in enumerate(sends):
            kind, size = send.msg.kind, len(send.msg.payload)
            ledger.sent(tick, send.sender, kind, size, send.intended)
            for reason, to in send.drops:
                ledger.book(tick, send.sender, kind, size, reason, len(to), to)
            if not copies[i]:
                continue
            far, lost = fars[i], copies[i] - fars[i] - keeps[i]
            a, b = starts[i], starts[i + 1]
            if far:
                ledger.book(
                    tick,
                    send.sender,
                    kind,
                    size,
                    "out_of_range",
                    far,
                    alive[rows[a:b][~in_range[a:b]]] if per_receiver else None,
                )
            if lost:
                ledger.book(
                    tick,
                    send.sender,
                    kind,
                    size,
                    "loss",
                    lost,
                    alive[rows[a:b][in_range[a:b] & ~kept[a:b]]] if per_receiver else None,
                )
            if keeps[i]:
                due = max(tick + 1, math.ceil(send.end / self.dt - _EPS)) + self.params.latency
                self._pending[due].append((kept_ids[i], send.sender, kind, send.msg.payload, tick))

    def late(self, book_at: int, sender: int, messages: Iterable[RadioMessage], alive: Sequence[int]) -> None:
        """Messages of a sample that reached the proxy after its tick's deadline (real-time clock):
        each is sent and every copy (one per intended receiver among ``alive``, the agents alive
        at the tick it was meant for) dropped as ``late``, booked at tick ``book_at``."""
        ledger = self.ledger
        for msg in messages:
            size = len(msg.payload)
            if msg.dest == BROADCAST:
                to = [int(a) for a in alive if a != sender]
            else:
                to = list(msg.dest) if isinstance(msg.dest, tuple) else [msg.dest]
            ledger.sent(book_at, sender, msg.kind, size, len(to))
            ledger.book(book_at, sender, msg.kind, size, "late", len(to), to)

    def deliver(self, tick: int, alive: Iterable[int]) -> dict[int, list[list]]:
        """Inboxes for ``tick``: ``{receiver: [[sender, kind, payload], ...]}`` for agents in ``alive``.

        Their bookings stay tentative until :meth:`confirm` (the tick really happened) or
        :meth:`finish` (the run ended first: ``run_ended``). A message's ``[sender, kind, payload]``
        is one list shared by every inbox it reaches."""
        is_alive = np.zeros(self.n_agents, dtype=bool)
        alive_ids = np.fromiter(alive, dtype=np.int64)
        is_alive[alive_ids[(alive_ids >= 0) & (alive_ids < self.n_agents)]] = True
        inboxes: dict[int, list[list]] = {}
        for receivers, sender, kind, payload, _sent in self._pending.pop(tick, ()):
            there = is_alive[receivers]
            reached, dead = receivers[there], receivers[~there]
            item = [sender, kind, payload]
            for r in reached.tolist():
                inboxes.setdefault(r, []).append(item)
            self._unconfirmed.append((tick, sender, kind, len(payload), reached, dead))
        return inboxes

    def confirm(self) -> None:
        """The inboxes handed out by :meth:`deliver` reached their tick: book them."""
        for tick, sender, kind, size, delivered, dead in self._unconfirmed:
            self.ledger.book(tick, sender, kind, size, DELIVERED, len(delivered), delivered)
            self.ledger.book(tick, sender, kind, size, "receiver_dead", len(dead), dead)
        self._unconfirmed.clear()

    def finish(self, last_tick: int) -> None:
        """The run is over after ``last_tick``: every copy not yet delivered is booked ``run_ended``."""
        for _tick, sender, kind, size, delivered, dead in self._unconfirmed:
            self.ledger.book(
                last_tick,
                sender,
                kind,
                size,
                "run_ended",
                len(delivered) + len(dead),
                np.concatenate([delivered, dead]),
            )
        self._unconfirmed.clear()
        for due in sorted(self._pending):
            for receivers, sender, kind, payload, _sent in self._pending[due]:
                self.ledger.book(last_tick, sender, kind, len(payload), "run_ended", len(receivers), receivers)
        self._pending.clear()
