"""The coordinator: owns simulated time and the world, drives the clock (lock-step or real-time).

Tick k: publish the world (positions, membership) to the proxy and one input sample to every live
agent (its observation and its inbox of tick k); wait for the proxy's step (every live agent's
action and message of tick k taken, or on the real-time clock those that came before the
deadline); apply the actions; record. On the real-time clock tick k starts at its wall time.
The coordinator's session is the run's Zenoh hub: it listens, everyone else connects to it as a
client.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from array import array
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from swarmbed.coordinator import results
from swarmbed.coordinator.tickets import Tickets
from swarmbed.extension.actions import admit
from swarmbed.extension.scenario import Scenario
from swarmbed.wire.codec import (
    EMPTY_INBOX,
    TAG_CHECKPOINT,
    TAG_RESUME,
    TAG_RETIRE,
    TAG_SNAPSHOT,
    NetemStep,
    WireError,
    WorldSample,
    decode_handover,
    decode_netem_step,
    decode_report,
    encode_control,
    encode_netem_stop,
    encode_status,
    encode_stop,
    encode_tick,
    encode_world,
)
from swarmbed.wire.keys import Keys, agent_id_of, alive_agent_of, incarnation_of
from swarmbed.wire.lifecycle import WORLD, component_rng
from swarmbed.wire.membership import accept_handovers, serve_text
from swarmbed.wire.rowfile import RowFile
from swarmbed.wire.rundir import RESTARTS, SWAPS
from swarmbed.wire.schema import LOCAL, Experiment, Targets, agent_spec, netem_spec

BLOCK = zenoh.CongestionControl.BLOCK
log = logging.getLogger("swarmbed.coordinator")
STATUS_EVERY = 0.25  # wall seconds between progress samples for watchers
CONSUMED = object()  # what an event filter of Coordinator._wait_for returns for an event it used
RESTART_COLUMNS = [
    "tick",
    "agent",
    "lost_at_tick",
    "incarnation",
    "host",
    "checkpoint_tick",
    "outcome",
    "reason",
    "wait_ms",
]


class RunError(RuntimeError):
    """The run cannot go on; the message says which process, at which tick, and where its log is."""


class Coordinator:
    """Drives one run. The launcher hands it the experiment, the scenario built from it, the
    allocator class (for the traits the world and the results read, such as ``event_names``) and
    the targets agents load."""

    def __init__(
        self,
        exp: Experiment,
        scenario: Scenario,
        allocator: type,
        targets: Targets,
        keys: Keys,
        session: zenoh.Session,
        out_dir: Path,
        hosts: dict[int, str] | None = None,
        carriers: Mapping[str, frozenset[int]] | None = None,
    ) -> None:
        self.exp = exp
        self.scenario = scenario
        self.targets = targets
        self.keys = keys
        self.session = session
        self.out_dir = out_dir
        self.n = exp.agents.count
        self.hosts = hosts or {}  # agent -> host it runs on, where not on this machine
        # host -> agents the hub lets it carry (wire.schema.carriers); None: no access control
        self.carriers = carriers
        self.world = scenario.make_world(component_rng(exp.run.seed, WORLD), allocator)
        self.event_names = list(getattr(allocator, "event_names", ()))
        self.event_totals: dict[str, int] = {}
        self.events: queue.SimpleQueue[tuple[str, Any]] = queue.SimpleQueue()  # (what, data) from Zenoh callbacks
        self.joined: set[str] = set()
        self.lost: dict[int, int] = {}  # agent -> tick at which it was lost
        self.retired: set[int] = set()  # lost by the scenario (agent loss), not by a crash
        self.fatal: dict[int, dict] = {}
        self.reports: dict[int, dict] = {}
        self.netem_report: dict | None = None
        self.malformed = 0
        # the time series (and trajectories, markers) stream to disk as the run goes (see run())
        self.tables: dict[str, RowFile] = {}
        self._markers: dict[int, tuple[float, float, str]] = {}
        self.realtime = exp.run.clock == "realtime"
        self._row_columns = (
            list(self.world.row())
            + ["messages_sent", "bytes_sent", "copies", "delivered", "dropped"]
            + self.event_names
            + (["late_agents", "start_lag_ms"] if self.realtime else [])
        )
        self.net_cum = [0, 0, 0, 0, 0]
        self.drops_cum: dict[str, int] = {}
        # the real-time clock's own accounting (wall-clock facts: never part of a lock-step run's files)
        self.late_ticks: dict[int, int] = {}  # agent -> ticks it missed
        self.start_lags = array("d")  # wall seconds each tick started after its time
        self.last_action: dict[int, list] = {}
        self.last_tick = -1
        self.wall: dict[str, float] = {}
        # for soak monitors (wall-clock facts, never in a run's result files)
        self.stop_requested = threading.Event()  # end the run after the tick under way (soak's duration)
        self.tick_started = 0.0  # perf_counter at the start of the tick under way
        self.slowest_tick = (0.0, -1)  # (wall seconds, tick): the longest a tick took from start to start
        self.slowest_in_interval = 0.0  # the same since a monitor last read it (and set it to 0)
        self._entities: list = []
        self._pushback: list[tuple[str, Any]] = []
        # moving agents between processes (swaps)
        self.incarnation: dict[int, int] = {}  # agent -> its current process, where not the first (0)
        self.snapshots: dict[int, bytes] = {}  # agent -> the snapshot its old process handed over
        self.tickets = Tickets()  # what state the coordinator asked for, and of whom
        self.swaps_due: dict[int, list[tuple[int, str]]] = {}  # tick -> (agent, host), scripted
        for entry in exp.swaps:
            self.swaps_due.setdefault(entry.tick, []).append((entry.agent, entry.to))
        self.swap_requests: queue.SimpleQueue[tuple[int, str, int]] = queue.SimpleQueue()  # (agent, host, number)
        self.swap_log: list[dict[str, Any]] = []
        self.requested_swaps: dict[int, dict[str, Any] | None] = {}  # number -> its record once done
        # agents whose process died, started again (run.on_agent_loss: restart)
        self.down: dict[int, int] = {}  # agent -> tick its process was found dead, until it is restarted
        self.restart_tries: dict[int, tuple[int, float]] = {}  # agent down -> (failed tries, next try, monotonic s)
        self.checkpoints: dict[int, tuple[int, bytes]] = {}  # agent -> (tick, state) of its last checkpoint
        self.restart_log: list[dict[str, Any]] = []
        # place(agent, host, incarnation, restore) starts a process (restoring the snapshot held for it,
        # or fresh); unplace(...) stops one (the runner's)
        self.place: Callable[..., None] | None = None
        self.unplace: Callable[[int, str, int], None] | None = None
        # exit_status(process name) says how a local child ended and how its log ends (the runner's)
        self.exit_status: Callable[[str], str] | None = None

    # -- setup -----------------------------------------------------------------------------------
    def declare(self) -> None:
        s, k, put = self.session, self.keys, self.events.put
        self._entities += [
            serve_text(s, k.agent_config, agent_spec(self.exp, self.targets).model_dump_json()),
            serve_text(s, k.netem_config, netem_spec(self.exp).model_dump_json()),
            s.declare_subscriber(k.netem_step, lambda x: put(("step", x.payload.to_bytes()))),
            accept_handovers(s, k.agent_report_all, lambda key, data: put(("report", (key, data)))),
            accept_handovers(s, k.netem_report, lambda _key, data: put(("netem_report", data))),
            s.liveliness().declare_subscriber(k.alive_all, self._on_alive, history=True),
            s.declare_queryable(k.agent_snapshot_all, self._on_snapshot_query),
            s.declare_queryable(k.swap, self._on_swap_query),
        ]
        self.agent_pubs = [s.declare_publisher(k.agent_in(i), congestion_control=BLOCK) for i in range(self.n)]
        self.world_pub = s.declare_publisher(k.world, congestion_control=BLOCK)
        self.stop_pub = s.declare_publisher(k.netem_stop, congestion_control=BLOCK)
        # progress for watchers: dropped rather than waited for when a watcher is slow (never blocks a tick)
        self.status_pub = s.declare_publisher(k.status, congestion_control=zenoh.CongestionControl.DROP)
        self._entities += self.agent_pubs + [self.world_pub, self.stop_pub, self.status_pub]
        self._entities.append(s.liveliness().declare_token(k.alive_coordinator))

    def _on_alive(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        if key not in (self.keys.alive_netem, self.keys.alive_coordinator):
            try:
                alive_agent_of(key, self.keys.root, self.n)
            except WireError as exc:  # a token no process of this run holds: never taken for one
                self._malformed(key, exc)
                return
        self.events.put(("join" if sample.kind == zenoh.SampleKind.PUT else "leave", key))

    def _on_snapshot_query(self, query: zenoh.Query) -> None:
        """An old process hands its snapshot over (payload), or the new one fetches it (none)."""
        try:
            agent = agent_id_of(str(query.key_expr))
        except ValueError:
            query.reply_err("no agent in the key")
            return
        if query.payload is not None:
            try:
                ticket, state = decode_handover(query.payload.to_bytes())
            except WireError as exc:
                self._malformed(str(query.key_expr), exc)
                query.reply_err(f"malformed snapshot handover: {exc}")
                return
            if not self.tickets.redeem("snapshot", agent, ticket):
                log.warning("coordinator: refused a snapshot of agent %d that was not asked for", agent)
                query.reply_err(f"no snapshot of agent {agent} was asked for")
                return
            self.snapshots[agent] = state
            query.reply(query.key_expr, b"ok")
            self.events.put(("snapshot", agent))
        elif agent in self.snapshots:
            query.reply(query.key_expr, self.snapshots[agent])
        else:
            query.reply_err(f"no snapshot of agent {agent} is held")

    def _on_swap_query(self, query: zenoh.Query) -> None:
        """``{"agent": I, "to": HOST}`` queues a swap before the next tick and answers its number;
        ``{"swap": N}`` answers swap N's record once it is done (``{"pending": true}`` before)."""
        try:
            req = json.loads(query.payload.to_bytes()) if query.payload is not None else None
            if isinstance(req, dict) and isinstance(req.get("swap"), int):
                record = self.requested_swaps.get(req["swap"])
                answer: dict[str, Any] = record if record is not None else {"pending": True}
            elif (
                isinstance(req, dict)
                and isinstance(req.get("agent"), int)
                and 0 <= req["agent"] < self.n
                and isinstance(req.get("to"), str)
                and req["to"]
            ):
                number = len(self.requested_swaps)
                self.requested_swaps[number] = None
                self.swap_requests.put((req["agent"], req["to"], number))
                answer = {"queued": number}
            else:
                answer = {"error": f'a swap request is {{"agent": 0..{self.n - 1}, "to": HOST}}'}
        except ValueError as exc:
            answer = {"error": f"not JSON: {exc}"}
        query.reply(query.key_expr, json.dumps(answer))

    def close(self) -> None:
        for e in reversed(self._entities):
            try:
                e.undeclare()
            except Exception:
                pass
        self._entities.clear()

    def _who(self, key: str) -> str:
        return "netem" if key == self.keys.alive_netem else f"agent_{agent_id_of(key)}"

    def wait_for_members(self, check_children: Callable[[], None]) -> None:
        """Until the proxy and every agent hold a liveliness token; ``check_children`` raises if a
        launched process already exited."""
        wanted = {"netem"} | {f"agent_{i}" for i in range(self.n)}
        deadline = time.monotonic() + self.exp.run.join_timeout
        while not wanted <= self.joined:
            check_children()
            if time.monotonic() > deadline:
                missing = sorted(wanted - self.joined)
                raise RunError(
                    f"not joined after {self.exp.run.join_timeout:.0f} s: {', '.join(missing[:10])}"
                    f"{' ...' if len(missing) > 10 else ''}"
                )
            try:
                what, data = self.events.get(timeout=0.1)
            except queue.Empty:
                continue
            if what == "join" and not data.endswith("/coordinator"):
                self.joined.add(self._who(data))
            elif what == "leave" and not data.endswith("/coordinator"):
                self.joined.discard(self._who(data))
            elif what == "report":
                self._on_report(data, tick=-1)

    def _record_markers(self, k: int) -> None:
        """Rows for the markers that appeared, changed or vanished since the last recorded tick."""
        now = self.world.markers()
        markers = self.tables[results.MARKERS]
        for m in sorted(self._markers.keys() - now.keys()):
            markers.write((k, m, "", "", "", "vanish"))
        for m in sorted(now):
            if self._markers.get(m) != now[m]:
                markers.write((k, m, *now[m], "appear"))
        self._markers = now

    # -- the tick loop (lock-step, or paced by the wall on the real-time clock) -----------------------
    def _open_tables(self) -> None:
        columns = {results.TIMESERIES: self._row_columns}
        if self.exp.run.record_trajectories:
            columns[results.TRAJECTORIES] = ["tick", "agent", "x", "y", "label"]
            columns[results.MARKERS] = ["tick", "marker", "x", "y", "label", "event"]
        self.tables = {name: RowFile(self.out_dir / name, cols) for name, cols in columns.items()}

    def abandon_tables(self) -> list[Path]:
        """The run did not complete: keep the rows streamed so far as ``partial_*`` files."""
        kept = [table.abandon() for table in self.tables.values()]
        self.tables.clear()
        return [p for p in kept if p is not None]

    def run(self, on_tick: Callable[[int, float], None] | None = None) -> None:
        w, r = self.world, self.exp.run
        self._open_tables()
        series = self.tables[results.TIMESERIES]
        inboxes: dict[int, bytes] = {}
        t0 = status_at = time.perf_counter()
        period = r.dt / r.speed  # wall seconds per tick on the real-time clock
        for k in range(self.exp.ticks):
            if (w.finished and self.exp.run.stop_when_done) or self.stop_requested.is_set():
                break
            now = time.perf_counter()
            if k:
                took = now - self.tick_started
                self.slowest_in_interval = max(self.slowest_in_interval, took)
                if took > self.slowest_tick[0]:
                    self.slowest_tick = (took, k - 1)
            self.tick_started = now
            if self.realtime:
                lag = time.perf_counter() - (t0 + k * period)
                if lag < 0:
                    time.sleep(-lag)
                    lag = time.perf_counter() - (t0 + k * period)
                self.start_lags.append(max(lag, 0.0))
            ids, xs, ys = w.positions()
            if self.exp.run.record_trajectories:
                labels = w.agent_labels()
                self.tables[results.TRAJECTORIES].write_many(
                    (k, i, x, y, labels.get(i, "")) for i, x, y in zip(ids, xs, ys)
                )
                self._record_markers(k)
            if k > 0:
                self._swap_due(k)
                self._restart_due(k)
                if r.snapshot_every and k % r.snapshot_every == 0 and r.agent_loss == "restart":
                    self._ask_checkpoints()
            doomed = w.draw_losses()  # lost at tick k+1: the proxy must not deliver to them then
            incarnations = {a: i for a, i in self.incarnation.items() if i}
            alive_next = [i for i in ids if i not in doomed]
            self.world_pub.put(encode_world(WorldSample(k, ids, xs, ys, alive_next, incarnations)))
            for i, obs in w.observations().items():
                self.agent_pubs[i].put(encode_tick(k, obs.to_wire(), inboxes.get(i, EMPTY_INBOX)))
            step = self._await_step(k)
            for j in step.lost:
                self._lose(j, k, "its process exited")
            actions = step.actions
            if step.late:
                for a in step.late:
                    self.late_ticks[a] = self.late_ticks.get(a, 0) + 1
                if r.on_late == "hold":  # the robot keeps its last command; "stop": the world's default
                    actions = {**{a: self.last_action[a] for a in step.late if a in self.last_action}, **actions}
            if self.realtime:
                self.last_action.update(actions)
            declared = self.scenario.actions  # a world sees only actions of the shapes its scenario declares
            w.apply({a: admit(act, declared) for a, act in actions.items() if w.alive[a]})
            for name, n in step.events.items():
                self.event_totals[name] = self.event_totals.get(name, 0) + n
            for j in doomed:
                self._retire(j, k + 1)
            inboxes = step.inboxes
            self.net_cum = [c + d for c, d in zip(self.net_cum, step.counters)]
            for reason, n in step.drops.items():
                self.drops_cum[reason] = self.drops_cum.get(reason, 0) + n
            self.last_tick = k
            if w.tick % self.exp.run.record_every == 0 or w.finished:
                row = w.row()
                events = [self.event_totals.get(e, 0) for e in self.event_names]
                clock = [len(step.late), round(1000 * self.start_lags[-1], 3)] if self.realtime else []
                series.write(list(row.values()) + self.net_cum + events + clock)
            if on_tick:
                on_tick(w.tick, w.time)
            if time.perf_counter() - status_at >= STATUS_EVERY:
                status_at = time.perf_counter()
                self._publish_status(status_at - t0)
                for table in self.tables.values():
                    table.tick()
        self._publish_status(time.perf_counter() - t0)
        self.wall["run_s"] = time.perf_counter() - t0

    def _publish_status(self, wall_s: float) -> None:
        """Where the run is, for ``swarmbed watch`` (wall-clock paced: never part of the results)."""
        w = self.world
        self.status_pub.put(
            encode_status(
                {
                    "name": self.exp.name,
                    "scenario": self.exp.scenario.kind,
                    "allocator": self.exp.allocator.name,
                    "tick": self.last_tick,
                    "time": w.time,
                    "ticks": self.exp.ticks,
                    "wall_s": wall_s,
                    "row": w.row(),
                    "network": dict(
                        zip(("messages_sent", "bytes_sent", "copies", "delivered", "dropped"), self.net_cum)
                    ),
                    "drops": self.drops_cum,
                    "alive": [int(a) for a in np.flatnonzero(w.alive)],
                    "late_ticks": sum(self.late_ticks.values()),
                    "positions": [list(p) for p in zip(*w.positions())],
                    "labels": w.agent_labels(),
                    "markers": [[x, y, label] for x, y, label in w.markers().values()],
                }
            )
        )

    def _await_step(self, k: int) -> NetemStep:
        timeout = self.exp.run.tick_timeout
        deadline = time.monotonic() + timeout
        while True:
            try:
                what, data = self._next_event(deadline - time.monotonic())
            except queue.Empty:
                raise RunError(
                    f"tick {k}: no step from the netem proxy within {timeout:.0f} s "
                    "(an agent or the proxy is stuck; see the logs)"
                ) from None
            if what == "step":
                try:
                    step = decode_netem_step(data)
                except WireError as exc:
                    self._malformed(self.keys.netem_step, exc)
                    continue
                if step.tick == k:
                    return step
                self._malformed(self.keys.netem_step, WireError(f"step for tick {step.tick} while at tick {k}"))
            elif what == "leave":
                if data == self.keys.alive_netem:
                    self._proxy_gone(k)
                if not data.endswith("/coordinator"):
                    agent = agent_id_of(data)
                    if incarnation_of(data) != self.incarnation.get(agent, 0):
                        continue  # a process swapped out: its agent goes on elsewhere
                    self._await_fatal_report(agent)
                    self._lose(agent, k, self._how_it_ended(agent))
            elif what == "report":
                self._on_report(data, k)
            elif what == "netem_report":  # mid-run, only a proxy that failed reports
                self._proxy_failed(k, data)

    def _next_event(self, timeout: float) -> tuple[str, Any]:
        if self._pushback:
            return self._pushback.pop(0)
        return self.events.get(timeout=max(0.0, timeout))

    def _proxy_failed(self, k: int, data: bytes) -> None:
        """A report from the proxy while ticks go on: only a failing proxy sends one (its error)."""
        try:
            rep = decode_report(data)
        except WireError as exc:
            self._malformed(self.keys.netem_report, exc)
            return
        if rep["kind"] == "fatal":
            raise RunError(f"tick {k}: the netem proxy failed: {rep.get('error')}; see logs/netem.log")

    def _proxy_gone(self, k: int, grace: float = 0.5) -> None:
        """The proxy's token went: raise with its own error if it reported one (it reports before it
        lets go of the token, but the two travel apart), else with its exit status and log."""

        def take(what: str, data: Any) -> object:
            if what != "netem_report":
                return None
            self._proxy_failed(k, data)  # raises on the proxy's error
            return CONSUMED

        self._wait_for(grace, take)
        how = self.exit_status("netem") if self.exit_status else ""
        raise RunError(
            f"tick {k}: the netem proxy exited unexpectedly; see logs/netem.log" + (f"\n{how}" if how else "")
        )

    def _how_it_ended(self, agent: int) -> str:
        """Why agent ``agent``'s process is gone, as precisely as this machine can tell (a process on
        another host: only that it exited)."""
        if agent in self.fatal or self.exit_status is None or self.hosts.get(agent, LOCAL) != LOCAL:
            return "its process exited"
        incarnation = self.incarnation.get(agent, 0)
        name = f"agent_{agent}" if incarnation == 0 else f"agent_{agent}.{incarnation}"
        how = self.exit_status(name).split(";", 1)[0]
        return f"its process {how.split(' ', 1)[1]}" if how else "its process exited"

    def _await_fatal_report(self, agent: int, grace: float = 0.25) -> None:
        """An agent left. Its fatal report (if it failed) travels apart from its liveliness token and
        may come a little later: wait briefly for it, keeping every other event in order."""

        def take(what: str, data: Any) -> object:
            if what != "report":
                return None
            self._on_report(data, -1)
            return True if agent in self.fatal else CONSUMED

        if agent not in self.fatal:
            self._wait_for(grace, take)

    def _wait_for(self, seconds: float, take: Callable[[str, Any], object], timeout: object = None) -> object:
        """Events for up to ``seconds``: ``take(what, data)`` returns None to keep an event for the
        tick loop (in order), :data:`CONSUMED` for one it used, anything else to end the wait with
        that value; ``timeout`` when the time is up."""
        deadline = time.monotonic() + seconds
        held: list[tuple[str, Any]] = []
        try:
            while True:
                try:
                    what, data = self.events.get(timeout=max(0.0, deadline - time.monotonic()))
                except queue.Empty:
                    return timeout
                got = take(what, data)
                if got is None:
                    held.append((what, data))
                elif got is not CONSUMED:
                    return got
        finally:
            self._pushback.extend(held)

    def _decode_report(self, key: str, data: bytes) -> dict | None:
        """An agent's report, if it is well formed and names the agent whose key it came on
        (else dropped and counted)."""
        try:
            rep = decode_report(data)
            agent = rep.get("agent")
            if not isinstance(agent, int) or not 0 <= agent < self.n:
                raise WireError(f"report names no agent of this run: {agent!r}")
            if agent != agent_id_of(key):
                raise WireError(f"report of agent {agent} on another agent's key")
        except WireError as exc:
            self._malformed(key, exc)
            return None
        return rep

    def _on_report(self, sample: tuple[str, bytes], tick: int) -> None:
        rep = self._decode_report(*sample)
        if rep is None:
            return
        agent = rep["agent"]
        if rep["kind"] == "fatal":
            self.fatal[agent] = rep
            self._lose(agent, rep.get("tick", tick), "it raised an exception")
        elif rep["kind"] == "final":
            self.reports[agent] = rep
        elif rep["kind"] == "checkpoint":
            state = rep.get("state")
            if not self.tickets.redeem("checkpoint", agent, rep.get("ticket")):
                # late (a newer checkpoint was asked since) or not asked for at all: never kept
                log.warning("coordinator: refused a checkpoint of agent %d that was not asked for", agent)
            elif rep.get("incarnation") == self.incarnation.get(agent, 0) and isinstance(state, bytes):
                self.checkpoints[agent] = (self.checkpoint_tick, state)

    def _lose(self, agent: int, tick: int, why: str) -> None:
        if agent in self.lost or agent in self.down:
            return
        fatal = self.fatal.get(agent)
        detail = f"\n{fatal['error']}\n{fatal.get('traceback', '')}" if fatal else ""
        policy = self.exp.run.agent_loss
        if policy == "fail":
            raise RunError(
                f"agent {agent} stopped at tick {tick} because {why}; see {self._log_of(agent)}"
                f" (set run.on_agent_loss to continue or restart to go on){detail}"
            )
        if policy == "restart" and fatal is None and self.place is not None:
            # a crashed process is started again at the next tick; a plugin that raised would raise again
            log.warning("coordinator: agent %d lost at tick %d (%s); restarting it", agent, tick, why)
            self.down[agent] = tick
            return
        self.lost[agent] = tick
        self.world.kill(agent)

    # -- agents that come back (run.on_agent_loss: restart) ------------------------------------------
    checkpoint_tick = -1

    def _ask_checkpoints(self) -> None:
        """Every live agent reports its state before this tick (kept, the last of each, to restart it)."""
        self.checkpoint_tick = self.last_tick + 1
        for i in map(int, np.flatnonzero(self.world.alive)):
            if i not in self.lost and i not in self.down:
                incarnation = self.incarnation.get(i, 0)
                ticket = self.tickets.issue("checkpoint", i, incarnation)
                self.agent_pubs[i].put(encode_control(TAG_CHECKPOINT, incarnation, ticket))

    def _restart_due(self, k: int) -> None:
        """Try each agent that is down and due: a failed try is tried again after
        ``run.restart_backoff`` wall seconds (doubling) while ticks go on without it, until
        ``run.restart_attempts`` tries have failed; then it is lost."""
        r = self.exp.run
        for agent in sorted(self.down):
            tries, due = self.restart_tries.get(agent, (0, 0.0))
            if time.monotonic() < due:
                continue
            record = self._restart(agent, k, tries)
            tries += 1
            self.restart_log.append(record)
            if record["outcome"] == "ok":
                self.restart_tries.pop(agent, None)
            elif tries < r.restart_attempts:
                record["outcome"] = "retrying"
                self.restart_tries[agent] = (tries, time.monotonic() + r.restart_backoff * 2 ** (tries - 1))
            else:
                self.restart_tries.pop(agent, None)
                lost_at = self.down.pop(agent)
                self.lost[agent] = lost_at
                self.world.kill(agent)

    def _restart(self, agent: int, k: int, failed_tries: int = 0) -> dict[str, Any]:
        """Start agent ``agent`` again before tick ``k``, under its id, on its host: from its last
        checkpoint if there is one, else fresh. Messages to it while it was gone were booked
        ``receiver_dead`` by the proxy. Each try is a new incarnation: a failed try's process,
        should it join late, is never taken for this one."""
        t0 = time.perf_counter()
        new = self.incarnation.get(agent, 0) + 1 + failed_tries
        host = self.hosts.get(agent, LOCAL)
        checkpoint = self.checkpoints.get(agent)
        record: dict[str, Any] = {
            "tick": k,
            "agent": agent,
            "lost_at_tick": self.down[agent],
            "incarnation": new,
            "host": host,
            "checkpoint_tick": checkpoint[0] if checkpoint else "",
            "outcome": "failed",
            "reason": "",
            "wait_ms": 0.0,
        }
        assert self.place is not None
        if checkpoint:
            self.snapshots[agent] = checkpoint[1]
        try:
            self.place(agent, host, new, restore=checkpoint is not None)
            got = self._await_swap_event(
                agent, -1, new, ("restored", "restore_failed") if checkpoint else ("join", "join")
            )
        except Exception as exc:
            got = f"cannot start it on {host}: {exc}"
        finally:
            self.snapshots.pop(agent, None)
        record["wait_ms"] = round((time.perf_counter() - t0) * 1000, 3)
        if got in ("restored", "join"):
            self.incarnation[agent] = new
            del self.down[agent]
            record["outcome"] = "ok"
        else:
            record["reason"] = got
            log.warning("coordinator: agent %d could not be restarted before tick %d: %s", agent, k, got)
            try:
                if self.unplace is not None:
                    self.unplace(agent, host, new)
            except Exception as exc:  # the host is away: its process, if any, is stale from now on
                log.warning("coordinator: could not stop the failed restart of agent %d on %s: %s", agent, host, exc)
        return record

    # -- moving agents (swaps) ---------------------------------------------------------------------
    def _swap_due(self, k: int) -> None:
        """Every swap scripted for tick ``k`` and every one requested since the last tick, in order."""
        due: list[tuple[int, str, int | None]] = [(a, h, None) for a, h in self.swaps_due.pop(k, [])]
        while True:
            try:
                due.append(self.swap_requests.get_nowait())
            except queue.Empty:
                break
        for agent, host, number in due:
            record = self._swap(agent, host, k)
            self.swap_log.append(record)
            if number is not None:
                self.requested_swaps[number] = record

    def _swap(self, agent: int, to: str, k: int) -> dict[str, Any]:
        """Move ``agent`` to host ``to`` before tick ``k``: the old process hands its state over and
        freezes, a new process on ``to`` restores it and announces itself, the old one retires.
        Any failure resumes the old process; the record says what happened."""
        t0 = time.perf_counter()
        old = self.incarnation.get(agent, 0)
        new = old + 1
        record: dict[str, Any] = {
            "tick": k,
            "agent": agent,
            "from": self.hosts.get(agent, "local"),
            "to": to,
            "outcome": "failed",
            "reason": "",
            "snapshot_bytes": 0,
            "pause_ms": 0.0,
        }

        def finish(reason: str = "") -> dict[str, Any]:
            record["pause_ms"] = round((time.perf_counter() - t0) * 1000, 3)
            if reason:
                record["reason"] = reason
                log.warning("coordinator: swap of agent %d to %s before tick %d failed: %s", agent, to, k, reason)
            return record

        if agent in self.lost or self.place is None:
            return finish("the agent is not running" if agent in self.lost else "this run cannot start processes")
        if to != LOCAL and self.carriers is not None and agent not in self.carriers.get(to, ()):
            return finish(
                f"host {to} may not carry agent {agent}: the hub admits a host only to the agents placed on "
                f"it, moved to it by a scripted swap or listed for it in may_carry"
            )
        self.snapshots.pop(agent, None)
        self.agent_pubs[agent].put(encode_control(TAG_SNAPSHOT, old, self.tickets.issue("snapshot", agent, old)))
        got = self._await_swap_event(agent, old, new, ("snapshot", "snapshot_failed"))
        if got != "snapshot":
            self.tickets.cancel("snapshot", agent)
            return finish(got)
        record["snapshot_bytes"] = len(self.snapshots[agent])
        try:
            self.place(agent, to, new)
        except Exception as exc:  # the host refused or is gone: the old process goes on
            self.agent_pubs[agent].put(encode_control(TAG_RESUME, old))
            return finish(f"cannot start it on {to}: {exc}")
        got = self._await_swap_event(agent, old, new, ("restored", "restore_failed"))
        if got != "restored":
            self.agent_pubs[agent].put(encode_control(TAG_RESUME, old))
            if self.unplace is not None:
                self.unplace(agent, to, new)
            return finish(got)
        self.incarnation[agent] = new
        self.agent_pubs[agent].put(encode_control(TAG_RETIRE, old))
        self.hosts[agent] = to
        self.snapshots.pop(agent, None)
        record["outcome"] = "ok"
        return finish()

    def _await_swap_event(self, agent: int, old: int, new: int, wanted: tuple[str, str]) -> str:
        """``wanted[0]`` when it comes; otherwise why not (the failure's reason). Other events wait."""

        def take(what: str, data: Any) -> object:
            if what == "snapshot" and data == agent and wanted[0] == "snapshot":
                return "snapshot"
            if what == "join" and wanted[0] == "join" and data == self.keys.alive_agent(agent, new):
                return "join"
            if what == "report":
                rep = self._decode_report(*data)
                if rep is None:
                    return CONSUMED
                if rep["agent"] == agent and rep.get("kind") in wanted:
                    return "restored" if rep["kind"] == "restored" else f"{rep['kind']}: {rep.get('error')}"
            if what == "leave" and not data.endswith(("/coordinator", "/netem")) and agent_id_of(data) == agent:
                gone = incarnation_of(data)
                if gone in (old, new):
                    return f"the {'old' if gone == old else 'new'} process of agent {agent} exited"
            return None

        timeout = self.exp.run.tick_timeout
        return str(self._wait_for(timeout, take, f"no {wanted[0]} within {timeout:.0f} s"))

    def _log_of(self, agent: int) -> str:
        host = self.hosts.get(agent, "local")
        if host == "local":
            return f"logs/agent_{agent}.log"
        return f"agent_{agent}.log in the logs of host {host} (run {self.keys.run_id})"

    def _retire(self, agent: int, tick: int) -> None:
        """Scheduled agent loss: the robot is gone from ``tick`` on and its process is stopped."""
        self.lost[agent] = tick
        self.retired.add(agent)
        self.world.kill(agent)
        self.agent_pubs[agent].put(encode_stop("agent lost"))

    def _malformed(self, key: str, exc: Exception) -> None:
        self.malformed += 1
        if self.malformed <= 20:
            log.warning("coordinator: malformed sample on %s dropped: %s", key, exc)

    # -- shutdown and results ---------------------------------------------------------------------
    def stop_and_collect(self, timeout: float = 30.0) -> None:
        """Tell the proxy and every live agent that the run is over; collect their final reports."""
        self.stop_pub.put(encode_netem_stop(self.last_tick))
        for agent, tick in sorted(self.down.items()):  # died in the last tick: never restarted
            self.lost[agent] = tick
        self.down.clear()
        retired = sorted(self.retired)
        live = [i for i in range(self.n) if i not in self.lost]
        for i in live:
            self.agent_pubs[i].put(encode_stop("run complete"))
        live += retired  # stopped earlier, but they report too
        deadline = time.monotonic() + timeout
        while self.netem_report is None or any(i not in self.reports for i in live):
            try:
                what, data = self._next_event(deadline - time.monotonic())
            except queue.Empty:
                missing = [f"agent_{i}" for i in live if i not in self.reports]
                if self.netem_report is None:
                    missing.insert(0, "netem")
                raise RunError(f"no final report within {timeout:.0f} s from: {', '.join(missing[:10])}") from None
            if what == "report":
                self._on_report(data, self.last_tick)
            elif what == "netem_report":
                try:
                    self.netem_report = decode_report(data)
                except WireError as exc:
                    self._malformed(self.keys.netem_report, exc)

    def summary(self) -> dict:
        w, exp = self.world, self.exp
        assert self.netem_report is not None, "summary() before the proxy's final report"
        net = self.netem_report["totals"]
        agent_bytes = sum(b for r in self.reports.values() for _, b in r["sent"].values())
        # a restarted agent's own counters begin again (or at its checkpoint): only the ledger has them all
        all_reported = len(self.reports) == self.n and not self.restart_log
        return {
            "name": exp.name,
            "scenario_kind": exp.scenario.kind,
            "seed": exp.run.seed,
            "allocator": exp.allocator.name,
            "agents": self.n,
            "ticks": self.last_tick + 1,
            **w.summary(),
            **{name: self.event_totals.get(name, 0) for name in self.event_names},
            "events": dict(sorted(self.event_totals.items())),
            "agents_lost": {str(a): t for a, t in sorted(self.lost.items())},
            **({"agent_restarts": sum(r["outcome"] == "ok" for r in self.restart_log)} if self.restart_log else {}),
            **({"realtime": self.clock_summary()} if self.realtime else {}),
            "network": {
                **net,
                "per_kind": self.netem_report["per_kind"],
                "bytes_sent_by_agents": agent_bytes if all_reported else None,
                "bytes_agree": (agent_bytes == net["bytes_sent"]) if all_reported else None,
                "malformed": {
                    "coordinator": self.malformed,
                    "netem": self.netem_report["malformed"],
                    "agents": sum(r["malformed"] for r in self.reports.values()),
                },
            },
        }

    def clock_summary(self) -> dict:
        """How well the real-time clock was kept: ticks agents missed, and ticks that started late
        (more than a tenth of a tick's wall period after their time) with the start lag's spread."""
        r = self.exp.run
        lags = np.asarray(self.start_lags) * 1000
        tolerance_ms = 100 * r.dt / r.speed
        spread = [float(v) for v in np.percentile(lags, [50, 99, 100])] if len(lags) else [None] * 3
        return {
            "speed": r.speed,
            "deadline": r.deadline,
            "on_late": r.on_late,
            "late_ticks_total": sum(self.late_ticks.values()),
            "late_ticks": {str(a): n for a, n in sorted(self.late_ticks.items())},
            "ticks_started_late": int((lags > tolerance_ms).sum()),
            "start_lag_ms": dict(zip(("p50", "p99", "max"), spread)),
        }

    def transport(self, summary: dict) -> dict:
        """TCP bytes each process of the run measured on its own sockets, beside the radio payload
        bytes of the ledger (see :mod:`swarmbed.wire.transport` for what they count).

        Every link of a run has the hub (this process's router) at one end, so measuring each
        client's end counts every byte once: what the clients sent is what the hub received, and
        the other way round; the hub's own sockets are not read (they would count it all twice)."""
        assert self.netem_report is not None
        processes: dict[str, dict] = {"netem": self.netem_report.get("transport", {})}
        for i in sorted(self.reports):
            processes[f"agent_{i}"] = self.reports[i].get("transport", {})
        agents = [p for name, p in processes.items() if name.startswith("agent_")]
        payload = summary["network"]["bytes_sent"]

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

    def write_results(self, timings: dict) -> dict:
        out, w = self.out_dir, self.world
        summary = self.summary()
        assert self.netem_report is not None
        per_sender = self.netem_report["per_sender"]
        for table in self.tables.values():
            table.finish()
        self.tables.clear()
        columns = w.per_agent()
        net_cols = ["messages", "bytes", "copies", "delivered"]
        rows = []
        for i in range(self.n):
            s = per_sender.get(str(i), {})
            rows.append(
                [i, int(i not in self.lost), self.lost.get(i, "")]
                + [col[i] for col in columns.values()]
                + [s.get(c, 0) for c in net_cols]
            )
        results.write_csv(
            out / results.AGENTS,
            ["agent", "alive", "lost_at_tick", *columns, "messages_sent", "bytes_sent", "copies", "delivered"],
            rows,
        )
        results.write_json(out / results.TIMINGS, timings)
        results.write_json(out / results.TRANSPORT, self.transport(summary))
        if self.swap_log:  # wall-clock pauses: not among the files that repeat byte for byte
            cols = ["tick", "agent", "from", "to", "outcome", "reason", "snapshot_bytes", "pause_ms"]
            results.write_csv(out / SWAPS, cols, [[r[c] for c in cols] for r in self.swap_log])
        if self.restart_log:
            results.write_csv(
                out / RESTARTS, RESTART_COLUMNS, [[r[c] for c in RESTART_COLUMNS] for r in self.restart_log]
            )
        results.write_json(out / results.SUMMARY, summary)
        return summary
