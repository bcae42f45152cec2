"""One agent's per-tick work, free of any networking: decode the inbox, tick the tree once,
encode the action and the outgoing messages. The process in ``agent_runtime.process`` wraps it in
Zenoh; tests and the conformance kit drive it directly."""

from __future__ import annotations

import logging
from collections import defaultdict
from importlib import resources
from pathlib import Path

import numpy as np

from swarmbed.agent_runtime.bt import Blackboard, load_tree
from swarmbed.agent_runtime.nodes import space_registry
from swarmbed.experiments.config import Experiment, scenario_sensing
from swarmbed.plugins import make
from swarmbed.plugins.base import LocalView, Message, TaskInfo
from swarmbed.wire.codec import RadioMessage, WireError, decode_inbox, decode_task_table, unpack
from swarmbed.wire.lifecycle import agent_seeds

log = logging.getLogger("swarmbed.agent")

DEFAULT_TREE = "space_default.xml"


def default_tree_path() -> Path:
    return Path(str(resources.files("swarmbed.agent_runtime") / "trees" / DEFAULT_TREE))


class AgentRuntime:
    def __init__(self, exp: Experiment, agent_id: int) -> None:
        self.exp = exp
        self.agent_id = agent_id
        n = exp.agents.count
        runtime_seed, allocator_seed = agent_seeds(exp.run.seed, agent_id, n, 2)
        self.rng = np.random.default_rng(runtime_seed)
        self.allocator = make(exp.allocator.name, exp.allocator.params(), agent_id,
                              np.random.default_rng(allocator_seed), exp.run.seed, exp.scenario.kind)
        sc = exp.scenario
        self.sensing = scenario_sensing(exp)
        bb = Blackboard()
        bb.set("exploration_duration", exp.agents.exploration_duration)
        bb.set("arrival_radius", getattr(sc, "arrival_radius", getattr(sc, "inspect_range", 1.0)))
        registry = space_registry()
        for node in type(self.allocator).bt_nodes:
            registry.register(node)
        if exp.agents.behavior_tree != "default":
            tree_path = Path(exp.agents.behavior_tree)
        elif type(self.allocator).default_tree:
            tree_path = Path(type(self.allocator).default_tree)
        else:
            tree_path = default_tree_path()
        self.tree = load_tree(tree_path, registry, blackboard=bb, context=self)
        self.view: LocalView | None = None
        self._action: list = ["stop"]
        self.sent: dict[str, list[int]] = defaultdict(lambda: [0, 0])  # kind -> [messages, payload bytes]
        self.malformed = 0
        self.ticks = 0

    def act(self, action: list) -> None:
        """Called by action nodes: the one action this agent sends for this tick (last one wins)."""
        self._action = action

    def _inbox(self, data: bytes) -> list[Message]:
        out = []
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

    def step(self, tick: int, obs: dict, inbox: bytes) -> tuple[list, list[RadioMessage], dict[str, int]]:
        me = obs["me"]
        tasks = {t[0]: TaskInfo(*t) for t in decode_task_table(obs["tasks"]).tolist()}
        a, sense = self.exp.agents, self.sensing
        self.view = LocalView(self.agent_id, a.count, tick, float(obs["t"]), me[0], me[1], me[2], me[3],
                              a.work_rate, tasks, self._inbox(inbox), sense.max_speed, sense.range, sense.angle,
                              int(obs.get("color", -1)), obs)
        self._action = ["stop"]
        self.allocator.observe(self.view)
        self.tree.tick_once()
        messages = []
        for out in self.view.outbox:
            msg = out.encode()
            counter = self.sent[out.kind]
            counter[0] += 1
            counter[1] += len(msg.payload)
            messages.append(msg)
        self.ticks += 1
        events, self.allocator.events = self.allocator.events, {}
        return self._action, messages, events

    def report(self) -> dict:
        return {
            "kind": "final",
            "agent": self.agent_id,
            "ticks": self.ticks,
            "sent": {k: list(v) for k, v in sorted(self.sent.items())},
            "malformed": self.malformed,
        }
