"""Our Groot2 monitoring answers against BehaviorTree.CPP's own Groot2Publisher: the same trees
ticked with the same leaf results, asked the same requests over ZeroMQ after every tick, give the
same status buffers, the same recorded status changes and the same tree shape."""

import contextlib
import re
import signal
import socket
import struct
import threading
import time

import msgpack
import pytest

from swarmbed.bt import NodeRegistry, Status, load_tree
from swarmbed.bt.groot_tree import STATUS_CODE, BlackboardWatch, ChangeRecorder, tree_xml
from swarmbed.results.groot2 import MonitoredTree, serve, tree_identity
from tests.bt_harness import Act, Cond, Script, btcpp_tree
from tests.test_btlog import CASES, TICKS, shape

bt = pytest.importorskip("behaviortreepy", reason="the reference needs the BehaviorTree.CPP bindings")
zmq = pytest.importorskip("zmq", reason="Groot2's protocol runs over ZeroMQ")


def free_port() -> int:
    """A port whose next one is free too (Groot2 uses both)."""
    while True:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port + 1))
                return port
            except OSError:
                continue


class Groot:
    """Groot2's side: a request socket."""

    def __init__(self, port: int) -> None:
        self.context = zmq.Context()
        self.socket = self.context.socket(zmq.REQ)
        self.socket.setsockopt(zmq.RCVTIMEO, 5000)
        self.socket.setsockopt(zmq.LINGER, 0)
        self.socket.connect(f"tcp://127.0.0.1:{port}")
        self.next_id = 0

    def ask(self, kind: str, payload: bytes | None = None) -> tuple[bytes, list[bytes]]:
        self.next_id += 1
        head = struct.pack("<BBI", 2, ord(kind), self.next_id)
        self.socket.send_multipart([head] + ([payload] if payload is not None else []))
        reply = self.socket.recv_multipart()
        if reply[0] != b"error":
            assert reply[0][:6] == head and len(reply[0]) == 22
        return reply[0], reply[1:]

    def close(self) -> None:
        self.socket.close()
        self.context.term()


def changes_of(recorded: bytes) -> list[tuple[int, int]]:
    return [struct.unpack_from("<HB", recorded, i + 6) for i in range(0, len(recorded), 9)]


@contextlib.contextmanager
def both_publishers(their_tree, monitored: MonitoredTree):
    """BehaviorTree.CPP's publisher on ``their_tree`` and ours on ``monitored``, each on a port of its
    own, and a Groot2 client of each: ``(mine, theirs)``."""
    their_port = free_port()
    publisher = bt.Groot2Publisher(their_tree, their_port)
    our_port, stop = free_port(), threading.Event()  # after theirs is bound: another port
    server = threading.Thread(target=serve, args=(monitored, our_port, stop), daemon=True)
    server.start()
    mine, theirs = Groot(our_port), Groot(their_port)
    try:
        time.sleep(0.2)
        yield mine, theirs
    finally:
        mine.close()
        theirs.close()
        stop.set()
        server.join(timeout=5)
        del publisher


def ask_both(mine: Groot, theirs: Groot, kind: str, payload: bytes | None = None):
    return mine.ask(kind, payload)[1], theirs.ask(kind, payload)[1]


def our_side(xml: str, scripts, name: str):
    """Our engine's tree of ``xml``, the recorder of its status changes, and the gateway's monitored
    tree they feed (served over ZeroMQ beside BehaviorTree.CPP's own publisher)."""
    registry = NodeRegistry()
    registry.register(Act)
    registry.register(Cond)
    our_tree = load_tree("<test>", registry, text=xml, context=Script(scripts))
    monitored = MonitoredTree()
    monitored.reset(tree_xml(our_tree), tree_identity("test", name), len(our_tree.nodes))
    return our_tree, ChangeRecorder(our_tree), monitored


@pytest.mark.parametrize("name", ["subtrees", *(f"random {s}" for s in range(0, 40, 3))])
def test_groot2_hears_from_us_what_btcpps_publisher_answers(name):
    xml, scripts = CASES[name]
    their_tree = btcpp_tree(xml, scripts)  # BehaviorTree.CPP's, with its own publisher
    our_tree, recorder, monitored = our_side(xml, scripts, name)
    with both_publishers(their_tree, monitored) as (mine, theirs):
        ours_xml, their_xml = ask_both(mine, theirs, "T")
        assert shape(ours_xml[0].decode()) == shape(their_xml[0].decode())
        ours_s, their_s = ask_both(mine, theirs, "S")
        assert ours_s == their_s
        ask_both(mine, theirs, "r", b"start")
        for tick in range(TICKS):
            their_tree.tick_exactly_once()
            our_tree.tick_once()
            monitored.apply(tick * 250_000, recorder.take())
            ours_s, their_s = ask_both(mine, theirs, "S")
            assert ours_s == their_s, f"status buffers differ after tick {tick}"
            ours_t, their_t = ask_both(mine, theirs, "t")
            assert changes_of(ours_t[0]) == changes_of(their_t[0]), f"changes differ at tick {tick}"
        assert ask_both(mine, theirs, "D") == ([b"[]"], [b"[]"])
        head, body = mine.ask("Z")
        assert (head, body) == (b"error", [b"Request not recognized"])
        assert mine.socket.send(b"abc") is None and mine.socket.recv_multipart() == [b"error", b"wrong request header"]


