"""The network ledger: every copy of every message ends delivered or dropped with a reason.

A *message* is one transmission by a sender; a *copy* is that message towards one intended
receiver (all agents alive at the send tick for a broadcast; the named ones for unicast or
multicast). Rows are booked at the tick the outcome was decided: ``sent`` rows count messages
(and their payload bytes), every other outcome counts copies (and copies x payload bytes).

Conservation, checked by :meth:`Ledger.check`: copies == delivered + sum(dropped).

With a :class:`ReceiverLog` (``network.ledger: per_receiver``) every copy also gets its own row
(tick, sender, receiver, kind, outcome, bytes) in a Parquet file: it grows as agents squared, so
it is written in row groups as ticks close and only on request.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from swarmbed.files.safefiles import open_fresh
from swarmbed.records.rowfile import RowFile
from swarmbed.records.run_folder import RECEIVER_COLUMNS

SENT = "sent"
DELIVERED = "delivered"
DROP_REASONS = ("out_of_range", "loss", "queue_full", "receiver_dead", "no_such_receiver", "run_ended", "late")
OUTCOMES = (SENT, DELIVERED) + DROP_REASONS
#: per-copy figures the radio's models compute, in the receiver ledger when a model is on
MEASURE_COLUMNS = ["distance", "power_dbm", "snr_db", "delay_s"]


class ReceiverLog:
    """One row per copy, streamed to a Parquet file in row groups of about ``group`` rows.

    ``measured``: the radio's models compute per-copy figures (:data:`MEASURE_COLUMNS`: distance,
    received power, SNR, added delay), one more column each, NaN where a copy never reached the
    step that computes it."""

    def __init__(self, path: Path, group: int = 1 << 16, measured: bool = False) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        self._pa = pa
        # strings stay strings here: Parquet dictionary-encodes the few kinds and outcomes itself
        types = [pa.int64(), pa.int32(), pa.int32(), pa.string(), pa.string(), pa.int32()]
        names = list(RECEIVER_COLUMNS)
        if measured:
            types += [pa.float64()] * len(MEASURE_COLUMNS)
            names += MEASURE_COLUMNS
        self.measured = measured
        self.schema = pa.schema(list(zip(names, types)))
        self._file = open_fresh(path)  # created fresh, never through a link
        self._writer: Any = pq.ParquetWriter(self._file, self.schema)
        self.group = group
        self.rows = 0
        self._cols: tuple[list, ...] = tuple([] for _ in names)

    def add(
        self,
        tick: int,
        sender: int,
        receivers: Iterable[int],
        kind: str,
        outcome: str,
        size: int,
        measures: np.ndarray | None = None,
    ) -> int:
        ticks, senders, recv, kinds, outcomes, sizes = self._cols[:6]
        before = len(recv)
        recv.extend(int(r) for r in receivers)
        n = len(recv) - before
        ticks.extend([tick] * n)
        senders.extend([sender] * n)
        kinds.extend([kind] * n)
        outcomes.extend([outcome] * n)
        sizes.extend([size] * n)
        if self.measured:
            values = measures if measures is not None else np.full((n, len(MEASURE_COLUMNS)), np.nan)
            for col, column in zip(self._cols[6:], values.T):
                col.extend(column.tolist())
        return n

    def flush(self, force: bool = False) -> None:
        if not self._cols[0] or (len(self._cols[0]) < self.group and not force):
            return
        pa = self._pa
        arrays = [pa.array(col, type=f.type) for col, f in zip(self._cols, self.schema)]
        self._writer.write_table(pa.Table.from_arrays(arrays, schema=self.schema))
        self.rows += len(self._cols[0])
        for col in self._cols:
            col.clear()

    def close(self) -> None:
        self.flush(force=True)
        self._writer.close()
        self._file.close()


class Ledger:
    """Accumulates rows tick by tick and streams finished ticks to a :class:`RowFile` (whose
    columns are :data:`~swarmbed.records.run_folder.LEDGER_COLUMNS`)."""

    def __init__(
        self,
        sink: RowFile | None = None,
        receivers: ReceiverLog | None = None,
        reasons: Sequence[str] = DROP_REASONS,
        batched: bool = False,
    ) -> None:
        """``reasons``: every reason a copy may be dropped for (the radio's ``drop_reasons``): each
        is counted, from zero, in ``dropped``; booking any other is an error. ``batched``: each row
        starts with the number of the :meth:`close_tick` that wrote it (a split radio's part,
        :mod:`swarmbed.netem.radio_split`)."""
        self.receivers = receivers
        self.batch: int | None = 0 if batched else None
        self._open: dict[tuple[int, int, str, str], list[int]] = defaultdict(lambda: [0, 0])
        self._sink = sink
        self.messages_sent = 0
        self.bytes_sent = 0
        self.copies = 0
        self.delivered = 0
        self.delivered_bytes = 0
        self.dropped: dict[str, int] = dict.fromkeys(reasons, 0)
        self.by_sender: dict[int, dict[str, int]] = defaultdict(lambda: defaultdict(int))
        self.by_kind: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))

    def sent(self, tick: int, sender: int, kind: str, size: int, copies: int) -> None:
        row = self._open[(tick, sender, kind, SENT)]
        row[0] += 1
        row[1] += size
        self.messages_sent += 1
        self.bytes_sent += size
        self.copies += copies
        for agg in (self.by_sender[sender], self.by_kind[kind]):
            agg["messages"] += 1
            agg["bytes"] += size
            agg["copies"] += copies

    @property
    def per_receiver(self) -> bool:
        return self.receivers is not None

    def book(
        self,
        tick: int,
        sender: int,
        kind: str,
        size: int,
        outcome: str,
        copies: int = 1,
        to: Iterable[int] | None = None,
        measures: np.ndarray | None = None,
    ) -> None:
        """Book ``copies`` copies of one message (``size`` payload bytes each) with ``outcome``.

        ``to``: the receivers of those copies, needed when the ledger is kept per receiver."""
        if copies <= 0:
            return
        if self.receivers is not None:
            if to is None:
                raise ValueError(f"ledger kept per receiver, but {outcome!r} was booked without its receivers")
            n = self.receivers.add(tick, sender, to, kind, outcome, size, measures)
            if n != copies:
                raise ValueError(f"{copies} {outcome!r} copies booked with {n} receivers")
        row = self._open[(tick, sender, kind, outcome)]
        row[0] += copies
        row[1] += copies * size
        if outcome == DELIVERED:
            self.delivered += copies
            self.delivered_bytes += copies * size
        else:
            self.dropped[outcome] += copies
        for agg in (self.by_sender[sender], self.by_kind[kind]):
            agg[outcome] += copies

    def close_tick(self, tick: int) -> None:
        """Write every row booked at ticks <= ``tick`` (their outcomes are final) to the sink."""
        done = sorted(k for k in self._open if k[0] <= tick)
        for key in done:
            messages, nbytes = self._open.pop(key)
            if self._sink is None:
                continue
            if self.batch is None:
                self._sink.write((*key, messages, nbytes))
            else:
                self._sink.write((self.batch, *key, messages, nbytes))
        if self.batch is not None:
            self.batch += 1
        if self.receivers is not None:
            self.receivers.flush()

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def check(self, pending: int = 0) -> None:
        """Raise if a copy is unaccounted for (``pending``: copies still scheduled for delivery)."""
        if self.copies != self.delivered + self.dropped_total + pending:
            raise AssertionError(
                f"ledger out of balance: copies={self.copies} delivered={self.delivered} "
                f"dropped={self.dropped_total} pending={pending}"
            )

    def totals(self) -> dict:
        return {
            "messages_sent": self.messages_sent,
            "bytes_sent": self.bytes_sent,
            "copies": self.copies,
            "delivered": self.delivered,
            "delivered_bytes": self.delivered_bytes,
            "dropped": dict(self.dropped),
            "dropped_total": self.dropped_total,
        }

    def per_sender(self) -> dict[int, dict[str, int]]:
        return {s: dict(v) for s, v in sorted(self.by_sender.items())}

    def per_kind(self) -> dict[str, dict[str, int]]:
        return {k: dict(v) for k, v in sorted(self.by_kind.items())}
