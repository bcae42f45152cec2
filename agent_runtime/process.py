"""The agent process: one per agent, a Zenoh client of the run's coordinator.

Per tick it waits for its one input sample (observation + inbox of tick k), ticks its tree once and
publishes one output sample (action + radio messages). It needs nothing but an endpoint, the run id
and its agent id: the experiment itself comes from the coordinator, so it can run on another host.
"""

from __future__ import annotations

import logging
import traceback

import zenoh
from pydantic import BaseModel

from swarmbed.agent_runtime.runtime import AgentRuntime
from swarmbed.wire.btlog import encode_tree_changes
from swarmbed.wire.codec import (
    ControlIn,
    StopIn,
    WireError,
    decode_agent_in,
    encode_agent_out,
    encode_handover,
    encode_stop,
)
from swarmbed.wire.keys import Keys
from swarmbed.wire.membership import JoinError, fetch_bytes, fetch_spec, hand_over, is_alive
from swarmbed.wire.process import child_args
from swarmbed.wire.reports import (
    Checkpoint,
    Fatal,
    Restored,
    RestoreFailed,
    SnapshotFailed,
    Transport,
    encode_report,
)
from swarmbed.wire.schema import AgentSpec
from swarmbed.wire.session import open_from_args
from swarmbed.wire.state import StateError
from swarmbed.wire.transport import tcp_counters

log = logging.getLogger("swarmbed.agent")

EXIT_OK, EXIT_PLUGIN_ERROR, EXIT_COORDINATOR_GONE = 0, 1, 3
COORDINATOR_GONE = "coordinator gone"


def serve(
    session: zenoh.Session,
    keys: Keys,
    runtime: AgentRuntime,
    incarnation: int = 0,
    restored: bool = False,
    malformed: int = 0,
) -> int:
    """Answer tick samples until the run stops this agent. Swap orders name an incarnation: on
    ``snapshot`` this process hands its state to the coordinator and freezes (answers no tick),
    then either ``retire``s (its successor goes on) or ``resume``s (the swap failed)."""
    agent_id = runtime.agent_id
    in_key = keys.agent_in(agent_id)
    # A channel subscriber wakes this thread directly (no Python callback thread in between): the
    # per-tick wake-up is what lock-step pays for, once per agent per tick.
    sub = session.declare_subscriber(in_key)

    def on_coordinator(sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE:  # wake the loop with a local stop order
            session.put(in_key, encode_stop(COORDINATOR_GONE))

    watch = session.liveliness().declare_subscriber(keys.alive_coordinator, on_coordinator)
    out = session.declare_publisher(keys.agent_out(agent_id), congestion_control=zenoh.CongestionControl.BLOCK)
    # before each answer, on the same session: the coordinator has a tick's changes before its end
    bt = session.declare_publisher(keys.agent_bt(agent_id), congestion_control=zenoh.CongestionControl.BLOCK)

    def report(data: BaseModel) -> None:
        if not hand_over(session, keys.agent_report(agent_id), encode_report(data)):
            log.error("agent %d: the coordinator did not take the %s report", agent_id, getattr(data, "kind", "?"))

    # monitors (swarmbed groot) announce themselves with a token; the loop starts or stops handing
    # over the tree's changes between ticks, never inside one
    monitors: set[str] = set()

    def on_monitor(sample: zenoh.Sample) -> None:
        (monitors.add if sample.kind == zenoh.SampleKind.PUT else monitors.discard)(str(sample.key_expr))

    watched = session.liveliness().declare_subscriber(keys.monitor(agent_id), on_monitor, history=True)
    token = session.liveliness().declare_token(keys.alive_agent(agent_id, incarnation))
    if restored:  # subscribed and announced: the coordinator may retire the old process and go on
        report(Restored(kind="restored", agent=agent_id, incarnation=incarnation))
    frozen = False
    sample_bytes = {"in": 0, "out": 0}  # this process's per-tick samples, for the wire-bytes accounting
    try:
        while True:
            data = sub.recv().payload.to_bytes()
            sample_bytes["in"] += len(data)
            try:
                msg = decode_agent_in(data)
            except WireError as exc:
                malformed += 1
                log.warning("agent %d: malformed sample on %s dropped: %s", agent_id, in_key, exc)
                continue
            if isinstance(msg, ControlIn):
                if msg.incarnation != incarnation:
                    continue  # an order for the other process of a swap
                if msg.order == "snapshot":
                    frozen = _hand_over_state(session, keys, runtime, incarnation, malformed, report, msg.ticket)
                elif msg.order == "checkpoint" and not frozen:
                    _checkpoint(runtime, incarnation, malformed, report, msg.ticket)
                elif msg.order == "resume":
                    frozen = False
                    log.info("agent %d: swap cancelled; going on here", agent_id)
                elif msg.order == "retire":
                    log.info("agent %d: moved to incarnation %d elsewhere; exiting", agent_id, incarnation + 1)
                    return EXIT_OK
                continue
            if isinstance(msg, StopIn):
                if msg.reason == COORDINATOR_GONE:
                    log.error("agent %d: the coordinator went away; exiting", agent_id)
                    return EXIT_COORDINATOR_GONE
                transport = Transport.model_validate({"tcp": tcp_counters(), "samples": sample_bytes})
                report(runtime.report(extra_malformed=malformed, transport=transport))
                return EXIT_OK
            if frozen:
                continue  # its successor answers this tick
            try:
                obs = runtime.decode_observation(msg.obs)
            except WireError as exc:  # blind for one tick: answer it (the clock must go on), count it
                malformed += 1
                log.warning("agent %d: malformed observation of tick %d dropped: %s", agent_id, msg.tick, exc)
                out.put(encode_agent_out(msg.tick, agent_id, ["stop"], []))
                continue
            if bool(monitors) != runtime.watched:
                runtime.monitored(bool(monitors))
            try:
                action, messages, events = runtime.step(msg.tick, obs, msg.inbox)
            except Exception as exc:  # a plugin or node raised: stop this agent, loudly
                tb = traceback.format_exc()
                log.error("agent %d: failed at tick %d:\n%s", agent_id, msg.tick, tb)
                error = f"{type(exc).__name__}: {exc}"
                report(Fatal(kind="fatal", agent=agent_id, tick=msg.tick, error=error, traceback=tb))
                return EXIT_PLUGIN_ERROR
            changes = runtime.tree_changes(msg.tick, obs.time)
            if changes is not None:
                bt.put(encode_tree_changes(changes))
            answer = encode_agent_out(msg.tick, agent_id, action, messages, events)
            sample_bytes["out"] += len(answer)
            out.put(answer)
    except Exception:  # ours, not the plugin's: logged before the token goes (the launcher then stops us)
        log.exception("agent %d: failed", agent_id)
        return EXIT_PLUGIN_ERROR
    finally:
        token.undeclare()
        for entity in (sub, watch, watched, out, bt):
            entity.undeclare()


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


def _add_args(ap) -> None:
    ap.add_argument("--id", type=int, required=True, help="0 <= id < agents.count")
    ap.add_argument("--incarnation", type=int, default=0, help="which process of this agent (a swap starts the next)")
    ap.add_argument("--restore", action="store_true", help="continue from the snapshot the coordinator holds")


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
            return serve(session, keys, runtime, args.incarnation, restored=args.restore, malformed=malformed)
        except Exception:
            # logged while the session, and with it the liveliness token, is still held (see netem)
            log.exception("agent %d: failed", args.id)
            return EXIT_PLUGIN_ERROR