def test_a_recording_nobody_reads_keeps_what_btcpps_publisher_keeps():
    """A client that starts a recording and never asks for it (``t``): the gateway keeps the newest
    changes only, bounded as BehaviorTree.CPP's publisher bounds them, and answers the same."""
    from swarmbed.results.groot2 import CHANGE_BYTES, MAX_RECORDED_CHANGES

    xml, scripts = CASES[next(iter(CASES))]
    their_tree = btcpp_tree(xml, scripts)
    our_tree, recorder, monitored = our_side(xml, scripts, "unread")
    with both_publishers(their_tree, monitored) as (mine, theirs):
        ask_both(mine, theirs, "r", b"start")
        for tick in range(3000):
            their_tree.tick_exactly_once()
            our_tree.tick_once()
            monitored.apply(tick * 250_000, recorder.take())
        assert len(monitored.recorded) <= MAX_RECORDED_CHANGES * CHANGE_BYTES
        ours_t, their_t = ask_both(mine, theirs, "t")
        assert len(changes_of(ours_t[0])) == len(changes_of(their_t[0])) == MAX_RECORDED_CHANGES
        assert changes_of(ours_t[0]) == changes_of(their_t[0])


BLACKBOARDS = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main"><Sequence>
    <SetBlackboard value="3" output_key="literal"/>
    <SubTree ID="Copy" x="{count}"/>
    <SubTree ID="Copy" name="shared" _autoremap="true"/>
    <SubTree ID="Outer" _autoremap="true"/>
  </Sequence></BehaviorTree>
  <BehaviorTree ID="Copy"><Sequence>
    <SetBlackboard value="{x}" output_key="y"/>
    <SetBlackboard value="kept here" output_key="_private"/>
  </Sequence></BehaviorTree>
  <BehaviorTree ID="Outer"><SubTree ID="Copy" x="{word}"/></BehaviorTree>
