"""The radio model: decides, per message and per intended receiver, what happens to each copy.

Pure and deterministic: given the same parameters, seed, positions and messages, it books the same
ledger and delivers the same inboxes. The proxy process drives it; tests drive it directly too.

Order of the checks for one message sent at tick k (a copy gets the first reason that applies):

1. addressing: a receiver that is not an agent of the run (or is the sender) -> ``no_such_receiver``;
   one that is not alive at tick k -> ``receiver_dead``.
2. sender queue (tc-netem ``limit``): if ``limit`` messages already wait behind the rate cap, the
   whole message is tail-dropped -> ``queue_full`` for every copy.
3. range: distance between sender and receiver at tick k greater than ``range`` -> ``out_of_range``.
   walls (``network.walls.line_of_sight``, :mod:`.walls`): the straight path crosses a wall of the
   ``obstacles:`` section -> ``blocked_by_wall``.
4. propagation (``network.propagation``, :mod:`.propagation`): received power (less the walls'
   loss, :mod:`.walls`) under the sensitivity -> ``below_sensitivity``.
5. the shared channel (``network.channel``, :mod:`.channel`): the receiver's airtime for the tick
   is spent -> ``channel_busy``.
6. propagation again: a bit error in the copy -> ``packet_error``.
7. bursts (``network.burst``, Gilbert-Elliott, :mod:`.bursts`) -> ``burst``.
8. loss: an independent Bernoulli draw per copy -> ``loss``.

On the real-time clock a sample that reaches the proxy after its tick's deadline is not routed:
every copy of its messages is ``late`` (:meth:`Radio.late`).

A message that survives is scheduled. With a ``rate`` cap it is transmitted after the ones queued
before it, taking ``size / rate`` seconds; idle time earns no credit (tc-netem ``rate``). A copy
arrives at the end of its transmission plus its added delay (``network.delay``, :mod:`.delay`;
none by default) and is delivered at the first tick at or after that, never before k+1, plus
``latency`` ticks. At delivery, a receiver that died meanwhile -> ``receiver_dead``.

Random numbers: the independent loss draws come from the radio's generator, one per copy that
reached step 8, in copy order (messages in sender order, then receivers in id order). Each other
model draws from its own stream, spawned from the radio's seed sequence in this order:
shadowing, fading, reception, bursts, delay; so turning one model on never changes another's draws,
and a run with none of them draws exactly what it drew before they existed. Shadowing, fading and
time-based bursts advance once per tick, whether anything was sent or not.

With ``network.draws: per_copy`` the loss draw of a copy is instead a function of the copy alone
(:func:`per_copy_uniform`: the run's radio key, the tick, the sender, the message's place among
its sender's messages of the tick, the receiver), so that it does not depend on which other copies
a radio decided before it: what lets K radios, each deciding the copies of the senders in its
region (``radio_split``), draw what one radio draws.
"""

from __future__ import annotations

import itertools
import math
from collections import defaultdict, deque
from collections.abc import Container, Iterable, Mapping, Sequence
from typing import NamedTuple

import numpy as np

from swarmbed.netem.bursts import BURST_STAGE, Bursts
from swarmbed.netem.channel import CHANNEL_STAGE, SharedChannel
from swarmbed.netem.delay import Delays
from swarmbed.netem.ledger import DELIVERED, DROP_REASONS, MEASURE_COLUMNS, Ledger
from swarmbed.netem.propagation import ERROR_STAGE, SENSITIVITY_STAGE, Propagation
from swarmbed.netem.stage import EPS as _EPS
from swarmbed.netem.stage import Stage, TickCopies
from swarmbed.netem.walls import WALLS_STAGE
from swarmbed.schema.experiment import NetworkSection
from swarmbed.schema.obstacles import Walls
from swarmbed.wire.codec import BROADCAST, RadioMessage


