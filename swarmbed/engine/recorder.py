"""A run's result files, as the coordinator records them.

During the run the time series (and, with ``run.record_trajectories``, trajectories and markers)
stream to disk in whole rows (:class:`~swarmbed.records.rowfile.RowFile`), so a long run never holds
its history in memory and a failed one keeps what it recorded as ``partial_*`` files. At the end
``agents.csv``, ``timings.json``, ``transport.json``, the swap and restart logs and, last,
``summary.json`` (checked against :class:`~swarmbed.records.summary.RunSummary`) are written whole.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

from swarmbed.engine import results
from swarmbed.extension.scenario import World
from swarmbed.records.rowfile import RowFile
from swarmbed.records.run_folder import MARKER_COLUMNS, RESTARTS, SWAPS
from swarmbed.records.summary import RunSummary
from swarmbed.schema.experiment import Experiment
from swarmbed.wire.codec import NetemStep
from swarmbed.wire.control import Final, NetemFinal, RestartRecord, SwapRecord, Transport

NETWORK_COLUMNS = ["messages_sent", "bytes_sent", "copies", "delivered", "dropped"]


class Membership(Protocol):
    """What the results say of the run's agents: the coordinator's
    :class:`~swarmbed.coordinator.lifecycle.AgentLifecycle`, or the in-process engine's."""

    lost: dict[int, int]  # agent -> tick it was lost
    swap_log: list[SwapRecord]
    restart_log: list[RestartRecord]


