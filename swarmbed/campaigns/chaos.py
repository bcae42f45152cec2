"""Faults injected into a running experiment, from YAML, seeded, each logged with how it ended.

A chaos file lists events; each happens at listed wall times (``at``, seconds after the run got
under way) or at a rate (``every``: the mean wall seconds between two, exponential gaps)::

    seed: 3                 # optional: the run's seed otherwise
    events:
      - action: kill_agent  # SIGKILL one live agent, drawn at random (or from `agents`)
        every: 20
      - action: stop_agent  # SIGSTOP one, SIGCONT it `for` seconds later
        at: [15, 40]
        for: 2
      - action: loss_burst  # the radio loses copies with probability `loss` for `for` seconds
        every: 30
        for: 5
        loss: 0.5
      - action: rate_cap    # the radio's per-sender rate cap (bytes per simulated second)
        at: [25]
        for: 10
        rate: 200
      - action: cut_host    # a host's network links down for `for` seconds (or from `hosts`)
        at: [30]
        for: 5

Radio changes reach the netem proxy on its control key and take effect from a tick after the one
under way (:class:`~swarmbed.wire.codec.NetemControl`); the copies they drop are booked in the
ledger like any other. While one is in force a second replaces it; its end restores the run's own
parameters. Only agents that run on this machine are signalled. An agent stopped longer than
Zenoh's lease (10 s) loses its session: keep ``for`` short for ``stop_agent``.

``cut_host`` needs several hosts, and reaches those that are stand-ins on this machine: a host
daemon in a network namespace of its own (:mod:`.netns`; root). Every link of the namespace but
loopback goes down for the window and comes back with its routes. Shorter than Zenoh's lease, the
links' TCP connections survive and the host's agents answer late (lock-step waits for them, up to
``run.tick_timeout``); longer, its sessions are closed and its agents are lost, restarted or fail
the run as ``run.on_agent_loss`` says. The outcome says which.

``chaos.csv`` gets one row per event once its ending is known: wall seconds, tick, action,
target, detail, outcome. An event is not started unless its window ends before the run does; one
whose ending is still within its allowance (its window plus ``RESOLVE_WITHIN``) when the run ends
(a kill moments before the end, say) is logged as cut short, which is not a breach; one whose
allowance ran out without an ending is unresolved, which is.
"""

from __future__ import annotations

import heapq
import logging
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from swarmbed.files.yamlfile import YamlFileError, read_yaml
from swarmbed.hosts import netns
from swarmbed.launch.runner import LiveRun
from swarmbed.records.rowfile import RowFile
from swarmbed.results.campaign_folders import CHAOS as CHAOS_FILE
from swarmbed.schema.experiment import Experiment
from swarmbed.wire.child_process import process_name
from swarmbed.wire.codec import NetemControl, encode_netem_control
from swarmbed.wire.regions import by_region
from swarmbed.wire.validation import validation_lines

log = logging.getLogger("swarmbed.chaos")
CHAOS_COLUMNS = ["wall_s", "tick", "action", "target", "detail", "outcome"]
RESOLVE_WITHIN = 30.0  # wall seconds an event's ending is waited for before it is called unresolved
CUT_SHORT = "cut short: the run ended before its ending was due"


class ChaosError(ValueError):
    """A chaos file that cannot be used; the message names the file and the entry."""


class ChaosEvent(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)
    action: Literal["kill_agent", "stop_agent", "loss_burst", "rate_cap", "cut_host"]
    at: list[float] = Field(default_factory=list, description="wall seconds after the run got under way")
    every: float | None = Field(None, gt=0, description="mean wall seconds between two (exponential gaps)")
    duration: float = Field(0.0, ge=0, alias="for", description="seconds a stop or a radio change lasts")
    agents: list[int] | None = Field(None, description="draw targets from these agents only")
    hosts: list[str] | None = Field(None, description="cut_host: draw from these hosts only")
    loss: float | None = Field(None, ge=0, le=1)
    rate: float | None = Field(None, gt=0)

    @model_validator(mode="after")
    def _complete(self) -> ChaosEvent:
        if not self.at and self.every is None:
            raise ValueError("give `at` (wall seconds) or `every` (mean seconds between two)")
        if self.action in ("stop_agent", "loss_burst", "rate_cap", "cut_host") and self.duration <= 0:
            raise ValueError(f"{self.action} needs `for` (seconds it lasts)")
        if self.action == "loss_burst" and self.loss is None:
            raise ValueError("loss_burst needs `loss` (probability a copy is lost)")
        if self.action == "rate_cap" and self.rate is None:
            raise ValueError("rate_cap needs `rate` (bytes per simulated second)")
        return self


