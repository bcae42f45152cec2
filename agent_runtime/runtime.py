"""One agent's per-tick work, free of any networking: decode the inbox, tick the tree once,
encode the action and the outgoing messages. The process in ``agent_runtime.process`` wraps it in
Zenoh; tests and the conformance kit drive it directly.

It is built from an :class:`~swarmbed.schema.experiment.AgentSpec` alone: the scenario and allocator
classes are loaded from the targets the launcher resolved, never looked up by name here.
"""

from __future__ import annotations

import logging
from collections import defaultdict
from typing import Any

import numpy as np

from swarmbed.bt import Blackboard, Status, load_tree
from swarmbed.bt.groot_tree import STATUS_CODE, BlackboardWatch, ChangeRecorder, tree_xml
from swarmbed.extension.allocator import Allocator
from swarmbed.extension.context import NodeContext
from swarmbed.extension.node_sets import node_registry, tree_path
from swarmbed.extension.scenario import Scenario
from swarmbed.extension.view import LocalView, Message, TaskInfo
from swarmbed.schema.experiment import AgentSpec
from swarmbed.wire.btlog import TreeChanges
from swarmbed.wire.codec import RadioMessage, WireError, decode_inbox, unpack
from swarmbed.wire.control import Final, Transport
from swarmbed.wire.observation import Observation
from swarmbed.wire.seeds import agent_seeds
from swarmbed.wire.stages import Stages
from swarmbed.wire.stages import enabled as stages_enabled
from swarmbed.wire.state import StateError, pack_state, unpack_state
from swarmbed.wire.targets import load_target

log = logging.getLogger("swarmbed.agent")

SNAPSHOT_VERSION = 1


def build_scenario(spec: AgentSpec) -> Scenario:
    cls = load_target(spec.targets.scenario, Scenario, spec.targets.digests)
    return cls(cls.Params.model_validate(spec.scenario.params()), spec.agents, spec.dt)


