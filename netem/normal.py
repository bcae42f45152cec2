"""The complementary error function and the normal CDF over numpy arrays, without scipy (the proxy
process stays lean: tests/test_packaging.py keeps scipy out of it).

``erfc`` is the Chebyshev fit of Press, Teukolsky, Vetterling and Flannery, *Numerical Recipes*
(2nd ed., section 6.2, ``erfcc``): a fractional error below 1.2e-7 everywhere, which keeps bit
error rates of 1e-9 and below accurate to seven digits. tests/test_radio_models.py checks it
against ``scipy.special.erfc``.
"""

from __future__ import annotations

import numpy as np

_COEFFS = (
    -1.26551223,
    1.00002368,
    0.37409196,
    0.09678418,
    -0.18628806,
    0.27886807,
    -1.13520398,
    1.48851587,
    -0.82215223,
    0.17087277,
)


def erfc(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    z = np.abs(x)
    t = 1.0 / (1.0 + 0.5 * z)
    poly = np.full_like(z, _COEFFS[-1])
    for c in reversed(_COEFFS[:-1]):
        poly = c + t * poly
    ans = t * np.exp(-z * z + poly)
    return np.where(x >= 0, ans, 2.0 - ans)


def normal_cdf(z: np.ndarray) -> np.ndarray:
    """P(Z <= z) for a standard normal Z."""
    return 0.5 * erfc(-np.asarray(z, dtype=float) / np.sqrt(2.0))
