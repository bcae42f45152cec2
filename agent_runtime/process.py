"""The agent process: one per agent, a Zenoh client of the run's coordinator.

Per tick it waits for its one input sample (observation + inbox of tick k), ticks its tree once and
publishes one output sample (action + radio messages). It needs nothing but an endpoint, the run id
and its agent id: the experiment itself comes from the coordinator, so it can run on another host.
"""

from __future__ import annotations

import argparse
import logging
import queue
import threading
import traceback
from typing import Any

import zenoh
from pydantic import BaseModel

from swarmbed.agent_runtime.runtime import AgentRuntime
from swarmbed.schema.experiment import AgentSpec
from swarmbed.wire.btlog import encode_tree_changes
from swarmbed.wire.child_process import child_args, pin_thread_state
from swarmbed.wire.codec import (
    ControlIn,
    StopIn,
    TickIn,
    WireError,
    encode_agent_out,
    encode_handover,
    encode_stop,
)
from swarmbed.wire.control import (
    Checkpoint,
    Fatal,
    Restored,
    RestoreFailed,
    SnapshotFailed,
    Transport,
    encode_report,
)
from swarmbed.wire.credentials import CredentialsError, check_host_name
from swarmbed.wire.keys import Keys
from swarmbed.wire.membership import JoinError, fetch_bytes, fetch_spec, hand_over, is_alive
from swarmbed.wire.observation import Observation
from swarmbed.wire.state import StateError
from swarmbed.wire.tcp_counters import tcp_counters
from swarmbed.wire.tickdecode import TickDecoder
from swarmbed.wire.zenoh_session import one_receiving_worker, open_from_args

log = logging.getLogger("swarmbed.agent")

EXIT_OK, EXIT_PLUGIN_ERROR, EXIT_COORDINATOR_GONE = 0, 1, 3
COORDINATOR_GONE = "coordinator gone"


#: The most an answer may put from inside the subscriber's callback on the single worker: a put
#: that overfills the transmit queue waits for the very thread it holds (measured: ~160 KB from one
#: callback stalls 5 s, 64 KB does not); a larger answer is put from the main thread instead.
INLINE_PUT_MAX = 32 * 1024


def serve(
    session: zenoh.Session,
    keys: Keys,
    runtime: AgentRuntime,
    incarnation: int = 0,
    restored: bool = False,
    malformed: int = 0,
    tick_in_callback: bool | None = None,
    host: str | None = None,
) -> int:
    """Answer tick samples until the run stops this agent. Swap orders name an incarnation: on
    ``snapshot`` this process hands its state to the coordinator and freezes (answers no tick),
    then either ``retire``s (its successor goes on) or ``resume``s (the swap failed).

    ``tick_in_callback`` (default: whether Zenoh receives on one worker, as ``run.zenoh_threads``
    ``default`` and ``single`` have it): a tick is answered inside the subscriber's own callback, so
    a sample in and a sample out wake that one thread and nothing else. Whatever may block (orders,
    reports, a failing tick, an answer too large to put from there) goes to the main thread, and so
    does every sample behind it, in arrival order.

    ``host``: the host daemon that started this process; its answers go to that host's relay
    (:mod:`swarmbed.hosts.relay`), which sends them on with the host's other agents'."""
    if tick_in_callback is None:
        tick_in_callback = one_receiving_worker()
    with _Agent(session, keys, runtime, incarnation, malformed, host) as agent:
        return agent.loop(tick_in_callback, restored)


