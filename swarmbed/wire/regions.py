"""Which netem proxy of a radio split over regions owns each agent (``radio_split``,
docs/machines.md), as the hub, the proxies and the in-process engine all compute it, from the
agents' x in the world sample of the tick.

``bands`` (the default): the agents ranked by x (ties by their order in the sample, which is by
id), proxy j owns ranks ``j N / K`` up to ``(j + 1) N / K``: K bands across x holding an equal
share of the agents however they crowd. ``strips``: the agent at x is in strip
``floor(x / strip_width)``, owned by proxy ``strip mod K``.
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
    def regions(self) -> str: ...

    @property
    def strip_width(self) -> float: ...


class Network(Protocol):
    """What of ``network`` decides whether the proxies read by region: its rate cap."""

    @property
    def rate(self) -> float | None: ...


def owners(xs: Sequence[float] | np.ndarray, split: RadioSplit) -> np.ndarray:
    """The proxy that owns each agent at positions ``xs``."""
    x = np.asarray(xs, dtype=float)
    if split.regions == "strips":
        return np.floor(x / split.strip_width).astype(np.int64) % split.shards
    rank = np.empty(len(x), dtype=np.int64)
    rank[np.argsort(x, kind="stable")] = np.arange(len(x))
    return rank * split.shards // max(len(x), 1)


def by_region(split: RadioSplit, network: Network) -> bool:
    """Whether each proxy of the split reads only the outputs of the agents it owns at the tick.
    Not with a rate cap: a sender's transmit queue then spans ticks, and every proxy keeps every
    sender's (so that it moves with its sender for free) from every output."""
    return split.shards > 1 and network.rate is None
