"""Where each robot's time goes, tick by tick: the time budget of a search-and-rescue run.

Issue 44 asked for it after an audit found robots busy inspecting 97 % of the time in every
strategy: a world where one activity fills the day mutes whatever a strategy does with the rest.
Every live robot's tick is booked to exactly one activity, so the shares sum to one; an
inspection whose victim was gone when it ended (it expired, or another robot rescued it) is booked
to ``inspecting`` and also counted apart, as ``inspecting_lost``.
"""

from __future__ import annotations

import numpy as np

#: the activities a tick is booked to, in the order the summary lists them
ACTIVITIES = ("moving", "inspecting", "rescuing", "penalty", "idle")
MOVING, INSPECTING, RESCUING, PENALTY, IDLE = range(len(ACTIVITIES))


class TimeBudget:
    """Ticks per robot per activity. ``doing(i, a)`` says what robot i does from this tick on (a
    timed action or a move penalty lasts over the ticks it keeps the robot busy); ``book(i)`` books
    this tick to it."""

    def __init__(self, robots: int) -> None:
        self.ticks = np.zeros((len(ACTIVITIES), robots), dtype=np.int64)
        self.activity = np.full(robots, IDLE, dtype=np.int64)
        self.lost = np.zeros(robots, dtype=np.int64)  # ticks of inspections whose victim was gone at their end

    def doing(self, robot: int, activity: int) -> None:
        self.activity[robot] = activity

    def book(self, robot: int) -> None:
        self.ticks[self.activity[robot], robot] += 1

    def inspection_lost(self, robot: int, ticks: int) -> None:
        self.lost[robot] += ticks

    def summary(self, dt: float) -> dict[str, float]:
        """Each activity's share of all live robot time, then the lost inspections' share and the
        robot time itself in seconds."""
        total = int(self.ticks.sum())
        share = {name: round(int(self.ticks[a].sum()) / max(total, 1), 6) for a, name in enumerate(ACTIVITIES)}
        return {
            **share,
            "inspecting_lost": round(int(self.lost.sum()) / max(total, 1), 6),
            "robot_seconds": round(total * dt, 6),
        }
