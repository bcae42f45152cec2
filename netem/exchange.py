"""One tick's exchange through the radio, with no network: the agents' outputs of tick k routed,
the inboxes of tick k+1 delivered, the ledger closed for the tick, and the step the coordinator
applies. The netem proxy runs it on what arrived over Zenoh; the in-process engine
(:mod:`swarmbed.engine`) on what it stepped itself, so both book every copy the same way.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

from swarmbed.files.safefiles import rename
from swarmbed.netem.ledger import Ledger, ReceiverLog
from swarmbed.netem.radio import Radio, drop_reasons, measured
from swarmbed.netem.radio_split import BATCH_COLUMNS, merge_finals, merge_ledgers, merge_steps
from swarmbed.records.rowfile import RowFile
from swarmbed.records.run_folder import LEDGER, LEDGER_COLUMNS, RECEIVER_LEDGER, ledger_part
from swarmbed.schema.experiment import NetemSpec
from swarmbed.schema.radio_sections import WallsSection
from swarmbed.wire.codec import AgentOut, NetemStep, WorldSample, encode_inbox
from swarmbed.wire.control import NetemFinal, Transport
from swarmbed.wire.regions import by_region, owners
from swarmbed.wire.seeds import NETEM, component_rng


class Exchange:
    """The radio, its ledger (streamed to ``network_ledger.csv`` in ``out_dir``) and the running
    counters a step reports as differences."""

    def __init__(self, spec: NetemSpec, out_dir: Path, shard: int = 0) -> None:
        """``shard``: which proxy of a split radio this is (``spec.split``,
        :mod:`swarmbed.netem.radio_split`): it decides the copies of the agents in its region and
        writes its part of the ledger."""
        self.out_dir = out_dir
        self.split = spec.split if spec.split.shards > 1 else None
        self.shard = shard
        # each proxy of the split reads only the outputs of the agents it owns (no rate cap)
        self.by_region = by_region(spec.split, spec.network)
        self._owned: tuple[int, set[int]] = (-1, set())  # (tick, owned then): the proxy asks first
        if self.split is None:
            self.sink = RowFile(out_dir / LEDGER, LEDGER_COLUMNS)
        else:
            self.sink = RowFile(out_dir / ledger_part(shard), BATCH_COLUMNS)
        self.receivers: ReceiverLog | None = None
        if spec.network.ledger == "per_receiver":
            self.receivers = ReceiverLog(out_dir / (RECEIVER_LEDGER + ".part"), measured=measured(spec.network))
        self.ledger = Ledger(self.sink, self.receivers, drop_reasons(spec.network), batched=self.split is not None)
        walls = None
        if spec.obstacles is not None:
            walls = spec.obstacles.compile((spec.network.walls or WallsSection()).loss_db)
        self.radio = Radio(spec.network, spec.agents, spec.dt, component_rng(spec.seed, NETEM), self.ledger, walls)
        self._last = [0, 0, 0, 0, 0]
        self._last_drops: dict[str, int] = dict(self.ledger.dropped)

    def confirm(self) -> None:
        """The inboxes made for the tick about to be routed arrived (:meth:`Radio.confirm`)."""
        self.radio.confirm()

    def owned(self, w: WorldSample) -> set[int] | None:
        """The agents whose copies this part of a split radio decides at tick ``w.tick`` (the
        owners of :mod:`swarmbed.wire.regions`); None where the radio is not split."""
        if self.split is None:
            return None
        if self._owned[0] != w.tick:
            mine = owners(w.xs, self.split).tolist()
            self._owned = (w.tick, {a for a, o in zip(w.ids, mine, strict=True) if o == self.shard})
        return self._owned[1]

    def route(
        self,
        w: WorldSample,
        outs: Mapping[int, AgentOut],
        lost: Iterable[int] = (),
        newly_lost: list[int] | None = None,
        events: dict[str, int] | None = None,
    ) -> NetemStep:
        """Route tick ``w.tick``: the messages of ``outs`` from agents the world names, the inboxes
        of tick k+1 for those alive then and not ``lost``. ``newly_lost``: agents whose process left
        since the last step (reported once); ``events``: counts carried in (late answers)."""
        gone = set(lost)
        members = set(w.ids)
        owned = self.owned(w)
        order: dict[int, list[int]] | None = None
        if owned is not None:
            order = {}
            if self.by_region:  # what a proxy reads: its own agents' outputs (all it is sent)
                outs = {a: o for a, o in outs.items() if a in owned}
        expected = w.ids if owned is None or not self.by_region else [a for a in w.ids if a in owned]
        late = [a for a in expected if a not in outs and a not in gone]  # only ever on the real-time clock
        sent = {a: o.messages for a, o in outs.items() if a in members}
        self.radio.route(w.tick, w.ids, w.xs, w.ys, sent, owned)
        inboxes = self.radio.deliver(w.tick + 1, [a for a in w.alive_next if a not in gone], order)
        led = self.ledger
        led.close_tick(w.tick)
        self.sink.tick()
        now = [led.messages_sent, led.bytes_sent, led.copies, led.delivered, led.dropped_total]
        counters = [a - b for a, b in zip(now, self._last)]
        self._last = now
        events = dict(events or {})
        for a in sorted(outs):
            for name, n in outs[a].events.items():
                events[name] = events.get(name, 0) + n
        drops = {r: n - self._last_drops[r] for r, n in led.dropped.items() if n != self._last_drops[r]}
        self._last_drops = dict(led.dropped)
        actions = {a: o.action for a, o in outs.items() if a in members}
        lost_now = list(newly_lost or ())
        if self.shard:  # proxy 0 of a split radio carries the losses, and without regions every action
            lost_now, late = [], []
            if not self.by_region:
                actions, events = {}, {}
        return NetemStep(
            w.tick,
            actions,
            {a: encode_inbox(v) for a, v in inboxes.items()},
            counters,
            lost_now,
            events,
            drops,
            late,
            self.shard,
            order or {},
        )

    def finish(self, last_tick: int, malformed: int, transport: Transport | None = None) -> NetemFinal:
        """Close the ledger after ``last_tick`` (every copy still in flight ends dropped with its
        reason), check that it balances, put its files in place and make the final report."""
        self.radio.finish(last_tick)
        self.ledger.close_tick(1 << 62)
        self.ledger.check()
        self.sink.finish()
        files = [LEDGER if self.split is None else ledger_part(self.shard)]
        if self.receivers is not None:
            self.receivers.close()
            rename(self.out_dir / (RECEIVER_LEDGER + ".part"), self.out_dir / RECEIVER_LEDGER)
            files.append(RECEIVER_LEDGER)
        return NetemFinal(
            kind="netem",
            totals=self.ledger.totals(),
            per_sender={str(k): v for k, v in self.ledger.per_sender().items()},
            per_kind=self.ledger.per_kind(),
            malformed=malformed,
            ledger=files,
            transport=transport,
            shard=self.shard,
        )


class SplitExchange:
    """A radio split over ``spec.split.shards`` exchanges in this process, merged after each tick
    as the hub merges the proxies of a split radio (:mod:`swarmbed.netem.radio_split`): what the
    in-process engine runs for ``radio_split``, and the reference the proxies' merge is checked
    against."""

    def __init__(self, spec: NetemSpec, out_dir: Path) -> None:
        self.out_dir = out_dir
        self.parts = [Exchange(spec, out_dir, shard) for shard in range(spec.split.shards)]

    def confirm(self) -> None:
        for part in self.parts:
            part.confirm()

    def route(self, w: WorldSample, outs: Mapping[int, AgentOut]) -> NetemStep:
        return merge_steps([part.route(w, outs) for part in self.parts])

    def finish(self, last_tick: int, malformed: int) -> NetemFinal:
        finals = [part.finish(last_tick, malformed) for part in self.parts]
        merge_ledgers(self.out_dir, len(self.parts))
        return merge_finals(finals)
