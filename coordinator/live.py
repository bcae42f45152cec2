"""What a monitor sees of a running run: in the launcher's process (a soak's sampler, chaos), a
:class:`LiveStatus`; anywhere on the run's network (``swarmbed watch``), the progress sample
:func:`progress_sample` builds.

Monitors run in their own threads beside the tick loop. They do not read the coordinator's
attributes (which the loop changes mid-tick); the coordinator publishes a :class:`LiveStatus`, an
immutable record of the run between two ticks, after every tick while a monitor is attached
(:meth:`~swarmbed.coordinator.zenoh_transport.ZenohTransport.live`), and nothing when none is, so a run
without monitors pays nothing. Wall-clock figures of the interval between two of a soak's samples
(the slowest tick, the latest start) are taken, and reset, with
:meth:`~swarmbed.coordinator.zenoh_transport.ZenohTransport.take_interval`.

Everything here is a wall-clock fact of one run on one machine: never part of a run's result files.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np
from pydantic import ValidationError

from swarmbed.coordinator.lifecycle import AgentLifecycle
from swarmbed.engine.hooks import TickHook
from swarmbed.engine.recorder import Recorder
from swarmbed.extension.scenario import World
from swarmbed.schema.experiment import Experiment
from swarmbed.wire.control import RestartRecord
from swarmbed.wire.run_status import NetworkCounters, RunStatus, encode_status

if TYPE_CHECKING:
    from swarmbed.coordinator.clock import WallClock

log = logging.getLogger("swarmbed.coordinator")
STATUS_EVERY = 0.25  # wall seconds between progress samples for watchers


def _frozen(mapping: Mapping) -> Mapping:
    return MappingProxyType(dict(mapping))


@dataclass(frozen=True)
class LiveStatus:
    """The run after its last tick stepped (``tick`` -1 before the first)."""

    tick: int
    time: float  # simulated seconds
    network: tuple[int, ...]  # messages sent, bytes sent, copies, delivered, dropped: so far
    drops: Mapping[str, int]  # copies dropped so far, by reason
    alive: frozenset[int]  # agents alive in the world
    down: frozenset[int]  # agents whose process was found dead and is being restarted
    lost: Mapping[int, int]  # agent -> tick it was lost
    incarnation: Mapping[int, int]  # agent -> its current process, where not the first (0)
    hosts: Mapping[int, str]  # agent -> the host it runs on, where not this machine
    restarts: tuple[RestartRecord, ...]  # the restart log so far (restarts.csv's rows)
    late_ticks: Mapping[int, int] = field(default_factory=dict)  # agent -> ticks it missed (real-time)
    slowest_tick: tuple[float, int] = (0.0, -1)  # (wall seconds, tick): the longest a tick took, start to start

    @property
    def restarts_ok(self) -> int:
        return sum(r.outcome == "ok" for r in self.restarts)

    @staticmethod
    def of(
        tick: int,
        time: float,
        network: list[int],
        drops: Mapping[str, int],
        alive: frozenset[int],
        agents: AgentLifecycle,
        late_ticks: Mapping[int, int],
        slowest_tick: tuple[float, int],
    ) -> LiveStatus:
        """A status from the run's parts, each copied (a restart record is complete once the tick
        that made it is over, and never changed after: the records themselves are shared)."""
        return LiveStatus(
            tick,
            time,
            tuple(network),
            _frozen(drops),
            alive,
            frozenset(agents.down),
            _frozen(agents.lost),
            _frozen(agents.incarnation),
            _frozen(agents.hosts),
            tuple(agents.restart_log),
            _frozen(late_ticks),
            slowest_tick,
        )


@dataclass(frozen=True)
class Interval:
    """Wall-clock figures since the last :meth:`take_interval`: the longest a tick took from start
    to start, and the latest a tick started after its time (real-time clock; None otherwise)."""

    slowest_tick_s: float
    latest_start_s: float | None


def progress_sample(
    exp: Experiment, w: World, recorder: Recorder, tick: int, late_ticks: Mapping[int, int], wall_s: float
) -> RunStatus:
    """Where the run is after ``tick``, for ``swarmbed watch``."""
    net = recorder.net_cum
    return RunStatus(
        name=exp.name,
        scenario=exp.scenario.kind,
        allocator=exp.allocator.name,
        tick=tick,
        time=w.time,
        ticks=exp.ticks,
        wall_s=wall_s,
        row=w.row(),
        network=NetworkCounters(
            messages_sent=net[0], bytes_sent=net[1], copies=net[2], delivered=net[3], dropped=net[4]
        ),
        drops=recorder.drops_cum,
        alive=[int(a) for a in np.flatnonzero(w.alive)],
        late_ticks=sum(late_ticks.values()),
        positions=list(zip(*w.positions())),
        labels=dict(w.agent_labels()),
        markers=list(w.markers().values()),
    )


class Watched(TickHook):
    """What the coordinator shows of the run as it goes, a hook of the tick loop: a progress sample
    for ``swarmbed watch`` every ``STATUS_EVERY`` wall seconds (handed to ``put_status``), and, once
    a monitor in this process asked for one (:meth:`live`), a :class:`LiveStatus` after every tick."""

    def __init__(
        self,
        exp: Experiment,
        world: World,
        recorder: Recorder,
        agents: AgentLifecycle,
        clock: WallClock,
        put_status: Callable[[bytes], None],
    ) -> None:
        self.exp, self.world, self.recorder, self.agents, self.clock = exp, world, recorder, agents, clock
        self.put_status = put_status
        self.refused = False  # a progress sample failed its model (logged once)
        self._live: LiveStatus | None = None
        self._status_at = 0.0  # perf_counter at the last progress sample
        self.last_tick = -1

    def live(self, tick: int) -> LiveStatus:
        """The run as of ``tick``, the last one stepped; from the first call on, one is made after
        every tick (a run nobody monitors builds none)."""
        if self._live is None:
            self._make_live(tick)
        assert self._live is not None
        return self._live

    def tick_done(self, k: int, admitted: Mapping[int, list]) -> None:
        self.last_tick = k
        if self.after_tick(k):
            self.recorder.flush()

    def run_ends(self) -> None:
        self.final(self.last_tick)

    def after_tick(self, tick: int) -> bool:
        """Tick ``tick`` is over: the live status if asked for, a progress sample if one is due.
        Returns whether a sample went out (the recorder flushes with it)."""
        if self._live is not None:
            self._make_live(tick)
        if time.perf_counter() - self._status_at < STATUS_EVERY:
            return False
        self.status(tick)
        return True

    def final(self, tick: int) -> None:
        """The ticks are over: the last progress sample and live status."""
        self.status(tick)
        if self._live is not None:
            self._make_live(tick)

    def status(self, tick: int) -> None:
        """Where the run is, for ``swarmbed watch`` (wall-clock paced: never part of the results)."""
        self._status_at = time.perf_counter()
        try:
            sample = progress_sample(
                self.exp, self.world, self.recorder, tick, self.clock.late_ticks, self.clock.elapsed()
            )
        except ValidationError as exc:  # a scenario's row of another shape: the run goes on, unwatched
            if not self.refused:
                log.warning("coordinator: progress sample not published (%s)", str(exc).splitlines()[0])
            self.refused = True
            return
        self.put_status(encode_status(sample))

    def _make_live(self, tick: int) -> None:
        alive = frozenset(int(a) for a in np.flatnonzero(self.world.alive))
        r, c = self.recorder, self.clock
        self._live = LiveStatus.of(
            tick, self.world.time, r.net_cum, r.drops_cum, alive, self.agents, c.late_ticks, c.slowest_tick
        )