class ChaosPlan(BaseModel):
    model_config = ConfigDict(extra="forbid")
    seed: int | None = Field(None, ge=0, description="seed of the draws; the run's seed when absent")
    events: list[ChaosEvent] = Field(default_factory=list)


def check_plan(plan: ChaosPlan, exp: Experiment) -> None:
    """Refuse, in one line, a plan the experiment cannot take: a rate cap in a radio split by region
    (:func:`swarmbed.wire.regions.by_region`), whose proxies keep no transmit queue of senders
    outside their region."""
    if any(event.action == "rate_cap" for event in plan.events) and by_region(exp.radio_split, exp.network):
        raise ChaosError(
            "rate_cap: the radio is split by region (radio_split.shards > 1 and no network.rate), so no proxy "
            "keeps the transmit queues of senders outside its region; set network.rate (every proxy then reads "
            "every output) or leave rate_cap out"
        )


def load_chaos(path: Path) -> ChaosPlan:
    try:
        data = read_yaml(path)
    except YamlFileError as exc:
        raise ChaosError(str(exc)) from None
    try:
        return ChaosPlan.model_validate(data or {})
    except ValidationError as exc:
        where = "; ".join(validation_lines(exc, ChaosPlan))
        raise ChaosError(f"{path}: {where}") from None


@dataclass(order=True)
class _Due:
    at: float
    order: int
    event: ChaosEvent = field(compare=False)
    kind: str = field(compare=False, default="begin")  # begin | end (of a stop or a radio change)
    data: dict[str, Any] = field(compare=False, default_factory=dict)


