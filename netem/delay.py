"""Delay with jitter: seconds added to each copy's arrival, in tc-netem's vocabulary.

A copy's added delay is ``max(0, mean + jitter * X)`` with X a standardised draw of the chosen
distribution: ``normal`` (X = z), ``uniform`` (X = 2 Phi(z) - 1: mean +- jitter), ``pareto`` (a
Pareto of shape 3, (P - 1.5) / sqrt(0.75) with P = (1 - Phi(z))^(-1/3): mean 0, sd 1, a heavy right
tail) and ``paretonormal`` ((0.25 pareto + 0.75 z') / sqrt(0.625), z' a second independent normal).
These shapes are ours in tc-netem's spirit; tc-netem itself reads tables whose exact values differ.

``correlation`` c makes a link's draws an AR(1) process on the normal score z: ``z <- c z +
sqrt(1 - c^2) e``, so consecutive copies on one link see similar delays and the marginal stays the
distribution's (tc-netem's own correlation is known not to keep it). The copy then arrives at the
first tick at or after the end of its transmission plus its delay (never before the next tick),
plus the run's whole-tick ``latency``; copies of one tick may thereby overtake each other.

Random numbers come from the model's own stream: one normal per copy that survived every loss, in
copy order, then for paretonormal a second normal per copy; with correlation the scores are
chained link by link (a link's first copy ever takes its normal as it is).
"""

from __future__ import annotations

import numpy as np

from swarmbed.netem.bursts import occurrence
from swarmbed.netem.normal import normal_cdf
from swarmbed.schema.radio_sections import DelaySection

PARETO_SHAPE = 3.0
_PARETO_MEAN = PARETO_SHAPE / (PARETO_SHAPE - 1)  # scale 1
_PARETO_SD = np.sqrt(PARETO_SHAPE / ((PARETO_SHAPE - 1) ** 2 * (PARETO_SHAPE - 2)))


def standardised(distribution: str, z: np.ndarray, z2: np.ndarray | None = None) -> np.ndarray:
    """X of the distribution from normal scores z (and z2, paretonormal's second normal)."""
    if distribution == "normal":
        return z
    u = normal_cdf(z)
    if distribution == "uniform":
        return 2.0 * u - 1.0
    pareto = (np.power(np.maximum(1.0 - u, 1e-300), -1.0 / PARETO_SHAPE) - _PARETO_MEAN) / _PARETO_SD
    if distribution == "pareto":
        return pareto
    assert z2 is not None
    return (0.25 * pareto + 0.75 * z2) / np.sqrt(0.25**2 + 0.75**2)


class Delays:
    def __init__(self, d: DelaySection, n_agents: int, rng: np.random.Generator) -> None:
        self.d = d
        self.n = n_agents
        self.rng = rng
        correlated = d.correlation > 0
        self.score = np.zeros(n_agents * n_agents) if correlated else None  # last z per link
        self.seen = np.zeros(n_agents * n_agents if correlated else 0, dtype=bool)  # links with a last z

    def draw(self, senders: np.ndarray, receivers: np.ndarray) -> np.ndarray:
        """Added seconds for these copies (ids, in copy order)."""
        d, count = self.d, len(senders)
        if d.jitter == 0:
            return np.full(count, d.mean)
        z = self.rng.standard_normal(count)
        z2 = self.rng.standard_normal(count) if d.distribution == "paretonormal" else None
        if self.score is not None:
            link = senders * self.n + receivers
            nth = occurrence(link)
            c = d.correlation
            for k in range(int(nth.max()) + 1 if count else 0):
                rows = np.flatnonzero(nth == k)
                here = link[rows]
                z[rows] = np.where(self.seen[here], c * self.score[here] + np.sqrt(1 - c * c) * z[rows], z[rows])
                self.score[here] = z[rows]
                self.seen[here] = True
        return np.maximum(0.0, d.mean + d.jitter * standardised(d.distribution, z, z2))
