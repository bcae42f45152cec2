"""A ROS 2 node without rclpy that decides for every robot of a run: nearest task, as the built-in
``nearest`` allocator does, through the ``ros2`` allocator's topics.

It reads each robot's ``/robot_<i>/observation`` (``swarmbed_msgs/msg/TaskObservation``) and
answers on ``/robot_<i>/cmd`` (``swarmbed_msgs/msg/TaskCommand``) with the same stamp, using only
eclipse-zenoh and rosbags, on rmw_zenoh's keys, attachments and graph tokens, so ``ros2 node list``
shows it as ``/nearest``. It needs no part of swarmbed: the message definitions come from the
``swarmbed_msgs`` package beside it. A run with ``allocator: {name: ros2}`` that it drives writes the
same result files as the same run with ``allocator: {name: nearest}`` (tests/test_ros2_run.py).

    python docs/ros2/nearest_node.py --connect tcp/127.0.0.1:7447 --credentials commander.json --domain 0

It leaves when the run's hub is gone: its router (the endpoint it connected to) drops the
connection, or the hub itself withdraws the ``/swarmbed`` node's token (a token under the router's own
id; any other session's token of that name is ignored, and the run's access rules refuse one anyway).
Ctrl-C leaves too.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import struct
import sys
import threading
import time
from pathlib import Path

import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

MSGS = Path(__file__).resolve().parent / "swarmbed_msgs" / "msg"
OBSERVATION, COMMAND = "swarmbed_msgs/msg/TaskObservation", "swarmbed_msgs/msg/TaskCommand"
NONE = -1


def dds(ros_type: str) -> str:
    package, kind, name = ros_type.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def nearest(obs) -> int:
    """The nearest task in view, ties to the lower id; NONE when none is in view."""
    best = None
    for task, x, y in zip(obs.task_ids.tolist(), obs.task_x.tolist(), obs.task_y.tolist()):
        key = (math.hypot(x - obs.x, y - obs.y), task)
        if best is None or key < best:
            best = key
    return NONE if best is None else best[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--connect", required=True, help="the run's hub endpoint")
    ap.add_argument("--credentials", help="a commander's credentials file (swarmbed credentials --role commander)")
    ap.add_argument("--domain", type=int, default=0)
    args = ap.parse_args()

    store = get_typestore(Stores.ROS2_JAZZY)
    for path in sorted(MSGS.glob("*.msg")):
        store.register(get_types_from_msg(path.read_text(), f"swarmbed_msgs/msg/{path.stem}"))
    Command, Header = store.types[COMMAND], store.types["std_msgs/msg/Header"]
    obs_hash, cmd_hash = store.hash_rihs01(OBSERVATION), store.hash_rihs01(COMMAND)

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([args.connect]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if args.credentials:
        who = json.loads(Path(args.credentials).read_text())
        conf.insert_json5("transport/auth/usrpwd", json.dumps({"user": who["user"], "password": who["password"]}))
    d = args.domain
    with zenoh.open(conf) as session:
        zid = str(session.zid())
        gid = os.urandom(16)
        sequence = [0]
        lock = threading.Lock()
        gone = threading.Event()
        tokens = [session.liveliness().declare_token(f"@ros2_lv/{d}/{zid}/0/0/NN/%/%/nearest")]  # ros2 node list

        def on_observation(sample: zenoh.Sample) -> None:
            obs = store.deserialize_cdr(sample.payload.to_bytes(), OBSERVATION)
            command = Command(
                header=Header(stamp=obs.header.stamp, frame_id=obs.header.frame_id), robot=obs.robot, task=nearest(obs)
            )
            with lock:
                sequence[0] += 1
                attachment = struct.pack("<qqB", sequence[0], time.time_ns(), 16) + gid
            key = f"{d}/robot_{obs.robot}/cmd/{dds(COMMAND)}/{cmd_hash}"
            session.put(key, bytes(store.serialize_cdr(command, COMMAND)), attachment=attachment)

        hub = {str(z) for z in session.info.routers_zid()}  # the run's hub: the router we reached

        def on_graph(sample: zenoh.Sample) -> None:
            chunks = str(sample.key_expr).split("/")
            # the hub's own session withdrew its node: never someone else's token of that name
            if (
                sample.kind == zenoh.SampleKind.DELETE
                and chunks[-4:] == ["NN", "%", "%", "swarmbed"]
                and chunks[2] in hub
            ):
                gone.set()

        subscriber = session.declare_subscriber(
            f"{d}/robot_$*/observation/{dds(OBSERVATION)}/{obs_hash}", on_observation
        )
        graph = session.liveliness().declare_subscriber(f"@ros2_lv/{d}/**", on_graph)
        print("ready", flush=True)
        try:
            while not gone.wait(0.5):
                if not hub & {str(z) for z in session.info.routers_zid()}:
                    break  # the hub's router closed the connection: the run is over
        except KeyboardInterrupt:
            pass
        for entity in [subscriber, graph, *tokens]:
            entity.undeclare()
    return 0


if __name__ == "__main__":
    sys.exit(main())
