"""Radio parameters. Names follow tc-netem where it has one (``loss``, ``rate``, ``limit``)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class NetemParams:
    range: float | None = None  # metres/units; None = unlimited
    loss: float = 0.0  # Bernoulli probability that one copy is lost, in [0, 1]
    rate: float | None = None  # per-sender cap, bytes per simulated second; None = unlimited
    limit: int | None = None  # messages that may wait behind the rate cap (tail drop); None = unlimited
    latency: int = 0  # extra ticks on top of the one-tick minimum

    def __post_init__(self) -> None:
        if self.range is not None and self.range < 0:
            raise ValueError("range must be >= 0")
        if not 0.0 <= self.loss <= 1.0:
            raise ValueError("loss must be in [0, 1]")
        if self.rate is not None and self.rate <= 0:
            raise ValueError("rate must be > 0")
        if self.limit is not None and self.limit < 1:
            raise ValueError("limit must be >= 1")
        if self.latency < 0:
            raise ValueError("latency must be >= 0")
