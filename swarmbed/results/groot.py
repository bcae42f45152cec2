"""``swarmbed groot``: watch any agent's behavior tree of a running run in Groot2, live.

Groot2 monitors one tree per port (BehaviorTree.CPP issue 662, Groot2 issue 44); this gateway is
that one tree, for whichever agent you pick, and lets you switch agents while Groot2 stays
connected (a new tree identity makes Groot2 load the new tree). It speaks BehaviorTree.CPP's Groot2
protocol on ``--port`` (:mod:`.groot2`) and reads the run over Zenoh as an operator: it announces
itself with a liveliness token on the agent's monitor key, which makes that agent (and only while a
monitor is there) hand over its tree and each tick's status changes on its own key. Monitoring never
changes a run's results: the agent's tree ticks the same, it only reports.

    swarmbed groot --connect tcp/192.0.2.10:7447 --credentials operator.json --agent 3

Type another agent's id and Enter to switch; Ctrl-C to stop.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Iterable

import zenoh

from swarmbed.results.groot2 import MonitoredTree, serve, tree_identity
from swarmbed.results.watch import WatchError, running_runs
from swarmbed.wire.btlog import decode_tree_changes, tree_size
from swarmbed.wire.errors import WireError
from swarmbed.wire.keys import Keys
from swarmbed.wire.zenoh_session import undeclare_all


class Gateway:
    """One monitored agent at a time: its monitor token, its subscriber, and the tree Groot2 sees."""

    def __init__(self, session: zenoh.Session, run_id: str, tree: MonitoredTree | None = None) -> None:
        self.session = session
        self.keys = Keys(run_id)
        self.tree = tree or MonitoredTree()
        self.agent: int | None = None
        self.samples = 0
        self.bytes = 0  # of the samples heard: what monitoring costs the agent on the wire
        self.malformed = 0
        self._entities: list = []
        self._n_nodes: int | None = None
        self.lock = threading.Lock()

    def show(self, agent: int) -> None:
        """Monitor ``agent`` instead: Groot2 sees an empty tree until its first sample."""
        with self.lock:
            self._drop()
            self.agent, self._n_nodes = agent, None
            self.tree.reset("", tree_identity(self.keys.run_id, agent, "waiting"), 0)
            sub = self.session.declare_subscriber(self.keys.view_bt(agent), self._on_sample)
            token = self.session.liveliness().declare_token(self.keys.monitor(agent))
            self._entities = [sub, token]

    def _on_sample(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        try:
            changes = decode_tree_changes(data, self._n_nodes)
        except WireError:
            self.malformed += 1
            return
        with self.lock:
            if changes.xml is not None:
                self._n_nodes = tree_size(changes.xml)
                if any(uid > self._n_nodes for uid, _ in changes.changes + changes.statuses):
                    self.malformed += 1
                    return
                identity = tree_identity(self.keys.run_id, self.agent, changes.xml)
                self.tree.reset(changes.xml, identity, self._n_nodes, changes.statuses, changes.blackboards)
                self.tree.apply(changes.time_us, [])  # its time: a recording started now starts here
            elif self._n_nodes is not None:
                self.tree.apply(changes.time_us, changes.changes, changes.blackboards)
            self.samples += 1
            self.bytes += len(data)

    def _drop(self) -> None:
        undeclare_all(self._entities)

    def close(self) -> None:
        with self.lock:
            self._drop()


def find_run(session: zenoh.Session, run_id: str | None, wait: float = 0.0) -> str:
    """The run to monitor: ``run_id``, or the one run this session sees; asked again for ``wait``
    seconds while none is seen (a run that is starting has no coordinator token yet)."""
    deadline = time.monotonic() + wait
    while True:
        runs = running_runs(session)
        if runs or time.monotonic() >= deadline:
            break
        time.sleep(0.2)
    if run_id is not None:
        if run_id not in runs:
            raise WatchError(f"no run {run_id} is running where this session reaches (running: {runs or 'none'})")
        return run_id
    if len(runs) != 1:
        raise WatchError(f"{len(runs)} runs are running ({', '.join(runs) or 'none'}): name one with --run")
    return runs[0]


def agent_command(text: str) -> int | None:
    """The agent id a line typed at the gateway names, or None: ASCII digits only (``"²".isdigit()``
    is true, and ``int("²")`` raises), at most 9 of them."""
    text = text.strip()
    return int(text) if text.isascii() and text.isdigit() and len(text) <= 9 else None


def run_gateway(
    session: zenoh.Session,
    run_id: str | None,
    agent: int,
    port: int,
    bind: str = "127.0.0.1",
    commands: Iterable[str] | None = None,
    wait: float = 0.0,
) -> int:
    """Serve Groot2 until Ctrl-C (or SIGTERM), switching agents on ``commands`` (default: stdin lines,
    an agent id each). Where the commands end: at a terminal's end of input (Ctrl-D) the gateway
    stops; a closed standard input that is no terminal (``&``, nohup, a service) leaves it serving."""
    run = find_run(session, run_id, wait)
    gateway = Gateway(session, run)
    stop = threading.Event()
    server = threading.Thread(target=serve, args=(gateway.tree, port, stop, bind), daemon=True)
    server.start()
    gateway.show(agent)
    print(f"groot: run {run}, agent {agent}; Groot2 connects to {bind}:{port}. Type an agent id to switch.", flush=True)
    try:
        for line in commands if commands is not None else sys.stdin:
            text = line.strip()
            if not text:
                continue
            chosen = agent_command(text)
            if chosen is None:
                print(f"groot: {text[:40]!r} is not an agent id", flush=True)
                continue
            gateway.show(chosen)
            print(f"groot: agent {chosen}", flush=True)
        if commands is None and not sys.stdin.isatty():
            stop.wait()  # no terminal to read: serve until interrupted
    except KeyboardInterrupt:
        pass
    finally:
        gateway.close()
        stop.set()
        server.join(timeout=5)
        mean = gateway.bytes / gateway.samples if gateway.samples else 0.0
        print(
            f"groot: heard {gateway.samples} samples, {gateway.bytes} bytes ({mean:.0f} per sample), "
            f"{gateway.malformed} malformed",
            flush=True,
        )
    return 0
