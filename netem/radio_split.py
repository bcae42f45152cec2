"""A radio split over K netem proxies (``radio_split``): who decides which copies, and the merge of
the K proxies' steps, ledgers and reports into what one proxy gives.

Regions are bands across x holding equal shares of the agents, or strips dealt to the proxies in
turn (:func:`swarmbed.wire.regions.owners`). The owner of a copy is the owner of its sender at the
tick it is sent (the world sample of that tick); an agent that crosses into another region changes
owner at the next tick. Without a rate cap an agent's output goes to its owner only (the hub tells each
agent its owner in its tick sample), which decides its copies and carries its action and events;
with one, every proxy receives every output and keeps every sender's transmit queue (so a sender's
queue moves with it for free), and proxy 0 carries every action and event
(:func:`swarmbed.wire.regions.by_region`). Proxy 0 reports the losses. Copies decided by a proxy
stay with it until they are delivered or dropped, so a copy is booked once, by one proxy, whatever
happens to its sender meanwhile.

The merge gives byte for byte what one radio gives (``tests/test_radio_split.py``): counters and
drops add up; a receiver's inbox is its parts merged in the order one radio delivers (by send
tick, then sender); the ledger is merged batch by batch (the rows each proxy closed at the same
tick), rows of one key added. The loss draws must be ``per_copy``
(:func:`swarmbed.netem.radio.per_copy_uniform`). The proxies use :func:`owners`; the hub, and the
in-process engine's :class:`swarmbed.netem.exchange.SplitExchange`, the merges (the launcher hands
them to the hub: a process role imports no other).
"""

from __future__ import annotations

import csv
import heapq
from collections.abc import Sequence
from pathlib import Path

from swarmbed.files.safefiles import remove
from swarmbed.records.rowfile import RowFile
from swarmbed.records.run_folder import LEDGER, LEDGER_COLUMNS, ledger_part
from swarmbed.wire.codec import NetemStep, WireError, encode_inbox, unpack
from swarmbed.wire.control import NetemFinal
from swarmbed.wire.regions import owners

__all__ = ["BATCH_COLUMNS", "merge_finals", "merge_inbox", "merge_ledgers", "merge_steps", "owners"]

#: the ledger part a proxy of a split radio writes, with a ``batch`` column before the ledger's
BATCH_COLUMNS = ("batch", *LEDGER_COLUMNS)


def merge_inbox(parts: Sequence[tuple[bytes, Sequence[int]]]) -> bytes:
    """One receiver's inbox from the proxies' parts (each: its encoded inbox and every item's send
    tick), in the order one radio delivers: by send tick, then sender, each part's own order kept.
    Raises WireError where a part does not match its send ticks."""
    if len(parts) == 1:
        return parts[0][0]
    runs = []
    for data, ticks in parts:
        items = unpack(data)
        if not (isinstance(items, list) and len(items) == len(ticks)):
            raise WireError(f"an inbox part of {len(ticks)} send ticks is not a list of as many items")
        if not all(isinstance(item, list) and len(item) == 3 and isinstance(item[0], int) for item in items):
            raise WireError("an inbox part's item is not [sender, kind, payload]")
        runs.append([(t, item[0], i, item) for i, (t, item) in enumerate(zip(ticks, items))])
    merged = heapq.merge(*runs, key=lambda e: (e[0], e[1]))
    return encode_inbox([e[3] for e in merged])


def merge_steps(steps: Sequence[NetemStep]) -> NetemStep:
    """The step one radio would give, from its proxies' steps of one tick (``steps[i]`` from proxy
    i; each carries the actions and events of the agents whose outputs it read, proxy 0 the losses
    and late answers). Raises WireError where two proxies carry one agent's action."""
    first = steps[0]
    actions: dict[int, list] = {}
    events: dict[str, int] = {}
    for step in steps:
        twice = actions.keys() & step.actions.keys()
        if twice:
            raise WireError(f"the actions of agents {sorted(twice)[:10]} come from two proxies")
        actions.update(step.actions)
        _add(events, step.events)
    parts: dict[int, list[tuple[bytes, Sequence[int]]]] = {}
    for step in steps:
        for receiver, data in step.inboxes.items():
            parts.setdefault(receiver, []).append((data, step.order.get(receiver, ())))
    inboxes = {r: merge_inbox(parts[r]) for r in sorted(parts)}
    counters = [sum(c) for c in zip(*(s.counters for s in steps))]
    drops: dict[str, int] = {}
    for step in steps:
        _add(drops, step.drops)
    return NetemStep(first.tick, actions, inboxes, counters, first.lost, events, drops, first.late)


def _add(into: dict[str, int], more: dict[str, int]) -> None:
    for key, n in more.items():
        into[key] = into.get(key, 0) + n


def merge_finals(finals: Sequence[NetemFinal]) -> NetemFinal:
    """The final report one proxy would give, from the K proxies' (the ledger already merged)."""
    totals: dict = {}
    for f in finals:
        for key, value in f.totals.items():
            if isinstance(value, dict):
                _add(totals.setdefault(key, {}), value)
            else:
                totals[key] = totals.get(key, 0) + value
    per_sender: dict[str, dict[str, int]] = {}
    per_kind: dict[str, dict[str, int]] = {}
    for f in finals:
        for sender, counts in f.per_sender.items():
            _add(per_sender.setdefault(sender, {}), counts)
        for kind, counts in f.per_kind.items():
            _add(per_kind.setdefault(kind, {}), counts)
    return NetemFinal(
        kind="netem",
        totals=totals,
        per_sender=dict(sorted(per_sender.items(), key=lambda kv: int(kv[0]))),
        per_kind=dict(sorted(per_kind.items())),
        malformed=max(f.malformed for f in finals),  # every proxy sees every sample
        ledger=[LEDGER],
        transport=finals[0].transport,
    )


def merge_ledgers(out_dir: Path, shards: int) -> Path:
    """Write ``network_ledger.csv`` in ``out_dir`` from the proxies' parts and remove them: batch
    by batch, the rows of one key added, sorted by key as one ledger closes a tick."""
    readers = []
    for shard in range(shards):
        with open(out_dir / ledger_part(shard), newline="") as f:
            rows = csv.reader(f)
            if next(rows, None) != list(BATCH_COLUMNS):
                raise ValueError(f"{ledger_part(shard)}: not a ledger part (its header)")
            readers.append([(int(r[0]), int(r[1]), int(r[2]), r[3], r[4], int(r[5]), int(r[6])) for r in rows])
    sink = RowFile(out_dir / LEDGER, LEDGER_COLUMNS)
    batch: dict[tuple[int, int, str, str], list[int]] = {}
    at = None
    for row in heapq.merge(*readers, key=lambda r: r[0]):
        if row[0] != at:
            _write_batch(sink, batch)
            at = row[0]
        counts = batch.setdefault(row[1:5], [0, 0])
        counts[0] += row[5]
        counts[1] += row[6]
    _write_batch(sink, batch)
    sink.finish()
    for shard in range(shards):
        remove(out_dir / ledger_part(shard))
    return out_dir / LEDGER


def _write_batch(sink: RowFile, batch: dict[tuple[int, int, str, str], list[int]]) -> None:
    sink.write_many((*key, *batch[key]) for key in sorted(batch))
    batch.clear()
