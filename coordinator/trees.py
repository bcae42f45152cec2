"""The agents' behavior trees, recorded: ``bt/agent_<id>.btlog`` per agent (``run.record_bt``), in
BehaviorTree.CPP's file-logger format so Groot2 replays them (:mod:`swarmbed.wire.btlog`).

Every agent hands over each tick's status changes on its own key, on the session that carries its
answer of the tick, so they are here before the run's end; its first sample carries its tree. Records
are stamped with the tick's simulated time, so a lock-step run's files are byte-identical on every
rerun and placement. A process that starts again from a checkpoint sends its tree again (ignored)
and ticks already recorded (ignored: the first account of a tick stands).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import zenoh

from swarmbed.files.safefiles import make_dirs, open_fresh, rename
from swarmbed.records.run_folder import BT, PART_SUFFIX, PARTIAL_PREFIX, btlog_name
from swarmbed.wire.btlog import decode_tree_changes, file_head, records, tree_size
from swarmbed.wire.errors import WireError
from swarmbed.wire.keys import Keys, agent_id_of

log = logging.getLogger("swarmbed.coordinator")


class _AgentLog:
    def __init__(self, path: Path, xml: str) -> None:
        self.path = path
        self.n_nodes = tree_size(xml)
        self.last_tick = -1
        self.file: BinaryIO = open_fresh(path)  # open for the run, closed by the recorder
        self.file.write(file_head(xml))


class TreeRecorder:
    """Writes each agent's ``.btlog`` as its samples arrive (on Zenoh's callback thread)."""

    def __init__(self, out_dir: Path, n_agents: int, dt: float, malformed: Callable[[str, Exception], None]) -> None:
        self.folder = out_dir / BT
        self.n = n_agents
        self.dt_us = dt * 1_000_000
        self.malformed = malformed
        self.logs: dict[int, _AgentLog] = {}
        self.lock = threading.Lock()
        make_dirs(out_dir, self.folder)  # the launcher emptied it: no earlier run's file passes for ours

    def on_sample(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            agent = agent_id_of(key)
            if not 0 <= agent < self.n:
                raise WireError(f"no agent {agent} in this run")
            with self.lock:
                known = self.logs.get(agent)
                changes = decode_tree_changes(sample.payload.to_bytes(), known.n_nodes if known else None)
                if known is None:
                    if changes.xml is None:
                        raise WireError("tree changes before the agent's tree")
                    known = self.logs[agent] = _AgentLog(self.folder / (btlog_name(agent) + PART_SUFFIX), changes.xml)
                    if any(uid > known.n_nodes for uid, _ in changes.changes):
                        raise WireError(f"tree changes of nodes beyond the {known.n_nodes} of agent {agent}'s tree")
                if changes.tick <= known.last_tick:
                    return  # a process restarted from a checkpoint: the first account of a tick stands
                known.last_tick = changes.tick
                known.file.write(records(round(changes.tick * self.dt_us), changes.changes))
        except WireError as exc:
            self.malformed(key, exc)

    def finish(self, last_tick: int, lost: set[int]) -> None:
        """The run completed: close every file under its name."""
        with self.lock:
            for agent, entry in sorted(self.logs.items()):
                entry.file.close()
                if entry.last_tick != last_tick and agent not in lost:
                    log.warning(
                        "coordinator: agent %d's tree log ends at tick %d of %d", agent, entry.last_tick, last_tick
                    )
                rename(entry.path, self.folder / btlog_name(agent))
            self.logs.clear()

    def abandon(self) -> None:
        """The run did not complete: keep what was recorded as ``partial_agent_<id>.btlog``."""
        with self.lock:
            for agent, entry in self.logs.items():
                entry.file.close()
                rename(entry.path, self.folder / (PARTIAL_PREFIX + btlog_name(agent)))
            self.logs.clear()


class TreeRelay:
    """Agents hand their trees' changes over while the run records them or a monitor watches;
    monitors (``swarmbed groot``) read them under ``view/`` from here, with DROP, so a monitor that
    stops reading holds nothing up. Only the changes of an agent someone monitors are republished
    (none while only recording)."""

    def __init__(self, session: zenoh.Session, keys: Keys, trees: TreeRecorder | None) -> None:
        self.session, self.keys, self.trees = session, keys, trees
        self.monitored: set[str] = set()  # monitor token keys alive now

    def declare(self) -> list:
        s, k = self.session, self.keys
        return [
            s.liveliness().declare_subscriber(k.monitor_all, self._on_monitor, history=True),
            s.declare_subscriber(k.agent_bt_all, self._on_bt),
        ]

    def _on_monitor(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        (self.monitored.add if sample.kind == zenoh.SampleKind.PUT else self.monitored.discard)(key)

    def _on_bt(self, sample: zenoh.Sample) -> None:
        if self.trees is not None:
            self.trees.on_sample(sample)
        if not self.monitored:
            return
        try:
            agent = agent_id_of(str(sample.key_expr))  # only agent i may publish on agent/<i>/bt
        except WireError:
            return
        if self.keys.monitor(agent) in self.monitored:
            self.session.put(self.keys.view_bt(agent), sample.payload, congestion_control=zenoh.CongestionControl.DROP)
