"""ROS 2 on Zenoh as rmw_zenoh lays it out: topic keys, graph tokens, attachments, CDR payloads.

A ROS 2 machine whose middleware is rmw_zenoh (``RMW_IMPLEMENTATION=rmw_zenoh_cpp``) sees a Zenoh
sample as a ROS 2 message when four things match what its own publishers write. Each function below
builds one of them, following rmw_zenoh's ``docs/design.md`` (rolling) and the source files named
beside each:

* the **key** ``<domain>/<topic without its outer slashes>/<DDS type name>/<RIHS01 type hash>``
  (``liveliness_utils.cpp``, ``TopicInfo``): :func:`topic_key`;
* the **payload**: the message in CDR with its 4-byte encapsulation header (``cdr.cpp``), which
  ``rosbags`` writes (:class:`Ros2Types`), with the REP-2016 type hash that ``rosbags`` computes;
* the **attachment** of every sample: sequence number (int64), source timestamp (int64 ns) and the
  publisher's 16-byte GID, in Zenoh's own serialisation (``attachment_helpers.cpp``,
  ``serialize_to_zbytes``): :func:`encode_attachment`, 33 bytes;
* **liveliness tokens** under ``@ros2_lv/<domain>/...`` for the node and each publisher, which is
  how ``ros2 node list`` and ``ros2 topic list`` learn of them: :func:`node_token` and
  :func:`endpoint_token`, with names mangled (``/`` -> ``%``) and the QoS written as rmw_zenoh's
  delta against its default profile (``qos_to_keyexpr``, defaults in ``qos.cpp``). An entity's GID
  is the XXH3-128 hash of its token (:func:`gid`), as rmw_zenoh derives it.

Type hashes are what ROS 2 Iron and newer put in keys, from the message definitions of the
distribution named in ``ros2.distro`` (rosbags' store of it); on Humble, whose rosidl has none,
rmw_zenoh writes ``TypeHashNotSupported`` in their place (``docs/ros2.md``).

Nothing here opens a session or needs a ROS installation; ``rosbags`` and ``xxhash`` come with the
``ros2`` extra and are imported only when a run asks for ROS 2.
"""

from __future__ import annotations

import struct
import time
from dataclasses import dataclass
from typing import Any

from swarmbed.wire.errors import WireError

ADMIN_SPACE = "@ros2_lv"
#: every ROS 2 node of a run is named with this prefix (/swarmbed, /swarmbed_radio): their graph
#: tokens are the run's alone
NODE_PREFIX = "swarmbed"
NODE, PUBLISHER, SUBSCRIPTION = "NN", "MP", "MS"
GID_BYTES = 16
ATTACHMENT_BYTES = 8 + 8 + 1 + GID_BYTES  # two int64 and a length-prefixed 16-byte array
EXTRA_HINT = "ROS 2 publishing needs the ros2 extra: pip install 'swarmbed[ros2]'"

# rmw's QoS policy codes (rmw/types.h)
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2


@dataclass(frozen=True)
class Qos:
    """The QoS policies a token states. Deadline, lifespan and liveliness stay at rmw_zenoh's
    defaults (infinite, automatic), which is all rmw_zenoh implements."""

    reliability: int = RELIABLE
    durability: int = VOLATILE
    history: int = KEEP_LAST
    depth: int = 10

    def keyexpr(self) -> str:
        """rmw_zenoh's compact form: each field only where it differs from its default profile
        (reliable, volatile, keep-last, depth 42), ``:`` between policies, ``,`` within one."""
        d = RMW_ZENOH_DEFAULT_QOS

        def differs(mine: int, theirs: int) -> str:
            return str(mine) if mine != theirs else ""

        head = f"{differs(self.reliability, d.reliability)}:{differs(self.durability, d.durability)}"
        return f"{head}:{differs(self.history, d.history)},{differs(self.depth, d.depth)}:,:,:,,"


RMW_ZENOH_DEFAULT_QOS = Qos(RELIABLE, VOLATILE, KEEP_LAST, 42)  # qos.cpp's RMW_ZENOH_DEFAULT_*
SENSOR_QOS = Qos(BEST_EFFORT, VOLATILE, KEEP_LAST, 1)  # /clock, as rclcpp's ClockQoS
LATCHED_QOS = Qos(RELIABLE, TRANSIENT_LOCAL, KEEP_LAST, 1)  # /tasks: the last state for late joiners (as /tf_static)


def dds_type_name(ros_type: str) -> str:
    """``geometry_msgs/msg/PoseStamped`` -> ``geometry_msgs::msg::dds_::PoseStamped_``."""
    parts = ros_type.split("/")
    if len(parts) != 3 or not all(parts):
        raise WireError(f"not a ROS 2 type name: {ros_type!r}")
    package, kind, name = parts
    return f"{package}::{kind}::dds_::{name}_"


