"""The run as ROS 2 topics: what a ROS 2 machine on rmw_zenoh sees of a running experiment.

With ``ros2:`` in the experiment, the coordinator's session (the hub) is also a ROS 2 node,
``/swarmbed``, that publishes at each tick:

=========================  ======================================  ==================================
topic                      type                                    what
=========================  ======================================  ==================================
``/clock``                 ``rosgraph_msgs/msg/Clock``             simulated time (for ``use_sim_time``)
``/robot_<i>/pose``        ``geometry_msgs/msg/PoseStamped``       robot i's pose (its heading), simulated time
``/tf``                    ``tf2_msgs/msg/TFMessage``              map -> robot_<i>/base_link, every robot
``/robot_<i>/odom``        ``nav_msgs/msg/Odometry``               robot i's pose and speed along its heading
``/robots``                ``geometry_msgs/msg/PoseArray``         every robot's pose
``/radio``                 ``visualization_msgs/msg/MarkerArray``  the tick's delivered copies as lines
``/walls``                 ``visualization_msgs/msg/MarkerArray``  the obstacles' walls, once, latched
``/robot_<i>/path``        ``nav_msgs/msg/Path``                   with ``ros2.path``: its last poses
``/tasks``                 ``visualization_msgs/msg/MarkerArray``  every task on the map, its holders
                                                                   (transient local: late joiners get it)
``/robot_<i>/radio/       ``swarmbed_msgs/msg/RadioInbox``        what robot i received this tick
received``
=========================  ======================================  ==================================

(The proxy's node publishes ``/robot_<i>/radio/sent``: ``netem/ros2_radio.py``.) With the ``ros2``
allocator, :class:`Ros2Commands` also publishes each robot's observation and gathers its decision.

Keys, payloads, attachments and tokens follow rmw_zenoh (:mod:`swarmbed.wire.ros2_conventions`). Samples go out
with congestion control DROP, as every view of a run does: a ROS 2 reader that stops reading loses
samples and never holds up a tick. Nothing here feeds back into the run: the results are the same
with publishing on or off (tests/test_ros2_run.py holds them byte-identical).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import zenoh

from swarmbed.engine.hooks import TickHook
from swarmbed.extension.actions import ActionSpec
from swarmbed.schema.experiment import Ros2Section
from swarmbed.wire.codec import Delivered, WireError, WorldSample, delivered_in
from swarmbed.wire.ros2_conventions import (
    LATCHED_QOS,
    NODE_PREFIX,
    RADIO_INBOX,
    SENSOR_QOS,
    TASK_COMMAND,
    TASK_OBSERVATION,
    Ros2Types,
    stamp,
)
from swarmbed.wire.ros2_node import Ros2Node

NODE_NAME = NODE_PREFIX
log = logging.getLogger("swarmbed.coordinator")
#: wall seconds between two reports of ticks that waited for commands that never came
WAIT_REPORT_EVERY_S = 10.0
CLOCK, POSE, MARKERS = "rosgraph_msgs/msg/Clock", "geometry_msgs/msg/PoseStamped", "visualization_msgs/msg/MarkerArray"
TF, ODOMETRY, POSE_ARRAY = "tf2_msgs/msg/TFMessage", "nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseArray"
PATH = "nav_msgs/msg/Path"
RADIO_LINES = (0.12, 0.47, 0.71, 0.8)  # RGBA of a delivered copy's line, sender to receiver
WALL_LINES = (0.23, 0.23, 0.23, 1.0)  # RGBA of the obstacles' walls
TASK_HEIGHT = 2.0  # metres of a task's cylinder; its diameter is the arrival radius, at least 1
FREE, HELD = (0.6, 0.6, 0.6, 0.8), (1.0, 0.55, 0.0, 0.9)  # RGBA of a task nobody / somebody pursues


class Ros2Out:
    """The ``/swarmbed`` node of one run, on the hub's session."""

    def __init__(
        self,
        session: zenoh.Session,
        settings: Ros2Section,
        n_agents: int,
        actions: ActionSpec,
        dt: float = 1.0,
        walls: Sequence[tuple[tuple[float, float], tuple[float, float]]] = (),
    ) -> None:
        self.node = Ros2Node(session, settings.domain, NODE_NAME, Ros2Types(settings.distro))
        # the obstacles' walls as one line list (a run with obstacles: only)
        self.walls = list(walls)
        # once, latched: a display that starts late gets them from the publisher's cache
        self.walls_topic = self.node.publisher("/walls", MARKERS, LATCHED_QOS) if self.walls else None
        self.dt = dt
        self.types = t = self.node.types
        self.settings = settings
        self.clock = self.node.publisher("/clock", CLOCK, SENSOR_QOS)
        # latched, as ROS keeps such state: a display that starts late gets the last markers
        self.tasks = self.node.publisher("/tasks", MARKERS, LATCHED_QOS)
        self.poses = [self.node.publisher(f"/robot_{i}/pose", POSE) for i in range(n_agents)]
        self.radio = [self.node.publisher(f"/robot_{i}/radio/received", RADIO_INBOX) for i in range(n_agents)]
        # what RViz2's TF, Odometry, PoseArray and Marker displays read
        self.tf = self.node.publisher("/tf", TF)
        self.odom = [self.node.publisher(f"/robot_{i}/odom", ODOMETRY) for i in range(n_agents)]
        self.robots = self.node.publisher("/robots", POSE_ARRAY)
        self.radio_lines = self.node.publisher("/radio", MARKERS)
        # with ros2.path: each robot's recent poses, as nav_msgs/Path (bounded)
        self.paths = [self.node.publisher(f"/robot_{i}/path", PATH) for i in range(n_agents)] if settings.path else []
        self.trails: dict[int, deque] = {i: deque(maxlen=settings.path) for i in range(n_agents)}
        # the actions that name a task or victim by its id (["goto_task", 12]): who pursues what
        self.aiming = frozenset(name for name, kinds in actions.items() if kinds == (int,))
        self.Header, self.Pose, self.PoseStamped = (
            t.cls("std_msgs/msg/Header"),
            t.cls("geometry_msgs/msg/Pose"),
            t.cls(POSE),
        )
        self.Point, self.Quaternion = t.cls("geometry_msgs/msg/Point"), t.cls("geometry_msgs/msg/Quaternion")
        self._tasks_shown: tuple[dict, dict] | None = None  # the task markers last published, and who pursued each

    def publish(
        self,
        tick: int,
        sim_time: float,
        positions: tuple[Sequence[int], Sequence[float], Sequence[float]],
        markers: Mapping[int, tuple[float, float, str]],
        actions: Mapping[int, list],
        inboxes: Mapping[int, bytes],
        marker_size: float,
        motion: Mapping[int, tuple[float, float]] | None = None,
    ) -> None:
        """Tick ``tick`` at ``sim_time``: the clock always; the rest every ``every`` ticks. ``inboxes``
        are the encoded inboxes the proxy made for the next tick (what each robot received);
        ``motion``: each robot's heading (radians from +x) and speed, from its observation."""
        t = self.types
        now = stamp(t, sim_time)
        self.node.put(self.clock, t.cls(CLOCK)(clock=now))
        if tick % self.settings.every:
            return
        header = self.Header(stamp=now, frame_id=self.settings.frame_id)
        if self.walls_topic is not None:
            self.node.put(self.walls_topic, self._wall_lines(header))
            self.walls_topic = None  # sent: the cache keeps it
        motion = motion or {}
        poses, transforms = [], []
        for i, x, y in zip(*positions):
            heading, speed = motion.get(i, (0.0, 0.0))
            pose = self._pose(x, y, 0.0, heading)
            poses.append(pose)
            stamped = self.PoseStamped(header=header, pose=pose)
            self.node.put(self.poses[i], stamped)
            self.node.put(self.odom[i], self._odometry(header, i, pose, speed))
            if self.paths:
                self.trails[i].append(stamped)
                self.node.put(self.paths[i], t.cls(PATH)(header=header, poses=list(self.trails[i])))
            transforms.append(self._transform(header, i, x, y, pose))
        self.node.put(self.tf, t.cls(TF)(transforms=transforms))
        self.node.put(self.robots, t.cls(POSE_ARRAY)(header=header, poses=poses))
        received = {i: delivered_in(inboxes.get(i)) for i in positions[0]}  # every live robot, decoded once
        self.node.put(self.radio_lines, self._radio_lines(header, positions, received))
        pursuers: dict[int, list[int]] = {}
        for agent, action in sorted(actions.items()):
            if action and action[0] in self.aiming:
                pursuers.setdefault(int(action[1]), []).append(agent)
        if (markers, pursuers) != self._tasks_shown:  # markers stay on a ROS 2 display until replaced
            self._tasks_shown = (dict(markers), pursuers)
            self.node.put(self.tasks, self._markers(header, markers, pursuers, marker_size))
        for i, items in received.items():  # an empty inbox too
            self.node.put(self.radio[i], self._inbox(header, i, items))

    def _odometry(self, header: object, robot: int, pose: object, speed: float) -> object:
        """Robot ``robot``'s odometry: its pose in the map, its speed along its heading (base_link's x)."""
        t = self.types
        zeros = np.zeros(36)
        Vector3 = t.cls("geometry_msgs/msg/Vector3")
        twist = t.cls("geometry_msgs/msg/Twist")(
            linear=Vector3(x=speed, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0)
        )
        return t.cls(ODOMETRY)(
            header=header,
            child_frame_id=f"robot_{robot}/base_link",
            pose=t.cls("geometry_msgs/msg/PoseWithCovariance")(pose=pose, covariance=zeros),
            twist=t.cls("geometry_msgs/msg/TwistWithCovariance")(twist=twist, covariance=zeros),
        )

    def _transform(self, header: object, robot: int, x: float, y: float, pose: Any) -> object:
        """map -> robot_<i>/base_link, as TF carries it."""
        t = self.types
        return t.cls("geometry_msgs/msg/TransformStamped")(
            header=header,
            child_frame_id=f"robot_{robot}/base_link",
            transform=t.cls("geometry_msgs/msg/Transform")(
                translation=t.cls("geometry_msgs/msg/Vector3")(x=x, y=y, z=0.0), rotation=pose.orientation
            ),
        )

    def _radio_lines(
        self,
        header: object,
        positions: tuple[Sequence[int], Sequence[float], Sequence[float]],
        received: Mapping[int, list[Delivered]],
    ) -> object:
        """The copies delivered for the next tick as one line list, sender to receiver, living one tick
        (``RadioInbox`` says the same in our own type, which RViz cannot draw)."""
        where = {i: (x, y) for i, x, y in zip(*positions)}
        points = [
            p for r, items in received.items() for d in items if d.sender in where for p in (where[d.sender], where[r])
        ]
        Marker = self.types.cls("visualization_msgs/msg/Marker")
        tick_ns = round(self.settings.every * self.dt * 1e9)
        line = self._marker(
            header,
            "radio",
            0,
            Marker.LINE_LIST,
            Marker.ADD,
            (0.0, 0.0, 0.0),
            (0.3, 0.0, 0.0),
            RADIO_LINES,
            "",
            points,
            tick_ns,
        )
        return self.types.cls(MARKERS)(markers=[line] if points else [])

    def _wall_lines(self, header: object) -> object:
        """The walls as one line list that never expires."""
        Marker = self.types.cls("visualization_msgs/msg/Marker")
        points = [p for wall in self.walls for p in wall]
        line = self._marker(
            header, "walls", 0, Marker.LINE_LIST, Marker.ADD, (0.0, 0.0, 0.0), (0.5, 0.0, 0.0), WALL_LINES, "", points
        )
        return self.types.cls(MARKERS)(markers=[line])

    def _inbox(self, header: object, robot: int, items: list[Delivered]) -> object:
        return self.types.cls(RADIO_INBOX)(
            header=header,
            robot=robot,
            senders=np.array([d.sender for d in items], dtype=np.int32),
            kinds=[d.kind for d in items],
            sizes=np.array([len(d.payload) for d in items], dtype=np.uint32),
        )

    def _markers(
        self,
        header: object,
        markers: Mapping[int, tuple[float, float, str]],
        pursuers: Mapping[int, list[int]],
        size: float,
    ) -> object:
        """A cylinder per task (grey when nobody pursues it, orange when someone does) and a label
        naming it and its pursuers; the array starts with DELETEALL, so tasks done disappear."""
        Marker = self.types.cls("visualization_msgs/msg/Marker")

        def marker(ns: str, ident: int, kind: int, action: int, x: float, y: float, z: float, scale, rgba, text: str):
            return self._marker(header, ns, ident, kind, action, (x, y, z), scale, rgba, text)

        out = [marker("", 0, Marker.CUBE, Marker.DELETEALL, 0.0, 0.0, 0.0, (1.0, 1.0, 1.0), FREE, "")]
        d = max(size, 1.0)
        for ident, (x, y, label) in sorted(markers.items()):
            who = pursuers.get(ident, [])
            out.append(
                marker(
                    "tasks",
                    ident,
                    Marker.CYLINDER,
                    Marker.ADD,
                    x,
                    y,
                    TASK_HEIGHT / 2,
                    (d, d, TASK_HEIGHT),
                    HELD if who else FREE,
                    "",
                )
            )
            text = f"{label} {ident}" + (" <- " + ",".join(map(str, who)) if who else "")
            out.append(
                marker(
                    "labels",
                    ident,
                    Marker.TEXT_VIEW_FACING,
                    Marker.ADD,
                    x,
                    y,
                    TASK_HEIGHT + 1,
                    (0, 0, d),
                    (1.0, 1.0, 1.0, 1.0),
                    text,
                )
            )
        return self.types.cls(MARKERS)(markers=out)

    def _marker(
        self,
        header: object,
        ns: str,
        ident: int,
        kind: int,
        action: int,
        where: tuple[float, float, float],
        scale: Sequence[float],
        rgba: Sequence[float],
        text: str = "",
        points: Sequence[tuple[float, float]] = (),
        lifetime_ns: int = 0,
    ) -> object:
        t = self.types
        Color, Vector3 = t.cls("std_msgs/msg/ColorRGBA"), t.cls("geometry_msgs/msg/Vector3")
        return t.cls("visualization_msgs/msg/Marker")(
            header=header,
            ns=ns,
            id=ident,
            type=kind,
            action=action,
            pose=self._pose(*where, 0.0),
            scale=Vector3(x=scale[0], y=scale[1], z=scale[2]),
            color=Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
            lifetime=t.cls("builtin_interfaces/msg/Duration")(
                sec=lifetime_ns // 1_000_000_000, nanosec=lifetime_ns % 1_000_000_000
            ),
            frame_locked=False,
            points=[self.Point(x=x, y=y, z=0.0) for x, y in points],
            colors=[],
            texture_resource="",
            texture=t.cls("sensor_msgs/msg/CompressedImage")(header=header, format="", data=_no_bytes()),
            uv_coordinates=[],
            text=text,
            mesh_resource="",
            mesh_file=t.cls("visualization_msgs/msg/MeshFile")(filename="", data=_no_bytes()),
            mesh_use_embedded_materials=False,
        )

    def _pose(self, x: float, y: float, z: float, heading: float) -> object:
        """A pose at (x, y, z) facing ``heading`` (radians from +x, about +z)."""
        half = heading / 2
        return self.Pose(
            position=self.Point(x=x, y=y, z=z),
            orientation=self.Quaternion(x=0.0, y=0.0, z=math.sin(half), w=math.cos(half)),
        )

    def close(self) -> None:
        self.node.close()


