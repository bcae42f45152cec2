"""``swarmbed run --foxglove [PORT]``: the recording's channels served live while the run goes.

A hook of the engine's tick loop (:class:`~swarmbed.engine.TickHook`) that starts Foxglove's
WebSocket server (its SDK, the one that writes the MCAP recordings) on 127.0.0.1 and logs, at each
tick as the transport carries it, what :mod:`.recording` writes after a run: ``/agents`` and
``/agents/poses`` (each agent with its heading, from its observation), ``/markers`` (tasks or
victims as they appear and vanish) and ``/radio`` (the copies delivered at this tick, as lines
from sender to receiver). Foxglove (or Lichtblick) connects with "Open connection" to
``ws://127.0.0.1:PORT``. Nothing feeds back into the run; a run without it pays nothing.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pandas as pd

from swarmbed.engine.hooks import TickHook
from swarmbed.experiments.views.recording import (
    EPOCH_NS,
    FRAME,
    RecordingError,
    _agent_entities,
    _marker_update,
    _radio_update,
    _stamp,
)
from swarmbed.extension.scenario import World
from swarmbed.wire.codec import WorldSample, delivered_in
from swarmbed.wire.observation import Observation

#: Foxglove's default WebSocket port
DEFAULT_PORT = 8765
TOPICS = ("/agents", "/agents/poses", "/markers", "/radio")


class FoxgloveLive(TickHook):
    """Serves ``world``'s run on ``host:port`` (port 0: a free one, then :attr:`port`) until it ends."""

    def __init__(self, world: World, dt: float, port: int = DEFAULT_PORT, host: str = "127.0.0.1") -> None:
        try:
            import foxglove
            from foxglove import channels
        except ImportError:
            raise RecordingError("a live view needs Foxglove's SDK: pip install 'swarmbed[viewers]'") from None
        self.world, self.dt = world, dt
        self.context = foxglove.Context()
        self.server = foxglove.start_server(name="swarmbed", host=host, port=port, context=self.context)
        self.port = self.server.port
        self.agents = channels.SceneUpdateChannel("/agents", context=self.context)
        self.poses = channels.PosesInFrameChannel("/agents/poses", context=self.context)
        self.markers = channels.SceneUpdateChannel("/markers", context=self.context)
        self.radio = channels.SceneUpdateChannel("/radio", context=self.context)
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
        self.server.stop()
