"""rmw_zenoh's conventions, checked against independent references: the examples of rmw_zenoh's
design document, rosbags' type hashes, the CDR layout and Zenoh's own serialiser. No ROS needed."""

import struct

import pytest

from swarmbed.wire.errors import WireError
from swarmbed.wire.ros2_conventions import (
    BEST_EFFORT,
    PUBLISHER,
    RADIO_INBOX,
    SENSOR_QOS,
    SUBSCRIPTION,
    Qos,
    Ros2Types,
    decode_attachment,
    encode_attachment,
    endpoint_token,
    gid,
    node_token,
    stamp,
    topic_key,
)

# rmw_zenoh docs/design.md: the chatter topic, its node and publisher tokens, as a talker writes them
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ZID = "8b20917502ee955ac4476e0266340d5c"


@pytest.fixture(scope="module")
def types():
    return Ros2Types()


def test_keys_and_tokens_are_those_of_rmw_zenohs_design_document(types):
    assert types.hash("std_msgs/msg/String") == STRING_HASH  # rosbags' REP-2016 hash = the document's
    assert topic_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH) == (
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    )
    assert topic_key(0, "/robot1/chatter", "std_msgs/msg/String", STRING_HASH).startswith("0/robot1/chatter/std_msgs")
    assert node_token(0, ZID, 0, "talker") == f"@ros2_lv/0/{ZID}/0/0/NN/%/%/talker"
    assert endpoint_token(
        PUBLISHER, 0, ZID, 0, 10, "talker", "/chatter", "std_msgs/msg/String", STRING_HASH, Qos(depth=7)
    ) == (f"@ros2_lv/0/{ZID}/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,")
    assert endpoint_token(
        SUBSCRIPTION, 0, ZID, 0, 10, "listener", "/chatter", "std_msgs/msg/String", STRING_HASH, Qos()
    ).endswith("/::,10:,:,:,,")
    # the QoS is a delta against rmw_zenoh's default profile (reliable, volatile, keep-last 42)
    assert Qos(depth=42).keyexpr() == "::,:,:,:,,"
    assert SENSOR_QOS.keyexpr() == f"{BEST_EFFORT}::,1:,:,:,,"
    with pytest.raises(WireError):
        topic_key(0, "/x", "PoseStamped", STRING_HASH)


def test_the_attachment_is_the_33_bytes_rmw_zenoh_reads():
    source = bytes(range(16))
    data = encode_attachment(41, 1_700_000_000_123_456_789, source)
    # the layout rmw_zenoh's design document gives: int64 sequence, int64 timestamp (little-endian),
    # the GID's length (16) and its bytes
    assert data == struct.pack("<qqB", 41, 1_700_000_000_123_456_789, 16) + source
    # and it is what Zenoh's own serialiser makes of (int64, int64, bytes)
    from zenoh.ext import Int64, z_serialize

    assert data == z_serialize((Int64(41), Int64(1_700_000_000_123_456_789), source)).to_bytes()
    assert decode_attachment(data) == (41, 1_700_000_000_123_456_789, source)
    for bad in (data[:-1], data + b"\0", b"\xff" * 33, b""):  # truncated, long, a wrong GID length
        with pytest.raises(WireError):
            decode_attachment(bad)
    with pytest.raises(WireError):
        encode_attachment(1, 2, b"short")


def test_a_gid_is_sixteen_bytes_of_the_token_and_differs_between_entities():
    a = gid(f"@ros2_lv/0/{ZID}/0/1/MP/%/%/swarmbed/%clock")
    b = gid(f"@ros2_lv/0/{ZID}/0/2/MP/%/%/swarmbed/%tasks")
    assert len(a) == len(b) == 16 and a != b
    assert a == gid(f"@ros2_lv/0/{ZID}/0/1/MP/%/%/swarmbed/%clock")


def test_payloads_are_cdr_with_the_encapsulation_header(types):
    clock = types.cls("rosgraph_msgs/msg/Clock")(clock=stamp(types, 12.25))
    data = types.serialize(clock, "rosgraph_msgs/msg/Clock")
    # CDR little-endian: the encapsulation header 00 01 00 00, then int32 sec and uint32 nanosec
    assert data == b"\x00\x01\x00\x00" + struct.pack("<iI", 12, 250_000_000)
    inbox = types.cls(RADIO_INBOX)
    assert types.hash(RADIO_INBOX).startswith("RIHS01_") and inbox is not None
    with pytest.raises(WireError):
        types.deserialize(data[:5], "geometry_msgs/msg/PoseStamped")


def test_stamps_carry_a_rounded_up_fraction_into_the_seconds(types):
    # tick 90 at dt 0.7 is 62.99999999999999 s in floating point: stamped 63 s, never 62 s
    t = 90 * 0.7
    assert (stamp(types, t).sec, stamp(types, t).nanosec) == (63, 0)
    previous = (-1, 0)
    for tick in range(2000):  # simulated time never runs backwards in the stamps
        s = stamp(types, tick * 0.7)
        assert 0 <= s.nanosec < 1_000_000_000 and (s.sec, s.nanosec) > previous, tick
        assert abs(s.sec + s.nanosec * 1e-9 - tick * 0.7) < 1e-6
        previous = (s.sec, s.nanosec)


