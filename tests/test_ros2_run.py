"""A run seen from a ROS 2 machine: a raw Zenoh client with an operator's credentials subscribes to
rmw_zenoh's keys and graph tokens, as rmw_zenoh would, and decodes every sample with rosbags. What
it reads is checked against the run's own record (trajectories, markers, ledger)."""

import csv
import json
import math
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import pytest
import zenoh

from swarmbed.launch.hub import HubOptions
from swarmbed.launch.runner import run_experiment
from swarmbed.wire.credentials import Identity, write_credentials
from swarmbed.wire.ros2_conventions import Ros2Types, decode_attachment, gid
from swarmbed.wire.zenoh_session import free_loopback_endpoint, zenoh_config
from tests.conftest import QUICKSTART, experiment, read_ledger, reference_run, same_results

DOMAIN = 7
PATH = 5  # ros2.path: each robot's last 5 poses on /robot_<i>/path
WALL = ((100.0, 20.0), (100.0, 130.0))  # one wall across the quickstart's 200 x 150 floor
SETTINGS = (
    "agents.count=4",
    "run.duration=80",
    "run.stop_when_done=false",
    "run.record_trajectories=true",
    f"obstacles={{walls: [{{start: {list(WALL[0])}, end: {list(WALL[1])}}}]}}",
)


