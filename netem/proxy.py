"""The netem proxy process: the emulated radio of one run.

Per tick k it takes the coordinator's world sample (positions and membership of tick k) and one
output sample from every live agent, routes their messages through :class:`~netem.radio.Radio`,
and hands the coordinator one step sample: the agents' actions of tick k, the inboxes of tick k+1
and this tick's counters. The ledger streams to ``network_ledger.csv`` in the run directory
(written under a temporary name, renamed when the run is over and the ledger balances).
"""

from __future__ import annotations

import argparse
import logging
import os
import queue
import socket
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from swarmbed.files.safefiles import rooted
from swarmbed.netem.exchange import Exchange
from swarmbed.netem.ros2_radio import Ros2Outboxes
from swarmbed.records.rowfile import TableWriteError
from swarmbed.schema.experiment import NetemSpec
from swarmbed.wire.child_process import child_args, pin_thread_state
from swarmbed.wire.codec import (
    AgentOut,
    NetemControl,
    WireError,
    WorldSample,
    decode_agent_out,
    decode_host_out,
    decode_netem_control,
    decode_netem_stop,
    decode_world,
    encode_netem_step,
    encode_traffic,
    pack,
)
from swarmbed.wire.control import NetemFatal, Transport, encode_report
from swarmbed.wire.keys import Keys, agent_id_of, alive_agent_of, run_host_of
from swarmbed.wire.membership import fetch_spec, hand_over
from swarmbed.wire.regions import by_region
from swarmbed.wire.stages import Stages
from swarmbed.wire.stages import enabled as stages_enabled
from swarmbed.wire.tcp_counters import tcp_counters
from swarmbed.wire.zenoh_session import open_from_args

log = logging.getLogger("swarmbed.netem")

TRAFFIC_EVERY = 0.25  # wall seconds between traffic samples for watchers


def _matching(publisher: zenoh.Publisher) -> bool:
    """Whether anyone subscribes to ``publisher``'s key. zenoh-python 1.10 returns a MatchingStatus
    (its ``.matching``); its type stub says a bool."""
    status: Any = publisher.matching_status
    return bool(getattr(status, "matching", status))