</root>"""
ROOT_VALUES = {
    "count": 3,
    "big": 70000,
    "negative": -40,
    "tenth": 0.1,
    "half": 2.5,
    "huge": 1e300,
    "infinite": float("inf"),
    "flag": True,
    "word": "hello",
    "x": "from the root",
    "long": "z" * 300,
}
ASKED = [b"Main", b"Copy::3", b"shared", b"Outer::11/Copy::12", b"Main;shared;Copy::3;Main"]
ASKED += [b"nope", b"", b";Main;nope"]


def test_groot2_sees_the_blackboards_btcpps_publisher_shows():
    """Typed values on the root blackboard, SetBlackboard writes in SubTrees (remapped, autoremapped,
    private, nested): the same msgpack bytes for every blackboard Groot2 may ask for."""
    their_tree = btcpp_tree(BLACKBOARDS, {})
    root = their_tree.root_blackboard()
    setters = {bool: root.set_bool, int: root.set_int, float: root.set_double, str: root.set_string}
    for key, value in ROOT_VALUES.items():
        setters[type(value)](key, value)
    our_tree = load_tree("<test>", NodeRegistry(), text=BLACKBOARDS)
    for key, value in ROOT_VALUES.items():
        our_tree.blackboard.set(key, value)
    assert their_tree.tick_exactly_once() == bt.NodeStatus.SUCCESS
    assert our_tree.tick_once() == Status.SUCCESS
    monitored = MonitoredTree()
    boards = BlackboardWatch(our_tree)
    monitored.reset(tree_xml(our_tree), tree_identity("test"), len(our_tree.nodes), [], boards.take(everything=True))
    with both_publishers(their_tree, monitored) as (mine, theirs):
        assert shape(mine.ask("T")[1][0].decode()) == shape(theirs.ask("T")[1][0].decode())
        for names in ASKED:
            ours, their = ask_both(mine, theirs, "B", names)
            assert ours == their, f"blackboards {names!r}: {ours} != {their}"
            assert (ours == [b"\xc0"]) == (names in (b"nope", b"")), names  # the names are the real ones
        mine.socket.send(struct.pack("<BBI", 2, ord("B"), 99))
        theirs.socket.send(struct.pack("<BBI", 2, ord("B"), 99))
        assert mine.socket.recv_multipart() == theirs.socket.recv_multipart()
        # a change reaches Groot2 with the next tick's changes; only what changed travels
        our_tree.blackboard.set("word", "again")
        assert boards.take() == {"Main": {**boards.last["Main"], "word": "again"}}
        assert boards.take() == {}


def test_a_tree_from_another_agent_has_another_identity_and_idle_nodes():
    xml = (
        '<root><BehaviorTree ID="M" _fullpath="">'
        '<Sequence _uid="1"><A _uid="2"/><A _uid="3"/></Sequence></BehaviorTree></root>'
    )
    monitored = MonitoredTree()
    monitored.reset(xml, tree_identity("run", 0), 3)
    monitored.apply(0, [(1, STATUS_CODE[Status.RUNNING]), (2, STATUS_CODE[Status.SUCCESS])])
    before = monitored.answer([struct.pack("<BBI", 2, ord("S"), 1)])
    monitored.reset(xml, tree_identity("run", 1), 3)
    after = monitored.answer([struct.pack("<BBI", 2, ord("S"), 1)])
    assert before[0][6:] != after[0][6:] and before[1] != after[1] == bytes.fromhex("010000020000030000")


# -- the gateway, against a real run ---------------------------------------------------------------
@pytest.mark.slow
def test_groot2_follows_any_agent_of_a_running_run_and_watching_changes_no_result(tmp_path, operator):
    import subprocess
    import sys

    from swarmbed.launch.hub import HubOptions
    from swarmbed.launch.runner import run_experiment
    from swarmbed.wire.zenoh_session import free_loopback_endpoint
    from tests.conftest import experiment, reference_run, same_results

    sets = ["agents.count=6", "allocator.name=cbba", "run.stop_when_done=false", "run.duration=6000", "run.seed=5"]
    endpoint, port = free_loopback_endpoint(), free_port()
    hub = HubOptions(listen=[endpoint], admit=[operator.identity])
    following = threading.Event()  # the first tick waits for the gateway: the run lasts some 13 wall s

    def hold(_keys, _endpoint) -> None:
        following.wait(timeout=60)

    runner = threading.Thread(
        target=run_experiment,
        args=(experiment(*sets), tmp_path / "watched"),
        kwargs={"progress": False, "hub": hub, "on_ready": hold},
    )
    runner.start()
    gateway = subprocess.Popen(
        [sys.executable, "-m", "swarmbed", "groot", "--connect", endpoint, *operator.args, "--port", str(port)]
        + ["--wait", "60"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    groot = Groot(port)
    seen: dict[int, tuple[bytes, str, set[bytes]]] = {}
    try:
        assert "groot: run" in gateway.stdout.readline()
        following.set()
        for agent in (0, 4):
            if agent:
                gateway.stdin.write(f"{agent}\n")
                gateway.stdin.flush()
            deadline, buffers = time.monotonic() + 60, set()
            while time.monotonic() < deadline and len(buffers) < 2:
                head, body = groot.ask("T")
                status_head, status = groot.ask("S")
                identity = head[6:]
                switched = agent == 0 or identity != seen[0][0]  # the gateway may not have switched yet
                if body[0] and status_head[6:] == identity and switched:
                    buffers.add(status[0])
                    seen[agent] = (identity, body[0].decode(), buffers)
                time.sleep(0.05)
        assert groot.ask("I", b'{"uid": 2}')[0] == b"error"  # no breakpoints: agents never pause
        main_id = re.search(r'<BehaviorTree ID="([^"]+)"', seen[4][1]).group(1)
        board = msgpack.unpackb(groot.ask("B", main_id.encode())[1][0])[main_id]  # agent 4's blackboard
        assert board["arrival_radius"] == 5.0 and "assigned_task" in board
    finally:
        groot.close()
        following.set()
        gateway.stdin.close()  # no terminal: a closed stdin leaves the gateway serving, until interrupted
        time.sleep(1.0)
        still_serving = gateway.poll() is None
        gateway.send_signal(signal.SIGINT)
        gateway.wait(timeout=20)
        runner.join(timeout=300)
    assert still_serving, "the gateway stopped when its standard input closed"
    assert set(seen) == {0, 4} and seen[0][0] != seen[4][0]  # another agent: another tree identity
    for _identity, xml, buffers in seen.values():
        assert len(buffers) == 2 and shape(xml)[0][0] == "BehaviorTree"  # its tree, ticking
        uids = [u for u, *_ in (struct.unpack_from("<HB", b, 0) for b in buffers)]
        assert uids and all(u == 1 for u in uids)
    reference_run(experiment(*sets), tmp_path / "alone")
    same_results(tmp_path / "watched", tmp_path / "alone")
