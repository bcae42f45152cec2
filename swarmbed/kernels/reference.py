"""The kernels in plain Python over numpy: the reference every compiled kernel is compared with,
bit for bit (``tests/test_kernels.py``), and what runs where no C compiler was found at install.

Every value here is made of IEEE-754 additions, multiplications, divisions and square roots in a
fixed order, which give the same bits on every CPU: no numpy ufunc whose result depends on the
CPU's vector extensions (numpy's own ``exp`` differs by one ulp between its AVX-512 code and the
rest on about 5 % of arguments), no fused multiply-add (the compiled twin is built with
``-ffp-contract=off``). The compiled kernels (``_compiled.pyx``) do the same operations in the
same order."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: ln 2 in two parts: the high one has 32 trailing zero bits, so that k * LN2_HI is exact for the
#: |k| < 2**11 an exponent of a double reaches; LN2_LO = ln 2 - LN2_HI, rounded
LN2_HI = float.fromhex("0x1.62e42fee00000p-1")
LN2_LO = float.fromhex("0x1.a39ef35793c76p-33")
INV_LN2 = float.fromhex("0x1.71547652b82fep+0")
#: 1/n! for n = 2..13, each the double nearest it; Horner's scheme runs them from the last
#: (|r| <= ln 2 / 2 after reduction: the first term left out, r**14/14!, is below 2**-60)
EXP_TAYLOR = tuple(
    float.fromhex(h)
    for h in (
        "0x1.0000000000000p-1",
        "0x1.5555555555555p-3",
        "0x1.5555555555555p-5",
        "0x1.1111111111111p-7",
        "0x1.6c16c16c16c17p-10",
        "0x1.a01a01a01a01ap-13",
        "0x1.a01a01a01a01ap-16",
        "0x1.71de3a556c734p-19",
        "0x1.27e4fb7789f5cp-22",
        "0x1.ae64567f544e4p-26",
        "0x1.1eed8eff8d898p-29",
        "0x1.6124613a86d09p-33",
    )
)
#: past these, exp(x) is infinite or zero in doubles (ln of the largest double, ln of half the smallest)
EXP_OVER = 709.782712893384
EXP_UNDER = -745.1332191019412


def exp(x: np.ndarray | float) -> np.ndarray:
    """e**x, elementwise, within one ulp of the exact value over the arguments tested, and the same
    bits on every CPU: x = k ln 2 + r with k = floor(x / ln 2 + 1/2), exp(r) by its Taylor series
    to r**13, then times 2**k (``ldexp``, exact but where the result is subnormal)."""
    x = np.asarray(x, dtype=np.float64)
    bad = np.isnan(x)
    xs = np.where(bad, 0.0, np.clip(x, EXP_UNDER - 1.0, EXP_OVER + 1.0))
    k = np.floor(xs * INV_LN2 + 0.5)
    r = (xs - k * LN2_HI) - k * LN2_LO
    q = np.full_like(r, EXP_TAYLOR[-1])
    for c in EXP_TAYLOR[-2::-1]:  # q = q * r + c, in place
        q *= r
        q += c
    q *= r * r
    q += r
    p = q + 1.0  # 1 + (r + r*r*q): addition is commutative in IEEE arithmetic, bit for bit
    with np.errstate(over="ignore"):  # past EXP_OVER: set to inf below
        out = np.ldexp(p, k.astype(np.int64))
    out = np.where(x > EXP_OVER, np.inf, np.where(x < EXP_UNDER, 0.0, out))
    return np.where(bad, np.nan, out)


def _distance(ax: np.ndarray, ay: np.ndarray, bx: np.ndarray | float, by: np.ndarray | float) -> np.ndarray:
    """Euclidean distance as sqrt(dx*dx + dy*dy): ``hypot`` is libm's, whose last bit is not promised."""
    dx, dy = ax - bx, ay - by
    return np.sqrt(dx * dx + dy * dy)


def path_gains(
    x0: float,
    y0: float,
    speed: float,
    rate: float,
    log_discount: float,
    cx: np.ndarray,
    cy: np.ndarray,
    cr: np.ndarray,
    px: np.ndarray,
    py: np.ndarray,
    pr: np.ndarray,
    at_end: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """CBBA's marginal gains (Algorithm 3, SPACE's time-discounted score): for each candidate task
    (``cx``, ``cy``, remaining work ``cr``) the best gain of inserting it at any position of the
    path (tasks ``px``, ``py``, ``pr``, visited in order from the robot at ``x0``, ``y0``), and
    that position (the first of equal ones); a candidate whose ``at_end`` is set (uint8: a team
    task's slot) only at the end of the path. A task's score is ``discount ** tau * remaining``,
    tau its arrival: travel at ``speed`` plus the work (``remaining / rate``) of the tasks before it."""
    nx = np.concatenate([[x0], px])
    ny = np.concatenate([[y0], py])
    seg = _distance(nx[1:], ny[1:], nx[:-1], ny[:-1])  # node n -> n+1
    work = pr / rate
    arrive = np.cumsum(seg / speed + work) - work  # tau of path task n
    finish = np.concatenate([[0.0], arrive + work])  # when the robot leaves node n
    disc = exp(log_discount * arrive) * pr
    suffix = np.concatenate([np.cumsum(disc[::-1])[::-1], [0.0]])  # suffix[n] = sum of disc[k >= n]
    d = _distance(cx[:, None], cy[:, None], nx[None, :], ny[None, :])  # candidate x node
    tau = finish[None, :] + d / speed
    delay = np.zeros_like(d)
    if len(pr):
        delay[:, :-1] = (d[:, :-1] + d[:, 1:] - seg[None, :]) / speed + (cr / rate)[:, None]
    gain = exp(log_discount * tau) * cr[:, None] + (exp(log_discount * delay) - 1.0) * suffix[None, :]
    best, where = gain.max(axis=1), gain.argmax(axis=1)
    last = at_end.astype(bool)
    best[last], where[last] = gain[last, -1], len(pr)
    return best, where


def distance_gains(
    x0: float, y0: float, speed: float, log_discount: float, cx: np.ndarray, cy: np.ndarray, cr: np.ndarray
) -> np.ndarray:
    """The score that does not depend on the path: ``discount ** (d / speed) * remaining``, d the
    distance from the robot at ``x0``, ``y0`` to each candidate."""
    return exp(log_discount * _distance(cx, cy, x0, y0) / speed) * cr


def task_columns(tasks: Sequence[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The x, y and remaining columns (fields 1-3 of :class:`~swarmbed.extension.view.TaskInfo`)
    of ``tasks``, as float64 arrays."""
    return (
        np.array([t[1] for t in tasks], dtype=float),
        np.array([t[2] for t in tasks], dtype=float),
        np.array([t[3] for t in tasks], dtype=float),
    )


def best_bid(agent: int, items: Sequence[int], gains: np.ndarray, z: dict[int, int], y: dict[int, float]) -> int:
    """Where in ``items`` (with their ``gains``) the bid CBBA's Algorithm 3 adds is: the first
    highest positive gain that beats the known winning bid (``y``, ``z``: higher, or equal with the
    known winner's id above ``agent``'s); -1 where none does, or the highest is infinite."""
    best, at = -math.inf, -1
    for n, item in enumerate(items):
        gain = float(gains[n])
        if not gain > 0 or not gain > best:
            continue
        known = y.get(item, 0.0)
        if gain > known or (gain == known and agent < z.get(item, agent + 1)):
            best, at = gain, n
    return at if math.isfinite(best) else -1
