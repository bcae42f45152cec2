"""A shared channel: the airtime a receiver has per tick, shared by the transmissions it hears.

Without it every copy is decided on its own, and 50 robots in range each get the full ``rate``.
With ``network.channel: {capacity: C}`` a receiver hears at most C x dt bytes per tick: the copies
addressed to it that were detected (in range, and above the sensitivity with a propagation model)
take its airtime in copy order (messages in sender id order, then in the order each sender sent
them) until the tick's budget is spent; the copy that would overrun it and every later one are
dropped as ``channel_busy``. A copy lost afterwards to a bit error, a burst or independent loss
still used its airtime. Unused airtime is not carried to the next tick.

What it does not model: no carrier sensing or backoff, no MAC retries, no capture effect, no
interference between simultaneous transmissions, and no airtime taken at a receiver by unicast
traffic between two other robots (only copies addressed to the receiver count; a broadcast is
addressed to everyone).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from swarmbed.netem.stage import EPS as _EPS
from swarmbed.netem.stage import Stage, TickCopies
from swarmbed.schema.radio_sections import ChannelSection

if TYPE_CHECKING:
    from swarmbed.netem.radio import Radio

CHANNEL_BUSY = "channel_busy"


class SharedChannel:
    def __init__(self, c: ChannelSection, dt: float) -> None:
        self.budget = c.capacity * dt  # bytes a receiver hears per tick

    def busy(self, receivers: np.ndarray, sizes: np.ndarray) -> np.ndarray:
        """Which of these copies (receiver ids and payload sizes, in copy order) find the channel busy."""
        if not len(receivers):
            return np.zeros(0, dtype=bool)
        order = np.argsort(receivers, kind="stable")  # each receiver's copies, still in copy order
        ranked, used = receivers[order], np.cumsum(sizes[order])
        first = np.r_[0, np.flatnonzero(ranked[1:] != ranked[:-1]) + 1]
        before = np.repeat(np.r_[0, used[first[1:] - 1]], np.diff(np.r_[first, len(ranked)]))
        busy = np.empty(len(receivers), dtype=bool)
        busy[order] = used - before > self.budget + _EPS
        return busy


def _channel_busy(radio: Radio, copies: TickCopies, at: np.ndarray) -> np.ndarray:
    assert radio.channel is not None
    return radio.channel.busy(copies.receivers[at], copies.sizes[at])


CHANNEL_STAGE = Stage(CHANNEL_BUSY, "#98df8a", lambda p: p.channel is not None, _channel_busy)
