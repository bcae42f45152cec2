"""The radio's parameters (the ``network:`` section): the disk's, and the models beyond it:
propagation, burst loss, delay and a shared channel.

Each is optional: left out (the default), the radio is today's disk with independent loss, and an
experiment that names none gives the same result files, byte for byte, as before they existed.
The names follow tc-netem where it has the concept (``delay``, ``jitter``, ``distribution``,
``correlation``, ``gemodel``'s p, r, 1-h, 1-k) and ns-3's propagation and PHY models where it
does not; every default says where it comes from (docs/radio.md has the formulas).
"""

from __future__ import annotations

import math
from typing import Any, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, SerializerFunctionWrapHandler, model_serializer, model_validator


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class PropagationSection(_Section):
    """Log-distance path loss, log-normal shadowing correlated over the distance a pair moves,
    optional block fading, and reception decided from the copy's SNR and its size in bits."""

    model: Literal["log_distance"] = Field("log_distance", description="path loss model")
    reference_distance: float = Field(
        1.0, gt=0, description="d0 in arena units (metres); ns-3 LogDistancePropagationLossModel's ReferenceDistance"
    )
    reference_loss_db: float = Field(
        46.6777, description="path loss at d0 in dB; ns-3's default (free space at 1 m and 5.15 GHz)"
    )
    exponent: float = Field(3.0, gt=0, description="path loss exponent n; ns-3's default")
    shadowing_db: float = Field(0.0, ge=0, description="standard deviation of log-normal shadowing in dB (0: none)")
    decorrelation_distance: float = Field(
        20.0,
        gt=0,
        description="distance the two ends of a link move, summed, over which shadowing decorrelates to 1/e "
        "(Gudmundson 1991; 20 m is in his measured suburban range)",
    )
    fading: Literal["none", "rayleigh", "nakagami"] = Field("none", description="small-scale fading of the power")
    nakagami_m: float = Field(1.0, ge=0.5, description="Nakagami shape m (m = 1 is Rayleigh)")
    coherence_time: float = Field(
        0.0, ge=0, description="seconds a fade holds (block fading); 0: a new fade every tick"
    )
    tx_power_dbm: float = Field(16.0206, description="transmit power in dBm; ns-3 WifiPhy's TxPowerStart")
    noise_floor_dbm: float = Field(
        -93.97,
        description="noise power in dBm: thermal -174 dBm/Hz over 20 MHz plus a 7 dB noise figure (ns-3's defaults)",
    )
    sensitivity_dbm: float = Field(
        -101.0, description="a copy received below this power is never detected; ns-3 WifiPhy's RxSensitivity"
    )
    reception: Literal["per", "threshold"] = Field(
        "per",
        description="per: a detected copy survives with probability (1 - BER(SNR))^bits; "
        "threshold: every detected copy survives",
    )
    modulation: Literal["bpsk", "qpsk"] = Field(
        "bpsk", description="bit error rate model over AWGN: BPSK Q(sqrt(2 SNR)), QPSK Q(sqrt(SNR))"
    )
    overhead_bytes: int = Field(0, ge=0, description="header bytes counted with the payload in the error model")


