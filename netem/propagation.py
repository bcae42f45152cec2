"""Propagation and reception: what power a copy arrives with, and whether it is received.

Received power of a copy from i to j at distance d (dBm)::

    P_rx = P_tx - PL(d) - S_ij + 10 log10(g_ij)
    PL(d) = PL0 + 10 n log10(max(d, d0) / d0)            log-distance path loss (ns-3's model)

``S_ij`` is log-normal shadowing in dB, the same for both directions of a pair, correlated over the
distance the pair moves (Gudmundson 1991): each tick, with m_i and m_j the distances the two agents
moved since the last tick, ``S <- rho S + sigma sqrt(1 - rho^2) W`` with ``rho = exp(-(m_i + m_j) /
decorrelation_distance)`` and W standard normal: a stationary AR(1) process with variance sigma^2,
so a link that does not move keeps its shadowing and one that moves far forgets it. ``g_ij`` is the
power gain of block fading (mean 1): exponential for Rayleigh, Gamma(m, 1/m) for Nakagami-m, drawn
anew every ``coherence_time`` seconds (every tick when 0).

A copy below ``sensitivity_dbm`` is never detected (``below_sensitivity``). With ``reception: per``
a detected copy of b bits (payload plus ``overhead_bytes``, times 8) survives with probability
``(1 - BER)^b`` over an AWGN channel, with ``SNR = P_rx - noise_floor_dbm`` as a power ratio:
BPSK ``BER = Q(sqrt(2 SNR)) = erfc(sqrt(SNR)) / 2``, QPSK (Gray-coded) ``BER = Q(sqrt(SNR))``
(Proakis, Digital Communications, 5th ed., 4.3; SNR taken as Eb/N0 per symbol of one bit for BPSK
and two for QPSK); a copy that loses the draw is ``packet_error``.

Random numbers, each from its own stream so that one model never shifts another's draws: shadowing
(its initial values, then one normal per pair i < j per tick, pairs in row-major order), fading
(one gain per pair i < j per block, row-major), reception (one uniform per detected copy, in copy
order: messages in sender order, then receivers in id order).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from swarmbed.netem.normal import erfc
from swarmbed.netem.stage import Stage, TickCopies
from swarmbed.netem.walls import wall_loss_db
from swarmbed.schema.radio_sections import PropagationSection

if TYPE_CHECKING:
    from swarmbed.netem.radio import Radio

BELOW_SENSITIVITY, PACKET_ERROR = "below_sensitivity", "packet_error"


def path_loss_db(p: PropagationSection, d: np.ndarray) -> np.ndarray:
    return p.reference_loss_db + 10.0 * p.exponent * np.log10(
        np.maximum(d, p.reference_distance) / p.reference_distance
    )


def bit_error_rate(p: PropagationSection, snr_db: np.ndarray) -> np.ndarray:
    snr = np.power(10.0, np.asarray(snr_db, dtype=float) / 10.0)
    per_bit = snr if p.modulation == "bpsk" else snr / 2.0
    return 0.5 * erfc(np.sqrt(per_bit))


def delivery_probability(
    p: PropagationSection, d: np.ndarray, payload_bytes: float, nodes: int = 64, wall_loss_db: float | np.ndarray = 0.0
) -> np.ndarray:
    """The probability that a copy of ``payload_bytes`` is received at distance ``d`` behind walls
    that cost ``wall_loss_db`` (per distance, or one figure): the formula the drawn copies follow,
    averaged over shadowing (Gauss-Hermite quadrature over the normal in dB) and fading (the gain's
    quantiles at ``nodes`` midpoints). Propagation alone: a disk, independent or burst loss and the
    shared channel multiply or cap it (what a report's model curve shows)."""
    d = np.asarray(d, dtype=float)
    if p.shadowing_db > 0:
        z, w = np.polynomial.hermite_e.hermegauss(nodes)
        shadows, shadow_weights = p.shadowing_db * z, w / w.sum()
    else:
        shadows, shadow_weights = np.zeros(1), np.ones(1)
    if p.fading != "none":
        from scipy import stats  # the report's curve only: the proxy never asks for it

        m = 1.0 if p.fading == "rayleigh" else p.nakagami_m
        gains = stats.gamma.ppf((np.arange(nodes) + 0.5) / nodes, a=m, scale=1 / m)
        fades, fade_weights = 10 * np.log10(gains), np.full(nodes, 1 / nodes)
    else:
        fades, fade_weights = np.zeros(1), np.ones(1)
    mean_dbm = p.tx_power_dbm - path_loss_db(p, d) - np.broadcast_to(np.asarray(wall_loss_db, dtype=float), d.shape)
    power = mean_dbm[:, None, None] - shadows[None, :, None] + fades[None, None, :]
    received = (power >= p.sensitivity_dbm).astype(float)
    if p.reception == "per":
        bits = 8.0 * (payload_bytes + p.overhead_bytes)
        ber = bit_error_rate(p, power - p.noise_floor_dbm)
        received *= np.exp(bits * np.log1p(-np.minimum(ber, 0.5)))
    return np.einsum("dsf,s,f->d", received, shadow_weights, fade_weights)


class Propagation:
    """The state of every pair's shadowing and fading, and the reception of a tick's copies."""

    def __init__(
        self,
        p: PropagationSection,
        n_agents: int,
        dt: float,
        shadowing_rng: np.random.Generator,
        fading_rng: np.random.Generator,
        reception_rng: np.random.Generator,
    ) -> None:
        self.p = p
        self.n = n_agents
        self.dt = dt
        self.shadowing_rng = shadowing_rng
        self.fading_rng = fading_rng
        self.reception_rng = reception_rng
        self.upper = np.triu_indices(n_agents, 1)  # pairs i < j in row-major order
        self.last_x = np.full(n_agents, np.nan)
        self.last_y = np.full(n_agents, np.nan)
        self.shadow: np.ndarray | None = None
        if p.shadowing_db > 0:
            self.shadow = np.zeros((n_agents, n_agents))
            self._set_pairs(self.shadow, p.shadowing_db * shadowing_rng.standard_normal(len(self.upper[0])))
        self.fade_db: np.ndarray | None = np.zeros((n_agents, n_agents)) if p.fading != "none" else None
        self.block = -1
        self.block_ticks = max(1, math.ceil(p.coherence_time / dt - 1e-9)) if p.coherence_time > 0 else 1

    def _set_pairs(self, matrix: np.ndarray, values: np.ndarray) -> None:
        i, j = self.upper
        matrix[i, j] = values
        matrix[j, i] = values

    def advance(self, tick: int, ids: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
        """Once per tick, with every live agent's position: shadowing follows what moved, and a new
        fading block begins when one is due. The number of draws never depends on the traffic."""
        moved = np.zeros(self.n)
        seen = ~np.isnan(self.last_x[ids])
        moved[ids[seen]] = np.hypot(x[seen] - self.last_x[ids[seen]], y[seen] - self.last_y[ids[seen]])
        self.last_x[ids], self.last_y[ids] = x, y
        if self.shadow is not None:
            i, j = self.upper
            rho = np.exp(-(moved[i] + moved[j]) / self.p.decorrelation_distance)
            innovation = self.shadowing_rng.standard_normal(len(i))
            self._set_pairs(
                self.shadow, rho * self.shadow[i, j] + self.p.shadowing_db * np.sqrt(1.0 - rho * rho) * innovation
            )
        if self.fade_db is not None and tick // self.block_ticks != self.block:
            self.block = tick // self.block_ticks
            pairs = len(self.upper[0])
            if self.p.fading == "rayleigh":
                gain = self.fading_rng.exponential(1.0, pairs)
            else:
                m = self.p.nakagami_m
                gain = self.fading_rng.gamma(m, 1.0 / m, pairs)
            self._set_pairs(self.fade_db, 10.0 * np.log10(np.maximum(gain, 1e-300)))

    def received_dbm(self, senders: np.ndarray, receivers: np.ndarray, d: np.ndarray) -> np.ndarray:
        """The power each copy arrives with (ids of senders and receivers, their distances)."""
        power = self.p.tx_power_dbm - path_loss_db(self.p, d)
        if self.shadow is not None:
            power -= self.shadow[senders, receivers]
        if self.fade_db is not None:
            power += self.fade_db[senders, receivers]
        return power

    def detected(self, power_dbm: np.ndarray) -> np.ndarray:
        """Which copies arrive at or above the sensitivity (the others: ``below_sensitivity``)."""
        return power_dbm >= self.p.sensitivity_dbm

    def errors(self, power_dbm: np.ndarray, payload_bytes: np.ndarray) -> np.ndarray:
        """Which detected copies a bit error spoils (``reception: per``; none with ``threshold``)."""
        if self.p.reception != "per":
            return np.zeros(len(power_dbm), dtype=bool)
        bits = 8.0 * (payload_bytes + self.p.overhead_bytes)
        ber = bit_error_rate(self.p, power_dbm - self.p.noise_floor_dbm)
        survive = np.exp(bits * np.log1p(-np.minimum(ber, 0.5)))
        return self.reception_rng.random(len(power_dbm)) >= survive


def _below_sensitivity(radio: Radio, copies: TickCopies, at: np.ndarray) -> np.ndarray:
    """Computes the received power of the copies in play (kept in ``copies.power`` for the error
    stage and the receiver ledger) and drops those under the sensitivity."""
    model = radio.propagation
    assert model is not None
    copies.power = np.full(len(copies.rows), np.nan)
    copies.power[at] = model.received_dbm(copies.senders[at], copies.receivers[at], copies.distance[at])
    if radio.walls is not None:
        copies.power[at] -= wall_loss_db(radio, copies, at)
    return ~model.detected(copies.power[at])


def _packet_error(radio: Radio, copies: TickCopies, at: np.ndarray) -> np.ndarray:
    assert radio.propagation is not None and copies.power is not None
    return radio.propagation.errors(copies.power[at], copies.sizes[at])


SENSITIVITY_STAGE = Stage(BELOW_SENSITIVITY, "#e377c2", lambda p: p.propagation is not None, _below_sensitivity)
ERROR_STAGE = Stage(PACKET_ERROR, "#f781bf", lambda p: p.propagation is not None, _packet_error)
