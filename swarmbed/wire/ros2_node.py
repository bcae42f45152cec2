"""A ROS 2 node on a Zenoh session, as rmw_zenoh's peers see one: its liveliness token, and
publishers and subscriptions each with its own token, GID and sequence numbers.

The hub (the coordinator's session) and the netem proxy each hold one when a run publishes ROS 2
topics (``docs/ros2.md``); the conventions themselves are in :mod:`swarmbed.wire.ros2_conventions`.

A publisher whose QoS is TRANSIENT_LOCAL is a Zenoh *advanced* publisher with a cache of ``depth``
samples and publisher detection, as rmw_zenoh declares one (ros2/rmw_zenoh#368, which replaced the
publication cache): a subscription that joins late (rmw_zenoh's advanced subscriber, with history
and late-publisher detection) is handed the last ``depth`` samples.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh

from swarmbed.wire.ros2_conventions import (
    PUBLISHER,
    SUBSCRIPTION,
    TRANSIENT_LOCAL,
    Qos,
    Ros2Types,
    encode_attachment,
    endpoint_token,
    gid,
    node_token,
    topic_key,
    wall_ns,
)
from swarmbed.wire.zenoh_session import undeclare_all


@dataclass
class Topic:
    """One publisher: its Zenoh publisher, token, GID and sequence number."""

    ros_type: str
    publisher: Any  # a zenoh.Publisher, or a zenoh.ext.AdvancedPublisher for TRANSIENT_LOCAL
    token: zenoh.LivelinessToken
    gid: bytes
    sequence: int = 0


class Ros2Node:
    """Node ``name`` of ROS domain ``domain`` on ``session``. Samples go out with congestion control
    DROP, as every view of a run does: a ROS 2 reader that stops reading never holds up a tick."""

    def __init__(self, session: zenoh.Session, domain: int, name: str, types: Ros2Types | None = None) -> None:
        self.types = types or Ros2Types()
        self.session, self.domain, self.name = session, domain, name
        self.zid = str(session.zid())
        self._entities: list[Any] = [session.liveliness().declare_token(node_token(domain, self.zid, 0, name))]
        self._next_id = 1

    def _token(self, kind: str, topic: str, ros_type: str, qos: Qos) -> str:
        token = endpoint_token(
            kind, self.domain, self.zid, 0, self._next_id, self.name, topic, ros_type, self.types.hash(ros_type), qos
        )
        self._next_id += 1
        return token

    def key(self, topic: str, ros_type: str) -> str:
        return topic_key(self.domain, topic, ros_type, self.types.hash(ros_type))

    def publisher(self, topic: str, ros_type: str, qos: Qos | None = None) -> Topic:
        qos = qos or Qos()
        token = self._token(PUBLISHER, topic, ros_type, qos)
        key, drop = self.key(topic, ros_type), zenoh.CongestionControl.DROP
        publisher: Any
        if qos.durability == TRANSIENT_LOCAL:
            from zenoh import ext

            publisher = ext.declare_advanced_publisher(
                self.session,
                key,
                congestion_control=drop,
                cache=ext.CacheConfig(max_samples=qos.depth),
                publisher_detection=True,
            )
        else:
            publisher = self.session.declare_publisher(key, congestion_control=drop)
        made = Topic(ros_type, publisher, self.session.liveliness().declare_token(token), gid(token))
        self._entities += [made.publisher, made.token]
        return made

    def subscription(self, topic: str, ros_type: str, qos: Qos | None = None) -> None:
        """Announce a subscription to ``topic`` in the graph (``ros2 topic info`` lists it); the
        Zenoh subscriber itself is the caller's, since one may listen to many topics at once."""
        self._entities.append(
            self.session.liveliness().declare_token(self._token(SUBSCRIPTION, topic, ros_type, qos or Qos()))
        )

    def listen(self, key_expr: str, callback: Callable[[zenoh.Sample], None]) -> None:
        self._entities.append(self.session.declare_subscriber(key_expr, callback))

    def put(self, topic: Topic, msg: object) -> None:
        topic.sequence += 1  # rmw_zenoh's publishers count from 1
        topic.publisher.put(
            self.types.serialize(msg, topic.ros_type),
            attachment=encode_attachment(topic.sequence, wall_ns(), topic.gid),
        )

    def close(self) -> None:
        undeclare_all(self._entities)