class _Agent:
    """One agent process's session entities and the state its loop keeps between ticks."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        runtime: AgentRuntime,
        incarnation: int,
        malformed: int,
        host: str | None = None,
    ) -> None:
        self.session, self.keys, self.runtime, self.incarnation = session, keys, runtime, incarnation
        agent_id = runtime.agent_id
        self.out_key = keys.agent_out(agent_id) if host is None else keys.hosted_out(host, agent_id)
        self.malformed = malformed
        self.frozen = False
        self.sample_bytes = {"in": 0, "out": 0}  # this process's per-tick samples, for the wire-bytes accounting
        # monitors (swarmbed groot) announce themselves with a token; the loop starts or stops handing
        # over the tree's changes between ticks, never inside one
        self.monitors: set[str] = set()
        # the main thread's work, in arrival order; while any is waiting, the callback answers nothing
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.pending = 0
        self.lock = threading.Lock()
        self.in_key = keys.agent_in(runtime.agent_id)
        self.decoder = TickDecoder(runtime.scenario.Observation)

    def __enter__(self) -> _Agent:
        s, keys, agent_id = self.session, self.keys, self.runtime.agent_id

        def on_coordinator(sample: zenoh.Sample) -> None:
            if sample.kind == zenoh.SampleKind.DELETE:  # wake the loop with a local stop order
                s.put(self.in_key, encode_stop(COORDINATOR_GONE))

        def on_monitor(sample: zenoh.Sample) -> None:
            (self.monitors.add if sample.kind == zenoh.SampleKind.PUT else self.monitors.discard)(str(sample.key_expr))

        self.watch = s.liveliness().declare_subscriber(keys.alive_coordinator, on_coordinator)
        self.out = s.declare_publisher(self.out_key, congestion_control=zenoh.CongestionControl.BLOCK)
        self.shard_outs: dict[int, zenoh.Publisher] = {}  # a radio split by region: one key per proxy
        # before each answer, on the same session: the coordinator has a tick's changes before its end
        self.bt = s.declare_publisher(keys.agent_bt(agent_id), congestion_control=zenoh.CongestionControl.BLOCK)
        self.watched = s.liveliness().declare_subscriber(keys.monitor(agent_id), on_monitor, history=True)
        self.sub: zenoh.Subscriber | None = None
        return self

    def __exit__(self, *exc: object) -> None:
        for entity in (self.sub, self.watch, self.watched, self.out, self.bt, *self.shard_outs.values()):
            if entity is not None:
                entity.undeclare()

    def report(self, data: BaseModel) -> None:
        agent_id = self.runtime.agent_id
        if not hand_over(self.session, self.keys.agent_report(agent_id), encode_report(data)):
            log.error("agent %d: the coordinator did not take the %s report", agent_id, getattr(data, "kind", "?"))

    def loop(self, tick_in_callback: bool, restored: bool) -> int:
        agent_id = self.runtime.agent_id
        channel = None
        if tick_in_callback:
            self.sub = self.session.declare_subscriber(
                self.in_key, zenoh.handlers.Callback(self._on_sample, indirect=False)
            )
        else:  # a channel subscriber wakes the main thread directly (no Python callback thread between)
            self.sub = channel = self.session.declare_subscriber(self.in_key)
        token = self.session.liveliness().declare_token(self.keys.alive_agent(agent_id, self.incarnation))
        if restored:  # subscribed and announced: the coordinator may retire the old process and go on
            self.report(Restored(kind="restored", agent=agent_id, incarnation=self.incarnation))
        try:
            while True:
                if tick_in_callback:
                    kind, item = self.queue.get()
                    code = self._main_work(kind, item)
                    with self.lock:
                        self.pending -= 1
                else:
                    data = channel.recv().payload.to_bytes()  # type: ignore[union-attr]
                    if self.runtime.stages is not None:
                        self.runtime.stages.start()
                    msg = self._decode(data)
                    code = None if msg is None else self._handle(msg)
                if code is not None:
                    return code
        except Exception:  # ours, not the plugin's: logged before the token goes (the launcher then stops us)
            log.exception("agent %d: failed", agent_id)
            return EXIT_PLUGIN_ERROR
        finally:
            token.undeclare()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        """The single worker's callback: answer a tick here when nothing waits for the main thread."""
        pin_thread_state()
        if self.runtime.stages is not None:
            self.runtime.stages.start()
        try:
            msg = self._decode(sample.payload.to_bytes())
            if msg is None:
                return
            with self.lock:
                if self.pending or self.frozen or not isinstance(msg, TickIn):
                    self._defer_locked("msg", msg)
                    return
            self._tick(msg, inline=True)
        except Exception as exc:  # ours: the main thread logs it and stops this agent
            self._defer("error", exc)

    def _defer(self, kind: str, item: object) -> None:
        with self.lock:
            self._defer_locked(kind, item)

    def _defer_locked(self, kind: str, item: object) -> None:
        self.pending += 1
        self.queue.put((kind, item))

    def _main_work(self, kind: str, item: Any) -> int | None:
        if kind == "msg":
            return self._handle(item)
        if kind == "put":
            publisher, data = item
            publisher.put(data)
            return None
        if kind == "answer":
            shard, data = item
            self._out(shard, inline=False).put(data)  # type: ignore[union-attr]
            return None
        if kind == "fatal":
            self.report(item)
            return EXIT_PLUGIN_ERROR
        raise item

    def _decode(self, data: bytes) -> TickIn | ControlIn | StopIn | None:
        self.sample_bytes["in"] += len(data)
        try:
            return self.decoder.decode(data)
        except WireError as exc:
            self.malformed += 1
            log.warning("agent %d: malformed sample on %s dropped: %s", self.runtime.agent_id, self.in_key, exc)
            return None

    def _handle(self, msg: TickIn | ControlIn | StopIn) -> int | None:
        """One sample on the main thread: an order, a stop, or a tick; an exit code ends the loop."""
        runtime, agent_id = self.runtime, self.runtime.agent_id
        if isinstance(msg, ControlIn):
            if msg.incarnation != self.incarnation:
                return None  # an order for the other process of a swap
            if msg.order == "snapshot":
                frozen = _hand_over_state(
                    self.session, self.keys, runtime, self.incarnation, self.malformed, self.report, msg.ticket
                )
                with self.lock:
                    self.frozen = frozen
            elif msg.order == "checkpoint" and not self.frozen:
                _checkpoint(runtime, self.incarnation, self.malformed, self.report, msg.ticket)
            elif msg.order == "resume":
                with self.lock:
                    self.frozen = False
                log.info("agent %d: swap cancelled; going on here", agent_id)
            elif msg.order == "retire":
                log.info("agent %d: moved to incarnation %d elsewhere; exiting", agent_id, self.incarnation + 1)
                return EXIT_OK
            return None
        if isinstance(msg, StopIn):
            if msg.reason == COORDINATOR_GONE:
                log.error("agent %d: the coordinator went away; exiting", agent_id)
                return EXIT_COORDINATOR_GONE
            if runtime.stages is not None:
                log.info("agent %d: %s", agent_id, runtime.stages.line())
            transport = Transport.model_validate({"tcp": tcp_counters(), "samples": self.sample_bytes})
            self.report(runtime.report(extra_malformed=self.malformed, transport=transport))
            return EXIT_OK
        if self.frozen:
            return None  # its successor answers this tick
        return self._tick(msg, inline=False)

    def _tick(self, msg: TickIn, inline: bool) -> int | None:
        """Answer one tick: step the tree and put its changes and the answer (from the callback, only
        what fits the transmit queue; a failure is reported from the main thread)."""
        runtime, agent_id = self.runtime, self.runtime.agent_id
        st = runtime.stages
        if st is not None:
            st.mark("decode")
        try:
            obs = msg.obs if isinstance(msg.obs, Observation) else runtime.decode_observation(msg.obs)
        except WireError as exc:  # blind for one tick: answer it (the clock must go on), count it
            self.malformed += 1
            log.warning("agent %d: malformed observation of tick %d dropped: %s", agent_id, msg.tick, exc)
            self._answer(msg.shard, None, encode_agent_out(msg.tick, agent_id, ["stop"], []), inline)
            return None
        if st is not None:
            st.mark("observation")
        if bool(self.monitors) != runtime.watched:
            runtime.monitored(bool(self.monitors))
        try:
            action, messages, events = runtime.step(msg.tick, obs, msg.inbox, msg.decision)
        except Exception as exc:  # a plugin or node raised: stop this agent, loudly
            tb = traceback.format_exc()
            log.error("agent %d: failed at tick %d:\n%s", agent_id, msg.tick, tb)
            error = f"{type(exc).__name__}: {exc}"
            fatal = Fatal(kind="fatal", agent=agent_id, tick=msg.tick, error=error, traceback=tb)
            if inline:
                self._defer("fatal", fatal)
                return None
            self.report(fatal)
            return EXIT_PLUGIN_ERROR
        changes = runtime.tree_changes(msg.tick, obs.time)
        tree = encode_tree_changes(changes) if changes is not None else None
        answer = encode_agent_out(msg.tick, agent_id, action, messages, events)
        self.sample_bytes["out"] += len(answer)
        self._answer(msg.shard, tree, answer, inline)
        if st is not None:
            st.mark("answer")
            st.ticks += 1
        return None

    def _out(self, shard: int | None, inline: bool) -> zenoh.Publisher | None:
        """Where this tick's answer goes: the output key, or below it the key of the proxy that
        reads it (a radio split by region), declared on first use by the main thread (None from
        the callback until then: the answer is deferred)."""
        if shard is None:
            return self.out
        publisher = self.shard_outs.get(shard)
        if publisher is None and not inline:
            publisher = self.session.declare_publisher(
                f"{self.out_key}/{shard}", congestion_control=zenoh.CongestionControl.BLOCK
            )
            self.shard_outs[shard] = publisher
        return publisher

    def _answer(self, shard: int | None, tree: bytes | None, answer: bytes, inline: bool) -> None:
        """Put the tick's tree changes (if any) and then its answer; from the callback, only what
        fits the transmit queue and has its publisher, the rest through the main thread in order."""
        out = self._out(shard, inline)
        if inline and (out is None or len(answer) + len(tree or b"") > INLINE_PUT_MAX):
            if tree is not None:
                self._defer("put", (self.bt, tree))
            self._defer("answer", (shard, answer))
            return
        assert out is not None
        if tree is not None:
            self._put(self.bt, tree, inline)
        self._put(out, answer, inline)

    def _put(self, publisher: zenoh.Publisher, data: bytes, inline: bool) -> None:
        if inline and len(data) > INLINE_PUT_MAX:
            self._defer("put", (publisher, data))
        else:
            publisher.put(data)


