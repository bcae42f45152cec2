"""What happens around a lock-step tick, as ordered lists of small handlers.

A run's tick body is :class:`~swarmbed.engine.loop.TickLoop`'s; everything a particular way of
running adds around it (pacing by the wall clock, starting and swapping agent processes, live
status for monitors, ROS 2 topics, profiling, a soak's stop) is a :class:`TickHook` in the list
the loop is given, called in list order at the points below (py_trees' pre- and post-tick
handlers are the model). A hook overrides only the points it needs; the loop calls no point a
hook leaves as it is, so an unused point costs nothing per tick.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping, Sequence

from swarmbed.wire.codec import WorldSample
from swarmbed.wire.observation import Observation
from swarmbed.wire.stages import Stages

#: the points of a tick, in the order the loop reaches them
POINTS = (
    "run_starts",
    "tick_starts",
    "before_world",
    "world_ready",
    "exchange_starts",
    "row_columns",
    "tick_done",
    "should_stop",
    "run_ends",
)


class TickHook:
    """A handler of some of a tick's points; every point does nothing until overridden."""

    def run_starts(self) -> None:
        """The first tick is about to start."""

    def tick_starts(self, k: int) -> None:
        """Tick ``k`` is about to start (a real-time clock waits for its wall time here)."""

    def before_world(self, k: int) -> None:
        """Tick ``k``'s positions are recorded (k > 0); what falls due before its world sample
        (swaps, restarts, checkpoints) happens now."""

    def world_ready(self, sample: WorldSample) -> None:
        """Tick ``k``'s world sample, before the observations are made."""

    def exchange_starts(
        self, k: int, sample: WorldSample, observed: Mapping[int, Observation], inboxes: Mapping[int, bytes]
    ) -> None:
        """The transport is about to carry tick ``k`` (ROS 2 publishes the tick here)."""

    def row_columns(self) -> Sequence[float]:
        """Columns this hook adds to a time-series row (the real-time clock's lateness)."""
        return ()

    def tick_done(self, k: int, admitted: Mapping[int, list]) -> None:
        """Tick ``k`` is applied and recorded (``admitted``: the actions the world took)."""

    def should_stop(self) -> bool:
        """Whether to end the run before the next tick."""
        return False

    def run_ends(self) -> None:
        """The ticks are over (the last one, or the one before a stop)."""


def handlers(hooks: Sequence[TickHook], point: str) -> list[Callable]:
    """The bound handlers of ``point`` of those ``hooks`` that override it, in list order."""
    base = getattr(TickHook, point)
    return [getattr(h, point) for h in hooks if getattr(type(h), point) is not base]


class StopWhenAsked(TickHook):
    """Ends the run after the tick under way once :meth:`ask` was called (from any thread: a
    soak's monitor at the end of its duration)."""

    def __init__(self) -> None:
        self.asked = threading.Event()

    def ask(self) -> None:
        self.asked.set()

    def should_stop(self) -> bool:
        return self.asked.is_set()


class Profile(TickHook):
    """Times the loop's stages of a tick for ``benchmarks/profile_tick.py`` (``SWARMBED_STAGES``):
    a tick starts, its world sample is out; the loop and the transport mark their own stages, and
    the line of totals is logged at the end."""

    def __init__(self, stages: Stages, log: logging.Logger, who: str) -> None:
        self.stages, self.log, self.who = stages, log, who

    def tick_starts(self, k: int) -> None:
        self.stages.start()

    def world_ready(self, sample: WorldSample) -> None:
        self.stages.mark("world")

    def run_ends(self) -> None:
        self.log.info("%s: %s", self.who, self.stages.line())