class Ros2Publishing(TickHook):
    """The tick loop's hook that publishes each tick as ROS 2 topics, as the transport carries it
    (``task_size``: how wide a task is drawn, the scenario's arrival diameter where it has one)."""

    def __init__(self, out: Ros2Out, world: Any, task_size: float) -> None:
        self.out, self.world, self.task_size = out, world, task_size
        self.pursuing: dict[int, list] = {}  # the actions the world was last given (for the task markers)

    def exchange_starts(
        self, k: int, sample: WorldSample, observed: Mapping[int, Any], inboxes: Mapping[int, bytes]
    ) -> None:
        w, ids = self.world, sample.ids
        pursuing = {a: self.pursuing[a] for a in ids if a in self.pursuing}
        motion = {i: (float(o.heading), float(o.speed)) for i, o in observed.items()}
        self.out.publish(k, w.time, (ids, sample.xs, sample.ys), w.markers(), pursuing, inboxes, self.task_size, motion)

    def tick_done(self, k: int, admitted: Mapping[int, list]) -> None:
        self.pursuing.update(admitted)


def _no_bytes() -> np.ndarray:
    return np.zeros(0, dtype=np.uint8)


MAX_COMMAND_BYTES = 1024  # a TaskCommand is about 40 bytes; anything far larger is not one


