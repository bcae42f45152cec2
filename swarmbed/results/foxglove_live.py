"""``swarmbed run --foxglove [PORT]`` and ``swarmbed watch --foxglove [PORT]``: the recording's
channels served live while the run goes.

A hook of the engine's tick loop (:class:`~swarmbed.engine.TickHook`) that starts Foxglove's
WebSocket server (its SDK, the one that writes the MCAP recordings) and logs, at each tick as the
transport carries it, what :mod:`.recording` writes after a run: ``/agents`` and ``/agents/poses``
(each agent with its heading, from its observation), ``/markers`` (tasks or victims as they appear
and vanish) and ``/radio`` (the copies delivered at this tick, as lines from sender to receiver).
Foxglove (or Lichtblick) connects with "Open connection" to the URL the command prints,
``ws://127.0.0.1:PORT/TOKEN``: a gate (:mod:`.view_gate`) admits at most ``--view-clients``
viewers at once (default 4), each with the run's token, and relays them to the server on a
loopback port of its own. Nothing feeds back into the run; a run without it pays nothing. A run
with obstacles also has ``/walls`` (its walls as lines, again every 50 ticks for a viewer that
joins late).

``watch --foxglove`` (:class:`StatusFoxglove`) serves a run already under way, from anywhere its
hub is reachable, out of the progress samples ``swarmbed watch`` reads: ``/agents``,
``/agents/poses`` (headings from the direction each agent last moved) and ``/markers``, at the
samples' pace (about one a wall second), without the radio's lines (an operator does not read the
agents' inboxes).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import pandas as pd

from swarmbed.engine.hooks import TickHook
from swarmbed.extension.scenario import World
from swarmbed.results.colours import LABEL_COLORS
from swarmbed.results.recording import (
    EPOCH_NS,
    FRAME,
    RecordingError,
    _agent_entities,
    _marker_update,
    _radio_update,
    _rgba,
    _stamp,
    _walls_update,
)
from swarmbed.results.view_gate import MAX_CLIENTS, ViewGate
from swarmbed.wire.codec import WorldSample, delivered_in
from swarmbed.wire.observation import Observation
from swarmbed.wire.run_status import RunStatus

#: Foxglove's default WebSocket port
DEFAULT_PORT = 8765
TOPICS = ("/agents", "/agents/poses", "/markers", "/radio")
#: messages the server keeps for a client that reads slower than the run logs (the oldest are
#: dropped past it): a scene of 1,000 agents is about 100 kB, so a client costs at most a few MB
#: (the SDK's default, 1,024, let 40 stalled clients hold gigabytes)
BACKLOG_MESSAGES = 32
#: ticks between two copies of /walls
WALLS_EVERY = 50


class Served:
    """Foxglove's server on a loopback port of its own, behind a :class:`ViewGate` on the port the
    user asked for: :attr:`port` and :attr:`url` (with the run's token) are the gate's."""

    def __init__(self, server: Any, gate: ViewGate) -> None:
        self.server, self.gate = server, gate
        self.port, self.url = gate.port, gate.url

    def stop(self) -> None:
        self.gate.close()
        self.server.stop()


def serve(host: str, port: int, max_clients: int = MAX_CLIENTS) -> tuple[Any, Served, dict[str, Any]]:
    """Foxglove's server with the live view's scene channels, behind a gate on host:port (0: a free
    one) that admits ``max_clients`` viewers at once, each with the run's token."""
    try:
        import foxglove
        from foxglove import channels
    except ImportError:
        raise RecordingError("a live view needs Foxglove's SDK: pip install 'swarmbed[viewers]'") from None
    context = foxglove.Context()
    try:
        gate = ViewGate(0, host, port, max_clients)
    except (OSError, OverflowError, ValueError) as exc:  # a port in use: one line, not a traceback
        raise RecordingError(f"--foxglove {port}: cannot serve on {host}:{port}: {str(exc).splitlines()[0]}") from None
    try:
        server = foxglove.start_server(
            name="swarmbed", host="127.0.0.1", port=0, context=context, message_backlog_size=BACKLOG_MESSAGES
        )
    except (RuntimeError, OSError) as exc:
        gate.close()
        raise RecordingError(f"--foxglove: cannot start Foxglove's server: {str(exc).splitlines()[0]}") from None
    gate.backend_port = server.port
    made = {
        "/agents": channels.SceneUpdateChannel("/agents", context=context),
        "/agents/poses": channels.PosesInFrameChannel("/agents/poses", context=context),
        "/markers": channels.SceneUpdateChannel("/markers", context=context),
    }
    return context, Served(server, gate), made


#: how long closing the live view waits for its server to stop: the SDK's stop() waits for every
#: client's close handshake, which a client that never reads never completes (the run's results
#: are written after the views close, so a stalled stop() would keep them from being written)
STOP_WAIT_S = 2.0


def stop(server: Any, wait: float = STOP_WAIT_S) -> None:
    """Stop ``server`` and wait at most ``wait`` seconds; past that it goes on stopping in a daemon
    thread while the run ends."""
    import threading

    stopper = threading.Thread(target=server.stop, name="foxglove-stop", daemon=True)
    stopper.start()
    stopper.join(wait)


class FoxgloveLive(TickHook):
    """Serves ``world``'s run on ``host:port`` (port 0: a free one, then :attr:`port`) until it ends."""

    def __init__(
        self,
        world: World,
        dt: float,
        port: int = DEFAULT_PORT,
        host: str = "127.0.0.1",
        walls: list[tuple[tuple[float, float], tuple[float, float]]] | None = None,
        served: tuple[Any, Served, dict[str, Any]] | None = None,
    ) -> None:
        """``served``: a server :func:`serve` started already (the command binds its port before it
        makes the output folder); else one is started on ``host:port``."""
        from foxglove import channels

        self.world, self.dt = world, dt
        self.context, self.server, made = served or serve(host, port)
        self.port, self.url = self.server.port, self.server.url
        self.agents, self.poses, self.markers = made["/agents"], made["/agents/poses"], made["/markers"]
        self.radio = channels.SceneUpdateChannel("/radio", context=self.context)
        self.walls = list(walls or [])
        self.walls_channel = channels.SceneUpdateChannel("/walls", context=self.context) if self.walls else None
        self.shown: dict[int, tuple[float, float, str]] = {}  # the markers on the map as last sent
        self.size = 1.0

    def exchange_starts(
        self, k: int, sample: WorldSample, observed: Mapping[int, Observation], inboxes: Mapping[int, bytes]
    ) -> None:
        from foxglove.messages import PosesInFrame, SceneUpdate

        stamp, log_time = _stamp(k, self.dt), EPOCH_NS + round(k * self.dt * 1e9)
        labels = self.world.agent_labels()
        rows = pd.DataFrame(
            {
                "agent": sample.ids,
                "x": sample.xs,
                "y": sample.ys,
                "heading": [float(observed[i].heading) if i in observed else 0.0 for i in sample.ids],
                "label": [labels.get(i, "") for i in sample.ids],
            }
        )
        if k == 0 and len(rows):
            span = max(float(rows["x"].max() - rows["x"].min()), float(rows["y"].max() - rows["y"].min()), 1.0)
            self.size = span / 100
        entities, poses = _agent_entities(rows, stamp, self.size)
        self.agents.log(SceneUpdate(entities=entities), log_time=log_time)
        self.poses.log(PosesInFrame(timestamp=stamp, frame_id=FRAME, poses=poses), log_time=log_time)
        self._markers(stamp, log_time)
        if self.walls_channel is not None and k % WALLS_EVERY == 0:
            self.walls_channel.log(_walls_update(self.walls, stamp), log_time=log_time)
        where = dict(zip(sample.ids, zip(sample.xs, sample.ys)))
        copies = [(d.sender, r, "delivered") for r, data in inboxes.items() for d in delivered_in(data)]
        if copies:
            table = pd.DataFrame(copies, columns=["sender", "receiver", "outcome"])
            self.radio.log(_radio_update(table, where, stamp, self.dt), log_time=log_time)

    def _markers(self, stamp: Any, log_time: int) -> None:
        now = self.world.markers()
        changes = [(m, *now[m], "appear") for m in sorted(now) if self.shown.get(m) != now[m]]
        changes += [(m, 0.0, 0.0, "", "vanish") for m in sorted(self.shown.keys() - now.keys())]
        self.shown = dict(now)
        if changes:
            table = pd.DataFrame(changes, columns=["marker", "x", "y", "label", "event"])
            self.markers.log(_marker_update(table, stamp, self.size), log_time=log_time)

    def run_ends(self) -> None:
        self.close()

    def close(self) -> None:
        stop(self.server)


class StatusFoxglove:
    """``swarmbed watch --foxglove``: a running run's progress samples, served to Foxglove."""

    def __init__(self, port: int = DEFAULT_PORT, host: str = "127.0.0.1", max_clients: int = MAX_CLIENTS) -> None:
        self.context, self.server, made = serve(host, port, max_clients)
        self.port, self.url = self.server.port, self.server.url
        self.agents, self.poses, self.markers = made["/agents"], made["/agents/poses"], made["/markers"]
        self.last_tick = -2
        self.where: dict[int, tuple[float, float]] = {}  # each agent's position in the last sample
        self.heading: dict[int, float] = {}
        self.size = 0.0

    def show(self, status: RunStatus) -> None:
        """Log ``status`` if it is a tick not shown yet."""
        from foxglove.messages import (
            CubePrimitive,
            Pose,
            PosesInFrame,
            Quaternion,
            SceneEntity,
            SceneUpdate,
            Vector3,
        )

        if status.tick <= self.last_tick:
            return
        self.last_tick = status.tick
        stamp = _stamp(1, status.time)
        log_time = EPOCH_NS + round(status.time * 1e9)
        for agent, x, y in status.positions:  # heading: the direction it moved since the last sample
            before = self.where.get(agent)
            if before is not None and (x, y) != before:
                self.heading[agent] = math.atan2(y - before[1], x - before[0])
            self.where[agent] = (x, y)
        rows = pd.DataFrame(
            {
                "agent": [a for a, _, _ in status.positions],
                "x": [x for _, x, _ in status.positions],
                "y": [y for _, _, y in status.positions],
                "heading": [self.heading.get(a, 0.0) for a, _, _ in status.positions],
                "label": [status.labels.get(a, "") for a, _, _ in status.positions],
            }
        )
        if not self.size and len(rows):
            span = max(float(rows["x"].max() - rows["x"].min()), float(rows["y"].max() - rows["y"].min()), 1.0)
            self.size = span / 100
        entities, poses = _agent_entities(rows, stamp, self.size or 1.0)
        self.agents.log(SceneUpdate(entities=entities), log_time=log_time)
        self.poses.log(PosesInFrame(timestamp=stamp, frame_id=FRAME, poses=poses), log_time=log_time)
        size = self.size or 1.0
        cubes = [
            CubePrimitive(
                pose=Pose(position=Vector3(x=x, y=y, z=0.0), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                size=Vector3(x=size, y=size, z=size),
                color=_rgba(LABEL_COLORS.get(label, "#999999")),
            )
            for x, y, label in status.markers
        ]
        entity = SceneEntity(timestamp=stamp, frame_id=FRAME, id="markers", cubes=cubes)
        self.markers.log(SceneUpdate(entities=[entity]), log_time=log_time)

    def close(self) -> None:
        stop(self.server)
