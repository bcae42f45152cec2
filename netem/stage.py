"""A drop stage of the radio: one reason a copy may be dropped for, decided for all of a tick's
copies still in play at once (:data:`swarmbed.netem.radio.STAGES` lists them in order)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from swarmbed.schema.radio_sections import NetworkSection

if TYPE_CHECKING:
    from swarmbed.netem.radio import Radio

EPS = 1e-9  # distances and times within this are equal


class TickCopies:
    """Every copy of a tick's messages (one per intended receiver that is alive and addressed), in
    copy order: messages in sender order, then receivers in id order. What the stages read; the
    distance and sizes are computed the first time a stage asks for them."""

    def __init__(
        self,
        tick: int,
        alive: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        rows: np.ndarray,
        from_rows: np.ndarray,
        sends: Sequence[Any],
        counts: np.ndarray,
    ) -> None:
        self.tick = tick
        self.alive, self.x, self.y = alive, x, y  # alive ids, sorted, and their positions
        self.rows, self.from_rows = rows, from_rows  # each copy's receiver and sender, as rows of alive
        self._sends, self._counts = sends, counts
        self.power: np.ndarray | None = None  # received dBm, set by the sensitivity stage (NaN: not reached)
        self.wall_loss: np.ndarray | None = None  # dB lost to walls, where the walls were asked (NaN: not yet)
        self.crossed: np.ndarray | None = None  # whether the copy's straight path crosses a wall (with wall_loss)

    @property
    def receivers(self) -> np.ndarray:
        return self.alive[self.rows]

    @property
    def senders(self) -> np.ndarray:
        return self.alive[self.from_rows]

    @cached_property
    def distance(self) -> np.ndarray:
        f, r = self.from_rows, self.rows
        return np.hypot(self.x[f] - self.x[r], self.y[f] - self.y[r])

    @cached_property
    def seqs(self) -> np.ndarray:
        """Each copy's message's place among its sender's messages of the tick."""
        per_message = np.fromiter((s.seq for s in self._sends), dtype=np.int64, count=len(self._sends))
        return np.repeat(per_message, self._counts)

    @cached_property
    def sizes(self) -> np.ndarray:
        """Each copy's payload size in bytes."""
        per_message = np.fromiter((len(s.msg.payload) for s in self._sends), dtype=np.int64, count=len(self._sends))
        return np.repeat(per_message, self._counts)


@dataclass(frozen=True)
class Stage:
    """``drop(radio, copies, at)``: which of the copies ``at`` (indices of the copies still in play)
    this stage drops, as a boolean array over ``at``; ``on(network)``: whether a run's
    ``network:`` section turns the stage on; ``colour``: the reason's colour in every view."""

    reason: str
    colour: str
    on: Callable[[NetworkSection], bool]
    drop: Callable[[Radio, TickCopies, np.ndarray], np.ndarray]
