"""Which netem proxy of a radio split over regions owns each agent (``radio_split``,
docs/machines.md), as the hub, the proxies and the in-process engine all compute it.

Regions are strips of ``strip_width`` across x, dealt to the proxies in turn: the agent at x is in
strip ``floor(x / strip_width)``, owned by proxy ``strip mod K``, from the world sample of the tick.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np


class RadioSplit(Protocol):
    """What of ``radio_split`` (``swarmbed.schema.experiment.RadioSplit``) decides the owners."""

    @property
    def shards(self) -> int: ...

    @property
    def strip_width(self) -> float: ...


class Network(Protocol):
    """What of ``network`` decides whether the proxies read by region: its rate cap."""

    @property
    def rate(self) -> float | None: ...


def owners(xs: Sequence[float] | np.ndarray, split: RadioSplit) -> np.ndarray:
    """The proxy that owns each agent at positions ``xs``."""
    strips = np.floor(np.asarray(xs, dtype=float) / split.strip_width).astype(np.int64)
    return strips % split.shards


def by_region(split: RadioSplit, network: Network) -> bool:
    """Whether each proxy of the split reads only the outputs of the agents it owns at the tick.
    Not with a rate cap: a sender's transmit queue then spans ticks, and every proxy keeps every
    sender's (so that it moves with its sender for free) from every output."""
    return split.shards > 1 and network.rate is None
