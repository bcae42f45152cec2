"""The agent process: one per agent, a Zenoh client of the run's coordinator.

Per tick it waits for its one input sample (observation + inbox of tick k), ticks its tree once and
publishes one output sample (action + radio messages). It needs nothing but an endpoint, the run id
and its agent id: the experiment itself comes from the coordinator, so it can run on another host.
"""

from __future__ import annotations

import logging
import traceback

import zenoh

from swarmbed.agent_runtime.runtime import AgentRuntime
from swarmbed.wire.codec import StopIn, WireError, decode_agent_in, encode_agent_out, encode_report, encode_stop
from swarmbed.wire.keys import Keys
from swarmbed.wire.lifecycle import child_args
from swarmbed.wire.membership import fetch_spec, hand_over, is_alive
from swarmbed.wire.schema import AgentSpec
from swarmbed.wire.session import open_from_args

log = logging.getLogger("swarmbed.agent")

EXIT_OK, EXIT_PLUGIN_ERROR, EXIT_COORDINATOR_GONE = 0, 1, 3
COORDINATOR_GONE = "coordinator gone"


def serve(session: zenoh.Session, keys: Keys, runtime: AgentRuntime) -> int:
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

    def report(data: dict) -> None:
        if not hand_over(session, keys.agent_report(agent_id), encode_report(data)):
            log.error("agent %d: the coordinator did not take the %s report", agent_id, data["kind"])

    token = session.liveliness().declare_token(keys.alive_agent(agent_id))
    malformed = 0
    try:
        while True:
            data = sub.recv().payload.to_bytes()
            try:
                msg = decode_agent_in(data)
            except WireError as exc:
                malformed += 1
                log.warning("agent %d: malformed sample on %s dropped: %s", agent_id, in_key, exc)
                continue
            if isinstance(msg, StopIn):
                if msg.reason == COORDINATOR_GONE:
                    log.error("agent %d: the coordinator went away; exiting", agent_id)
                    return EXIT_COORDINATOR_GONE
                final = runtime.report()
                final["malformed"] += malformed
                report(final)
                return EXIT_OK
            try:
                obs = runtime.decode_observation(msg.obs)
            except WireError as exc:  # blind for one tick: answer it (the clock must go on), count it
                malformed += 1
                log.warning("agent %d: malformed observation of tick %d dropped: %s", agent_id, msg.tick, exc)
                out.put(encode_agent_out(msg.tick, agent_id, ["stop"], []))
                continue
            try:
                action, messages, events = runtime.step(msg.tick, obs, msg.inbox)
            except Exception as exc:  # a plugin or node raised: stop this agent, loudly
                tb = traceback.format_exc()
                log.error("agent %d: failed at tick %d:\n%s", agent_id, msg.tick, tb)
                report({"kind": "fatal", "agent": agent_id, "tick": msg.tick,
                        "error": f"{type(exc).__name__}: {exc}", "traceback": tb})
                return EXIT_PLUGIN_ERROR
            out.put(encode_agent_out(msg.tick, agent_id, action, messages, events))
    finally:
        token.undeclare()
        for entity in (sub, watch, out):
            entity.undeclare()


def main(argv: list[str] | None = None) -> int:
    args = child_args("swarmbed agent", "run one swarmbed agent process",
                      lambda ap: ap.add_argument("--id", type=int, required=True, help="0 <= id < agents.count"),
                      argv)
    keys = Keys(args.run_id)
    with open_from_args(args) as session:
        spec = fetch_spec(session, keys.agent_config, AgentSpec, f"agent config of run {args.run_id}")
        if not 0 <= args.id < spec.agents.count:
            log.error("agent id %d is outside 0..%d of run %s", args.id, spec.agents.count - 1, args.run_id)
            return 2
        if is_alive(session, keys.alive_agent(args.id)):
            log.error("agent %d of run %s is already running (its liveliness token is held); "
                      "refusing to start a second one", args.id, args.run_id)
            return 2
        runtime = AgentRuntime(spec, args.id)
        return serve(session, keys, runtime)