class Recorder:
    """The run's tables and the running totals their rows carry."""

    def __init__(self, exp: Experiment, world: World, out_dir: Path, event_names: Sequence[str]) -> None:
        self.exp = exp
        self.world = world
        self.out_dir = out_dir
        self.event_names = list(event_names)
        self.realtime = exp.run.clock == "realtime"
        self.columns = (
            list(world.row())
            + NETWORK_COLUMNS
            + self.event_names
            + (["late_agents", "start_lag_ms"] if self.realtime else [])
        )
        self.tables: dict[str, RowFile] = {}
        self.markers: dict[int, tuple[float, float, str]] = {}
        self.net_cum = [0, 0, 0, 0, 0]  # the proxy's counters of NETWORK_COLUMNS, summed over ticks
        self.drops_cum: dict[str, int] = {}
        self.event_totals: dict[str, int] = {}

    # -- while the run goes -----------------------------------------------------------------------
    def open(self) -> None:
        columns = {results.TIMESERIES: self.columns}
        if self.exp.run.record_trajectories:
            columns[results.TRAJECTORIES] = ["tick", "agent", "x", "y", "label"]
            columns[results.MARKERS] = list(MARKER_COLUMNS)
        self.tables = {name: RowFile(self.out_dir / name, cols) for name, cols in columns.items()}

    def positions(self, k: int, ids: list[int], xs: list[float], ys: list[float]) -> None:
        """Where every live agent is at tick ``k`` and the markers that changed (trajectories only)."""
        if not self.exp.run.record_trajectories:
            return
        labels = self.world.agent_labels()
        self.tables[results.TRAJECTORIES].write_many((k, i, x, y, labels.get(i, "")) for i, x, y in zip(ids, xs, ys))
        now = self.world.markers()
        markers = self.tables[results.MARKERS]
        for m in sorted(self.markers.keys() - now.keys()):
            markers.write((k, m, "", "", "", "vanish"))
        for m in sorted(now):
            if self.markers.get(m) != now[m]:
                markers.write((k, m, *now[m], "appear"))
        self.markers = now

    def step(self, step: NetemStep) -> None:
        """Add one tick's traffic and events to the running totals."""
        for name, n in step.events.items():
            self.event_totals[name] = self.event_totals.get(name, 0) + n
        self.net_cum = [c + d for c, d in zip(self.net_cum, step.counters)]
        for reason, n in step.drops.items():
            self.drops_cum[reason] = self.drops_cum.get(reason, 0) + n

    def row(self, clock: Sequence[Any] = ()) -> None:
        """The time-series row of the world's current tick (``clock``: the real-time columns)."""
        events = [self.event_totals.get(e, 0) for e in self.event_names]
        self.tables[results.TIMESERIES].write(list(self.world.row().values()) + self.net_cum + events + list(clock))

    def flush(self) -> None:
        for table in self.tables.values():
            table.tick()

    def abandon(self) -> list[Path]:
        """The run did not complete: keep the rows streamed so far as ``partial_*`` files."""
        kept = [table.abandon() for table in self.tables.values()]
        self.tables.clear()
        return [p for p in kept if p is not None]

    # -- at the end -------------------------------------------------------------------------------
    def summary(
        self,
        ticks: int,
        agents: Membership,
        reports: dict[int, Final],
        netem_report: NetemFinal,
        malformed: int,
        clock: dict | None,
    ) -> RunSummary:
        """The run's summary, checked against its model here: a run never completes with a summary
        its readers refuse."""
        exp, n = self.exp, self.exp.agents.count
        net = netem_report.totals
        agent_bytes = sum(b for r in reports.values() for _, b in r.sent.values())
        # a restarted agent's own counters begin again (or at its checkpoint): only the ledger has them all
        all_reported = len(reports) == n and not agents.restart_log
        document = {
            "name": exp.name,
            "scenario_kind": exp.scenario.kind,
            "seed": exp.run.seed,
            "allocator": exp.allocator.name,
            "agents": n,
            "ticks": ticks,
            **self.world.summary(),
            **{name: self.event_totals.get(name, 0) for name in self.event_names},
            "events": dict(sorted(self.event_totals.items())),
            "agents_lost": {str(a): t for a, t in sorted(agents.lost.items())},
            **({"agent_restarts": sum(r.outcome == "ok" for r in agents.restart_log)} if agents.restart_log else {}),
            **({"realtime": clock} if clock is not None else {}),
            "network": {
                **net,
                "per_kind": netem_report.per_kind,
                "bytes_sent_by_agents": agent_bytes if all_reported else None,
                "bytes_agree": (agent_bytes == net["bytes_sent"]) if all_reported else None,
                "malformed": {
                    "coordinator": malformed,
                    "netem": netem_report.malformed,
                    "agents": sum(r.malformed for r in reports.values()),
                },
            },
        }
        return RunSummary.of(document)

    @staticmethod
    def transport(summary: RunSummary, reports: dict[int, Final], netem_report: NetemFinal) -> dict:
        """TCP bytes each process of the run measured on its own sockets, beside the radio payload
        bytes of the ledger (see :mod:`swarmbed.wire.tcp_counters` for what they count).

        Every link of a run has the hub (the coordinator's router) at one end, so measuring each
        client's end counts every byte once: what the clients sent is what the hub received, and
        the other way round; the hub's own sockets are not read (they would count it all twice)."""

        def measured(transport: Transport | None) -> dict:
            return transport.model_dump(by_alias=True, exclude_none=True) if transport is not None else {}

        processes: dict[str, dict] = {"netem": measured(netem_report.transport)}
        for i in sorted(reports):
            processes[f"agent_{i}"] = measured(reports[i].transport)
        agents = [p for name, p in processes.items() if name.startswith("agent_")]
        payload = summary.network.bytes_sent

        def total(of: list[dict], layer: str, field: str) -> int | None:
            values = [(p.get(layer) or {}).get(field) for p in of]
            known = [int(v) for v in values if v is not None]
            return sum(known) if values and len(known) == len(values) else None

        agents_sent = total(agents, "tcp", "sent")
        everyone = list(processes.values())
        totals = {
            "radio_payload_bytes": payload,
            "agent_sample_bytes_out": total(agents, "samples", "out"),
            "agent_sample_bytes_in": total(agents, "samples", "in"),
            "agent_tcp_bytes_sent": agents_sent,
            "agent_tcp_bytes_received": total(agents, "tcp", "received"),
            "tcp_bytes_sent": total(everyone, "tcp", "sent"),
            "tcp_bytes_received": total(everyone, "tcp", "received"),
            "overhead_ratio": agents_sent / payload if agents_sent is not None and payload else None,
            "agents_reporting": len(agents),
        }
        return {"totals": totals, "processes": processes}

    def write(
        self,
        summary: RunSummary,
        timings: dict,
        agents: Membership,
        reports: dict[int, Final],
        netem_report: NetemFinal,
    ) -> None:
        """Close the streamed tables and write the rest, ``summary.json`` last."""
        out, n = self.out_dir, self.exp.agents.count
        per_sender = netem_report.per_sender
        for table in self.tables.values():
            table.finish()
        self.tables.clear()
        columns = self.world.per_agent()
        net_cols = ["messages", "bytes", "copies", "delivered"]
        rows = []
        for i in range(n):
            s = per_sender.get(str(i), {})
            rows.append(
                [i, int(i not in agents.lost), agents.lost.get(i, "")]
                + [col[i] for col in columns.values()]
                + [s.get(c, 0) for c in net_cols]
            )
        results.write_csv(
            out / results.AGENTS,
            ["agent", "alive", "lost_at_tick", *columns, "messages_sent", "bytes_sent", "copies", "delivered"],
            rows,
        )
        results.write_json(out / results.TIMINGS, timings)
        results.write_json(out / results.TRANSPORT, self.transport(summary, reports, netem_report))
        if agents.swap_log:  # wall-clock pauses: not among the files that repeat byte for byte
            results.write_csv(out / SWAPS, SwapRecord.columns(), [r.row() for r in agents.swap_log])
        if agents.restart_log:
            results.write_csv(out / RESTARTS, RestartRecord.columns(), [r.row() for r in agents.restart_log])
        results.write_json(out / results.SUMMARY, summary.document)
