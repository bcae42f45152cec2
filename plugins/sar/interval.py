"""CBBA-ETC's adaptive consensus interval (CBBA-ETC paper, Section 4.4, Eqs. 2 to 4).

    I(t)   = clip(I(t-1) * rho(Lc, dLc), I_base * phi_min, I_base * phi_max)            (2)
    rho    = rho_base - omega(Lc, dLc)                                                  (3)
    omega  =  kappa  * s(Lc - theta_high) * (1 + gamma * sign(dLc))   if Lc >= theta_high (4)
              0                                                        if theta_low < Lc < theta_high
             -lambda * s(theta_low - Lc)  * (1 + gamma * sign(-dLc))  if Lc <= theta_low

with s the sigmoid of steepness mu, s(x) = 1 / (1 + exp(-mu * x)); Lc the tasks lost in the last
consensus round and dLc its change from the round before. High conflict shrinks the interval
slowly (small kappa); calm stretches it fast (large lambda); between the thresholds it holds.
"""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field


class IntervalParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    base_interval: float = Field(
        100.0,
        gt=0,
        description="I_base, seconds: the adaptive interval lies in [I_base x phi_min, I_base x phi_max] (Eq. 2); "
        "100 s, the only time-based consensus period the text states (docs/reproduction.md section 4)",
    )
    rho_base: float = Field(1.0, description="rho_base, Eq. 3: the interval's factor per round in the dead zone")
    theta_high: float = Field(
        3.0, description="theta_high, Eq. 4: tasks lost in a round at or above which the interval shortens"
    )
    theta_low: float = Field(
        1.0, description="theta_low, Eq. 4: tasks lost in a round at or below which the interval lengthens"
    )
    mu: float = Field(10.0, description="sigmoid steepness")
    kappa: float = Field(0.1, description="kappa, Eq. 4: how fast high conflict shortens the interval")
    lam: float = Field(6.0, description="lambda, Eq. 4: how fast low conflict lengthens the interval")
    gamma: float = Field(0.001, description="gamma, Eq. 4: weight of the conflict's trend (sign of dLc)")
    phi_min: float = Field(3.0, description="phi_min, Eq. 2: the shortest interval is I_base x phi_min")
    phi_max: float = Field(8.0, description="phi_max, Eq. 2: the longest interval is I_base x phi_max")


def sigmoid(x: float, mu: float) -> float:
    z = -mu * x
    if z > 700:
        return 0.0
    return 1.0 / (1.0 + math.exp(z))


def _sign(x: float) -> float:
    return (x > 0) - (x < 0)


def omega(lost: float, change: float, p: IntervalParams) -> float:
    if lost >= p.theta_high:
        return p.kappa * sigmoid(lost - p.theta_high, p.mu) * (1 + p.gamma * _sign(change))
    if lost <= p.theta_low:
        return -p.lam * sigmoid(p.theta_low - lost, p.mu) * (1 + p.gamma * _sign(-change))
    return 0.0


def next_interval(current: float, lost: float, change: float, p: IntervalParams) -> float:
    rho = p.rho_base - omega(lost, change, p)
    low, high = p.base_interval * p.phi_min, p.base_interval * p.phi_max
    return min(max(current * rho, low), high)