def topic_key(domain: int, topic: str, ros_type: str, type_hash: str) -> str:
    """Where rmw_zenoh publishes ``topic``: slashes inside the name stay key separators."""
    return f"{domain}/{topic.strip('/')}/{dds_type_name(ros_type)}/{type_hash}"


def mangle(name: str) -> str:
    """A name as one chunk of a token: every ``/`` becomes ``%``; the empty name is ``%``."""
    return name.replace("/", "%") or "%"


def node_token(domain: int, zid: str, node_id: int, name: str, namespace: str = "", enclave: str = "") -> str:
    """A node's liveliness token (the node id stands in both id places)."""
    return f"{ADMIN_SPACE}/{domain}/{zid}/{node_id}/{node_id}/{NODE}/{mangle(enclave)}/{mangle(namespace)}/{name}"


def endpoint_token(
    kind: str,
    domain: int,
    zid: str,
    node_id: int,
    entity_id: int,
    node: str,
    topic: str,
    ros_type: str,
    type_hash: str,
    qos: Qos,
    namespace: str = "",
    enclave: str = "",
) -> str:
    """A publisher's (``MP``) or subscription's (``MS``) liveliness token."""
    return (
        f"{ADMIN_SPACE}/{domain}/{zid}/{node_id}/{entity_id}/{kind}/{mangle(enclave)}/{mangle(namespace)}/{node}/"
        f"{mangle(topic)}/{dds_type_name(ros_type)}/{type_hash}/{qos.keyexpr()}"
    )


def gid(token: str) -> bytes:
    """An entity's GID: XXH3-128 of its liveliness token, the low 64 bits then the high, each
    little-endian (``Entity``'s constructor in ``liveliness_utils.cpp``)."""
    try:
        import xxhash
    except ImportError as exc:
        raise ImportError(EXTRA_HINT) from exc
    value = xxhash.xxh3_128_intdigest(token.encode())
    return (value & (2**64 - 1)).to_bytes(8, "little") + (value >> 64).to_bytes(8, "little")


def encode_attachment(sequence: int, stamp_ns: int, source_gid: bytes) -> bytes:
    """A sample's attachment as Zenoh's serialiser (zenoh-ext) lays out what rmw_zenoh writes:
    int64, int64 (little-endian), then the GID as a length-prefixed byte array. Packed directly (a
    sample a robot a tick); tests/test_ros2.py holds it equal to ``zenoh.ext.z_serialize``'s."""
    if len(source_gid) != GID_BYTES:
        raise WireError(f"a GID has {GID_BYTES} bytes, not {len(source_gid)}")
    return _ATTACHMENT_HEAD.pack(sequence, stamp_ns, GID_BYTES) + source_gid


_ATTACHMENT_HEAD = struct.Struct("<qqB")


