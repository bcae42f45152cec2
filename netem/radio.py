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

import numpy as np

from swarmbed.netem.ledger import DELIVERED, Ledger
from swarmbed.wire.codec import BROADCAST, RadioMessage
from swarmbed.wire.schema import NetworkSection

_EPS = 1e-9


class Radio:
    def __init__(self, params: NetworkSection, n_agents: int, dt: float, rng: np.random.Generator,
                 ledger: Ledger | None = None) -> None:
        self.params = params
        self.n_agents = n_agents
        self.dt = dt
        self.rng = rng
        self.ledger = ledger if ledger is not None else Ledger()
        self._busy_until: dict[int, float] = defaultdict(float)
        self._in_queue: dict[int, deque[float]] = defaultdict(deque)  # transmission end times
        # delivery tick -> [(receivers, sender, kind, payload, send_tick)]
        self._pending: dict[int, list[tuple[list[int], int, str, bytes, int]]] = defaultdict(list)
        # (tick, sender, kind, size, receivers delivered to, receivers found dead)
        self._unconfirmed: list[tuple[int, int, str, int, list[int], list[int]]] = []

    @property
    def pending_copies(self) -> int:
        """Copies scheduled or handed out but not yet booked."""
        scheduled = sum(len(r) for entries in self._pending.values() for r, *_ in entries)
        return scheduled + sum(len(d) + len(x) for *_, d, x in self._unconfirmed)

    def route(self, tick: int, ids: Sequence[int], xs: Sequence[float], ys: Sequence[float],
              outs: Mapping[int, Iterable[RadioMessage]]) -> None:
        """Take every message sent at ``tick``. ``ids``/``xs``/``ys``: agents alive at ``tick``."""
        order = np.argsort(np.asarray(ids, dtype=np.int64), kind="stable")
        alive = np.asarray(ids, dtype=np.int64)[order]
        px = np.asarray(xs, dtype=float)[order]
        py = np.asarray(ys, dtype=float)[order]
        row_of = {int(a): i for i, a in enumerate(alive)}
        near = None
        if self.params.range is not None and len(alive):
            near = np.hypot(px[:, None] - px[None, :], py[:, None] - py[None, :]) <= self.params.range + _EPS
        for sender in sorted(outs):
            for msg in outs[sender]:
                self._route_one(tick, sender, msg, row_of, alive, near)

    def _route_one(self, tick: int, sender: int, msg: RadioMessage, row_of: dict[int, int],
                   alive: np.ndarray, near: np.ndarray | None) -> None:
        p, ledger, kind, size = self.params, self.ledger, msg.kind, len(msg.payload)
        if msg.dest == BROADCAST:
            receivers = alive[alive != sender]
            ledger.sent(tick, sender, kind, size, len(receivers))
        else:
            wanted = msg.dest if isinstance(msg.dest, tuple) else (msg.dest,)
            ledger.sent(tick, sender, kind, size, len(wanted))
            ok = []
            for r in wanted:
                if r == sender or not 0 <= r < self.n_agents:
                    ledger.book(tick, sender, kind, size, "no_such_receiver", to=(r,))
                elif r not in row_of:
                    ledger.book(tick, sender, kind, size, "receiver_dead", to=(r,))
                else:
                    ok.append(r)
            receivers = np.asarray(ok, dtype=np.int64)

        t_now = tick * self.dt
        end = t_now
        if p.rate is not None:
            queue = self._in_queue[sender]
            while queue and queue[0] <= t_now + _EPS:
                queue.popleft()
            if p.limit is not None and len(queue) >= p.limit:
                ledger.book(tick, sender, kind, size, "queue_full", len(receivers), receivers)
                return
            end = max(t_now, self._busy_until[sender]) + size / p.rate
            self._busy_until[sender] = end
            queue.append(end)
        if not len(receivers):
            return

        if near is not None:
            in_range = near[row_of[sender], [row_of[int(r)] for r in receivers]]
            n_far = int(len(receivers) - in_range.sum())
            if n_far:
                ledger.book(tick, sender, kind, size, "out_of_range", n_far,
                            receivers[~in_range] if ledger.per_receiver else None)
                receivers = receivers[in_range]
        if p.loss > 0.0 and len(receivers):
            kept = self.rng.random(len(receivers)) >= p.loss
            n_lost = int(len(receivers) - kept.sum())
            if n_lost:
                ledger.book(tick, sender, kind, size, "loss", n_lost, receivers[~kept] if ledger.per_receiver else None)
                receivers = receivers[kept]
        if not len(receivers):
            return
        deliver = max(tick + 1, math.ceil(end / self.dt - _EPS)) + p.latency
        self._pending[deliver].append((receivers.tolist(), sender, kind, msg.payload, tick))

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
        :meth:`finish` (the run ended first: ``run_ended``)."""
        alive_set = set(alive)
        inboxes: dict[int, list[list]] = {}
        for receivers, sender, kind, payload, _sent in self._pending.pop(tick, ()):
            reached, dead = [], []
            for r in receivers:
                if r in alive_set:
                    inboxes.setdefault(r, []).append([sender, kind, payload])
                    reached.append(r)
                else:
                    dead.append(r)
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
            self.ledger.book(last_tick, sender, kind, size, "run_ended", len(delivered) + len(dead), delivered + dead)
        self._unconfirmed.clear()
        for due in sorted(self._pending):
            for receivers, sender, kind, payload, _sent in self._pending[due]:
                self.ledger.book(last_tick, sender, kind, len(payload), "run_ended", len(receivers), receivers)
        self._pending.clear()