class BurstSection(_Section):
    """Gilbert-Elliott burst loss: a good and a bad state per link (or per receiver), each with
    its own loss probability. Give ``mean_loss`` and ``mean_burst``, or the transition
    parameters of the chosen ``advance``."""

    per: Literal["link", "receiver"] = Field("link", description="one chain per (sender, receiver) or per receiver")
    advance: Literal["time", "packet"] = Field(
        "time",
        description="time: the chain steps once per tick for every live link, sent on or not (bursts last "
        "the same in seconds for a chatty and a quiet allocator); packet: once per copy, as tc-netem's gemodel",
    )
    mean_loss: float | None = Field(None, gt=0, lt=1, description="stationary loss probability")
    mean_burst: float | None = Field(
        None, gt=0, description="mean time in the bad state: seconds (advance: time) or copies (advance: packet)"
    )
    good_s: float | None = Field(None, gt=0, description="advance: time; mean seconds in the good state")
    bad_s: float | None = Field(None, gt=0, description="advance: time; mean seconds in the bad state")
    p: float | None = Field(None, gt=0, le=1, description="advance: packet; P(good -> bad) per copy (gemodel p)")
    r: float | None = Field(None, gt=0, le=1, description="advance: packet; P(bad -> good) per copy (gemodel r)")
    loss_bad: float = Field(1.0, ge=0, le=1, description="loss probability in the bad state (gemodel 1-h)")
    loss_good: float = Field(0.0, ge=0, le=1, description="loss probability in the good state (gemodel 1-k)")

    @model_validator(mode="after")
    def _one_parametrisation(self) -> BurstSection:
        by_mean = self.mean_loss is not None or self.mean_burst is not None
        own = (self.good_s, self.bad_s) if self.advance == "time" else (self.p, self.r)
        other = (self.p, self.r) if self.advance == "time" else (self.good_s, self.bad_s)
        names = ("good_s", "bad_s") if self.advance == "time" else ("p", "r")
        if any(v is not None for v in other):
            wrong = ("p", "r") if self.advance == "time" else ("good_s", "bad_s")
            raise ValueError(
                f"{' and '.join(wrong)} belong to advance: {'packet' if self.advance == 'time' else 'time'}"
            )
        if by_mean == any(v is not None for v in own):
            raise ValueError(f"give mean_loss and mean_burst, or {names[0]} and {names[1]} (one pair)")
        if by_mean and (self.mean_loss is None or self.mean_burst is None):
            raise ValueError("mean_loss and mean_burst go together")
        if not by_mean and (own[0] is None or own[1] is None):
            raise ValueError(f"{names[0]} and {names[1]} go together")
        if by_mean:
            assert self.mean_loss is not None
            if not min(self.loss_good, self.loss_bad) < self.mean_loss < max(self.loss_good, self.loss_bad):
                raise ValueError("mean_loss must lie between loss_good and loss_bad")
        return self

    def bad_share(self) -> float:
        """The stationary probability of the bad state."""
        if self.mean_loss is not None:
            return (self.mean_loss - self.loss_good) / (self.loss_bad - self.loss_good)
        if self.advance == "time":
            assert self.good_s is not None and self.bad_s is not None
            return self.bad_s / (self.good_s + self.bad_s)
        assert self.p is not None and self.r is not None
        return self.p / (self.p + self.r)

    def step_probabilities(self, dt: float) -> tuple[float, float]:
        """(P(good -> bad), P(bad -> good)) per step: per tick of ``dt`` seconds (advance: time,
        the exact discretisation of a continuous-time chain with the mean sojourns) or per copy."""
        pi_bad = self.bad_share()
        if self.advance == "packet":
            if self.p is not None and self.r is not None:
                return self.p, self.r
            assert self.mean_burst is not None
            r = min(1.0, 1.0 / self.mean_burst)
            return min(1.0, r * pi_bad / (1 - pi_bad)), r
        if self.good_s is not None and self.bad_s is not None:
            good_s, bad_s = self.good_s, self.bad_s
        else:
            assert self.mean_burst is not None
            bad_s = self.mean_burst
            good_s = bad_s * (1 - pi_bad) / pi_bad
        return 1 - math.exp(-dt / good_s), 1 - math.exp(-dt / bad_s)


class DelaySection(_Section):
    """Seconds added to each copy's arrival, drawn per copy: ``mean`` plus ``jitter`` times a
    standardised draw of ``distribution`` (tc-netem's ``delay MEAN JITTER CORR distribution D``)."""

    mean: float = Field(0.0, ge=0, description="mean added delay in seconds (tc-netem delay)")
    jitter: float = Field(
        0.0, ge=0, description="spread in seconds: the distribution's standard deviation, or for uniform the half-width"
    )
    distribution: Literal["normal", "uniform", "pareto", "paretonormal"] = Field(
        "normal", description="shape of the spread (docs/radio.md gives each one's formula)"
    )
    correlation: float = Field(
        0.0, ge=0, lt=1, description="how much a link's next delay follows its last (AR(1) on the normal score)"
    )


