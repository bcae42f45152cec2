"""CPU per tick by stage, measured live inside a process (``benchmarks/profile_tick.py``).

Off unless the environment has ``SWARMBED_PROFILE_STAGES=1`` (a run's children inherit it): then a
process keeps a :class:`Stages` and charges the CPU time of the thread that ticks (Linux's
per-thread clock, so other processes' and threads' work never counts) to the stage that used it,
and writes one line of microseconds per tick at the end of its log. Off, the cost is one attribute
test per stage.
"""

from __future__ import annotations

import os
import time
from collections import defaultdict

ENV = "SWARMBED_PROFILE_STAGES"
PREFIX = "stages (thread CPU us per agent-tick): "


def enabled() -> bool:
    return os.environ.get(ENV) == "1"


class Stages:
    """Thread CPU nanoseconds charged to named stages, between marks."""

    def __init__(self) -> None:
        self.ns: defaultdict[str, int] = defaultdict(int)
        self.ticks = 0
        self.idle = 0  # an agent's ticks that repeated the last answer with nothing new (issue 43)
        self.quiet = 0  # the same, tasks in view changed or not
        self._at = time.thread_time_ns()

    def start(self) -> None:
        """The tick begins: what ran before it is not charged to any stage."""
        self._at = time.thread_time_ns()

    def mark(self, stage: str) -> None:
        """Charge the time since the last mark (or start) to ``stage``."""
        now = time.thread_time_ns()
        self.ns[stage] += now - self._at
        self._at = now

    def line(self) -> str:
        """One line: microseconds per counted tick (an agent's tick; the hub and the proxy count one
        per agent they tick) of every stage, in the order they were first charged."""
        ticks = max(self.ticks, 1)
        cells = ", ".join(f"{name} {ns / 1000 / ticks:.1f}" for name, ns in self.ns.items())
        idle = f", {self.idle} idle, {self.quiet} quiet" if self.quiet else ""
        return f"{PREFIX}{cells} (over {self.ticks} ticks{idle})"


def counts(line: str) -> tuple[int, int, int]:
    """(ticks, idle ticks, quiet ticks) of a :meth:`Stages.line`."""
    tail = line.split(" (over ", 1)[1].rstrip(")")
    ticks, _, rest = tail.partition(" ticks")
    if " idle" not in rest:
        return int(ticks), 0, 0
    idle, quiet = (part.split(" ")[0] for part in rest.split(", ")[1:3])
    return int(ticks), int(idle), int(quiet)


def parse(line: str) -> dict[str, float]:
    """The stages of a :meth:`Stages.line`, as {stage: us per tick}."""
    cells = line.split(PREFIX, 1)[1].split(" (over", 1)[0]
    return {name: float(us) for name, us in (cell.rsplit(" ", 1) for cell in cells.split(", "))}
