"""Point-mass (unicycle) kinematics honouring speed, acceleration and turn-rate limits.

Per step of ``dt``: the heading turns toward the target by at most ``max_turn_rate * dt``; the speed
moves toward a target speed by at most ``max_accel * dt``; the target speed is ``max_speed``,
reduced so that the agent can still stop at the target (``sqrt(2 a d)``) and scaled down by the
cosine of the heading error (no speed while facing away). The agent never overshoots its target.
With an ``approach_radius`` r > 0 the target speed is also at most ``max_speed * d / r`` within r of
the target (SPACE's code, ``target_approaching_radius``: an agent slows as it closes in).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Limits:
    max_speed: float
    max_accel: float
    max_turn_rate: float
    approach_radius: float = 0.0


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def step(
    x: float, y: float, heading: float, speed: float, target: tuple[float, float] | None, lim: Limits, dt: float
) -> tuple[float, float, float, float]:
    """One step toward ``target`` (None: brake). Returns the new x, y, heading, speed."""
    dv = lim.max_accel * dt
    if target is None:
        speed = max(0.0, speed - dv)
        return x + speed * dt * math.cos(heading), y + speed * dt * math.sin(heading), heading, speed
    dx, dy = target[0] - x, target[1] - y
    dist = math.hypot(dx, dy)
    if dist < 1e-12:
        return x, y, heading, max(0.0, speed - dv)
    err = _wrap(math.atan2(dy, dx) - heading)
    max_turn = lim.max_turn_rate * dt
    heading = _wrap(heading + max(-max_turn, min(max_turn, err)))
    err = _wrap(math.atan2(dy, dx) - heading)
    wanted = min(lim.max_speed, math.sqrt(2.0 * lim.max_accel * dist))
    if dist < lim.approach_radius:
        wanted = min(wanted, lim.max_speed * dist / lim.approach_radius)
    wanted *= max(0.0, math.cos(err))
    speed = max(0.0, min(lim.max_speed, speed + max(-dv, min(dv, wanted - speed))))
    travel = speed * dt
    if travel >= dist and abs(err) < 1e-9:
        return target[0], target[1], heading, speed
    return x + travel * math.cos(heading), y + travel * math.sin(heading), heading, speed