class Proxy:
    def __init__(self, spec: NetemSpec, keys: Keys, session: zenoh.Session, out_dir: Path, shard: int = 0) -> None:
        self.spec = spec
        self.keys = keys
        self.session = session
        self.out_dir = out_dir
        if not 0 <= shard < spec.split.shards:
            raise ValueError(f"--shard {shard}: the run's radio is split over {spec.split.shards} proxies")
        self.shard = shard
        self.exchange = Exchange(spec, out_dir, shard)
        self.sink, self.ledger, self.radio = self.exchange.sink, self.exchange.ledger, self.exchange.radio
        self.events: queue.SimpleQueue = queue.SimpleQueue()
        # agents' outputs gather here, taken in Zenoh's own thread (no Python thread hop per
        # sample); the main thread is woken once for all that gathered while it was busy
        self.arrived: list[tuple[str, bytes]] = []
        self.arrived_lock = threading.Lock()
        self.outs: dict[int, dict[int, AgentOut]] = {}
        self.gone: set[tuple[int, int]] = set()  # (agent, incarnation) whose process left
        self.lost: set[int] = set()  # agents whose current process left
        self.lost_unreported: list[int] = []
        self.world: WorldSample | None = None
        self.awaited: set[int] = set()  # agents of the tick in hand not yet answered nor lost
        self.malformed = 0
        self.read = 0  # agents' outputs taken (a proxy of a radio split by region: its region's)
        # the real-time clock: a tick is routed when every agent answered or `answer_within` wall
        # seconds after its world sample arrived, whichever comes first; later answers are late
        self.answer_by: float | None = None
        self.routed = -1  # the last tick routed
        self.members: dict[int, list[int]] = {}  # tick -> agents alive then (recent ticks, for late answers)
        self.answered: dict[int, int] = {}  # agent -> the last tick it answered
        self.late_events: dict[str, int] = {}
        self.controls: list[NetemControl] = []  # parameter changes not yet in force (chaos)
        self.stages: Stages | None = Stages() if stages_enabled() else None  # benchmarks/profile_tick.py
        # for watchers (wall-clock paced, never in a result): agent -> [messages, payload bytes] sent,
        # counted only while someone subscribes to the view
        self.traffic: dict[int, list[int]] = {}
        self.watched = False
        self.traffic_at = 0.0
        # a radio split by region: this proxy reads only the outputs of the agents it owns at the tick
        self.by_region = by_region(spec.split, spec.network)
        self.carriers = None if spec.carriers is None else {h: frozenset(ids) for h, ids in spec.carriers.items()}
        self.ros2: Ros2Outboxes | None = Ros2Outboxes(session, spec) if spec.ros2 is not None else None

    # -- events ----------------------------------------------------------------------------------
    def _on_agent_alive(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE:
            key = str(sample.key_expr)
            try:
                self.events.put(("left", alive_agent_of(key, self.keys.root, self.spec.agents)))
            except WireError as exc:
                self._malformed(key, exc)

    def _on_coordinator(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE:
            self.events.put(("gone", None))

    def _on_out(self, sample: zenoh.Sample) -> None:
        pin_thread_state()  # a direct callback in Zenoh's thread: keep its Python thread state
        item = (str(sample.key_expr), sample.payload.to_bytes())
        with self.arrived_lock:
            self.arrived.append(item)
            first = len(self.arrived) == 1
        if first:
            self.events.put(("outs", None))

    def _on_host_out(self, sample: zenoh.Sample) -> None:
        """A host relay's gathered outputs: each taken as if its agent had put it on its own key
        (checked then like any other), if the run lets that host carry the agent."""
        pin_thread_state()
        key = str(sample.key_expr)
        try:
            host = run_host_of(key, self.keys.root)
            entries = decode_host_out(sample.payload.to_bytes())
            may = self.carriers.get(host, frozenset()) if self.carriers is not None else None
            strangers = [a for a, _ in entries if may is not None and a not in may]
            if strangers:
                raise WireError(f"host {host} may not carry agents {strangers[:10]}")
        except WireError as exc:
            self.events.put(("malformed", (key, exc)))
            return
        items = [(self.keys.hosted_out(host, agent), data) for agent, data in entries]
        with self.arrived_lock:
            first = not self.arrived
            self.arrived += items
        if first and items:
            self.events.put(("outs", None))

    def _on_awaiting_query(self, query: zenoh.Query) -> None:
        """Which tick is in hand and which agents have not answered it (for a coordinator that waited
        too long: it names them)."""
        world, awaited = self.world, sorted(self.awaited)
        query.reply(self.keys.netem_awaiting, pack([-1 if world is None else world.tick, awaited]))

    def _take_arrived(self) -> list[tuple[str, bytes]]:
        with self.arrived_lock:
            arrived, self.arrived = self.arrived, []
        return arrived

    def run(self) -> int:
        s, k = self.session, self.keys
        put = self.events.put
        subs: list[Any] = [
            s.declare_subscriber(k.world, lambda x: put(("world", x.payload.to_bytes()))),
            *(
                s.declare_subscriber(f"{key}{mine}", zenoh.handlers.Callback(take, indirect=False))
                for key, take in ((k.agent_out_all, self._on_out), (k.host_out_all, self._on_host_out))
                for mine in ("", *((f"/{self.shard}",) if self.by_region else ()))
            ),
            s.declare_subscriber(k.netem_stop, lambda x: put(("stop", x.payload.to_bytes()))),
            s.declare_subscriber(k.netem_control, lambda x: put(("control", x.payload.to_bytes()))),
            s.liveliness().declare_subscriber(k.alive_agents, self._on_agent_alive),
            s.liveliness().declare_subscriber(k.alive_coordinator, self._on_coordinator),
        ]
        subs.append(s.declare_queryable(k.netem_awaiting, self._on_awaiting_query))
        self.step_pub = s.declare_publisher(k.netem_step, congestion_control=zenoh.CongestionControl.BLOCK)
        # DROP: a watcher that stops reading loses samples and never holds up a tick
        self.traffic_pub = s.declare_publisher(k.view_traffic, congestion_control=zenoh.CongestionControl.DROP)
        token = s.liveliness().declare_token(k.netem_tokens(self.spec.split.shards)[self.shard])
        try:
            return self._loop()
        finally:
            token.undeclare()
            self.traffic_pub.undeclare()
            for sub in subs:
                sub.undeclare()
            self.sink.flush()

    def _loop(self) -> int:
        while True:
            try:
                wait = None if self.answer_by is None else max(0.0, self.answer_by - time.monotonic())
                what, data = self.events.get(timeout=wait)
            except queue.Empty:  # the deadline of the tick in hand passed: route what came
                assert self.world is not None
                self._route(self.world)
                self.world = None
                continue
            if what == "gone":
                log.error("netem: the coordinator went away; exiting (ledger left as %s)", self.sink.part.name)
                return 3
            if what == "stop":
                try:
                    last = decode_netem_stop(data)
                except WireError as exc:
                    self._malformed(self.keys.netem_stop, exc)
                    continue
                log.info("netem: run over after tick %d; closing the ledger", last)
                if self.spec.answer_within is not None:
                    self._await_last_answers(last)
                self._finish(last)
                log.info("netem: ledger balanced and written; report sent")
                return 0
            if what == "control":
                self._take_control(data)
                continue
            if what == "malformed":
                self._malformed(*data)
                continue
            if what == "left":  # lost only if that process is the agent's current one (not one swapped out)
                self.gone.add(data)
                self._note_losses(self.world)
                self.awaited -= self.lost
            elif what == "world":
                try:
                    world = decode_world(data)
                except WireError as exc:
                    self._malformed(self.keys.world, exc)
                    continue
                if self.world is not None:
                    early = WireError(f"tick {world.tick} before tick {self.world.tick} was done")
                    self._malformed(self.keys.world, early)
                    continue
                self.radio.confirm()  # tick `world.tick` happens: the inboxes made for it arrived
                self.world = world
                self._note_losses(world)
                self.awaited = set(self._readers(world)).difference(self.outs.get(world.tick, ()), self.lost)
                if self.spec.answer_within is not None:
                    self.answer_by = time.monotonic() + self.spec.answer_within
                    self.members[world.tick] = list(world.ids)
                    self.members.pop(world.tick - 1000, None)
            elif what == "outs":
                if self.stages is not None:
                    self.stages.start()
                for key, sample in self._take_arrived():
                    out = self._take_out(key, sample)
                    if out is None:
                        continue
                    if out.tick <= self.routed:
                        self._late(out)
                    else:
                        self.outs.setdefault(out.tick, {})[out.agent_id] = out
                        if self.world is not None and out.tick == self.world.tick:
                            self.awaited.discard(out.agent_id)
            if self.world is not None and not self.awaited:
                self._route(self.world)
                self.world = None

    def _readers(self, world: WorldSample) -> list[int]:
        """The agents whose answers to tick ``world.tick`` this proxy reads: every one, or in a
        radio split by region those it owns then."""
        owned = self.exchange.owned(world) if self.by_region else None
        return world.ids if owned is None else [a for a in world.ids if a in owned]

    def _take_out(self, key: str, data: bytes) -> AgentOut | None:
        """An agent's output, if it follows the contract: decodable, sent on its own agent's key,
        for the tick in hand (or, on the real-time clock, a late answer to one already routed),
        and the first for its tick. Anything else is malformed: dropped and counted."""
        try:
            out = decode_agent_out(data)
            if not out.agent_id < self.spec.agents:
                raise WireError(f"output of agent {out.agent_id}, outside 0..{self.spec.agents - 1}")
            if agent_id_of(key) != out.agent_id:
                raise WireError(f"output of agent {out.agent_id} on another agent's key")
            if out.tick > self.routed + 1:
                raise WireError(f"output for tick {out.tick} while tick {self.routed + 1} is in hand")
            if out.tick <= self.routed and self.spec.answer_within is None:
                raise WireError(f"output for tick {out.tick}, already routed")
            if out.tick <= self.answered.get(out.agent_id, -1):
                raise WireError(f"a second output of agent {out.agent_id} for tick {out.tick}")
        except WireError as exc:
            self._malformed(key, exc)
            return None
        self.answered[out.agent_id] = out.tick
        self.read += 1
        return out

    def _take_control(self, data: bytes) -> None:
        """A change of the radio's parameters from a tick on; one for a tick already routed is
        malformed (it would rewrite the past)."""
        try:
            control = decode_netem_control(data)
            if control.from_tick <= self.routed:
                raise WireError(f"control for tick {control.from_tick}, already routed")
            self.spec.network.model_validate({**self.spec.network.model_dump(), **control.overrides})
            if self.by_region and control.overrides.get("rate") is not None:  # the launcher refuses it first
                raise WireError("a rate cap in a radio split by region: no proxy keeps every sender's queue")
        except (WireError, ValueError) as exc:  # pydantic's ValidationError is a ValueError
            self._malformed(self.keys.netem_control, exc)
            return
        self.controls.append(control)

    def _apply_controls(self, tick: int) -> None:
        """Put in force every change due at or before ``tick``, in the order they came."""
        due = [c for c in self.controls if c.from_tick <= tick]
        if not due:
            return
        self.controls = [c for c in self.controls if c.from_tick > tick]
        for control in due:
            self.radio.params = self.spec.network.model_copy(update=control.overrides)
            log.info(
                "netem: from tick %d the radio is %s (%s)", tick, control.overrides or "as configured", control.label
            )

    def _malformed(self, key: str, exc: Exception) -> None:
        self.malformed += 1
        if self.malformed <= 20:
            log.warning("netem: malformed sample on %s dropped: %s", key, exc)

    def _note_losses(self, w: WorldSample | None) -> None:
        """Agents whose current process (as tick ``w`` names it) has left are lost (until a new
        process of theirs is current)."""
        if w is None:
            return
        # an agent started again (run.on_agent_loss: restart) is back once the world names its new process
        self.lost = {a for a in self.lost if (a, w.incarnation(a)) in self.gone}
        for agent, incarnation in self.gone:
            if agent not in self.lost and incarnation == w.incarnation(agent):
                self.lost.add(agent)
                self.lost_unreported.append(agent)

    def _late(self, out: AgentOut) -> None:
        """An answer for a tick already routed (real-time clock): its messages are booked late."""
        self.radio.late(self.routed + 1, out.agent_id, out.messages, self.members.get(out.tick, []))
        for name, n in out.events.items():
            self.late_events[name] = self.late_events.get(name, 0) + n

    def _await_last_answers(self, last: int, timeout: float = 10.0) -> None:
        """Book every answer still on its way for the last ticks (each agent answers in order)."""
        until = time.monotonic() + timeout
        left: set[int] = set()
        while any(
            self.answered.get(a, -1) < last for a in self.members.get(last, []) if a not in self.lost and a not in left
        ):
            try:
                what, data = self.events.get(timeout=max(0.0, until - time.monotonic()))
            except queue.Empty:
                log.warning("netem: some agents never answered up to tick %d", last)
                return
            if what == "outs":
                for key, sample in self._take_arrived():
                    out = self._take_out(key, sample)
                    if out is not None:
                        self._late(out)
            elif what == "left":
                left.add(data[0])

    def _route(self, w: WorldSample) -> None:
        st = self.stages
        if st is not None:
            st.mark("take outputs")
        self.answer_by = None
        self.routed = w.tick
        if w.tick == 0:
            log.info("netem: tick 0 routed; the run is under way")
        outs = self.outs.pop(w.tick, {})
        self._apply_controls(w.tick)
        events, self.late_events = self.late_events, {}
        step = self.exchange.route(w, outs, self.lost, self.lost_unreported, events)
        if st is not None:
            st.mark("route and deliver")
        self.lost_unreported = []
        self.step_pub.put(encode_netem_step(step))
        self._publish_traffic(outs)
        if self.ros2 is not None:  # after the step: the coordinator does not wait for it
            self.ros2.publish(w.tick, w.ids, outs)
        if st is not None:
            st.mark("step")
            st.ticks += len(w.ids)  # per agent-tick

    def _publish_traffic(self, outs: dict[int, AgentOut]) -> None:
        """Count what each agent sent while anyone watches; hand watchers the totals every
        ``TRAFFIC_EVERY`` wall seconds."""
        if self.watched:
            for a, o in outs.items():
                if o.messages:
                    total = self.traffic.setdefault(a, [0, 0])
                    total[0] += len(o.messages)
                    total[1] += sum(len(m.payload) for m in o.messages)
        now = time.monotonic()
        if now - self.traffic_at >= TRAFFIC_EVERY:
            self.traffic_at = now
            if self.watched:
                self.traffic_pub.put(encode_traffic(self.traffic))
            self.watched = _matching(self.traffic_pub)
            if self.watched and not self.traffic:  # the first watcher: counted from the tick in hand
                self._publish_traffic(outs)

    def _finish(self, last_tick: int) -> None:
        if self.ros2 is not None:
            self.ros2.close()
        if self.stages is not None:
            log.info("netem: %s", self.stages.line())
        log.info("netem: read %d agent outputs over %d ticks", self.read, last_tick + 1)
        if self.watched:  # the totals as the run ends
            self.traffic_pub.put(encode_traffic(self.traffic))
        report = self.exchange.finish(last_tick, self.malformed, Transport.model_validate({"tcp": tcp_counters()}))
        if not hand_over(self.session, self.keys.netem_report, encode_report(report)):
            log.error("netem: the coordinator did not take the final report")


def _proxy_args(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--out", required=True, help="run directory for the ledger")
    ap.add_argument("--shard", type=int, default=0, help="which proxy of a radio split over proxies (radio_split)")


def main(argv: list[str] | None = None) -> int:
    args = child_args(
        "swarmbed netem",
        "run the netem proxy of one swarmbed run",
        _proxy_args,
        argv,
    )
    keys = Keys(args.run_id)
    with open_from_args(args) as session:
        try:
            spec = fetch_spec(session, keys.netem_config, NetemSpec, f"netem config of run {args.run_id}")
            if spec.split.shards > 1:
                node = os.environ.get("SLURMD_NODENAME")
                where = f" on Slurm node {node}" if node else f" on {socket.gethostname()}"
                log.info("netem: proxy %d of %d%s", args.shard, spec.split.shards, where)
            with rooted(args.out):  # the run's folder, opened once: no link below it is followed
                return Proxy(spec, keys, session, Path(args.out), args.shard).run()
        except Exception as exc:
            # logged and reported while the session, and with it the liveliness token, is still
            # held: the launcher stops every child once the token goes, which could cut it off
            log.exception("netem: failed")
            why = str(exc) if isinstance(exc, TableWriteError) else f"{type(exc).__name__}: {exc}"
            hand_over(session, keys.netem_report, encode_report(NetemFatal(kind="fatal", error=why)), timeout=5)
            return 1
