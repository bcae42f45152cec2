"""The coordinator: the Zenoh transport of a run's :class:`~swarmbed.engine.Session`.

The session owns the world, the recorder and the tick loop; per tick k the coordinator publishes
the world (positions, membership) to the proxy and the live agents' inputs (each one's
observation and inbox of tick k: one sample for an agent on this machine, one for all of a host's,
which the host's relay hands out, :mod:`swarmbed.hosts.relay`), and waits for the proxy's step
(every live agent's action and message of tick k taken, or on the real-time clock those that came
before the deadline). What a run over processes adds around a tick are the hooks it hands the
loop: the wall clock
(:mod:`~swarmbed.coordinator.clock`), the agents' lifecycle, which starts, swaps and restarts
them and is the run's membership (:mod:`~swarmbed.coordinator.lifecycle`), ROS 2 topics
(:mod:`~swarmbed.coordinator.ros2_hub`) and the run's progress (:mod:`~swarmbed.coordinator.live`).
The coordinator's session is the run's Zenoh hub: it listens, everyone else connects to it as a
client.
"""

from __future__ import annotations

import logging
import queue
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import zenoh

from swarmbed.coordinator.clock import WallClock
from swarmbed.coordinator.events import CONSUMED, EventQueue
from swarmbed.coordinator.lifecycle import AgentLifecycle
from swarmbed.coordinator.live import Interval, LiveStatus, Watched
from swarmbed.coordinator.process_control import Placement
from swarmbed.coordinator.tick_inputs import TickInputs
from swarmbed.coordinator.trees import TreeRecorder, TreeRelay
from swarmbed.engine import Session, StopWhenAsked, TickHook, refusals
from swarmbed.engine.hooks import Profile
from swarmbed.engine.recorder import Recorder
from swarmbed.engine.run_errors import RunError
from swarmbed.extension.allocator import Allocator
from swarmbed.extension.scenario import Scenario, World
from swarmbed.records.summary import RunSummary
from swarmbed.schema.experiment import Experiment, Targets, agent_spec, netem_spec
from swarmbed.schema.obstacles import wall_lines
from swarmbed.wire.codec import (
    NetemStep,
    WireError,
    WorldSample,
    decode_netem_step,
    encode_netem_stop,
    encode_stop,
    encode_world,
    unpack,
)
from swarmbed.wire.control import (
    AgentReport,
    Checkpoint,
    Fatal,
    Final,
    NetemFatal,
    NetemFinal,
    decode_agent_report,
    decode_netem_report,
)
from swarmbed.wire.keys import Keys, agent_id_of, alive_agent_of, incarnation_of, proxy_name
from swarmbed.wire.membership import accept_handovers, serve_text
from swarmbed.wire.observation import Observation
from swarmbed.wire.regions import by_region
from swarmbed.wire.stages import Stages
from swarmbed.wire.stages import enabled as stages_enabled
from swarmbed.wire.zenoh_session import undeclare_all

BLOCK = zenoh.CongestionControl.BLOCK
log = logging.getLogger("swarmbed.coordinator")
__all__ = ["RunError", "ZenohTransport"]


class RadioMerge(Protocol):
    """The merge of a split radio's K proxy parts into what one proxy gives; the launcher hands it
    (``swarmbed.netem.radio_split``), as the coordinator imports no other process role."""

    def merge_steps(self, steps: Sequence[NetemStep]) -> NetemStep: ...

    def merge_finals(self, finals: Sequence[NetemFinal]) -> NetemFinal: ...

    def merge_ledgers(self, out_dir: Path, shards: int) -> Path: ...


class _OneProxy:
    """One proxy's parts need no merge: a run of one radio never calls these."""

    def merge_steps(self, steps: Sequence[NetemStep]) -> NetemStep:
        raise RuntimeError("one proxy: no steps to merge")

    def merge_finals(self, finals: Sequence[NetemFinal]) -> NetemFinal:
        raise RuntimeError("one proxy: no reports to merge")

    def merge_ledgers(self, out_dir: Path, shards: int) -> Path:
        raise RuntimeError("one proxy: no ledger parts to merge")


_ONE_PROXY = _OneProxy()