class Chaos:
    """Runs a :class:`ChaosPlan` against a live run (a :class:`~swarmbed.launch.runner.RunObserver`)."""

    def __init__(self, plan: ChaosPlan, horizon_s: float, seed: int) -> None:
        self.plan = plan
        self.horizon_s = horizon_s
        self.rng = np.random.default_rng(
            np.random.SeedSequence(plan.seed if plan.seed is not None else seed).spawn(1)[0]
        )
        self.rows: list[list[Any]] = []  # every resolved event (also in chaos.csv)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._pending: list[tuple[float, dict[str, Any]]] = []  # (give up at, record)
        self._stopped: set[int] = set()  # pids SIGSTOPped and not yet continued
        self._radio_label: str | None = None
        self._cut: dict[str, netns.Cut] = {}  # host -> its links taken down, until the window ends

    # -- schedule ------------------------------------------------------------------------------
    def schedule(self) -> list[_Due]:
        """Every event whose window ends within the horizon, in time order (drawn once, from the seed).

        A stop or a radio change that would still be in force when the run ends is left out: its
        ending could not be seen, so it would test nothing.
        """
        due: list[_Due] = []
        for i, event in enumerate(self.plan.events):
            last_start = self.horizon_s - event.duration
            times = [t for t in event.at if t <= last_start]
            if event.every is not None:
                t = float(self.rng.exponential(event.every))
                while t <= self.horizon_s:  # every draw is taken, so the sequence does not hang on `for`
                    if t <= last_start:
                        times.append(t)
                    t += float(self.rng.exponential(event.every))
            due += [_Due(t, i, event) for t in times]
        return sorted(due)

    # -- observer ------------------------------------------------------------------------------
    def start(self, run: LiveRun) -> None:
        self.run = run
        self.table = RowFile(run.out_dir / CHAOS_FILE, CHAOS_COLUMNS, chunk_rows=1)
        self.control = run.session.declare_publisher(run.keys.netem_control)
        self.t0 = time.monotonic()
        self._thread = threading.Thread(target=self._loop, name="chaos", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)
        for pid in list(self._stopped):  # never leave a process stopped, nor a host cut off
            self._signal(pid, signal.SIGCONT)
        for cut in self._cut.values():
            netns.reconnect(cut)
        self._cut.clear()
        self._resolve(final=True)
        self.table.finish()
        self.control.undeclare()

    # -- the loop ------------------------------------------------------------------------------
    def _loop(self) -> None:
        queue = self.schedule()
        heapq.heapify(queue)
        order = len(queue)
        while not self._stop.is_set():
            now = time.monotonic() - self.t0
            while queue and queue[0].at <= now:
                due = heapq.heappop(queue)
                try:
                    end = self._act(due)
                except Exception as exc:  # a fault that could not be injected is logged, never fatal
                    log.exception("chaos: %s failed", due.event.action)
                    self._record(due, "", "", f"not injected: {exc}")
                    end = None
                if end is not None:
                    order += 1
                    heapq.heappush(queue, _Due(due.at + due.event.duration, order, due.event, "end", end))
            self._resolve()
            self._stop.wait(0.05)

    def _act(self, due: _Due) -> dict[str, Any] | None:
        event, live = due.event, self.run.coordinator.live()
        if due.kind == "end":
            if event.action == "stop_agent":
                self._signal(due.data["pid"], signal.SIGCONT)
                due.data["record"]["resumed_tick"] = live.tick
            elif event.action == "cut_host":
                netns.reconnect(due.data["cut"])
                self._cut.pop(due.data["record"]["target"], None)
                due.data["record"]["end_tick"] = live.tick
            else:
                self._radio(NetemControl(live.tick + 2, {}, f"end of {event.action}"))
                due.data["record"]["end_tick"] = live.tick + 2
                due.data["record"]["drops_end"] = dict(live.drops)
            due.data["record"]["ended"] = True
            return None
        if event.action in ("kill_agent", "stop_agent"):
            target = self._draw_agent(event)
            if target is None:
                self._record(due, "", "", "skipped: no live local agent")
                return None
            agent, pid = target
            if event.action == "kill_agent":
                self._signal(pid, signal.SIGKILL)
                self._pend(due, agent, f"SIGKILL pid {pid}", {"kind": "kill", "agent": agent, "tick": live.tick})
                return None
            self._signal(pid, signal.SIGSTOP)
            late_before = live.late_ticks.get(agent, 0)
            record = self._pend(
                due,
                agent,
                f"SIGSTOP pid {pid} for {event.duration:g} s",
                {"kind": "stop", "agent": agent, "tick": live.tick, "late_before": late_before, "ended": False},
            )
            return {"pid": pid, "record": record}
        if event.action == "cut_host":
            return self._cut_host(due)
        overrides = {"loss": event.loss} if event.action == "loss_burst" else {"rate": event.rate}
        start = live.tick + 2
        self._radio(NetemControl(start, overrides, event.action))
        detail = ", ".join(f"{k} {v:g}" for k, v in overrides.items()) + f" for {event.duration:g} s"
        record = self._pend(
            due,
            "netem",
            detail,
            {"kind": "radio", "start_tick": start, "ended": False, "drops_start": dict(live.drops)},
        )
        return {"record": record}

    def _draw_agent(self, event: ChaosEvent) -> tuple[int, int] | None:
        live, procs = self.run.coordinator.live(), self.run.children.procs
        candidates = []
        for agent in event.agents if event.agents is not None else range(self.run.coordinator.n):
            if agent in live.lost or agent in live.down or agent not in live.alive:
                continue
            proc = procs.get(process_name(agent, live.incarnation.get(agent, 0)))
            if proc is not None and proc.poll() is None and proc.pid not in self._stopped:
                candidates.append((agent, proc.pid))
        if not candidates:
            return None
        return candidates[int(self.rng.integers(len(candidates)))]

    def _cut_host(self, due: _Due) -> dict[str, Any] | None:
        live = self.run.coordinator.live()
        candidates = []
        for host, info in sorted(self.run.hosts.items()):
            ns = netns.namespace_of(info.pid) if info is not None else None
            if ns is not None and host not in self._cut and (due.event.hosts is None or host in due.event.hosts):
                candidates.append((host, ns))
        if not candidates:
            self._record(due, "", "", "skipped: no host of this run in a network namespace of its own here")
            return None
        host, ns = candidates[int(self.rng.integers(len(candidates)))]
        cut = netns.cut_off(ns)
        self._cut[host] = cut
        agents = sorted(a for a, h in live.hosts.items() if h == host)
        record = self._pend(
            due,
            host,
            f"{', '.join(cut.links)} of {ns} down for {due.event.duration:g} s",
            {
                "kind": "cut",
                "tick": live.tick,
                "agents": agents,
                "ended": False,
                "restarts_before": len(live.restarts),
            },
        )
        return {"cut": cut, "record": record}

    def _signal(self, pid: int, sig: int) -> None:
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            pass
        if sig == signal.SIGSTOP:
            self._stopped.add(pid)
        elif sig == signal.SIGCONT:
            self._stopped.discard(pid)

    def _radio(self, control: NetemControl) -> None:
        self.control.put(encode_netem_control(control))

    # -- outcomes ------------------------------------------------------------------------------
    def _pend(self, due: _Due, target: Any, detail: str, state: dict[str, Any]) -> dict[str, Any]:
        record = {"wall_s": round(due.at, 3), "action": due.event.action, "target": target, "detail": detail, **state}
        self._pending.append((time.monotonic() + due.event.duration + RESOLVE_WITHIN, record))
        return record

    def _cut_outcome(self, record: dict[str, Any]) -> str | None:
        """Once ticks go on after the window: what became of the host's agents."""
        live = self.run.coordinator.live()
        if live.tick <= record["end_tick"] + 1 or any(a in live.down for a in record["agents"]):
            return None
        restarts = [r for r in live.restarts[record["restarts_before"] :] if r.agent in record["agents"]]
        ok = sorted({r.agent for r in restarts if r.outcome == "ok"})
        lost = sorted(a for a in record["agents"] if live.lost.get(a, -1) >= record["tick"])
        went = f"ticks {record['tick']}-{record['end_tick']} during the cut"
        if not ok and not lost:
            return f"reconnected, every agent kept its session ({went})"
        return f"{went}; agents restarted: {ok or 'none'}; agents lost: {lost or 'none'}"

    def _record(self, due: _Due, target: Any, detail: str, outcome: str) -> None:
        self._write(
            {
                "wall_s": round(due.at, 3),
                "tick": self.run.coordinator.live().tick,
                "action": due.event.action,
                "target": target,
                "detail": detail,
            },
            outcome,
        )

    def _write(self, record: dict[str, Any], outcome: str) -> None:
        row = [
            record["wall_s"],
            record.get("tick", record.get("start_tick", "")),
            record["action"],
            record["target"],
            record["detail"],
            outcome,
        ]
        self.rows.append(row)
        self.table.write(row)

    def _resolve(self, final: bool = False) -> None:
        still = []
        for give_up, record in self._pending:
            outcome = self._outcome(record)
            if outcome is None and (final or time.monotonic() > give_up):
                # a run that ended inside the time an ending is given cut it short: not a fault's failure
                expired = time.monotonic() > give_up
                outcome = f"unresolved: no ending within {RESOLVE_WITHIN:g} s" if expired else CUT_SHORT
            if outcome is None:
                still.append((give_up, record))
            else:
                self._write(record, outcome)
        self._pending = still

    def _outcome(self, record: dict[str, Any]) -> str | None:
        coord = self.run.coordinator
        live = coord.live()
        if record["kind"] == "kill":
            agent = record["agent"]
            for r in live.restarts:
                if r.agent == agent and r.lost_at_tick >= record["tick"] and r.outcome != "retrying":
                    if r.outcome != "ok":
                        return f"restart failed: {r.reason}"
                    source = f"checkpoint of tick {r.checkpoint_tick}" if r.checkpoint_tick != "" else "fresh"
                    return f"restarted before tick {r.tick} ({source}, {r.wait_ms:.0f} ms)"
            if agent in live.lost:
                return f"lost at tick {live.lost[agent]} (on_agent_loss: {coord.exp.run.agent_loss})"
            return None
        if not record["ended"]:
            return None
        if record["kind"] == "stop":
            agent = record["agent"]
            if agent in live.lost:
                return f"lost at tick {live.lost[agent]}"
            if live.tick <= record["resumed_tick"] + 1:
                return None  # resumed: wait until it answered a tick again
            late = live.late_ticks.get(agent, 0) - record["late_before"]
            waited = f", {late} late ticks" if coord.exp.run.clock == "realtime" else ""
            return f"resumed at tick {record['resumed_tick']}{waited}"
        if record["kind"] == "cut":
            return self._cut_outcome(record)
        if live.tick < record["end_tick"]:
            return None
        drops = {k: v - record["drops_start"].get(k, 0) for k, v in record["drops_end"].items()}
        booked = ", ".join(f"{n} {reason}" for reason, n in sorted(drops.items()) if n) or "no drops"
        return f"in force ticks {record['start_tick']}-{record['end_tick'] - 1}: {booked}"