def _hand_over_state(
    session: zenoh.Session, keys: Keys, runtime: AgentRuntime, incarnation: int, malformed: int, report, ticket: bytes
) -> bool:
    """Give the coordinator this agent's snapshot; whether it took it (and this process is frozen)."""
    agent_id = runtime.agent_id
    try:
        state = runtime.snapshot({"malformed": malformed})
    except StateError as exc:
        log.error("agent %d: cannot snapshot its state: %s", agent_id, exc)
        report(SnapshotFailed(kind="snapshot_failed", agent=agent_id, incarnation=incarnation, error=str(exc)))
        return False
    if not hand_over(session, keys.agent_snapshot(agent_id), encode_handover(ticket, state)):
        log.error("agent %d: the coordinator did not take the snapshot", agent_id)
        return False
    log.info("agent %d: state handed over (%d bytes); waiting to retire or resume", agent_id, len(state))
    return True


def _checkpoint(runtime: AgentRuntime, incarnation: int, malformed: int, report, ticket: bytes) -> None:
    """Report this agent's state and go on (the coordinator keeps the last to restart it from)."""
    try:
        state = runtime.snapshot({"malformed": malformed})
    except StateError as exc:  # nothing to restart from: the agent would start fresh
        log.warning("agent %d: no checkpoint: %s", runtime.agent_id, exc)
        return
    report(
        Checkpoint(
            kind="checkpoint",
            agent=runtime.agent_id,
            incarnation=incarnation,
            ticks=runtime.ticks,
            state=state,
            ticket=ticket,
        )
    )


