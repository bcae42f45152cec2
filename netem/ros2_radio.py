"""What each robot handed the radio, as ROS 2 topics: ``/robot_<i>/radio/sent``
(``swarmbed_msgs/msg/RadioOutbox``), published by the proxy's own ROS 2 node, ``/swarmbed_radio``,
when the run has a ``ros2:`` section (``docs/ros2.md``). What each robot received is the hub's
``/robot_<i>/radio/received``; where each copy went is the ledger's."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import zenoh

from swarmbed.schema.experiment import NetemSpec
from swarmbed.wire.codec import BROADCAST
from swarmbed.wire.ros2_conventions import NODE_PREFIX, RADIO_OUTBOX, Ros2Types, stamp
from swarmbed.wire.ros2_node import Ros2Node

NODE_NAME = NODE_PREFIX + "_radio"


class Ros2Outboxes:
    def __init__(self, session: zenoh.Session, spec: NetemSpec) -> None:
        assert spec.ros2 is not None
        self.settings, self.dt = spec.ros2, spec.dt
        self.node = Ros2Node(session, spec.ros2.domain, NODE_NAME, Ros2Types(spec.ros2.distro))
        self.sent = [self.node.publisher(f"/robot_{i}/radio/sent", RADIO_OUTBOX) for i in range(spec.agents)]
        t = self.node.types
        self.Header, self.Outbox = t.cls("std_msgs/msg/Header"), t.cls(RADIO_OUTBOX)

    def publish(self, tick: int, alive: Sequence[int], outs: Mapping[int, Any]) -> None:
        """The messages every live robot sent at ``tick`` (none: an empty outbox)."""
        if tick % self.settings.every:
            return
        header = self.Header(stamp=stamp(self.node.types, tick * self.dt), frame_id=self.settings.frame_id)
        for robot in alive:
            out = outs.get(robot)
            messages = out.messages if out is not None else []
            self.node.put(
                self.sent[robot],
                self.Outbox(
                    header=header,
                    robot=robot,
                    kinds=[m.kind for m in messages],
                    sizes=np.array([len(m.payload) for m in messages], dtype=np.uint32),
                    addressed=np.array([_addressed(m.dest) for m in messages], dtype=np.int32),
                ),
            )

    def close(self) -> None:
        self.node.close()


def _addressed(dest: int | tuple[int, ...]) -> int:
    if isinstance(dest, tuple):
        return len(dest)
    return -1 if dest == BROADCAST else 1