class RosReader:
    """What a ROS 2 machine on the domain receives: data samples by topic, graph tokens."""

    def __init__(self, endpoint: str, credentials: str) -> None:
        self.samples: dict[str, list[tuple[str, bytes, bytes | None]]] = defaultdict(list)
        self.tokens: set[str] = set()
        self.lock = threading.Lock()
        self.session = zenoh.open(zenoh_config("client", [endpoint], credentials=credentials))
        self.hub = str(next(iter(self.session.info.routers_zid())))
        self.sub = self.session.declare_subscriber(f"{DOMAIN}/**", self._on_sample)
        self.graph = self.session.liveliness().declare_subscriber(f"@ros2_lv/{DOMAIN}/**", self._on_token, history=True)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        topic = "/" + "/".join(key.split("/")[1:-2])
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
        with self.lock:
            self.samples[topic].append((key, sample.payload.to_bytes(), attachment))

    def _on_token(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            with self.lock:
                self.tokens.add(str(sample.key_expr))


@pytest.fixture(scope="module")
def seen(tmp_path_factory):
    """One run with ROS 2 on, read from outside; one with it off, same seed."""
    from tests.conftest import Operator

    base = tmp_path_factory.mktemp("ros2")
    operator = Operator(base)
    endpoint = free_loopback_endpoint()
    readers: list[RosReader] = []

    def on_ready(_keys, _endpoint) -> None:
        readers.append(RosReader(endpoint, str(operator.path)))
        time.sleep(0.5)  # the reader's subscriptions reach the hub before the first tick
        # another operator session tries to pass a pose off as robot 0's: the hub must refuse it
        forger = zenoh.open(zenoh_config("client", [endpoint], credentials=str(operator.path)))
        forger.put(f"{DOMAIN}/robot_0/pose/geometry_msgs::msg::dds_::PoseStamped_/forged", b"forged")
        forger.liveliness().declare_token(f"@ros2_lv/{DOMAIN}/forged/0/0/NN/%/%/impostor")
        hub = str(next(iter(forger.info.routers_zid())))
        for name in ("swarmbed", "swarmbed_radio"):  # the run's own nodes' tokens are the run's alone
            forger.liveliness().declare_token(f"@ros2_lv/{DOMAIN}/{hub}/0/0/NN/%/%/{name}")
        time.sleep(0.2)
        forger.close()

    exp = experiment(*SETTINGS, f"ros2={{domain: {DOMAIN}, path: {PATH}}}")
    on = run_experiment(
        exp,
        base / "on",
        progress=False,
        hub=HubOptions(listen=[endpoint], admit=[operator.identity]),
        on_ready=on_ready,
    )
    time.sleep(0.5)
    reader = readers[0]
    reader.session.close()
    off = reference_run(experiment(*SETTINGS), base / "off")
    return on, off, reader


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_every_topic_is_on_rmw_zenohs_key_with_its_type_hash_and_attachment(seen):
    on, _off, reader = seen
    types = Ros2Types()
    ticks = on.summary["ticks"]
    expected = {
        "/clock": "rosgraph_msgs/msg/Clock",
        "/tasks": "visualization_msgs/msg/MarkerArray",
        **{f"/robot_{i}/pose": "geometry_msgs/msg/PoseStamped" for i in range(4)},
        **{f"/robot_{i}/radio/received": "swarmbed_msgs/msg/RadioInbox" for i in range(4)},
        **{f"/robot_{i}/radio/sent": "swarmbed_msgs/msg/RadioOutbox" for i in range(4)},  # the proxy's node
        "/tf": "tf2_msgs/msg/TFMessage",
        "/robots": "geometry_msgs/msg/PoseArray",
        "/radio": "visualization_msgs/msg/MarkerArray",
        **{f"/robot_{i}/odom": "nav_msgs/msg/Odometry" for i in range(4)},
        **{f"/robot_{i}/path": "nav_msgs/msg/Path" for i in range(4)},
        "/walls": "visualization_msgs/msg/MarkerArray",
    }
    assert set(reader.samples) == set(expected)
    tokens = {t.split("/")[9].replace("%", "/"): t for t in reader.tokens if "/MP/" in t}
    for topic, ros_type in expected.items():
        samples = reader.samples[topic]
        package, _, name = ros_type.split("/")
        key = f"{DOMAIN}{topic}/{package}::msg::dds_::{name}_/{types.hash(ros_type)}"
        assert {k for k, _, _ in samples} == {key}, topic
        # /tasks: when it changed; /walls: once (latched)
        published = {"/tasks": len(samples), "/walls": 1}.get(topic, ticks)
        assert len(samples) == published, topic  # one a tick, none lost on loopback, none forged
        # the publisher's token names the same topic, type and hash; the attachment's GID is its hash
        token = tokens[topic]
        assert token.split("/")[10:12] == key.split("/")[-2:]
        attachments = [decode_attachment(a) for _, _, a in samples]
        assert [seq for seq, _, _ in attachments] == list(range(1, published + 1)), topic
        assert {g for _, _, g in attachments} == {gid(token)}
        for _, payload, _ in samples:
            types.deserialize(payload, ros_type)
    hub, proxy = tokens["/clock"].split("/")[2], tokens["/robot_0/radio/sent"].split("/")[2]
    assert hub != proxy  # two nodes, each on its own process's session
    assert {
        f"@ros2_lv/{DOMAIN}/{hub}/0/0/NN/%/%/swarmbed",
        f"@ros2_lv/{DOMAIN}/{proxy}/0/0/NN/%/%/swarmbed_radio",
    } <= reader.tokens
    # an operator's ROS 2 tools join the graph (their own node's token), but the pose it forged for
    # robot 0 never reached a reader: the hub refused the put
    assert any("/impostor" in t for t in reader.tokens)
    assert not any(t.split("/")[2] != reader.hub and t.endswith("/swarmbed") for t in reader.tokens)
    assert sum(t.endswith(("/NN/%/%/swarmbed", "/NN/%/%/swarmbed_radio")) for t in reader.tokens) == 2
    assert not any(p == b"forged" for samples in reader.samples.values() for _, p, _ in samples)


def test_clock_poses_and_markers_are_the_runs_own_record(seen):
    on, _off, reader = seen
    types = Ros2Types()
    dt = 1.0  # the quick start's
    clock = [types.deserialize(p, "rosgraph_msgs/msg/Clock").clock for _, p, _ in reader.samples["/clock"]]
    assert [c.sec + c.nanosec / 1e9 for c in clock] == pytest.approx([k * dt for k in range(len(clock))])
    trajectory = {
        (int(r["tick"]), int(r["agent"])): (float(r["x"]), float(r["y"]))
        for r in _rows(on.out_dir / "trajectories.csv")
    }
    for i in range(4):
        for k, (_, payload, _) in enumerate(reader.samples[f"/robot_{i}/pose"]):
            msg = types.deserialize(payload, "geometry_msgs/msg/PoseStamped")
            assert (msg.header.stamp.sec, msg.header.frame_id) == (int(k * dt), "map")
            assert (msg.pose.position.x, msg.pose.position.y) == pytest.approx(trajectory[(k, i)])
    events = defaultdict(list)  # markers.csv: each task as it appears and vanishes
    for r in _rows(on.out_dir / "markers.csv"):
        events[int(r["tick"])].append((int(r["marker"]), r["event"]))
    standing: set[int] = set()
    shown = {}  # tick -> the task ids of the markers published at it
    for _, payload, _ in reader.samples["/tasks"]:
        markers = types.deserialize(payload, "visualization_msgs/msg/MarkerArray").markers
        assert markers[0].action == 3  # DELETEALL first: tasks done disappear
        shown[round(markers[0].header.stamp.sec / dt)] = ({m.id for m in markers if m.ns == "tasks"}, markers)
    assert 0 in shown and len(shown) < on.summary["ticks"]  # published when the map or a pursuit changed
    for k in range(on.summary["ticks"]):
        for marker, event in events[k]:
            (standing.add if event == "appear" else standing.discard)(marker)
        if k in shown:
            assert shown[k][0] == standing, k
        else:
            assert not events[k], k  # nothing appeared or vanished without a new array
    assert any("<-" in m.text for _, markers in shown.values() for m in markers)  # and it says who pursues what


def test_inboxes_carry_every_delivered_copy(seen):
    on, _off, reader = seen
    types = Ros2Types()
    received = received_bytes = 0
    for i in range(4):
        for _, payload, _ in reader.samples[f"/robot_{i}/radio/received"]:
            msg = types.deserialize(payload, "swarmbed_msgs/msg/RadioInbox")
            assert msg.robot == i and len(msg.senders) == len(msg.kinds) == len(msg.sizes)
            assert i not in set(msg.senders.tolist())
            received += len(msg.senders)
            received_bytes += int(msg.sizes.sum())
    # copies sent at the last tick end as run_ended: every delivered copy was handed to a robot
    net = on.summary["network"]
    delivered = sum(r["messages"] for r in read_ledger(on.out_dir) if r["outcome"] == "delivered")
    assert received == delivered == net["delivered"] > 0
    assert received_bytes == net["delivered_bytes"]
    sent = sent_bytes = 0
    for i in range(4):
        for _, payload, _ in reader.samples[f"/robot_{i}/radio/sent"]:
            msg = types.deserialize(payload, "swarmbed_msgs/msg/RadioOutbox")
            assert msg.robot == i and len(msg.kinds) == len(msg.sizes) == len(msg.addressed)
            assert set(msg.addressed.tolist()) <= {-1}  # the quick start's FCG broadcasts its claims
            sent += len(msg.kinds)
            sent_bytes += int(msg.sizes.sum())
    assert (sent, sent_bytes) == (net["messages_sent"], net["bytes_sent"]) != (0, 0)


def _yaw(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def test_tf_odometry_pose_array_and_radio_lines_are_what_rviz_reads(seen):
    """Issue 62: /tf (map -> robot_<i>/base_link), /robot_<i>/odom, /robots and /radio, decoded with
    rosbags' Jazzy types, against the run's own record: positions are the trajectories', every pose
    faces the robot's heading (the direction it moved from the tick before, wherever it moved), the
    same in TF, odometry, PoseStamped and the pose array, odometry's speed is the distance it then
    covers per tick, and /radio's lines are the copies delivered, sender to receiver."""
    on, _off, reader = seen
    types = Ros2Types()
    trajectory = {
        (int(r["tick"]), int(r["agent"])): (float(r["x"]), float(r["y"]))
        for r in _rows(on.out_dir / "trajectories.csv")
    }
    tf = [types.deserialize(p, "tf2_msgs/msg/TFMessage").transforms for _, p, _ in reader.samples["/tf"]]
    robots = [types.deserialize(p, "geometry_msgs/msg/PoseArray").poses for _, p, _ in reader.samples["/robots"]]
    turned = 0
    for i in range(4):
        odom = [types.deserialize(p, "nav_msgs/msg/Odometry") for _, p, _ in reader.samples[f"/robot_{i}/odom"]]
        pose = [
            types.deserialize(p, "geometry_msgs/msg/PoseStamped").pose for _, p, _ in reader.samples[f"/robot_{i}/pose"]
        ]
        for k, o in enumerate(odom):
            (t,) = [t for t in tf[k] if t.child_frame_id == f"robot_{i}/base_link"]
            assert (t.header.frame_id, o.header.frame_id, o.child_frame_id) == ("map", "map", f"robot_{i}/base_link")
            x, y = trajectory[(k, i)]
            assert (t.transform.translation.x, t.transform.translation.y) == pytest.approx((x, y))
            yaw = _yaw(t.transform.rotation)
            assert yaw == pytest.approx(_yaw(o.pose.pose.orientation)) == pytest.approx(_yaw(pose[k].orientation))
            assert yaw == pytest.approx(_yaw(robots[k][i].orientation))
            if (k - 1, i) in trajectory:
                px, py = trajectory[(k - 1, i)]
                moved = math.hypot(x - px, y - py)
                assert o.twist.twist.linear.x * 1.0 == pytest.approx(moved, abs=1e-6)  # the quick start's dt
                if moved > 1e-6:
                    assert math.cos(yaw - math.atan2(y - py, x - px)) == pytest.approx(1.0, abs=1e-6)
                    turned += abs(yaw) > 1e-3
        assert len(odom) == on.summary["ticks"]
        paths = [types.deserialize(p, "nav_msgs/msg/Path").poses for _, p, _ in reader.samples[f"/robot_{i}/path"]]
        for k, trail in enumerate(paths):  # the last PATH poses, oldest first, ending with this tick's
            assert len(trail) == min(k + 1, PATH)
            xy = [c for p in trail for c in (p.pose.position.x, p.pose.position.y)]
            assert xy == pytest.approx([c for j in range(k + 1 - len(trail), k + 1) for c in trajectory[(j, i)]])
    assert turned > 0  # headings are not all +x
    lines = 0
    for _, payload, _ in reader.samples["/radio"]:
        markers = types.deserialize(payload, "visualization_msgs/msg/MarkerArray").markers
        for m in markers:
            assert (m.type, m.ns, m.header.frame_id) == (5, "radio", "map")  # LINE_LIST
            lines += len(m.points) // 2
    assert lines == on.summary["network"]["delivered"] > 0


def test_the_walls_are_one_line_list_that_never_expires(seen):
    _on, _off, reader = seen
    types = Ros2Types()
    for _, payload, _ in reader.samples["/walls"]:
        (marker,) = types.deserialize(payload, "visualization_msgs/msg/MarkerArray").markers
        assert marker.type == marker.LINE_LIST and marker.lifetime.sec == 0 and marker.lifetime.nanosec == 0
        assert [(p.x, p.y) for p in marker.points] == list(WALL)


def test_results_are_byte_identical_with_publishing_on_and_off(seen):
    on, off, _reader = seen
    same_results(on.out_dir, off.out_dir)
    for name in ("trajectories.csv", "markers.csv"):
        assert (on.out_dir / name).read_bytes() == (off.out_dir / name).read_bytes(), name


NODE = Path(__file__).resolve().parent.parent / "docs" / "ros2" / "nearest_node.py"
DRIVEN = ("agents.count=5", "run.duration=400", "run.seed=4")


@pytest.fixture(scope="module")
def driven(tmp_path_factory):
    """The quick start decided by the example ROS 2 node through the ros2 allocator, while an
    operator tries to halt robot 0 at every tick; and the same run with the built-in nearest."""
    base = tmp_path_factory.mktemp("ros2_driven")
    commander = Identity.new("commander", "commander")
    write_credentials(base / "commander.json", commander)
    operator = Identity.new("meddler", "operator")
    endpoint = free_loopback_endpoint()
    held: dict = {}

    def on_ready(_keys, _endpoint) -> None:
        node = subprocess.Popen(
            [
                sys.executable,
                str(NODE),
                "--connect",
                endpoint,
                "--credentials",
                str(base / "commander.json"),
                "--domain",
                str(DOMAIN),
            ],
            stdout=subprocess.PIPE,
            text=True,
        )
        held["node"] = node
        assert node.stdout.readline().strip() == "ready"
        meddler = zenoh.open(
            zenoh_config(
                "client",
                [endpoint],
                settings={"transport/auth/usrpwd": {"user": operator.user, "password": operator.password}},
            )
        )
        held["meddler"] = meddler
        types = Ros2Types()
        halt_key = (
            f"{DOMAIN}/robot_0/cmd/swarmbed_msgs::msg::dds_::TaskCommand_/{types.hash('swarmbed_msgs/msg/TaskCommand')}"
        )
        Command, Header = types.cls("swarmbed_msgs/msg/TaskCommand"), types.cls("std_msgs/msg/Header")

        def halt_robot_0(sample) -> None:  # an operator may read the observations, not decide
            obs = types.deserialize(sample.payload.to_bytes(), "swarmbed_msgs/msg/TaskObservation")
            forged = Command(header=Header(stamp=obs.header.stamp, frame_id="map"), robot=0, task=-3)
            meddler.put(halt_key, types.serialize(forged, "swarmbed_msgs/msg/TaskCommand"))

        # an operator drops a token named as the hub's node: the node must not take it for the run's end
        hub = str(next(iter(meddler.info.routers_zid())))
        meddler.liveliness().declare_token(f"@ros2_lv/{DOMAIN}/{hub}/0/0/NN/%/%/swarmbed").undeclare()
        held["sub"] = meddler.declare_subscriber(
            f"{DOMAIN}/robot_0/observation/swarmbed_msgs::msg::dds_::TaskObservation_/**", halt_robot_0
        )
        # a commander's malformed commands: dropped and counted, never fatal, never a decision
        sloppy = zenoh.open(zenoh_config("client", [endpoint], credentials=str(base / "commander.json")))
        wrong_robot = Command(
            header=Header(stamp=types.cls("builtin_interfaces/msg/Time")(sec=0, nanosec=0), frame_id="map"),
            robot=2,
            task=-3,
        )
        future = Command(  # stamped at the end of time: every later command would look older
            header=Header(stamp=types.cls("builtin_interfaces/msg/Time")(sec=2**31 - 1, nanosec=0), frame_id="map"),
            robot=1,
            task=-3,
        )
        for key, payload in (
            (halt_key.replace("robot_0", "robot_1"), b"\x00\x01\x00\x00garbage"),  # not CDR of a TaskCommand
            (halt_key.replace("robot_0", "robot_1"), types.serialize(wrong_robot, "swarmbed_msgs/msg/TaskCommand")),
            (halt_key.replace("robot_0", "robot_1"), b"\x00" * 4096),  # oversized
            (halt_key.replace("robot_0", "robot_99"), types.serialize(wrong_robot, "swarmbed_msgs/msg/TaskCommand")),
            (halt_key.replace("robot_0", "robot_1"), types.serialize(future, "swarmbed_msgs/msg/TaskCommand")),
        ):
            sloppy.put(key, payload)
        time.sleep(0.5)  # the node's and the meddler's subscriptions reach the hub before tick 0
        sloppy.close()

    exp = experiment(*DRIVEN, "allocator.name=ros2", f"ros2={{domain: {DOMAIN}, command_timeout: 2}}")
    try:
        ros = run_experiment(
            exp,
            base / "ros2",
            progress=False,
            hub=HubOptions(listen=[endpoint], admit=[commander, operator]),
            on_ready=on_ready,
        )
        assert held["node"].wait(timeout=30) == 0  # it leaves when the run's node leaves the graph
    finally:
        if "node" in held and held["node"].poll() is None:
            held["node"].kill()
            held["node"].wait()
        if "meddler" in held:
            held["meddler"].close()
    builtin = run_experiment(experiment(*DRIVEN, "allocator.name=nearest"), base / "nearest", progress=False)
    return ros, builtin


def test_a_ros2_node_in_the_loop_gives_the_builtin_allocators_results(driven):
    ros, builtin = driven
    assert ros.timings["ros2_command_timeouts"] == 0  # every robot had its decision at every tick
    assert ros.summary["tasks_completed"] > 0
    # the forged halts changed nothing: every result file is the built-in run's, but for the name
    for name in ("timeseries.csv", "agents.csv", "network_ledger.csv"):
        assert (ros.out_dir / name).read_bytes() == (builtin.out_dir / name).read_bytes(), name
    ours, theirs = (json.loads((run.out_dir / "summary.json").read_text()) for run in (ros, builtin))
    assert (ours.pop("allocator"), theirs.pop("allocator")) == ("ros2", "nearest")
    # the commander's five malformed commands (one from the future), counted where the run counts drops
    assert (ours["network"]["malformed"]["coordinator"], theirs["network"]["malformed"]["coordinator"]) == (5, 0)
    ours["network"]["malformed"]["coordinator"] = 0
    assert ours == theirs


def test_on_the_real_time_clock_no_tick_waits_for_a_command(tmp_path):
    """Nobody commands: in lock-step each tick would wait command_timeout (5 s) for every robot; on
    the real-time clock the last command (none: the tree explores) holds and the clock goes on."""
    exp = experiment(
        "agents.count=3",
        "run.duration=60",
        "run.stop_when_done=false",
        "run.clock=realtime",
        "run.speed=20",
        "allocator.name=ros2",
        f"ros2={{domain: {DOMAIN + 1}, command_timeout: 5}}",
    )
    result = run_experiment(exp, tmp_path / "rt", progress=False)
    assert result.summary["ticks"] == 60
    assert result.timings["run_s"] < 15  # 60 ticks at 20x: 3 s; waiting would take 300 s
    assert result.timings["ros2_command_timeouts"] == 0  # nothing is waited for, so nothing times out


def test_a_tick_that_waits_for_a_node_says_so_and_check_counts_the_wait(tmp_path):
    """Nobody answers: each lock-step tick waits command_timeout, and the run says which robots it
    waited for (once per 10 s, not per tick); --check puts the wait into its estimate."""
    root = Path(__file__).resolve().parent.parent
    sets = [
        "--set",
        "agents.count=2",
        "--set",
        "run.duration=12",
        "--set",
        "run.stop_when_done=false",
        "--set",
        "allocator.name=ros2",
        "--set",
        f"ros2={{domain: {DOMAIN + 2}, command_timeout: 0.5}}",
    ]
    swarmbed = [sys.executable, "-m", "swarmbed", "run", "experiments/quickstart.yaml", *sets]
    check = subprocess.run([*swarmbed, "--check"], capture_output=True, text=True, cwd=root, timeout=120)
    assert check.returncode == 0 and "ros2.command_timeout" in check.stdout and "never answers" in check.stdout
    started = time.monotonic()
    done = subprocess.run(
        [*swarmbed, "--out", str(tmp_path / "run"), "--no-progress"], capture_output=True, text=True, cwd=root
    )
    assert done.returncode == 0, done.stderr
    waits = [line for line in done.stderr.splitlines() if "ros2.command_timeout" in line]
    assert len(waits) == 1 and "robot(s) 0, 1" in waits[0] and "no command has come yet" in waits[0], done.stderr
    assert time.monotonic() - started >= 12 * 0.5
    bad = subprocess.run(
        [*swarmbed[:-2], "--set", f"ros2={{domain: {DOMAIN + 2}, command_timeout: 1e300}}", "--check"],
        capture_output=True,
        text=True,
        cwd=root,
        timeout=120,
    )
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "command_timeout" in bad.stderr


def test_a_display_that_starts_late_gets_the_last_tasks_markers(tmp_path, operator):
    """/tasks is transient local, as rmw_zenoh makes such a topic (an advanced publisher with a cache
    of one): an operator's subscription that joins after the run published it, as rmw_zenoh's
    advanced subscriber does (history, late-publisher detection), is handed the markers at once;
    a plain (volatile) subscription joined at the same moment gets nothing, for nothing changed.
    The tasks never change here: the robots run no allocator, so no one works a task."""
    from zenoh import ext

    endpoint = free_loopback_endpoint()
    exp = experiment(
        "agents.count=3",
        "allocator.name=noop",
        "run.clock=realtime",
        "run.duration=12",
        "run.stop_when_done=false",
        f"ros2={{domain: {DOMAIN}}}",
    )
    result: list = []
    runner = threading.Thread(
        target=lambda: result.append(
            run_experiment(
                exp, tmp_path / "run", progress=False, hub=HubOptions(listen=[endpoint], admit=[operator.identity])
            )
        )
    )
    runner.start()
    types = Ros2Types()
    key = (
        f"{DOMAIN}/tasks/visualization_msgs::msg::dds_::MarkerArray_/{types.hash('visualization_msgs/msg/MarkerArray')}"
    )
    time.sleep(5)  # well after tick 0, when /tasks was published (and never again)
    session = zenoh.open(zenoh_config("client", [endpoint], credentials=str(operator.path)))
    late, plain = [], []
    history = ext.HistoryConfig(detect_late_publishers=True, max_samples=1)
    advanced = ext.declare_advanced_subscriber(
        session, key, lambda s: late.append(s.payload.to_bytes()), history=history
    )
    volatile = session.declare_subscriber(key, lambda s: plain.append(s.payload.to_bytes()))
    deadline = time.monotonic() + 5
    while not late and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)
    advanced.undeclare()
    volatile.undeclare()
    session.close()
    runner.join(timeout=60)
    assert result and result[0].summary["ticks"] == 12
    assert len(late) == 1 and plain == []
    markers = types.deserialize(late[0], "visualization_msgs/msg/MarkerArray").markers
    cubes = [m for m in markers if m.ns == "tasks"]
    assert len(cubes) == result[0].summary["tasks_total"]


def test_the_guides_echo_recipe_prints_a_robots_poses_from_a_run_without_ros(tmp_path, operator):
    """Issue 74 item 18: docs/ros2.md's "echo a topic without ROS" script, as written, prints robot
    3's poses from a running run reached through its hub with an operator's credentials."""
    import re
    import socket
    import subprocess
    import sys

    from tests.conftest import ROOT

    text = (ROOT / "docs" / "ros2.md").read_text()
    script = dict(re.findall(r"```python file=(\S+)\n(.*?)```", text, flags=re.S))["echo_pose.py"]
    (tmp_path / "echo_pose.py").write_text(script)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    endpoint = f"tcp/127.0.0.1:{port}"
    run = subprocess.Popen(
        [sys.executable, "-m", "swarmbed", "run", str(QUICKSTART), "--out", str(tmp_path / "run"), "--no-progress",
         "--listen", endpoint, "--admit", str(operator.path), "--set", "ros2.domain=0", "--set", "run.clock=realtime",
         "--set", "run.speed=20", "--set", "run.stop_when_done=false", "--set", "run.duration=600"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    echo = None
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert run.poll() is None, run.stderr.read()
                time.sleep(0.1)
        echo = subprocess.Popen(
            [sys.executable, str(tmp_path / "echo_pose.py"), endpoint, str(operator.path)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        lines = [echo.stdout.readline() for _ in range(3)]
    finally:
        for proc in (echo, run):
            if proc is not None:
                proc.terminate()
                proc.wait(timeout=30)
    poses = [re.fullmatch(r"t=([\d.]+) x=([-\d.]+) y=([-\d.]+)\n", line) for line in lines]
    assert all(poses), lines
    stamps = [float(m.group(1)) for m in poses]
    assert stamps == sorted(stamps) and len(set(stamps)) == 3, lines
    assert all(0 <= float(m.group(2)) <= 200 and 0 <= float(m.group(3)) <= 150 for m in poses), lines