def _host_name(text: str) -> str:
    try:
        return check_host_name(text)
    except CredentialsError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _add_args(ap) -> None:
    ap.add_argument("--id", type=int, required=True, help="0 <= id < agents.count")
    ap.add_argument("--incarnation", type=int, default=0, help="which process of this agent (a swap starts the next)")
    ap.add_argument("--restore", action="store_true", help="continue from the snapshot the coordinator holds")
    ap.add_argument("--host", type=_host_name, default=None, help="the host daemon that started it (set by it)")


def main(argv: list[str] | None = None) -> int:
    args = child_args("swarmbed agent", "run one swarmbed agent process", _add_args, argv)
    keys = Keys(args.run_id)
    with open_from_args(args) as session:
        try:
            spec = fetch_spec(session, keys.agent_config, AgentSpec, f"agent config of run {args.run_id}")
            if not 0 <= args.id < spec.agents.count:
                log.error("agent id %d is outside 0..%d of run %s", args.id, spec.agents.count - 1, args.run_id)
                return 2
            if not args.restore and is_alive(session, keys.alive_agent_any(args.id)):
                log.error(
                    "agent %d of run %s is already running (its liveliness token is held); "
                    "refusing to start a second one",
                    args.id,
                    args.run_id,
                )
                return 2
            runtime = AgentRuntime(spec, args.id)
            malformed = 0
            if args.restore:
                try:
                    malformed = int(runtime.restore(fetch_bytes(session, keys.agent_snapshot(args.id)))["malformed"])
                except (StateError, JoinError, KeyError, ValueError) as exc:
                    log.error("agent %d: cannot restore: %s", args.id, exc)
                    if not hand_over(
                        session,
                        keys.agent_report(args.id),
                        encode_report(
                            RestoreFailed(
                                kind="restore_failed", agent=args.id, incarnation=args.incarnation, error=str(exc)
                            )
                        ),
                    ):
                        log.error("agent %d: the coordinator did not take the restore_failed report", args.id)
                    return EXIT_PLUGIN_ERROR
            return serve(
                session, keys, runtime, args.incarnation, restored=args.restore, malformed=malformed, host=args.host
            )
        except Exception:
            # logged while the session, and with it the liveliness token, is still held (see netem)
            log.exception("agent %d: failed", args.id)
            return EXIT_PLUGIN_ERROR