class ZenohTransport(TickHook):
    """The coordinator of one run: the Zenoh transport of its :class:`~swarmbed.engine.Session`. The
    launcher hands it the experiment, the scenario, the session's world and recorder, the allocator
    class (for where its decisions come from) and the targets agents load; :meth:`hooks` are what
    it adds around a tick."""

    def __init__(
        self,
        exp: Experiment,
        scenario: Scenario,
        world: World,
        recorder: Recorder,
        allocator: type[Allocator],
        targets: Targets,
        keys: Keys,
        session: zenoh.Session,
        out_dir: Path,
        hosts: dict[int, str] | None = None,
        carriers: Mapping[str, frozenset[int]] | None = None,
        placement: Placement | None = None,
        decider: Any = None,
        radio_merge: RadioMerge | None = None,
    ) -> None:
        self.exp = exp
        self.scenario = scenario
        self.targets = targets
        self.keys = keys
        self.session = session
        self.out_dir = out_dir
        self.n = exp.agents.count
        self.placement = placement  # starts and stops agent processes (the launcher's); None: it cannot
        self.world = world
        self.events = EventQueue()  # (what, data) from Zenoh callbacks
        self.agents = AgentLifecycle(
            exp, keys, self.world, self.events, hosts or {}, carriers, placement, self._decode_report, self._malformed
        )
        self.recorder = recorder
        self.trees = TreeRecorder(out_dir, self.n, exp.run.dt, self._malformed) if exp.run.record_bt else None
        self.joined: set[str] = set()
        self.reports: dict[int, Final] = {}
        self.netem_report: NetemFinal | None = None
        # the proxies: one, or the K of a radio split over proxies (swarmbed.netem.radio_split), each
        # with its token, its step of every tick and its final report, merged here
        self.shards = exp.radio_split.shards
        if self.shards > 1 and radio_merge is None:
            raise ValueError("a radio split over proxies needs the merge of their parts (radio_merge)")
        self.radio_merge: RadioMerge = radio_merge or _ONE_PROXY
        self.proxy_tokens = {key: i for i, key in enumerate(keys.netem_tokens(self.shards))}
        self.steps: dict[int, NetemStep] = {}
        self.finals: dict[int, NetemFinal] = {}
        self.malformed = 0
        self.clock = WallClock(exp.run)  # pacing and wall-clock facts (never in a lock-step run's files)
        self.last_tick = -1
        self.wall: dict[str, float] = {}
        self.stop = StopWhenAsked()  # end the run after the tick under way (a soak's duration)
        self._entities: list = []
        self.ros2: Any = None  # a Ros2Out while the run publishes ROS 2 topics
        # where the decisions of an allocator that takes them from outside come from: ROS 2 topics
        # (a Ros2Commands, made in declare) or the decider the launcher was handed (swarmbed.envs)
        self.decision_source = allocator.decision_source
        self.commands: Any = decider if self.decision_source == "env" else None
        self.stages = Stages() if stages_enabled() else None  # benchmarks/profile_tick.py
        split = exp.radio_split if by_region(exp.radio_split, exp.network) else None
        self.inputs = TickInputs(session, keys, split)  # where each tick's inputs go
        self.watched = Watched(exp, self.world, self.recorder, self.agents, self.clock, self._put_status)

    def hooks(self) -> list[TickHook]:
        """What a run over processes adds around a tick, in order: the wall clock, the agents'
        lifecycle (swaps, restarts, checkpoints), the world sample out to the proxy, ROS 2 topics,
        the live status, a soak's stop and the profile."""
        hooks: list[TickHook] = [self.clock, self.agents, self]
        if self.ros2 is not None:
            from swarmbed.coordinator.ros2_hub import Ros2Publishing

            hooks.append(Ros2Publishing(self.ros2, self.world, self._task_size))
        hooks += [self.watched, self.stop]
        if self.stages is not None:
            hooks.append(Profile(self.stages, log, "coordinator"))
        return hooks

    # -- setup -----------------------------------------------------------------------------------
    def declare(self) -> None:
        s, k, put = self.session, self.keys, self.events.put
        self._entities += [
            serve_text(s, k.agent_config, agent_spec(self.exp, self.targets).model_dump_json()),
            serve_text(s, k.netem_config, netem_spec(self.exp, self.agents.carriers).model_dump_json()),
            s.declare_subscriber(k.netem_step, lambda x: put(("step", x.payload.to_bytes()))),
            accept_handovers(s, k.agent_report_all, lambda key, data: put(("report", (key, data)))),
            accept_handovers(s, k.netem_report, lambda _key, data: put(("netem_report", data))),
            s.liveliness().declare_subscriber(k.alive_all, self._on_alive, history=True),
            s.declare_queryable(k.agent_snapshot_all, self.agents.on_snapshot_query),
            s.declare_queryable(k.swap, self.agents.on_swap_query),
        ]
        self._entities += TreeRelay(s, k, self.trees).declare()
        self.agent_pubs = [s.declare_publisher(k.agent_in(i), congestion_control=BLOCK) for i in range(self.n)]
        self.agents.agent_pubs = self.agent_pubs
        self.inputs.agent_pubs = self.agent_pubs
        self.world_pub = s.declare_publisher(k.world, congestion_control=BLOCK)
        self.stop_pub = s.declare_publisher(k.netem_stop, congestion_control=BLOCK)
        # progress for watchers: dropped rather than waited for when a watcher is slow (never blocks a tick)
        self.status_pub = s.declare_publisher(k.status, congestion_control=zenoh.CongestionControl.DROP)
        self._entities += self.agent_pubs + [self.world_pub, self.stop_pub, self.status_pub]
        self._entities.append(s.liveliness().declare_token(k.alive_coordinator))
        if self.exp.ros2 is not None:  # the run as ROS 2 topics (docs/ros2.md): the hub is also a ROS 2 node
            from swarmbed.coordinator.ros2_hub import Ros2Commands, Ros2Out

            try:
                walls = wall_lines(self.exp.obstacles)
                self.ros2 = Ros2Out(s, self.exp.ros2, self.n, self.scenario.actions, self.exp.run.dt, walls)
            except ImportError as exc:  # the ros2 extra is not installed: say so before any process starts
                raise RunError(str(exc)) from None
            if self.decision_source == "ros2":
                timeout = self.exp.ros2.command_timeout
                self.commands = Ros2Commands(self.ros2, self.n, timeout, self.clock.realtime, self._malformed)
        if self.decision_source == "env" and self.commands is None:
            raise RunError(refusals(self.exp, "env")[0])

    def _on_alive(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        if key not in self.proxy_tokens and key != self.keys.alive_coordinator:
            try:
                alive_agent_of(key, self.keys.root, self.n)
            except WireError as exc:  # a token no process of this run holds: never taken for one
                self._malformed(key, exc)
                return
        self.events.put(("join" if sample.kind == zenoh.SampleKind.PUT else "leave", key))

    @property
    def _task_size(self) -> float:
        """How wide a task is drawn for ROS 2: the scenario's arrival diameter, where it has one."""
        return 2.0 * float(getattr(self.scenario.params, "arrival_radius", 0.5))

    def close(self) -> None:
        self.inputs.close()
        self.commands = None  # its entities are the node's, closed with it
        if self.ros2 is not None:
            self.ros2.close()
            self.ros2 = None
        undeclare_all(self._entities)

    def _who(self, key: str) -> str:
        if key in self.proxy_tokens:
            return proxy_name(self.proxy_tokens[key])
        return f"agent_{agent_id_of(key)}"

    def wait_for_members(self, check_children: Callable[[], None]) -> None:
        """Until the proxy and every agent hold a liveliness token; ``check_children`` raises if a
        launched process already exited."""
        wanted = {proxy_name(i) for i in range(self.shards)} | {f"agent_{i}" for i in range(self.n)}
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
                what, data = self.events.next(0.1)
            except queue.Empty:
                continue
            if what == "join" and not data.endswith("/coordinator"):
                self.joined.add(self._who(data))
            elif what == "leave" and not data.endswith("/coordinator"):
                self.joined.discard(self._who(data))
            elif what == "report":
                self._on_report(data, tick=-1)

    # -- the tick loop (lock-step, or paced by the wall on the real-time clock) -----------------------
    def abandon_tables(self) -> list[Path]:
        """The run did not complete: keep the rows streamed so far as ``partial_*`` files."""
        if self.trees is not None:
            self.trees.abandon()
        return self.recorder.abandon()

    # -- the transport and its own hook points (swarmbed.engine.TickLoop drives them) ---------------
    def world_ready(self, sample: WorldSample) -> None:
        self.world_pub.put(encode_world(sample))  # the proxy routes with it while observations are made

    def exchange(
        self,
        k: int,
        sample: WorldSample,
        observed: Mapping[int, Observation],
        inboxes: Mapping[int, bytes],
        decisions: Mapping[int, int],
    ) -> NetemStep:
        """Put every live agent's input of tick ``k`` and wait for the proxy's step; on the real-time
        clock an agent that missed the deadline keeps its last command where ``run.on_late`` says."""
        st, w = self.stages, self.world
        if self.commands is not None and not decisions:
            decisions = self.commands.decide(k, w, observed, inboxes)
        self.inputs.put(k, sample, observed, inboxes, decisions, self.agents.hosts)
        if st is not None:
            st.mark("encode and put")
        step = self._await_step(k)
        if st is not None:
            st.mark("await step")
        return self.clock.answers(step)

    def tick_done(self, k: int, admitted: Mapping[int, list]) -> None:
        self.last_tick = k

    def run_ends(self) -> None:
        self.wall["run_s"] = self.clock.elapsed()

    # -- for monitors in this process (soak, chaos): see coordinator/live.py --------------------------
    def live(self) -> LiveStatus:
        """The run as of its last tick. The first call makes the coordinator publish a status after
        every tick from then on (a run nobody monitors builds none)."""
        return self.watched.live(self.last_tick)

    def _put_status(self, data: bytes) -> None:
        self.status_pub.put(data)

    def take_interval(self) -> Interval:
        """The slowest tick and the latest start since the last call (a soak's sample interval)."""
        return self.clock.take_interval()

    def _stuck(self) -> str:
        """Who held the tick up, as the proxy sees it: the agents that did not answer, or the proxy."""
        try:
            replies = self.session.get(self.keys.netem_awaiting, timeout=2.0)
            for reply in replies:
                if reply.ok is None:
                    continue
                tick, awaited = unpack(reply.ok.payload.to_bytes(), max_bytes=1 << 20)
                if awaited:
                    named = ", ".join(map(str, awaited[:20])) + (" ..." if len(awaited) > 20 else "")
                    logs = ", ".join(self.agents.log_of(int(a)) for a in awaited[:3])
                    return f"the proxy still waits for agent(s) {named} at tick {tick}; see {logs}"
                return f"the proxy has every answer of tick {tick}; see logs/netem.log"
        except Exception:  # a malformed or missing answer: say what is known
            pass
        return "the netem proxy did not answer; see logs/netem.log"

    def _await_step(self, k: int) -> NetemStep:
        timeout = self.exp.run.tick_timeout
        deadline = time.monotonic() + timeout
        while True:
            try:
                what, data = self.events.next(deadline - time.monotonic())
            except queue.Empty:
                raise RunError(
                    f"tick {k}: no step from the netem proxy within {timeout:.0f} s ({self._stuck()})"
                ) from None
            if what == "step":
                try:
                    step = decode_netem_step(data)
                except WireError as exc:
                    self._malformed(self.keys.netem_step, exc)
                    continue
                if step.tick != k:
                    self._malformed(self.keys.netem_step, WireError(f"step for tick {step.tick} while at tick {k}"))
                elif step.shard >= self.shards or step.shard in self.steps:
                    self._malformed(self.keys.netem_step, WireError(f"a step of proxy {step.shard} not awaited"))
                elif self.shards == 1:
                    return step
                else:
                    self.steps[step.shard] = step
                    if len(self.steps) == self.shards:
                        steps = [self.steps.pop(i) for i in range(self.shards)]
                        try:
                            return self.radio_merge.merge_steps(steps)
                        except WireError as exc:  # a proxy's own step is inconsistent: it is broken
                            raise RunError(f"tick {k}: the proxies' steps do not merge: {exc}") from None
            elif what == "leave":
                if data in self.proxy_tokens:
                    self._proxy_gone(k, self.proxy_tokens[data])
                if not data.endswith("/coordinator"):
                    agent = agent_id_of(data)
                    if incarnation_of(data) != self.agents.incarnation.get(agent, 0):
                        continue  # a process swapped out: its agent goes on elsewhere
                    self._await_fatal_report(agent)
                    self.agents.gone(agent, k)
            elif what == "report":
                self._on_report(data, k)
            elif what == "netem_report":  # mid-run, only a proxy that failed reports
                self._proxy_failed(k, data)

    def _proxy_failed(self, k: int, data: bytes) -> None:
        """A report from the proxy while ticks go on: only a failing proxy sends one (its error)."""
        try:
            rep = decode_netem_report(data)
        except WireError as exc:
            self._malformed(self.keys.netem_report, exc)
            return
        if isinstance(rep, NetemFatal):
            raise RunError(f"tick {k}: the netem proxy failed: {rep.error}; see logs/netem.log")

    def _proxy_gone(self, k: int, shard: int = 0, grace: float = 0.5) -> None:
        """The proxy's token went: raise with its own error if it reported one (it reports before it
        lets go of the token, but the two travel apart), else with its exit status and log."""

        def take(what: str, data: Any) -> object:
            if what != "netem_report":
                return None
            self._proxy_failed(k, data)  # raises on the proxy's error
            return CONSUMED

        self.events.wait_for(grace, take)
        name = proxy_name(shard)
        how = self.placement.exit_status(name) if self.placement else ""
        raise RunError(
            f"tick {k}: the netem proxy exited unexpectedly; see logs/{name}.log" + (f"\n{how}" if how else "")
        )

    def _await_fatal_report(self, agent: int, grace: float = 0.25) -> None:
        """An agent left. Its fatal report (if it failed) travels apart from its liveliness token and
        may come a little later: wait briefly for it, keeping every other event in order."""

        def take(what: str, data: Any) -> object:
            if what != "report":
                return None
            self._on_report(data, -1)
            return True if agent in self.agents.fatal else CONSUMED

        if agent not in self.agents.fatal:
            self.events.wait_for(grace, take)

    def _decode_report(self, key: str, data: bytes) -> AgentReport | None:
        """An agent's report, if it is well formed and names the agent whose key it came on
        (else dropped and counted)."""
        try:
            rep = decode_agent_report(data)
            if rep.agent >= self.n:
                raise WireError(f"report names no agent of this run: {rep.agent}")
            if rep.agent != agent_id_of(key):
                raise WireError(f"report of agent {rep.agent} on another agent's key")
        except WireError as exc:
            self._malformed(key, exc)
            return None
        return rep

    def _on_report(self, sample: tuple[str, bytes], tick: int) -> None:
        rep = self._decode_report(*sample)
        if rep is None:
            return
        agent = rep.agent
        if isinstance(rep, Fatal):
            self.agents.fatal[agent] = rep
            self.agents.lose(agent, rep.tick, "it raised an exception")
        elif isinstance(rep, Final):
            self.reports[agent] = rep
        elif isinstance(rep, Checkpoint):
            self.agents.on_checkpoint(agent, rep)

    def _malformed(self, key: str, exc: Exception) -> None:
        self.malformed += 1
        if self.malformed <= 20:
            log.warning("coordinator: malformed sample on %s dropped: %s", key, exc)

    # -- shutdown and results ---------------------------------------------------------------------
    def stop_and_collect(self, timeout: float = 30.0) -> None:
        """Tell the proxy and every live agent that the run is over; collect their final reports."""
        self.stop_pub.put(encode_netem_stop(self.last_tick))
        self.agents.end()
        retired = sorted(self.agents.retired)
        live = [i for i in range(self.n) if i not in self.agents.lost]
        for i in live:
            self.agent_pubs[i].put(encode_stop("run complete"))
        live += retired  # stopped earlier, but they report too
        deadline = time.monotonic() + timeout
        while len(self.finals) < self.shards or any(i not in self.reports for i in live):
            try:
                what, data = self.events.next(deadline - time.monotonic())
            except queue.Empty:
                missing = [f"agent_{i}" for i in live if i not in self.reports]
                missing[:0] = [proxy_name(i) for i in range(self.shards) if i not in self.finals]
                raise RunError(f"no final report within {timeout:.0f} s from: {', '.join(missing[:10])}") from None
            if what == "report":
                self._on_report(data, self.last_tick)
            elif what == "netem_report":
                try:
                    report = decode_netem_report(data)
                except WireError as exc:
                    self._malformed(self.keys.netem_report, exc)
                    continue
                if isinstance(report, NetemFatal):
                    raise RunError(f"the netem proxy failed at the end of the run: {report.error}; see logs/netem*.log")
                if report.shard >= self.shards or report.shard in self.finals:
                    self._malformed(self.keys.netem_report, WireError(f"a report of proxy {report.shard} not awaited"))
                    continue
                self.finals[report.shard] = report
        if self.shards == 1:
            self.netem_report = self.finals[0]
        else:  # every proxy wrote its part of the ledger in the run folder, here
            self.radio_merge.merge_ledgers(self.out_dir, self.shards)
            self.netem_report = self.radio_merge.merge_finals([self.finals[i] for i in range(self.shards)])

    def write_results(self, run: Session, timings: dict) -> RunSummary:
        """The run's result files, from the final reports :meth:`stop_and_collect` gathered."""
        assert self.netem_report is not None, "results before the proxy's final report"
        clock = self.clock.summary() if self.clock.realtime else None
        summary = run.write(self.reports, self.netem_report, self.malformed, clock, timings)
        if self.trees is not None:
            self.trees.finish(self.last_tick, set(self.agents.lost))
        return summary