class Ros2Commands:
    """Decisions from ROS 2 for a run whose allocator is ``ros2``: before each tick, every robot's
    observation goes out on ``/robot_<i>/observation``, and the decision for that tick comes back on
    ``/robot_<i>/cmd``, stamped with the observation's stamp.

    Lock-step: the tick waits until every robot has its decision, at most ``command_timeout`` wall
    seconds; a robot without one then keeps its last decision (counted: a run with such ticks is
    not reproducible, and the count says so). Real-time clock: no waiting, the last decision holds.
    A command is decoded into its declared type only, from a bounded payload, for the robot its key
    names; anything else is dropped and counted, never fatal."""

    def __init__(
        self,
        out: Ros2Out,
        n_agents: int,
        timeout: float,
        realtime: bool,
        malformed: Callable[[str, Exception], None],
    ) -> None:
        self.out, self.n, self.timeout, self.realtime, self.malformed = out, n_agents, timeout, realtime, malformed
        node = out.node
        self.observations = [node.publisher(f"/robot_{i}/observation", TASK_OBSERVATION) for i in range(n_agents)]
        for i in range(n_agents):  # a subscription per robot in the graph: ros2 topic info shows who listens
            node.subscription(f"/robot_{i}/cmd", TASK_COMMAND)
        command_key = node.key("/robot_0/cmd", TASK_COMMAND).split("/")
        command_key[1] = "robot_$*"  # every robot's, its type and hash
        node.listen("/".join(command_key), self._on_command)
        self.cond = threading.Condition()
        self.latest: dict[int, tuple[tuple[int, int], int]] = {}  # robot -> (stamp, decision)
        self.held: dict[int, int] = {}  # robot -> the decision it acts on
        self.timeouts = 0  # robot-ticks that kept their last decision because none came in time
        self.asked: tuple[int, int] = (-1, -1)  # the stamp of the observations last published
        self.commands = 0  # commands taken
        self._reported_at = -float("inf")  # when a wait was last reported (monotonic)

    def _on_command(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            robot = _robot_of(key, self.n)
            data = sample.payload.to_bytes()
            if len(data) > MAX_COMMAND_BYTES:
                raise WireError(f"a command of {len(data)} bytes")
            msg = self.out.types.deserialize(data, TASK_COMMAND)
            if msg.robot != robot:
                raise WireError(f"a command for robot {msg.robot} on robot {robot}'s topic")
            if not -3 <= msg.task < 2**31:
                raise WireError(f"task {msg.task}: a task id, -1 (none), -2 (hold) or -3 (halt)")
            stamp_key = (int(msg.header.stamp.sec), int(msg.header.stamp.nanosec))
        except (WireError, AttributeError, TypeError, ValueError) as exc:
            self.malformed(key, exc if isinstance(exc, WireError) else WireError(str(exc)))
            return
        with self.cond:
            if stamp_key > self.asked:  # no observation of that time was published: never a decision
                future = WireError(f"a command stamped {stamp_key[0]}.{stamp_key[1]:09d} s, after the tick asked")
            elif robot not in self.latest or stamp_key >= self.latest[robot][0]:
                future = None
                self.latest[robot] = (stamp_key, int(msg.task))
                self.commands += 1
                self.cond.notify_all()
            else:
                future = None
        if future is not None:
            self.malformed(key, future)

    def decide(
        self, tick: int, world: Any, observed: Mapping[int, Any], inboxes: Mapping[int, bytes]
    ) -> dict[int, int]:
        """Publish the observations of tick ``tick`` and gather the decisions for it."""
        sim_time = world.time
        t = self.out.types
        now = stamp(t, sim_time)
        header = self.out.Header(stamp=now, frame_id=self.out.settings.frame_id)
        Msg = t.cls(TASK_OBSERVATION)
        wanted = (int(now.sec), int(now.nanosec))
        with self.cond:
            self.asked = wanted
        for i, obs in observed.items():
            tasks = obs.tasks
            self.out.node.put(
                self.observations[i],
                Msg(
                    header=header,
                    robot=i,
                    x=float(obs.x),
                    y=float(obs.y),
                    heading=float(obs.heading),
                    speed=float(obs.speed),
                    task_ids=np.ascontiguousarray(tasks["id"], dtype=np.int32),
                    task_x=np.ascontiguousarray(tasks["x"], dtype=np.float64),
                    task_y=np.ascontiguousarray(tasks["y"], dtype=np.float64),
                    task_remaining=np.ascontiguousarray(tasks["remaining"], dtype=np.float64),
                ),
            )
        deadline = time.monotonic() + (0.0 if self.realtime else self.timeout)
        with self.cond:
            while not self.realtime and not all(self.latest.get(i, ((-1, -1), 0))[0] == wanted for i in observed):
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self.cond.wait(left)
            missing = []
            for i in observed:
                got = self.latest.get(i)
                if got is not None and (self.realtime or got[0] == wanted):
                    self.held[i] = got[1]
                elif not self.realtime:
                    missing.append(i)  # lock-step without its decision in time: the last one holds
        if missing:
            self.timeouts += len(missing)
            self._report_wait(tick, missing)
        return {i: self.held[i] for i in observed if i in self.held}

    def _report_wait(self, tick: int, missing: list[int]) -> None:
        """Say, at most every :data:`WAIT_REPORT_EVERY_S` wall seconds, that a tick waited the whole
        ``command_timeout`` for robots whose command never came."""
        now = time.monotonic()
        if now - self._reported_at < WAIT_REPORT_EVERY_S:
            return
        self._reported_at = now
        robots = ", ".join(map(str, missing[:10])) + (f" and {len(missing) - 10} more" if len(missing) > 10 else "")
        hint = "" if self.commands else "; no command has come yet: is a ROS 2 node answering /robot_<i>/cmd?"
        log.warning(
            "ros2: tick %d waited %g s (ros2.command_timeout) for robot(s) %s, which keep their last decision "
            "(%d robot-ticks so far)%s",
            tick,
            self.timeout,
            robots,
            self.timeouts,
            hint,
        )


def _robot_of(key: str, n: int) -> int:
    """The robot a command key names (``<domain>/robot_<i>/cmd/...``), within the run's robots."""
    chunks = key.split("/")
    name = chunks[1] if len(chunks) > 2 else ""
    digits = name.removeprefix("robot_")
    if not name.startswith("robot_") or not digits.isdigit() or len(digits) > 6 or int(digits) >= n:
        raise WireError(f"not a robot of this run: {name[:40]!r}")
    return int(digits)