def test_the_shipped_ros2_package_defines_the_types_the_run_uses(types):
    from pathlib import Path

    from swarmbed.wire.ros2_conventions import OUR_TYPES

    folder = Path(__file__).resolve().parent.parent / "docs" / "ros2" / "swarmbed_msgs" / "msg"
    assert {p.stem for p in folder.glob("*.msg")} == {name.rsplit("/", 1)[1] for name in OUR_TYPES}
    for name, text in OUR_TYPES.items():  # what a ROS 2 machine builds is what the hashes name
        assert (folder / f"{name.rsplit('/', 1)[1]}.msg").read_text() == text, name
        assert types.hash(name).startswith("RIHS01_")
    from swarmbed.extension.allocator import HALT, HOLD
    from swarmbed.plugins.external import NONE

    command = types.cls("swarmbed_msgs/msg/TaskCommand")
    assert (command.NONE, command.HOLD, command.HALT) == (NONE, HOLD, HALT)  # the codes the allocator reads


def test_a_decision_travels_in_the_tick_sample_only_when_there_is_one():
    from swarmbed.wire.codec import EMPTY_INBOX, decode_agent_in, encode_tick, pack

    plain = encode_tick(3, {"x": 1.0}, EMPTY_INBOX)
    assert plain == pack([0, 3, {"x": 1.0}, EMPTY_INBOX])  # unchanged for every other allocator
    assert decode_agent_in(plain).decision is None
    for decision in (0, 17, -1, -2, -3):
        assert decode_agent_in(encode_tick(3, {}, EMPTY_INBOX, decision)).decision == decision
    for bad in (2**31, "12", 1.5, None, [1]):
        with pytest.raises(WireError):
            decode_agent_in(pack([0, 3, {}, EMPTY_INBOX, bad]))


def test_a_command_key_names_a_robot_of_the_run():
    from swarmbed.coordinator.ros2_hub import _robot_of

    assert _robot_of("7/robot_3/cmd/swarmbed_msgs::msg::dds_::TaskCommand_/RIHS01_x", 5) == 3
    for key in (
        "7/robot_5/cmd/t/h",
        "7/robot_-1/cmd/t/h",
        "7/robotx/cmd/t/h",
        "7/robot_/cmd/t/h",
        "7",
        "7/robot_9999999/cmd",
    ):
        with pytest.raises(WireError):
            _robot_of(key, 5)


def test_the_shipped_rviz_configuration_shows_topics_the_run_publishes():
    """docs/ros2/swarmbed.rviz parses, is in the map frame, and every topic it names is one the
    hub's node publishes (coordinator/ros2_hub.py)."""
    import yaml

    from tests.conftest import ROOT

    config = yaml.safe_load((ROOT / "docs" / "ros2" / "swarmbed.rviz").read_text())
    manager = config["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "map"
    topics = {d["Topic"]["Value"] for d in manager["Displays"] if "Topic" in d}
    source = (ROOT / "coordinator" / "ros2_hub.py").read_text()
    assert topics == {"/robots", "/tasks", "/radio", "/robot_0/odom"}
    for topic in topics:
        assert f'"{topic}"' in source or 'f"/robot_{i}/odom"' in source, topic
    assert {d["Class"] for d in manager["Displays"]} >= {"rviz_default_plugins/TF", "rviz_default_plugins/PoseArray"}


@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted", "lyrical", "rolling"])
def test_each_distribution_s_keys_and_cdr_are_rosbags_store_of_it(distro):
    """``ros2.distro``: the type hash in keys and tokens is the one rosidl computes from that
    distribution's definitions (rosbags' store of it, asked directly here), and Humble's is
    rmw_zenoh's placeholder; a message serialised for the distribution decodes with its store."""
    from rosbags.typesys import Stores, get_typestore

    from swarmbed.wire.ros2_conventions import DISTRO_STORES, NO_TYPE_HASH

    types = Ros2Types(distro)
    reference = get_typestore(getattr(Stores, DISTRO_STORES[distro]))
    for ros_type in ("visualization_msgs/msg/MarkerArray", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"):
        expected = NO_TYPE_HASH if distro == "humble" else reference.hash_rihs01(ros_type)
        assert types.hash(ros_type) == expected
        key = topic_key(0, "/x", ros_type, types.hash(ros_type))
        assert key.endswith("/" + expected)
    clock = types.cls("rosgraph_msgs/msg/Clock")(clock=stamp(types, 12.5))
    decoded = reference.deserialize_cdr(types.serialize(clock, "rosgraph_msgs/msg/Clock"), "rosgraph_msgs/msg/Clock")
    assert (decoded.clock.sec, decoded.clock.nanosec) == (12, 500_000_000)


def test_a_distribution_rosbags_does_not_offer_is_refused_in_one_line():
    from swarmbed.config import ConfigError
    from tests.conftest import experiment

    with pytest.raises(ConfigError) as exc:
        experiment("ros2={distro: iron}")
    assert "ros2.distro" in str(exc.value) and len(str(exc.value).splitlines()) == 1