class AgentRuntime:
    def __init__(self, spec: AgentSpec, agent_id: int) -> None:
        self.spec = spec
        self.agent_id = agent_id
        self.n_agents = spec.agents.count
        runtime_seed, allocator_seed = agent_seeds(spec.seed, agent_id, self.n_agents, 2)
        self.scenario = build_scenario(spec)
        allocator_cls = load_target(spec.targets.allocator, Allocator, spec.targets.digests)
        self.allocator = allocator_cls(
            agent_id,
            allocator_cls.Params.model_validate(spec.allocator.params()),
            np.random.default_rng(allocator_seed),
            spec.seed,
        )
        self.sensing = self.scenario.sensing()
        self.context = NodeContext(agent_id, np.random.default_rng(runtime_seed), self.scenario, self.allocator)
        bb = Blackboard()
        for key, value in self.scenario.blackboard().items():
            bb.set(key, value)
        registry = node_registry([type(self.scenario), allocator_cls])
        self.tree = load_tree(
            tree_path(spec.agents.behavior_tree, type(self.scenario), allocator_cls),
            registry,
            blackboard=bb,
            context=self.context,
        )
        self.changes = ChangeRecorder(self.tree) if spec.record_bt else None
        self._tree_sent = False  # this process has not yet handed over its tree's XML
        self.watched = False  # a monitor (swarmbed groot) is looking
        self.boards: BlackboardWatch | None = None  # while it looks: what it last saw of the blackboards
        self.sent: dict[str, list[int]] = defaultdict(lambda: [0, 0])  # kind -> [messages, payload bytes]
        self.malformed = 0
        self.ticks = 0
        # the tasks in view at the last tick, as records and as the view's TaskInfo (see _tasks_in_view)
        self._table_bytes, self._table_ids = b"", b""
        self._tasks: dict[int, TaskInfo] = {}
        self.stages: Stages | None = Stages() if stages_enabled() else None  # benchmarks/profile_tick.py
        self._last_action: list | None = None
        self._last_tasks = b""
        if self.stages is not None:
            self._time_decide(self.stages)

    def _count_idle(self, st: Stages, obs: Observation, action: list, messages: list) -> None:
        """Count a tick that a step skipping idle agents could have spared (issue 43): the same answer
        as the tick before and no message sent, nothing received, and the same tasks
        in view; and the looser *quiet* tick, whatever its view. Profiling only."""
        tasks = obs.tasks.tobytes()
        if action == self._last_action and not messages and not self.context.view.inbox:
            st.quiet += 1
            st.idle += tasks == self._last_tasks
        self._last_action, self._last_tasks = list(action), tasks

    def _time_decide(self, st: Stages) -> None:
        """Charge ``decide`` to the allocator, not to the tree that calls it (profiling only). The
        allocator becomes an instance of a subclass that times it: its attributes, and so its
        snapshot, are untouched."""
        cls = type(self.allocator)

        def decide(allocator: Allocator, view: LocalView) -> Any:
            st.mark("tree")
            try:
                return cls.decide(allocator, view)
            finally:
                st.mark("allocator")

        self.allocator.__class__ = type(cls.__name__, (cls,), {"decide": decide, "__module__": cls.__module__})

    @property
    def view(self) -> LocalView:
        return self.context.view

    def decode_observation(self, raw: object) -> Observation:
        """The scenario's typed observation; a WireError names what is wrong with it."""
        return self.scenario.Observation.from_wire(raw)

    def _inbox(self, data: bytes) -> list[Message]:
        out: list[Message] = []
        try:
            delivered = decode_inbox(data)
        except WireError as exc:
            self.malformed += 1
            log.warning("agent %d: malformed inbox dropped: %s", self.agent_id, exc)
            return out
        for d in delivered:
            try:
                out.append(Message(d.sender, d.kind, unpack(d.payload)))
            except WireError as exc:
                self.malformed += 1
                log.warning("agent %d: malformed %r message from %d dropped: %s", self.agent_id, d.kind, d.sender, exc)
        return out

    def _tasks_in_view(self, table: np.ndarray) -> dict[int, TaskInfo]:
        """The view's task table. From one tick to the next most rows are the same (only the tasks
        being worked change, and the set in view changes now and then), so only the rows whose bytes
        changed are rebuilt: the same dict, in the same order, as rebuilding it all. Each view gets
        its own copy (a plugin may change it)."""
        raw = table.tobytes()
        if raw != self._table_bytes:
            ids = table["id"].tobytes()
            if ids == self._table_ids and len(self._tasks) == len(table):  # same ids, none repeated
                size, old = table.dtype.itemsize, self._table_bytes
                for row in range(len(table)):
                    at = row * size
                    if raw[at : at + size] != old[at : at + size]:
                        record = TaskInfo._make(table[row].tolist())
                        self._tasks[record[0]] = record
            else:
                self._tasks = {t[0]: t for t in map(TaskInfo._make, table.tolist())}
            self._table_bytes, self._table_ids = raw, ids
        return dict(self._tasks)

    def step(
        self, tick: int, obs: Observation, inbox: bytes, decision: int | None = None
    ) -> tuple[list, list[RadioMessage], dict[str, int]]:
        tasks = self._tasks_in_view(obs.tasks)
        a, sense, ctx = self.spec.agents, self.sensing, self.context
        ctx.view = LocalView(
            self.agent_id,
            self.n_agents,
            tick,
            obs.time,
            obs.x,
            obs.y,
            obs.heading,
            obs.speed,
            a.work_rate,
            tasks,
            self._inbox(inbox),
            a.max_speed,
            sense.range,
            sense.angle,
            obs,
            decision=decision,
        )
        ctx.action = ["stop"]
        st = self.stages
        if st is not None:
            st.mark("view")
        self.allocator.observe(ctx.view)
        if st is not None:
            st.mark("allocator")
        self.tree.tick_once()
        if st is not None:
            st.mark("tree")
        messages = []
        for out in ctx.view.outbox:
            msg = out.encode()
            counter = self.sent[out.kind]
            counter[0] += 1
            counter[1] += len(msg.payload)
            messages.append(msg)
        self.ticks += 1
        if st is not None:
            self._count_idle(st, obs, ctx.action, messages)
            st.mark("messages")
        events, self.allocator.events = self.allocator.events, {}
        return ctx.action, messages, events

    def tree_changes(self, tick: int, time: float) -> TreeChanges | None:
        """The status changes of the tick just stepped, when the run records them or someone
        monitors this agent; with the tree and every node's status the first time (for a monitor
        that joins now, a start)."""
        if self.changes is None:
            return None
        changes = self.changes.take()
        time_us = round(time * 1_000_000)
        if self._tree_sent:
            boards = self.boards.take() if self.boards is not None else {}
            return TreeChanges(tick, time_us, changes, blackboards=boards)
        self._tree_sent = True
        statuses = [(n.uid, STATUS_CODE[n.status]) for n in self.tree.nodes if n.status is not Status.IDLE]
        boards = self.boards.take(everything=True) if self.boards is not None else {}
        return TreeChanges(tick, time_us, changes, tree_xml(self.tree), statuses, boards)

    def monitored(self, watched: bool) -> None:
        """Someone began (or stopped) monitoring this agent's tree: hand over its changes from the
        next tick (with the tree), or stop unless the run records them."""
        self.watched = watched
        self.boards = BlackboardWatch(self.tree) if watched else None
        if watched:
            if self.changes is None:
                self.changes = ChangeRecorder(self.tree)
            self._tree_sent = False
        elif not self.spec.record_bt and self.changes is not None:
            self.tree.watch(None)
            self.changes = None

    # -- moving to another process ----------------------------------------------------------------
    #: node attributes the tree loader sets, and who watches a node's status: not state
    STRUCTURE = frozenset(
        {"name", "config", "_literals", "_children", "child", "uid", "tree_id", "fullpath", "_watcher"}
    )

    def _blackboards(self) -> list[Blackboard]:
        seen: dict[int, Blackboard] = {}
        for node in self.tree.nodes:
            seen.setdefault(id(node.config.blackboard), node.config.blackboard)
        return list(seen.values())

    def snapshot(self, extra: dict | None = None) -> bytes:
        """Everything that makes this agent continue as it would have: the allocator's state, every
        tree node's state, the blackboards, the agent's random generator and its counters. Taken
        between ticks; raises StateError (naming what) when something cannot move."""
        if not self.allocator.snapshottable:
            raise StateError(
                f"allocator {type(self.allocator).__name__} says its state cannot move (snapshottable = False)"
            )
        state = {
            "version": SNAPSHOT_VERSION,
            "agent": self.agent_id,
            "ticks": self.ticks,
            "sent": dict(self.sent),
            "malformed": self.malformed,
            "rng": self.context.rng,
            "allocator": self.allocator.snapshot(),
            "nodes": [{k: v for k, v in vars(n).items() if k not in self.STRUCTURE} for n in self.tree.nodes],
            "blackboards": [bb._store for bb in self._blackboards()],
            "extra": extra or {},
        }
        return pack_state(state)

    def restore(self, data: bytes) -> dict:
        """Continue from a snapshot taken by the same agent of the same run; returns its ``extra``."""
        state = unpack_state(data)
        if state.get("version") != SNAPSHOT_VERSION or state.get("agent") != self.agent_id:
            raise StateError(
                f"snapshot of agent {state.get('agent')} (version {state.get('version')}) "
                f"given to agent {self.agent_id}"
            )
        if len(state["nodes"]) != len(self.tree.nodes) or len(state["blackboards"]) != len(self._blackboards()):
            raise StateError("the snapshot's behavior tree has another shape than this agent's")
        self.ticks, self.malformed, self.context.rng = state["ticks"], state["malformed"], state["rng"]
        self.sent.clear()
        self.sent.update(state["sent"])
        self.allocator.restore(state["allocator"])
        for node, attrs in zip(self.tree.nodes, state["nodes"]):
            node.__dict__.update(attrs)
        for bb, store in zip(self._blackboards(), state["blackboards"]):
            bb._store = store
        return state["extra"]

    def report(self, extra_malformed: int = 0, transport: Transport | None = None) -> Final:
        """The agent's final report: what it sent per kind, and the samples it dropped as malformed
        (its runtime's and ``extra_malformed`` of its process)."""
        return Final(
            kind="final",
            agent=self.agent_id,
            ticks=self.ticks,
            sent={k: list(v) for k, v in sorted(self.sent.items())},
            malformed=self.malformed + extra_malformed,
            transport=transport,
        )
