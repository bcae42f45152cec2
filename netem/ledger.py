"""The network ledger: every copy of every message ends delivered or dropped with a reason.

A *message* is one transmission by a sender; a *copy* is that message towards one intended
receiver (all agents alive at the send tick for a broadcast; the named ones for unicast or
multicast). Rows are booked at the tick the outcome was decided: ``sent`` rows count messages
(and their payload bytes), every other outcome counts copies (and copies x payload bytes).

Conservation, checked by :meth:`Ledger.check`: copies == delivered + sum(dropped).
"""

from __future__ import annotations

import csv
import io
from collections import defaultdict

SENT = "sent"
DELIVERED = "delivered"
DROP_REASONS = ("out_of_range", "loss", "queue_full", "receiver_dead", "no_such_receiver", "run_ended")
OUTCOMES = (SENT, DELIVERED) + DROP_REASONS
LEDGER_COLUMNS = ("tick", "sender", "kind", "outcome", "messages", "bytes")


class Ledger:
    """Accumulates rows tick by tick and streams finished ticks to a CSV text sink."""

    def __init__(self, sink: io.TextIOBase | None = None) -> None:
        self._open: dict[tuple[int, int, str, str], list[int]] = defaultdict(lambda: [0, 0])
        self._writer = csv.writer(sink, lineterminator="\n") if sink is not None else None
        if self._writer:
            self._writer.writerow(LEDGER_COLUMNS)
        self.messages_sent = 0
        self.bytes_sent = 0
        self.copies = 0
        self.delivered = 0
        self.delivered_bytes = 0
        self.dropped: dict[str, int] = {r: 0 for r in DROP_REASONS}
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

    def book(self, tick: int, sender: int, kind: str, size: int, outcome: str, copies: int = 1) -> None:
        """Book ``copies`` copies of one message (``size`` payload bytes each) with ``outcome``."""
        if copies <= 0:
            return
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
            if self._writer:
                self._writer.writerow((*key, messages, nbytes))

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
