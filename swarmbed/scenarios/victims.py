"""Where a search-and-rescue world keeps its victims: place, colour, birth time and status, one row
each, in arrays that double when full and drop the rows of victims gone long ago.

Victim ids are given in birth order and never reused; the rows hold ids ``base .. nv-1``. A
steady-state run spawns tens of thousands of victims, so the rows of those whose lifetime ended
long ago leave (see :meth:`VictimRows._at`): always a prefix, because rows are in birth order.
"""

from __future__ import annotations

import numpy as np

ALIVE, RESCUED, EXPIRED, UNUSED = 0, 1, 2, 3


class VictimRows:
    """The victims' arrays and their bookkeeping, for a world class to build on."""

    def _init_victims(self) -> None:
        self.nv = 0  # victims ever spawned: ids 0 .. nv-1
        self.base = 0  # the id of the first row
        self.vx, self.vy, self.vspawn = np.zeros(0), np.zeros(0), np.zeros(0)
        self.vcolor = np.zeros(0, dtype=np.int64)
        self.vstatus = np.zeros(0, dtype=np.int64)

    def _at(self, victim: int) -> int | None:
        """Where ``victim``'s row is in the arrays; None for one that left them.

        A victim leaves once its lifetime ended more than a lifetime ago: every robot forgot it by
        then (a robot drops a victim at the end of the lifetime it saw), so only a plugin that
        names it from memory that old can ask for it, and such an action is stale. Until then it
        stays, with its place and colour, for the robots that still go where it was."""
        return victim - self.base if victim >= self.base else None

    def _forget_born_before(self, keep_after: float) -> None:
        """Drop the rows of the victims born before ``keep_after`` (a prefix: rows are in birth order)."""
        first = int(np.searchsorted(self.vspawn[: self.nv - self.base], keep_after, side="left"))
        if first:
            for name in ("vx", "vy", "vspawn", "vcolor", "vstatus"):
                arr = getattr(self, name)
                arr[: len(arr) - first] = arr[first:]
                arr[len(arr) - first :] = UNUSED if name == "vstatus" else 0
            self.base += first

    def _grow(self, grow: int) -> None:
        self.vx, self.vy, self.vspawn = (np.concatenate([a, np.zeros(grow)]) for a in (self.vx, self.vy, self.vspawn))
        self.vcolor = np.concatenate([self.vcolor, np.zeros(grow, dtype=np.int64)])
        self.vstatus = np.concatenate([self.vstatus, np.full(grow, UNUSED, dtype=np.int64)])

    def _next_row(self, keep_after: float) -> int:
        """The row the next victim goes in: when the arrays are full, the rows of victims born
        before ``keep_after`` leave first, and they double unless a quarter came free."""
        if self.nv - self.base == len(self.vstatus):
            self._forget_born_before(keep_after)
            if self.nv - self.base >= 0.75 * len(self.vstatus):
                self._grow(max(64, len(self.vstatus)))
        return self.nv - self.base

    @property
    def victims_alive(self) -> int:
        return int(np.count_nonzero(self.vstatus == ALIVE))
