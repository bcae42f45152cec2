"""Gilbert-Elliott burst loss: a two-state Markov chain per link (sender, receiver) or per receiver.

In the good state a copy is lost with probability ``loss_good`` (tc-netem's 1-k), in the bad state
with ``loss_bad`` (1-h). The stationary share of the bad state is pi_B = p / (p + r) and the mean
loss ``pi_G loss_good + pi_B loss_bad``; a stay in the bad state lasts 1/r steps on average.

``advance: time`` (the default) steps every chain once per tick, whether its link carried anything
or not, with the per-tick probabilities of a continuous-time chain whose mean sojourns are the
configured seconds (``1 - exp(-dt / T)``): a burst lasts as long in seconds for a chatty allocator
as for a quiet one. A copy's loss is drawn from its link's state at its tick. ``advance: packet``
steps a link's chain once per copy on it, as tc-netem's ``gemodel`` does per packet: the copy is
lost with the probability of the state the link is in, then the link moves (the kernel's order).

Random numbers come from the model's own stream: the initial states (one uniform per chain,
stationary start, row-major), then per tick (time) one uniform per chain, row-major, and one per
copy in play, in copy order; with ``advance: packet`` two uniforms per copy (transition, loss),
drawn in rounds: every link's first copy of the tick in copy order, then every link's second, and
so on (a link's own copies stay in order, and the rounds keep the work vectorised).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from swarmbed.netem.stage import Stage, TickCopies
from swarmbed.schema.radio_sections import BurstSection

if TYPE_CHECKING:
    from swarmbed.netem.radio import Radio

BURST = "burst"


def occurrence(keys: np.ndarray) -> np.ndarray:
    """For each element, how many earlier elements share its key (0 for the first)."""
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    starts = np.r_[0, np.flatnonzero(sorted_keys[1:] != sorted_keys[:-1]) + 1]
    run = np.zeros(len(keys), dtype=np.int64)
    if len(keys):
        first = np.zeros(len(keys), dtype=np.int64)
        first[starts] = starts
        first = np.maximum.accumulate(first)
        run[order] = np.arange(len(keys)) - first
    return run


class Bursts:
    def __init__(self, b: BurstSection, n_agents: int, dt: float, rng: np.random.Generator) -> None:
        self.b = b
        self.n = n_agents
        self.rng = rng
        self.p_gb, self.p_bg = b.step_probabilities(dt)
        shape = (n_agents, n_agents) if b.per == "link" else (n_agents,)
        self.bad = rng.random(shape) < b.bad_share()  # stationary start

    def advance(self) -> None:
        """One tick (``advance: time`` only)."""
        if self.b.advance != "time":
            return
        u = self.rng.random(self.bad.shape)
        self.bad = np.where(self.bad, u >= self.p_bg, u < self.p_gb)

    def lose(self, senders: np.ndarray, receivers: np.ndarray) -> np.ndarray:
        """Which of these copies (ids, in copy order) the chains lose."""
        link = receivers if self.b.per == "receiver" else senders * self.n + receivers
        flat = self.bad.reshape(-1)
        if self.b.advance == "time":
            p_loss = np.where(flat[link], self.b.loss_bad, self.b.loss_good)
            return self.rng.random(len(link)) < p_loss
        lost = np.zeros(len(link), dtype=bool)
        nth = occurrence(link)
        for k in range(int(nth.max()) + 1 if len(link) else 0):  # a link's copies in turn, all links at once
            rows = np.flatnonzero(nth == k)
            u = self.rng.random((len(rows), 2))  # per copy: transition, then loss
            state = flat[link[rows]]
            lost[rows] = u[:, 1] < np.where(state, self.b.loss_bad, self.b.loss_good)
            flat[link[rows]] = np.where(state, u[:, 0] >= self.p_bg, u[:, 0] < self.p_gb)
        return lost


def _burst(radio: Radio, copies: TickCopies, at: np.ndarray) -> np.ndarray:
    assert radio.bursts is not None
    return radio.bursts.lose(copies.senders[at], copies.receivers[at])


BURST_STAGE = Stage(BURST, "#1f3b73", lambda p: p.burst is not None, _burst)