class ChannelSection(_Section):
    """A receiver's airtime per tick, shared by the copies it hears (``swarmbed.netem.channel``)."""

    capacity: float = Field(gt=0, description="bytes per second a receiver hears, all senders together")


class WallsSection(_Section):
    """What walls (the ``obstacles:`` section) do to the radio: the multi-wall model of COST 231
    (each wall a copy's straight path crosses adds its material's loss, in dB, to the path loss;
    with ``propagation``) and, for the disc model, a line-of-sight switch."""

    loss_db: dict[str, float] = Field(
        default_factory=lambda: {"light": 3.4, "heavy": 6.9},
        description="dB a copy loses per wall it crosses, by material (COST 231's multi-wall model, 1999, "
        "section 4.7.3: light 3.4, heavy 6.9); used with network.propagation",
    )
    line_of_sight: bool = Field(
        False, description="drop every copy whose straight path crosses a wall (blocked_by_wall), with any model"
    )

    @model_validator(mode="after")
    def _finite(self) -> WallsSection:
        bad = [m for m, v in self.loss_db.items() if not (math.isfinite(v) and v >= 0)]
        if bad:
            raise ValueError(f"loss_db[{bad[0]}] must be a finite number of dB >= 0")
        return self


class NetworkSection(BaseModel):
    """The radio's parameters, named as tc-netem names them; the one definition of their bounds."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    range: float | None = Field(None, ge=0, description="communication range; null = unlimited")
    loss: float = Field(0.0, ge=0, le=1, description="probability a copy is lost")
    rate: float | None = Field(None, gt=0, description="per-sender cap in bytes per simulated second; null = none")
    limit: int | None = Field(None, ge=1, description="messages that may wait behind the rate cap (tail drop)")
    latency: int = Field(0, ge=0, description="extra ticks of delay on top of the one-tick minimum")
    ledger: Literal["per_sender", "per_receiver"] = Field(
        "per_sender", description="per_receiver adds network_ledger_receivers.parquet: one row per copy"
    )
    draws: Literal["sequential", "per_copy"] = Field(
        "sequential",
        description="the loss draws: sequential (one stream, in copy order) or per_copy (each copy's own, from "
        "its tick, sender, message and receiver: what a radio split over proxies needs, radio_split)",
    )
    # the models beyond the disk (docs/radio.md); left out, the radio is the disk above
    propagation: PropagationSection | None = Field(
        None, description="log-distance path loss, shadowing, fading and SNR-based reception"
    )
    burst: BurstSection | None = Field(None, description="Gilbert-Elliott burst loss per link or receiver")
    delay: DelaySection | None = Field(None, description="seconds added to each copy's arrival, with jitter")
    channel: ChannelSection | None = Field(None, description="a receiver's airtime per tick, shared by what it hears")
    walls: WallsSection | None = Field(
        None, description="what the obstacles' walls do to copies (loss per wall, line of sight); null: the defaults"
    )

    @model_serializer(mode="wrap")
    def _models_left_out_stay_out(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        """A resolved config names only the models it turns on: an experiment that uses none
        writes the config.yaml it wrote before they existed."""
        data = handler(self)
        for key in _MODEL_KEYS:
            if data.get(key) is None:
                data.pop(key, None)
        if data.get("draws") == "sequential":  # so does one that keeps the one stream of draws
            data.pop("draws")
        return data


def _is_model(annotation: object) -> bool:
    return any(isinstance(a, type) and issubclass(a, _Section) for a in get_args(annotation))


#: the keys of the models beyond the disk (each a section that is None when left out)
_MODEL_KEYS = tuple(key for key, field in NetworkSection.model_fields.items() if _is_model(field.annotation))