def decode_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp in ns, GID) of an attachment, or :class:`WireError`. The
    layout is fixed (33 bytes), so it is read as such, not through a general deserialiser."""
    if len(data) != ATTACHMENT_BYTES:
        raise WireError(f"an rmw_zenoh attachment has {ATTACHMENT_BYTES} bytes, not {len(data)}")
    sequence, stamp_ns, length = _ATTACHMENT_HEAD.unpack_from(data)
    if length != GID_BYTES:
        raise WireError(f"attachment GID of {length} bytes, not {GID_BYTES}")
    return sequence, stamp_ns, bytes(data[17:])


# -- our own message type: what a robot heard over the emulated radio ----------------------------
#: ``swarmbed_msgs/msg/RadioInbox``: the copies the proxy delivered to one robot at one tick.
#: No standard ROS 2 type says who sent what of which kind (``std_msgs`` has only bare arrays), so
#: it is ours; docs/ros2/swarmbed_msgs is the package a ROS 2 machine builds to read it.
RADIO_INBOX = "swarmbed_msgs/msg/RadioInbox"
RADIO_INBOX_MSG = """\
# The radio messages one robot received at one tick of simulated time (its inbox, in delivery order)
std_msgs/Header header
int32 robot
int32[] senders
string[] kinds
uint32[] sizes
"""


#: ``swarmbed_msgs/msg/RadioOutbox``: what one robot handed the radio at one tick (the proxy's side).
RADIO_OUTBOX = "swarmbed_msgs/msg/RadioOutbox"
RADIO_OUTBOX_MSG = """\
# The radio messages one robot sent at one tick of simulated time, in the order it sent them
std_msgs/Header header
int32 robot
string[] kinds
uint32[] sizes
# how many robots each message named: -1 for a broadcast (every robot in range)
int32[] addressed
"""

#: ``swarmbed_msgs/msg/TaskObservation``: what a robot commanded from ROS 2 senses at a tick (the
#: observation its agent process is handed), published before the tick for the node that decides.
TASK_OBSERVATION = "swarmbed_msgs/msg/TaskObservation"
TASK_OBSERVATION_MSG = """\
# What one robot senses at the tick stamped in the header (simulated time): itself and the tasks in view
std_msgs/Header header
int32 robot
float64 x
float64 y
float64 heading
float64 speed
int32[] task_ids
float64[] task_x
float64[] task_y
float64[] task_remaining
"""

#: ``swarmbed_msgs/msg/TaskCommand``: a ROS 2 node's decision for one robot at one tick.
TASK_COMMAND = "swarmbed_msgs/msg/TaskCommand"
TASK_COMMAND_MSG = """\
# The decision for one robot at the tick stamped in the header (the stamp of the observation it answers)
std_msgs/Header header
int32 robot
# a task id to pursue; NONE lets the robot's tree explore; HOLD stays put; HALT stays put, stopping at once
int32 task
int32 NONE=-1
int32 HOLD=-2
int32 HALT=-3
"""

#: every type of ours, by name: what ``docs/ros2/swarmbed_msgs`` defines for a ROS 2 machine
OUR_TYPES = {
    RADIO_INBOX: RADIO_INBOX_MSG,
    RADIO_OUTBOX: RADIO_OUTBOX_MSG,
    TASK_OBSERVATION: TASK_OBSERVATION_MSG,
    TASK_COMMAND: TASK_COMMAND_MSG,
}


#: ``ros2.distro`` -> rosbags' type store of that distribution (rolling: its latest)
DISTRO_STORES = {
    "humble": "ROS2_HUMBLE",
    "jazzy": "ROS2_JAZZY",
    "kilted": "ROS2_KILTED",
    "lyrical": "ROS2_LYRICAL",
    "rolling": "LATEST",
}
#: what rmw_zenoh puts where a type hash goes on Humble, whose rosidl has none
NO_TYPE_HASH = "TypeHashNotSupported"


class Ros2Types:
    """CDR and type hashes for the messages a run publishes: rosbags' type store of one
    distribution (``distro``, Jazzy by default) plus ours."""

    def __init__(self, distro: str = "jazzy") -> None:
        try:
            from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        except ImportError as exc:
            raise ImportError(EXTRA_HINT) from exc
        if distro not in DISTRO_STORES:
            raise ValueError(f"ros2.distro {distro!r}: one of {', '.join(DISTRO_STORES)}")
        self.distro = distro
        self.store = get_typestore(getattr(Stores, DISTRO_STORES[distro]))
        for name, text in OUR_TYPES.items():
            self.store.register(get_types_from_msg(text, name))
        self._hashes: dict[str, str] = {}

    def hash(self, ros_type: str) -> str:
        """``RIHS01_<sha256>``, as rosidl computes it (REP-2016) from this distribution's
        definition; on Humble, which has no type hashes, rmw_zenoh's placeholder."""
        if ros_type not in self._hashes:
            self._hashes[ros_type] = NO_TYPE_HASH if self.distro == "humble" else self.store.hash_rihs01(ros_type)
        return self._hashes[ros_type]

    def serialize(self, msg: Any, ros_type: str) -> bytes:
        return bytes(self.store.serialize_cdr(msg, ros_type))

    def deserialize(self, data: bytes, ros_type: str) -> Any:
        try:
            return self.store.deserialize_cdr(data, ros_type)
        except Exception as exc:  # rosbags raises several types on truncated or crafted CDR
            raise WireError(f"not a CDR {ros_type}: {exc}") from exc

    def cls(self, ros_type: str) -> Any:
        """The message class of ``ros_type`` (``geometry_msgs/msg/PoseStamped``)."""
        return self.store.types[ros_type]


def stamp(types: Ros2Types, seconds: float) -> Any:
    """A ``builtin_interfaces/Time`` of simulated seconds, rounded to the nearest nanosecond (a
    fraction that rounds up to a whole second carries into ``sec``: 62.99999999999999 is 63 s)."""
    sec, nanosec = divmod(round(seconds * 1e9), 1_000_000_000)
    return types.cls("builtin_interfaces/msg/Time")(sec=int(sec), nanosec=int(nanosec))


def wall_ns() -> int:
    """The attachment's source timestamp: the wall clock, as rmw_zenoh stamps it."""
    return time.time_ns()
