"""The coordinator's wall clock: pacing the real-time clock, and what it measured.

Simulated time is the world's; this is the other clock. On the real-time clock tick k starts at
its wall time (``run.dt / run.speed`` seconds per tick) and an agent whose answer misses the
deadline keeps its last command or stops (``run.on_late``). On either clock the time from one
tick's start to the next is watched for soak monitors. Wall-clock facts: never part of a
lock-step run's result files.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from array import array

import numpy as np

from swarmbed.coordinator.live import Interval
from swarmbed.engine.hooks import TickHook
from swarmbed.schema.experiment import RunSection
from swarmbed.wire.codec import NetemStep


class WallClock(TickHook):
    """The run's wall clock, a hook of the tick loop: times every tick and, on the real-time clock,
    paces them (waits for each tick's wall time, counts the agents that missed it)."""

    def __init__(self, run: RunSection) -> None:
        self.run = run
        self.realtime = run.clock == "realtime"
        self.late_ticks: dict[int, int] = {}  # agent -> ticks it missed
        self.start_lags = array("d")  # wall seconds each tick started after its time
        self.last_action: dict[int, list] = {}  # agent -> the command it was last given (on_late: hold)
        self.late_now = 0  # agents late at the tick in hand
        self.t0 = 0.0  # perf_counter when the ticks began
        self.tick_started = 0.0  # perf_counter at the start of the tick under way
        self.slowest_tick = (0.0, -1)  # (wall seconds, tick): the longest a tick took from start to start
        self.slowest_in_interval = 0.0  # the same since a monitor last took it (take_interval)
        self._lags_taken = 0  # start lags a monitor has taken (take_interval)
        self._interval_lock = threading.Lock()

    def start(self) -> None:
        self.t0 = time.perf_counter()

    def run_starts(self) -> None:
        self.start()

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def tick_starts(self, k: int) -> None:
        """Note how long the last tick took; on the real-time clock, wait for tick ``k``'s time."""
        now = time.perf_counter()
        if k:
            took = now - self.tick_started
            with self._interval_lock:
                self.slowest_in_interval = max(self.slowest_in_interval, took)
            if took > self.slowest_tick[0]:
                self.slowest_tick = (took, k - 1)
        self.tick_started = now
        if self.realtime:
            due = self.t0 + k * self.run.dt / self.run.speed
            lag = time.perf_counter() - due
            if lag < 0:
                time.sleep(-lag)
                lag = time.perf_counter() - due
            self.start_lags.append(max(lag, 0.0))

    def answers(self, step: NetemStep) -> NetemStep:
        """Count the agents that missed this tick; with ``run.on_late: hold`` they keep their last
        command (with ``stop``, the world's default for an agent without an action)."""
        self.late_now = len(step.late)
        if step.late:
            for a in step.late:
                self.late_ticks[a] = self.late_ticks.get(a, 0) + 1
            if self.run.on_late == "hold":
                held = {a: self.last_action[a] for a in step.late if a in self.last_action}
                step = dataclasses.replace(step, actions={**held, **step.actions})
        if self.realtime:
            self.last_action.update(step.actions)
        return step

    def row_columns(self) -> list[float]:
        return self.columns()

    def columns(self) -> list[float]:
        """The real-time columns of a time-series row: agents late at this tick, its start lag (ms)."""
        return [self.late_now, round(1000 * self.start_lags[-1], 3)] if self.realtime else []

    def take_interval(self) -> Interval:
        """The slowest tick and the latest start since the last call (a soak's sample interval)."""
        with self._interval_lock:
            slowest, self.slowest_in_interval = self.slowest_in_interval, 0.0
        lags = self.start_lags[self._lags_taken :]
        self._lags_taken += len(lags)
        return Interval(slowest, max(lags) if len(lags) else None)

    def summary(self) -> dict:
        """How well the real-time clock was kept: ticks agents missed, and ticks that started late
        (more than a tenth of a tick's wall period after their time) with the start lag's spread."""
        r = self.run
        lags = np.asarray(self.start_lags) * 1000
        tolerance_ms = 100 * r.dt / r.speed
        spread = [float(v) for v in np.percentile(lags, [50, 99, 100])] if len(lags) else [None] * 3
        return {
            "speed": r.speed,
            "deadline": r.deadline,
            "on_late": r.on_late,
            "late_ticks_total": sum(self.late_ticks.values()),
            "late_ticks": {str(a): n for a, n in sorted(self.late_ticks.items())},
            "ticks_started_late": int((lags > tolerance_ms).sum()),
            "start_lag_ms": dict(zip(("p50", "p99", "max"), spread)),
        }
