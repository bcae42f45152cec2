"""Comparing strategies (CBBA-ETC paper, Section 5.4): per metric, a one-way ANOVA across the
strategies, then Dunnett's test of every strategy against a control, and Cohen's d against the
control (pooled standard deviation; positive when the strategy's mean is above the control's).

Dunnett's test rests on one variance pooled over every strategy. Where the strategies' variances
differ by orders of magnitude (message counts: ``tree`` sends none, the consensus strategies
thousands with a wide spread) the pooled variance is dominated by the widest group and its p-values
say little about a narrow one. Each row therefore also has ``welch_holm_p``: Welch's t-test of the
strategy against the control (no common variance assumed), adjusted by Holm's step-down method over
the metric's comparisons so that, like Dunnett's, it holds the family-wise error rate.

Where two strategies are to be called similar, absence of a significant difference is not evidence
of one: each row also has the two one-sided tests (TOST, Welch's t) of equivalence within a stated
margin, :data:`EQUIVALENCE` of the control's mean; ``tost_p`` below 0.05 says the means differ by
less than the margin."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy import stats

DUNNETT_SEED = 20240521  # any fixed value; documented so that a reader can recompute the p-values
#: the equivalence margin of the TOST column, as a share of the control's mean (5 %: stated here,
#: before any table uses it)
EQUIVALENCE = 0.05


def tost_p(a: np.ndarray, b: np.ndarray, margin: float) -> float:
    """The p-value of the two one-sided Welch t-tests that mean(a) - mean(b) lies within
    (-margin, +margin): the larger of the two one-sided p-values."""
    if len(a) < 2 or len(b) < 2 or not margin > 0:
        return float("nan")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        above = stats.ttest_ind(a + margin, b, equal_var=False, alternative="greater").pvalue
        below = stats.ttest_ind(a - margin, b, equal_var=False, alternative="less").pvalue
    return float(max(above, below))


def holm(p_values: list[float]) -> list[float]:
    """Holm's step-down adjustment of a family of p-values (NaN entries pass through and do not
    count in the family): the k-th smallest of m is multiplied by m - k + 1, made monotone and capped
    at 1."""
    values = np.asarray(p_values, dtype=float)
    adjusted = np.full(len(values), np.nan)
    present = np.flatnonzero(~np.isnan(values))
    m = len(present)
    running = 0.0
    for rank, i in enumerate(present[np.argsort(values[present], kind="stable")]):
        running = max(running, min(1.0, (m - rank) * values[i]))
        adjusted[i] = running
    return adjusted.tolist()


def welch_holm(samples: dict[str, np.ndarray], others: list[str], control: str) -> list[float]:
    """Welch's two-sided t-test of each of ``others`` against ``control``, Holm-adjusted over the
    family. A pair with no spread at all in either group gives 0 where the means differ, 1 where not."""
    raw = []
    for g in others:
        a, b = samples[g], samples[control]
        if a.var() == 0 and b.var() == 0:
            raw.append(1.0 if a.mean() == b.mean() else 0.0)
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            raw.append(float(stats.ttest_ind(a, b, equal_var=False).pvalue))
    return holm(raw)


def paired_p(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Two-sided p-values that paired samples ``x`` and ``y`` (run r of one against run r of the
    other, the same seed) differ: the paired t-test's and, beside it, the Wilcoxon signed-rank
    test's, which does not lean on the differences being normal (exact below 50 pairs without ties;
    zero differences dropped). NaN where a test has nothing to go on (under two pairs, all equal)."""
    d = np.asarray(x, dtype=float) - np.asarray(y, dtype=float)
    if len(d) < 2 or not np.any(d):
        return float("nan"), float("nan")
    t = float(stats.ttest_1samp(d, 0.0).pvalue) if d.std() > 0 else float("nan")
    return t, float(stats.wilcoxon(d).pvalue)


def cohens_d(a: np.ndarray, b: np.ndarray) -> float:
    """Effect size of ``a`` against ``b`` with the pooled standard deviation."""
    na, nb = len(a), len(b)
    if na < 2 or nb < 2:
        return float("nan")
    pooled = np.sqrt(((na - 1) * a.var(ddof=1) + (nb - 1) * b.var(ddof=1)) / (na + nb - 2))
    if pooled == 0:
        return 0.0 if a.mean() == b.mean() else float("inf") * np.sign(a.mean() - b.mean())
    return float((a.mean() - b.mean()) / pooled)


def compare(df: pd.DataFrame, group: str, metrics: list[str], control: str) -> pd.DataFrame:
    """One row per (metric, strategy other than the control): means, ANOVA F and p (the same for
    every row of a metric), Dunnett's p and the Welch-Holm p against the control, Cohen's d and
    the TOST p of equivalence."""
    rows = []
    names = sorted(df[group].unique())
    if control not in names:
        raise ValueError(f"control {control!r} is not among {names}")
    others = [g for g in names if g != control]
    for metric in metrics:
        if metric not in df:
            continue
        samples = {g: df.loc[df[group] == g, metric].dropna().to_numpy(dtype=float) for g in names}
        if any(len(v) < 2 for v in samples.values()):
            continue
        constant = (
            all(np.all(v == v[0]) for v in samples.values()) and len({float(v[0]) for v in samples.values()}) == 1
        )
        if constant:
            f, p_anova, dunnett_p = float("nan"), 1.0, [1.0] * len(others)
        else:
            with warnings.catch_warnings():  # near-constant groups (e.g. nothing expired) only cost precision
                warnings.simplefilter("ignore", RuntimeWarning)
                f, p_anova = stats.f_oneway(*samples.values())
                # its p-values integrate a multivariate t by randomized quasi-Monte Carlo: a fixed
                # seed makes the same table give the same statistics.csv, byte for byte
                dunnett = stats.dunnett(*[samples[g] for g in others], control=samples[control], rng=DUNNETT_SEED)
                dunnett_p = list(dunnett.pvalue)
        welch_p = welch_holm(samples, others, control)
        for g, p, w in zip(others, dunnett_p, welch_p):
            rows.append(
                {
                    "metric": metric,
                    "strategy": g,
                    "mean": samples[g].mean(),
                    "sd": samples[g].std(ddof=1),
                    "control": control,
                    "control_mean": samples[control].mean(),
                    "anova_F": float(f),
                    "anova_p": float(p_anova),
                    "dunnett_p": float(p),
                    "welch_holm_p": float(w),
                    "cohens_d": cohens_d(samples[g], samples[control]),
                    "tost_margin": EQUIVALENCE * abs(samples[control].mean()),
                    "tost_p": tost_p(samples[g], samples[control], EQUIVALENCE * abs(samples[control].mean())),
                    "n": len(samples[g]),
                }
            )
    return pd.DataFrame(rows)