def _seed_sequence(rng: np.random.Generator) -> np.random.SeedSequence:
    """The seed sequence ``rng`` was made from (spawning children draws nothing from ``rng``)."""
    seq = getattr(rng.bit_generator, "seed_seq", None) or rng.bit_generator._seed_seq  # type: ignore[attr-defined]
    assert isinstance(seq, np.random.SeedSequence)
    return seq


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _mix(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser over an array of uint64 (wrapping arithmetic)."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def per_copy_uniform(key: int, tick: int, senders: np.ndarray, seqs: np.ndarray, receivers: np.ndarray) -> np.ndarray:
    """One number in [0, 1) per copy, from the copy's own coordinates only: ``key`` (the radio's),
    ``tick``, and per copy its sender, the place of its message among the sender's messages of the
    tick, and its receiver, absorbed one after the other through SplitMix64's finaliser; the top
    53 bits make the float. Statistical quality, not secrecy: a stream per copy, independent of the
    order in which copies are decided and of which radio decides them."""
    h = np.full(len(senders), np.uint64(key), dtype=np.uint64)
    for part in (np.full(len(senders), tick, dtype=np.int64), senders, seqs, receivers):
        h = _mix(h + _GOLDEN + np.asarray(part, dtype=np.int64).astype(np.uint64))
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


def measured(params: NetworkSection) -> bool:
    """Whether ``params`` turn on a model that computes per-copy figures (the receiver ledger's
    distance, power_dbm, snr_db and delay_s columns)."""
    return params.propagation is not None or params.delay is not None


def _out_of_range(radio: Radio, copies: TickCopies, at: np.ndarray) -> np.ndarray:
    return copies.distance[at] > radio.params.range + _EPS  # type: ignore[operator]


def _loss(radio: Radio, copies: TickCopies, at: np.ndarray) -> np.ndarray:
    if radio.params.draws == "per_copy":
        u = per_copy_uniform(radio.copy_key, copies.tick, copies.senders[at], copies.seqs[at], copies.receivers[at])
    else:
        u = radio.rng.random(len(at))
    return u < radio.params.loss


#: what may drop a copy after it is addressed and queued, in the order a copy meets them (the
#: module's docstring); each stage's reason, legend colour and whether ``network:`` turns it on.
#: A new model adds its stage here, where its copies should meet it.
STAGES: tuple[Stage, ...] = (
    Stage("out_of_range", "#9467bd", lambda p: p.range is not None, _out_of_range),
    WALLS_STAGE,
    SENSITIVITY_STAGE,
    CHANNEL_STAGE,
    ERROR_STAGE,
    BURST_STAGE,
    Stage("loss", "#d62728", lambda p: p.loss > 0.0, _loss),
)


def drop_reasons(params: NetworkSection) -> tuple[str, ...]:
    """Every reason a copy may be dropped for under ``params``: the disk's, and those of the stages
    it turns on (a run's summary lists these, each with its count)."""
    return DROP_REASONS + tuple(s.reason for s in STAGES if s.reason not in DROP_REASONS and s.on(params))


#: up to this many agents, :func:`neighbours` compares every pair (a few microseconds) instead of
#: building SciPy's KD-tree, whose import alone costs a process about a second of CPU
PAIRWISE_UP_TO = 128


def neighbours(x: np.ndarray, y: np.ndarray, rows: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Every point within ``reach`` of each point of ``rows`` (itself included), by its own distance:
    (sender, candidate) pairs grouped by sender in the order of ``rows``, candidates ascending. The
    caller tests them again with the radio's own distance, so the two ways below give it the same
    copies. Up to :data:`PAIRWISE_UP_TO` points, every pair is compared; beyond, SciPy's KD-tree
    finds them (a uniform grid of ``reach``-wide cells, the 3 x 3 cells about each sender, then a
    sort, measured 1.3-2.6x slower at 200-1,000 agents: docs/benchmarks.md)."""
    if len(x) <= PAIRWISE_UP_TO:
        near = np.hypot(x[None, :] - x[rows][:, None], y[None, :] - y[rows][:, None]) <= reach
        senders, candidates = np.nonzero(near)  # row-major: grouped by sender, candidates ascending
        return rows[senders], candidates.astype(np.int64)
    from scipy.spatial import cKDTree

    points = np.column_stack((x, y))
    found = cKDTree(points).query_ball_point(points[rows], reach, return_sorted=True)
    lengths = np.fromiter((len(f) for f in found), dtype=np.int64, count=len(found))
    candidates = np.fromiter(itertools.chain.from_iterable(found), dtype=np.int64, count=int(lengths.sum()))
    return np.repeat(rows, lengths), candidates


class _Send(NamedTuple):
    """One message on its way through :meth:`Radio.route`."""

    sender: int
    sender_row: int
    msg: RadioMessage
    intended: int  # copies: one per intended receiver
    drops: list[tuple[str, np.ndarray]]  # copies dropped before range and loss: (reason, receivers)
    rows: np.ndarray  # the receivers (rows of the sorted alive ids) still in play
    end: float  # end of its transmission, in seconds
    seq: int  # its place among its sender's messages of the tick
    unheard: int = 0  # a broadcast's copies out of range, counted without being made (see _near)


class Radio:
    def __init__(
        self,
        params: NetworkSection,
        n_agents: int,
        dt: float,
        rng: np.random.Generator,
        ledger: Ledger | None = None,
        walls: Walls | None = None,
    ) -> None:
        self.walls = walls  # the world's walls (:mod:`.walls`), None: open ground
        self.params = params  # also the stages it turns on (see the setter)
        self.n_agents = n_agents
        self.dt = dt
        self.rng = rng
        self.ledger = ledger if ledger is not None else Ledger(reasons=drop_reasons(params))
        self._busy_until: dict[int, float] = defaultdict(float)
        self._in_queue: dict[int, deque[float]] = defaultdict(deque)  # transmission end times
        # delivery tick -> [(receivers, sender, kind, payload, send_tick, their measures or None)]
        self._pending: dict[int, list[tuple[np.ndarray, int, str, bytes, int, np.ndarray | None]]] = defaultdict(list)
        # (tick, sender, kind, size, receivers delivered to, receivers found dead, their measures or None)
        self._unconfirmed: list[tuple[int, int, str, int, np.ndarray, np.ndarray, np.ndarray | None]] = []
        # the models beyond the disk, each with its own stream (see the module's docstring)
        seq = _seed_sequence(rng)
        streams = [np.random.default_rng(s) for s in seq.spawn(5)]
        # network.draws: per_copy: the key of every copy's own draw, from the sequence's next child
        self.copy_key = int(seq.spawn(1)[0].generate_state(1, np.uint64)[0])
        self.propagation = Propagation(params.propagation, n_agents, dt, *streams[:3]) if params.propagation else None
        self.bursts = Bursts(params.burst, n_agents, dt, streams[3]) if params.burst else None
        self.delays = Delays(params.delay, n_agents, streams[4]) if params.delay else None
        self.channel = SharedChannel(params.channel, dt) if params.channel else None
        # per-copy distance, power, SNR and delay in the receiver ledger, where a model computes them
        self.measuring = self.ledger.per_receiver and measured(params)

    @property
    def params(self) -> NetworkSection:
        return self._params

    @params.setter
    def params(self, params: NetworkSection) -> None:
        """The radio's parameters, and with them the stages they turn on: a soak's chaos replaces
        them mid-run (a loss burst turns loss on from 0, a rate cap sets ``rate``)."""
        self._params = params
        self.stages = tuple(stage for stage in STAGES if stage.on(params))

    @property
    def pending_copies(self) -> int:
        """Copies scheduled or handed out but not yet booked."""
        scheduled = sum(len(r) for entries in self._pending.values() for r, *_ in entries)
        return scheduled + sum(len(u[4]) + len(u[5]) for u in self._unconfirmed)

    def route(
        self,
        tick: int,
        ids: Sequence[int],
        xs: Sequence[float],
        ys: Sequence[float],
        outs: Mapping[int, Iterable[RadioMessage]],
        owned: Container[int] | None = None,
    ) -> None:
        """Take every message sent at ``tick``. ``ids``/``xs``/``ys``: agents alive at ``tick``.
        ``owned``: the senders whose copies this radio decides (one shard of a split radio); every
        other sender's messages only take their place in its transmit queue, so each shard's
        queues are what one radio's are. None: every sender.

        Three passes: each message is addressed and queued (Python, per message); the drop stages
        (:data:`STAGES`: range, the models, loss) decide for every copy of the tick at once, each on
        the copies the stages before it left in play; then each message is booked, in order, and
        what survives is scheduled."""
        order = np.argsort(np.asarray(ids, dtype=np.int64), kind="stable")
        alive = np.asarray(ids, dtype=np.int64)[order]
        every_row = np.arange(len(alive))
        row_of = dict(zip(alive.tolist(), every_row.tolist()))
        x = np.asarray(xs, dtype=float)[order]
        y = np.asarray(ys, dtype=float)[order]
        if self.propagation is not None:
            self.propagation.advance(tick, alive, x, y)
        if self.bursts is not None:
            self.bursts.advance()
        mine = outs if owned is None else {s: m for s, m in outs.items() if s in owned}
        near = self._near(mine, row_of, x, y)
        sends: list[_Send] = []
        for sender in sorted(outs):
            sender_row = row_of.get(sender)
            decided = owned is None or sender in owned
            for seq, msg in enumerate(outs[sender]):
                if sender_row is None:
                    raise KeyError(f"agent {sender} sent at tick {tick} but is not alive then")
                if decided:
                    sends.append(self._address(tick, sender, sender_row, msg, alive, row_of, every_row, seq, near))
                elif self.params.rate is not None:
                    self._transmit(tick, sender, len(msg.payload))
        if not sends:
            return
        counts = np.fromiter((len(s.rows) for s in sends), dtype=np.int64, count=len(sends))
        rows = np.concatenate([s.rows for s in sends])
        from_rows = np.repeat(np.fromiter((s.sender_row for s in sends), dtype=np.int64, count=len(sends)), counts)
        copies = TickCopies(tick, alive, x, y, rows, from_rows, sends, counts)
        in_play = np.ones(len(rows), dtype=bool)
        drops: list[tuple[str, np.ndarray]] = []  # (reason, which copies), in booking order
        for stage in self.stages if len(rows) else ():
            at = np.flatnonzero(in_play)
            hit = np.zeros(len(rows), dtype=bool)
            hit[at[stage.drop(self, copies, at)]] = True
            in_play &= ~hit
            drops.append((stage.reason, hit))
        measures = None
        if self.measuring and len(rows):
            measures = np.full((len(rows), len(MEASURE_COLUMNS)), np.nan)
            measures[:, 0] = copies.distance
            if copies.power is not None:
                measures[:, 1] = copies.power
                measures[:, 2] = copies.power - self.propagation.p.noise_floor_dbm  # type: ignore[union-attr]
        self._book_and_schedule(tick, sends, counts, alive, rows, from_rows, drops, in_play, measures)

    def _near(
        self, outs: Mapping[int, Iterable[RadioMessage]], row_of: dict[int, int], x: np.ndarray, y: np.ndarray
    ) -> dict[int, np.ndarray] | None:
        """For each sender row that broadcasts this tick, the rows within ``network.range`` of it
        (itself left out, in row order): found through a KD-tree, so that the copies out of range
        are counted, never made. The range test is the range stage's own (the same distance, the
        same tolerance), and out of range is the first stage a copy meets, so no later stage or
        random draw sees a difference. None where every copy must be made: no range, or a ledger
        kept per receiver (it lists each out-of-range receiver)."""
        reach = self.params.range
        if reach is None or self.ledger.per_receiver or len(x) < 2:
            return None
        rows = sorted({row_of[s] for s, msgs in outs.items() if s in row_of and any(m.dest == BROADCAST for m in msgs)})
        if not rows:
            return {}
        senders, candidates = neighbours(x, y, np.asarray(rows, dtype=np.int64), reach + _EPS + 1e-6 * max(1.0, reach))
        keep = candidates != senders
        keep[keep] = (
            np.hypot(x[senders[keep]] - x[candidates[keep]], y[senders[keep]] - y[candidates[keep]]) <= reach + _EPS
        )
        heard = np.split(
            candidates[keep], np.cumsum(np.bincount(np.searchsorted(rows, senders[keep]), minlength=len(rows)))[:-1]
        )
        return dict(zip(rows, heard, strict=True))

    def _address(
        self,
        tick: int,
        sender: int,
        sender_row: int,
        msg: RadioMessage,
        alive: np.ndarray,
        row_of: dict[int, int],
        every_row: np.ndarray,
        seq: int,
        near: dict[int, np.ndarray] | None = None,
    ) -> _Send:
        """A message's intended receivers (as rows of ``alive``, the sorted ids; ``row_of`` maps an
        id to its row) that may still get a copy, the copies already dropped (addressing, the
        sender's queue) and the end of its transmission. ``near``: the rows in range of each
        broadcasting sender (:meth:`_near`): a broadcast's other copies are counted as
        ``unheard``, out of range, and not made."""
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
        end = self._transmit(tick, sender, len(msg.payload))
        if end is None:
            drops.append(("queue_full", alive[rows]))
            return _Send(sender, sender_row, msg, intended, drops, rows[:0], tick * self.dt, seq)
        if near is not None and msg.dest == BROADCAST:
            heard = near[sender_row]
            return _Send(sender, sender_row, msg, intended, drops, heard, end, seq, len(rows) - len(heard))
        return _Send(sender, sender_row, msg, intended, drops, rows, end, seq)

    def _transmit(self, tick: int, sender: int, size: int) -> float | None:
        """The end of the transmission of a ``size``-byte message ``sender`` queues at ``tick``
        (now, without a rate cap), or None where its queue is full (tail drop)."""
        p = self.params
        end = t_now = tick * self.dt
        if p.rate is not None:
            queue = self._in_queue[sender]
            while queue and queue[0] <= t_now + _EPS:
                queue.popleft()
            if p.limit is not None and len(queue) >= p.limit:
                return None
            end = max(t_now, self._busy_until[sender]) + size / p.rate
            self._busy_until[sender] = end
            queue.append(end)
        return end

    def _book_and_schedule(
        self,
        tick: int,
        sends: list[_Send],
        counts: np.ndarray,
        alive: np.ndarray,
        rows: np.ndarray,
        from_rows: np.ndarray,
        drops: list[tuple[str, np.ndarray]],
        kept: np.ndarray,
        measures: np.ndarray | None = None,
    ) -> None:
        """Book every copy of the tick and schedule the kept ones. ``measures``: per copy, the
        receiver ledger's figures (:data:`MEASURE_COLUMNS`), or None when none are kept."""
        ledger, per_receiver = self.ledger, self.ledger.per_receiver
        bounds = np.concatenate(([0], np.cumsum(counts)))
        # copies per message and outcome in one pass: column 0 kept, column r the r-th drop reason
        outcome = np.zeros(len(rows), dtype=np.int64)
        for r, (_reason, which) in enumerate(drops, 1):
            outcome[which] = r
        width = len(drops) + 1
        message = np.repeat(np.arange(len(sends)), counts)
        table = np.bincount(message * width + outcome, minlength=len(sends) * width).reshape(len(sends), width)
        n_dropped = [(reason, which, table[:, r].tolist()) for r, (reason, which) in enumerate(drops, 1)]
        n_kept = table[:, 0]
        kept_at = np.flatnonzero(kept)
        kept_ids = np.split(alive[rows[kept_at]], np.cumsum(n_kept)[:-1])
        starts, copies, keeps = bounds.tolist(), counts.tolist(), n_kept.tolist()
        latency = self.params.latency
        # with a delay model, each kept copy's own delivery tick (in copy order): the first tick at
        # or after the end of its message's transmission plus its delay
        dues: list[np.ndarray] | None = None
        spread: list[bool] = []  # whether a message's copies fall on more than one tick
        if self.delays is not None and len(kept_at):
            ends = np.repeat(np.fromiter((s.end for s in sends), dtype=float, count=len(sends)), n_kept)
            added = self.delays.draw(alive[from_rows[kept_at]], alive[rows[kept_at]])
            if measures is not None:
                measures[kept_at, 3] = added
            due_all = np.maximum(tick + 1, np.ceil((ends + added) / self.dt - _EPS).astype(np.int64)) + latency
            dues = np.split(due_all, np.cumsum(n_kept)[:-1])
            first = np.cumsum(n_kept) - n_kept
            has = n_kept > 0
            lo = np.zeros(len(sends), dtype=np.int64)
            hi = np.zeros(len(sends), dtype=np.int64)
            lo[has] = np.minimum.reduceat(due_all, first[has])
            hi[has] = np.maximum.reduceat(due_all, first[has])
            spread = (lo != hi).tolist()
        for i, send in enumerate(sends):
            kind, size = send.msg.kind, len(send.msg.payload)
            ledger.sent(tick, send.sender, kind, size, send.intended)
            for reason, to in send.drops:
                ledger.book(tick, send.sender, kind, size, reason, len(to), to)
            ledger.book(tick, send.sender, kind, size, "out_of_range", send.unheard)
            if not copies[i]:
                continue
            a, b = starts[i], starts[i + 1]
            for reason, which, per_message in n_dropped:
                if per_message[i]:
                    receivers = alive[rows[a:b][which[a:b]]] if per_receiver else None
                    figures = measures[a:b][which[a:b]] if measures is not None else None
                    ledger.book(tick, send.sender, kind, size, reason, per_message[i], receivers, figures)
            if not keeps[i]:
                continue
            kept_figures = measures[a:b][kept[a:b]] if measures is not None else None
            if dues is None:
                due = max(tick + 1, math.ceil(send.end / self.dt - _EPS)) + latency
                self._pending[due].append((kept_ids[i], send.sender, kind, send.msg.payload, tick, kept_figures))
            elif not spread[i]:
                entry = (kept_ids[i], send.sender, kind, send.msg.payload, tick, kept_figures)
                self._pending[int(dues[i][0])].append(entry)
            else:
                for due in np.unique(dues[i]).tolist():  # earliest first; receivers stay in id order
                    on = dues[i] == due
                    figures = kept_figures[on] if kept_figures is not None else None
                    self._pending[due].append((kept_ids[i][on], send.sender, kind, send.msg.payload, tick, figures))

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

    def deliver(
        self, tick: int, alive: Iterable[int], order: dict[int, list[int]] | None = None
    ) -> dict[int, list[list]]:
        """Inboxes for ``tick``: ``{receiver: [[sender, kind, payload], ...]}`` for agents in ``alive``.
        ``order``: filled with each inbox item's send tick (what a split radio's merge orders by).

        Their bookings stay tentative until :meth:`confirm` (the tick really happened) or
        :meth:`finish` (the run ended first: ``run_ended``). A message's ``[sender, kind, payload]``
        is one list shared by every inbox it reaches."""
        is_alive = np.zeros(self.n_agents, dtype=bool)
        alive_ids = np.fromiter(alive, dtype=np.int64)
        is_alive[alive_ids[(alive_ids >= 0) & (alive_ids < self.n_agents)]] = True
        inboxes: dict[int, list[list]] = {}
        for receivers, sender, kind, payload, sent, figures in self._pending.pop(tick, ()):
            there = is_alive[receivers]
            reached, dead = receivers[there], receivers[~there]
            item = [sender, kind, payload]
            for r in reached.tolist():
                inboxes.setdefault(r, []).append(item)
                if order is not None:
                    order.setdefault(r, []).append(sent)
            if figures is not None:  # delivered copies first, then the dead ones, as they are booked
                figures = np.concatenate([figures[there], figures[~there]])
            self._unconfirmed.append((tick, sender, kind, len(payload), reached, dead, figures))
        return inboxes

    def confirm(self) -> None:
        """The inboxes handed out by :meth:`deliver` reached their tick: book them."""
        for tick, sender, kind, size, delivered, dead, figures in self._unconfirmed:
            n = len(delivered)
            first, rest = (figures[:n], figures[n:]) if figures is not None else (None, None)
            self.ledger.book(tick, sender, kind, size, DELIVERED, n, delivered, first)
            self.ledger.book(tick, sender, kind, size, "receiver_dead", len(dead), dead, rest)
        self._unconfirmed.clear()

    def finish(self, last_tick: int) -> None:
        """The run is over after ``last_tick``: every copy not yet delivered is booked ``run_ended``."""
        for _tick, sender, kind, size, delivered, dead, figures in self._unconfirmed:
            self.ledger.book(
                last_tick,
                sender,
                kind,
                size,
                "run_ended",
                len(delivered) + len(dead),
                np.concatenate([delivered, dead]),
                figures,
            )
        self._unconfirmed.clear()
        for due in sorted(self._pending):
            for receivers, sender, kind, payload, _sent, figures in self._pending[due]:
                self.ledger.book(last_tick, sender, kind, len(payload), "run_ended", len(receivers), receivers, figures)
        self._pending.clear()
