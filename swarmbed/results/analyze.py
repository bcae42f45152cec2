"""``swarmbed analyze SWEEP_DIR [SWEEP_DIR ...]``: tables and figures from sweeps' ``sweep.parquet`` (or ``sweep.csv``).

- ``scenario_summary.csv`` / ``.md``: per scenario and metric, n, mean, sd, median and the 95 %
  confidence interval of the mean (Student t).
- ``statistics.csv`` / ``.md``, where the scenario names a control allocator
  (``Scenario.control_allocator``, cbba-etc for search and rescue) or ``--control`` does: one-way
  ANOVA across allocators; Dunnett's test, Welch's t (Holm-adjusted), Cohen's d and TOST against the
  control (``swarmbed.results.stats``).
- Figures: the ones each scenario names in ``Scenario.figures`` (``swarmbed.extension.figures``).
  MT-SR: SPACE Fig. 3 panels, one PNG per metric, one value per run as SPACE's Monte Carlo
  analysis plots them (mission time, times to 95 % and 99 % of tasks, mean travel distance per
  agent, and the Gini coefficients of work and distance per agent), boxes by communication range,
  one group per algorithm, one panel per agent count. Search and rescue
  (CBBA-ETC Section 5.4): mean rescued and expired per trial with 95 % CI bars, boxplots per
  trial, rescued against messages sent, and over several sweeps (the victim-count or robot-count
  series) messages and rescues against victim count and robot count. A scenario that names none
  gets one box per allocator for each of its outcome metrics.

With several directories, the first one receives the outputs.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import NullLocator  # noqa: E402
from scipy import stats  # noqa: E402

from swarmbed.extension import Figure, Scenario  # noqa: E402
from swarmbed.files import safefiles
from swarmbed.plugins.registry import registered_scenario  # noqa: E402
from swarmbed.records.run_folder import (  # noqa: E402
    RunDir,  # noqa: E402
    RunFileError,
    read_json_member,
)
from swarmbed.results.campaign_folders import PARQUET, SPEC, TABLE, read_table  # noqa: E402
from swarmbed.results.colours import STRATEGY_ORDER, strategy_color, strategy_label  # noqa: E402
from swarmbed.results.pooling import mixed_configurations, mixed_versions  # noqa: E402
from swarmbed.results.progress import Progress
from swarmbed.results.stats import compare  # noqa: E402

AGENTS, RANGE, ALLOCATOR = "agents.count", "network.range", "allocator"
#: what every scenario's runs send, tabulated beside the scenario's own metrics
NETWORK_LABELS = {
    "network.messages_sent": "messages sent per trial",  # one per broadcast, however many hear it
    "network.delivered": "copies delivered per trial",  # one per receiver that got it
    "network.bytes_sent": "payload bytes sent per trial",
}


class AnalyzeError(ValueError):
    pass


def load(sweep_dirs: list[Path], mixed_versions_ok: bool = False, trusted: bool = False) -> pd.DataFrame:
    """Completed runs of the sweeps, one row each; ``attrs["factors"]``: the keys they vary."""
    frames: list[pd.DataFrame] = []
    factors: list[str] = []
    for sweep_dir in sweep_dirs:
        spec = sweep_dir / SPEC
        if not spec.exists():
            raise AnalyzeError(f"{sweep_dir}: no {SPEC}; run `swarmbed sweep` into it first")
        if not ((sweep_dir / TABLE).exists() or (sweep_dir / PARQUET).exists()):
            raise AnalyzeError(
                f"{sweep_dir}: no {TABLE} yet (a sweep writes it when it stops); run the same "
                f"`swarmbed sweep` again: it skips the runs that completed and writes the table"
            )
        try:
            df = read_table(sweep_dir)
            meta = read_json_member(sweep_dir, SPEC)
        except RunFileError as exc:
            raise AnalyzeError(str(exc)) from None
        if not isinstance(meta.get("name"), str) or not isinstance(meta.get("factors", []), list):
            raise AnalyzeError(f"{spec}: not a sweep's plan (no name, or factors that are not a list)")
        mixed = mixed_configurations(sweep_dir, df)
        if mixed:
            raise AnalyzeError(
                f"{sweep_dir}: {mixed}; a scenario's runs may differ only in their seed "
                "(redo them with swarmbed sweep ... --redo-mismatched)"
            )
        df["sweep"] = meta["name"]
        df["run_dir"] = [str(sweep_dir / str(sc) / f"run_{int(r):03d}") for sc, r in zip(df["scenario"], df["run"])]
        factors += [f for f in meta.get("factors", []) if isinstance(f, str) and f not in factors]
        frames.append(df)
    df = pd.concat(frames, ignore_index=True)
    versions = mixed_versions(df)
    if versions and not mixed_versions_ok:
        raise AnalyzeError(
            f"{', '.join(map(str, sweep_dirs))}: runs made by {versions}: their results may not be "
            "comparable (provenance.json of each run says which); pass --mixed-versions to pool them"
        )
    df = df[df["status"] == "ok"].copy()
    if df.empty:
        raise AnalyzeError(f"{', '.join(map(str, sweep_dirs))}: no completed run to analyze")
    df[ALLOCATOR] = df["allocator"].map(_allocator_label)  # every summary names its allocator
    kinds = df["scenario_kind"].dropna().unique() if "scenario_kind" in df else []
    _resolve_keys(
        df, tuple(k for kind in kinds for f in figures_of(scenario_class(kind, trusted)) for k in f.over if k != AGENTS)
    )
    if len(sweep_dirs) > 1:
        df["scenario"] = df["sweep"] + "/" + df["scenario"]
    df.attrs["factors"] = factors
    return df


def _resolve_keys(df: pd.DataFrame, keys: tuple[str, ...]) -> None:
    """A sweep that leaves a key at its base's value (the V100 of a victim-count series) gets the
    value its runs used, from their resolved ``config.yaml``, so that series line up."""
    for key in keys:
        if key in df and df[key].notna().all():
            continue
        first = df.groupby(["sweep", "scenario"])["run_dir"].first()  # a scenario's runs differ only in their seed
        used = {group: _config_value(RunDir(run_dir), key) for group, run_dir in first.items()}
        values = pd.Series([used[(sw, sc)] for sw, sc in zip(df["sweep"], df["scenario"])], index=df.index)
        df[key] = df[key].fillna(values) if key in df else values


ALLOCATOR_KEYS = (ALLOCATOR, "allocator.name")


def _short(value: Any) -> str:
    if value is None or (isinstance(value, float) and np.isnan(value)):
        return "none"
    text = f"{value:g}" if isinstance(value, float) else str(value)
    return re.sub(r"[^A-Za-z0-9.]+", "-", text).strip("-")[:40] or "none"


def _group_by_setting(df: pd.DataFrame) -> None:
    """``df["group"]``: the sweep, and where a sweep varies factors besides the allocator (a loss
    model, a tick length), the setting of those factors too. Strategies are compared, and their
    means drawn, within one group: runs made under different settings are never pooled."""
    others = [f for f in df.attrs.get("factors", []) if f in df and f not in ALLOCATOR_KEYS]
    if not others:
        df["group"] = df["sweep"]
        return
    settings = df[others].apply(lambda row: "_".join(f"{k.split('.')[-1]}-{_short(row[k])}" for k in others), axis=1)
    df["group"] = df["sweep"] + "_" + settings


def _config_value(run: RunDir, key: str) -> Any:
    """The value of dotted ``key`` in a run's resolved config, or NaN where it cannot be read."""
    try:
        value: Any = run.config()
        for part in key.split("."):
            value = value[part]
    except (RunFileError, KeyError, TypeError):
        return np.nan
    return value


def ci95(values: pd.Series) -> tuple[float, float]:
    """The 95 % confidence interval of the mean (Student t); NaN with fewer than two values."""
    v = values.dropna().to_numpy(dtype=float)
    if len(v) < 2:
        return (float("nan"), float("nan"))
    half = stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v))
    return float(v.mean() - half), float(v.mean() + half)


def scenario_summary(df: pd.DataFrame, metrics: dict, capped_by: Mapping[str, str] | None = None) -> pd.DataFrame:
    """Per scenario and metric: n, mean, sd, median, 95 % CI. ``capped_by``: metrics a run stopped by
    its duration reports as the duration (metric -> the summary flag true where it got there); for
    those, ``capped`` counts the runs that did not, and ``note`` says the mean is then a lower bound."""
    rows = []
    capped_by = capped_by or {}
    for scenario, group in df.groupby("scenario", sort=True):
        for metric in metrics:
            if metric not in group:
                continue
            v = group[metric].dropna().astype(float)
            lo, hi = ci95(v)
            flag = capped_by.get(metric)
            capped = int((group[flag].astype(str).str.lower() != "true").sum()) if flag in group else 0
            rows.append(
                {
                    "scenario": scenario,
                    "metric": metric,
                    "n": len(v),
                    "mean": v.mean(),
                    "sd": v.std(ddof=1),
                    "median": v.median(),
                    "ci95_low": lo,
                    "ci95_high": hi,
                    "capped": capped,
                    "note": f"{capped} of {len(group)} runs stopped at run.duration: a lower bound" if capped else "",
                }
            )
    return pd.DataFrame(rows)


def to_markdown(table: pd.DataFrame) -> str:
    cols = list(table.columns)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, row in table.iterrows():
        cells = [f"{v:.4g}" if isinstance(v, float) else str(v) for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _allocator_label(value) -> str:
    if isinstance(value, str) and value.startswith("{"):
        try:
            named = json.loads(value)
        except (ValueError, RecursionError):  # a crafted cell nested 100,000 deep
            return value
        return str(named.get("name", value)) if isinstance(named, dict) else value
    return str(value)


# -- figure style: one name and one colour per strategy in every figure, vector output beside PNG,
#    sized for a paper's column (3.5 in) or page (7 in) at 8-9 pt text ------------------------------
COLUMN_IN, PAGE_IN = 3.5, 7.16
STYLE: Any = {  # matplotlib types rc keys as literals
    "font.size": 8,
    "axes.titlesize": 8,
    "axes.labelsize": 8,
    "xtick.labelsize": 7,
    "ytick.labelsize": 7,
    "legend.fontsize": 7,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "savefig.bbox": "tight",
    "pdf.fonttype": 42,
    "svg.fonttype": "none",
}
MEDIAN = {"color": "black", "linewidth": 1.4}  # visible on every fill colour


def _ordered(strategies) -> list[str]:
    """The papers' order (CBBA-ETC Table 2, SPACE Fig. 3), then any others by name."""
    known = [s for s in STRATEGY_ORDER if s in set(strategies)]
    return known + sorted(set(strategies) - set(known))


def _save(fig, out: Path, stem: str) -> Path:
    """PNG for the page, PDF and SVG for the paper; returns the PNG."""
    for ext in ("pdf", "svg", "png"):  # each under a fresh name, renamed over a link, never through it
        with safefiles.replacing(out / f"{stem}.{ext}") as tmp:
            fig.savefig(tmp, **({"dpi": 200} if ext == "png" else {}))
    plt.close(fig)
    return out / f"{stem}.png"


SHOW_POINTS_UP_TO = 20  # runs per box: fewer, and each run is drawn too (a box of 1 to 3 runs says little)


def _boxes(ax, data: list, positions, width: float, colors: list[str]) -> None:
    points = [0 < len(values) <= SHOW_POINTS_UP_TO for values in data]
    bp = ax.boxplot(
        data,
        positions=positions,
        widths=width,
        patch_artist=True,
        manage_ticks=False,
        medianprops=MEDIAN,
        flierprops={"markersize": 2.5, "alpha": 0.6},
        showfliers=not all(points),
    )  # every run drawn: no second marker for outliers
    for box, color in zip(bp["boxes"], colors):
        box.set_facecolor(color)
        box.set_alpha(0.75)
    for values, x, color, draw in zip(data, positions, colors, points):
        if draw:  # spread evenly across the box, the same in every figure
            spread = np.linspace(-0.25, 0.25, len(values)) * width if len(values) > 1 else np.zeros(1)
            ax.scatter(x + spread, values, s=9, color=color, edgecolors="black", linewidths=0.4, zorder=3)


def _log_counts(ax, axis: str = "y") -> None:
    """A log-like axis for counts that shows zero (the tree strategy sends no message): linear
    below 1, logarithmic above, zero clear of the axis."""
    if axis == "y":
        ax.set_yscale("symlog", linthresh=1.0)
        ax.set_ylim(-0.5, max(10.0, ax.get_ylim()[1]))  # a zero sits just above the axis
    else:
        ax.set_xscale("symlog", linthresh=1.0)
        ax.set_xlim(-0.5, max(10.0, ax.get_xlim()[1]))


def _values(rows: pd.DataFrame, metric: str) -> pd.Series:
    """One value per run, or for a metric the summary holds per agent one per agent of every run."""
    if metric in rows:
        return rows[metric].dropna()
    values: list[float] = []
    for run_dir in rows["run_dir"]:
        values += RunDir(run_dir).summary().document.get(metric, [])
    return pd.Series(values, dtype=float)


@dataclass
class Canvas:
    """Where one scenario kind's figures go, and how to name them (prefixed by the kind when the
    sweeps hold several), with the kind's metric labels."""

    out: Path
    prefix: str
    labels: dict[str, str]
    counts: tuple[str, ...] = ()  # the keys ``against_count`` figures plot against

    def save(self, fig, stem: str) -> Path:
        return _save(fig, self.out, self.prefix + stem)

    def label(self, metric: str) -> str:
        return self.labels.get(metric, metric.replace("_", " "))


NO_DISK = "no disk"


def _range_label(value: float) -> str:
    """A communication range as the figures label it: its number, or "no disk" where the run had
    none (``network.range: null``, a propagation model deciding alone)."""
    return NO_DISK if pd.isna(value) else f"{float(value):g}"


def _by_range(df: pd.DataFrame, figure: Figure, canvas: Canvas) -> list[Path]:
    written = []
    for metric in figure.metrics:
        path = _by_range_one(df, metric, canvas)
        if path:
            written.append(path)
    return written


def _by_range_one(df: pd.DataFrame, metric: str, canvas: Canvas) -> Path | None:
    per_agent = metric not in df and f"{metric}_mean" in df
    if not per_agent and (metric not in df or df[metric].dropna().empty):
        return None
    label = canvas.label(metric)
    have = all(c in df for c in (AGENTS, RANGE)) and df[ALLOCATOR].notna().all()
    with plt.rc_context(STYLE):
        if not have:
            groups = sorted(df["scenario"].unique())
            fig, ax = plt.subplots(figsize=(max(COLUMN_IN, 0.5 * len(groups)), 2.8))
            _boxes(
                ax,
                [_values(df[df["scenario"] == g], metric) for g in groups],
                np.arange(len(groups)),
                0.6,
                ["0.75"] * len(groups),
            )
            ax.set_xticks(range(len(groups)), groups)
            ax.set_ylabel(label)
            ax.tick_params(axis="x", rotation=30)
        else:
            algos = _ordered(df[ALLOCATOR].unique())
            counts = sorted(df[AGENTS].unique())
            df = df.assign(**{RANGE: df[RANGE].map(_range_label)})  # no disk (a propagation model alone): its own group
            ranges = sorted(df[RANGE].unique(), key=lambda r: (r == NO_DISK, float(r) if r != NO_DISK else 0.0))
            fig, axes = plt.subplots(1, len(counts), figsize=(PAGE_IN, 2.4), sharey=True, squeeze=False)
            width = 0.8 / len(algos)
            for ax, n in zip(axes[0], counts):
                sub = df[df[AGENTS] == n]
                for a, algo in enumerate(algos):
                    data = [_values(sub[(sub[RANGE] == r) & (sub[ALLOCATOR] == algo)], metric) for r in ranges]
                    pos = np.arange(len(ranges)) + (a - (len(algos) - 1) / 2) * width
                    _boxes(ax, data, pos, width * 0.85, [strategy_color(algo)] * len(ranges))
                    ax.plot([], [], color=strategy_color(algo), lw=5, alpha=0.75, label=strategy_label(algo))
                ax.set_xticks(range(len(ranges)), ranges)
                ax.set_xlabel("communication range")
                ax.set_title(f"{n} agents")
            axes[0][0].set_ylabel(label)
            axes[0][-1].legend(frameon=False)
        return canvas.save(fig, f"fig_{metric.replace('.', '_')}")


def _strategies(df: pd.DataFrame) -> tuple[list[str], list[str], list[str], dict[str, pd.DataFrame], np.ndarray]:
    strategies = _ordered(df[ALLOCATOR].unique())
    per = {g: df[df[ALLOCATOR] == g] for g in strategies}
    return (
        strategies,
        [strategy_label(g) for g in strategies],
        [strategy_color(g) for g in strategies],
        per,
        np.arange(len(strategies)),
    )


def _numeric(df: pd.DataFrame, metrics: tuple[str, ...]) -> list[str]:
    return [
        m for m in metrics if m in df and pd.api.types.is_numeric_dtype(df[m]) and not pd.api.types.is_bool_dtype(df[m])
    ]


def _means(df: pd.DataFrame, figure: Figure, canvas: Canvas) -> list[Path]:
    """Means per allocator with 95 % CI bars, the first metric filled, the others hatched; one figure
    per group (sweep, and setting of its other factors) where there are several: a failure level's
    trials are not pooled with another's."""
    metrics = _numeric(df, figure.metrics)
    if not metrics:
        return []
    strategies, labels, colors, per, x = _strategies(df)
    written = []
    width = 0.8 / len(metrics)
    with plt.rc_context(STYLE):
        sweeps = sorted(df["group"].unique()) if "group" in df and df["group"].nunique() > 1 else [None]
        for sweep in sweeps:
            chosen = per if sweep is None else {g: per[g][per[g]["group"] == sweep] for g in strategies}
            fig, ax = plt.subplots(figsize=(COLUMN_IN, 2.6))
            for k, metric in enumerate(metrics):
                means = np.array([chosen[g][metric].mean() for g in strategies])
                cis = [ci95(chosen[g][metric]) for g in strategies]
                err = [[m - lo for m, (lo, _) in zip(means, cis)], [hi - m for m, (_, hi) in zip(means, cis)]]
                ax.bar(
                    x + (k - (len(metrics) - 1) / 2) * width,
                    means,
                    width,
                    yerr=np.nan_to_num(err),
                    capsize=2,
                    color=colors,
                    alpha=0.85 if k == 0 else 0.35,
                    hatch=None if k == 0 else "///",
                    edgecolor="0.2",
                    linewidth=0.5,
                    error_kw={"elinewidth": 0.8},
                )
            ax.set_xticks(x, labels, rotation=30, ha="right")
            ax.set_ylabel(f"{figure.label or 'per trial'} (mean, 95 % CI)")
            ax.legend(
                handles=[
                    Patch(
                        facecolor="0.5",
                        alpha=0.85 if k == 0 else 0.35,
                        hatch=None if k == 0 else "///",
                        edgecolor="0.2",
                        linewidth=0.5,
                        label=metric.replace("_", " "),
                    )
                    for k, metric in enumerate(metrics)
                ],
                frameon=False,
            )
            if sweep is not None:
                ax.set_title(str(sweep))
            stem = "fig_" + "_".join(m.replace(".", "_") for m in metrics)
            written.append(canvas.save(fig, stem + ("" if sweep is None else f"_{sweep}")))
    return written


def _boxes_figure(df: pd.DataFrame, figure: Figure, canvas: Canvas) -> list[Path]:
    shown = _numeric(df, figure.metrics)
    if not shown:
        return []
    strategies, labels, colors, per, x = _strategies(df)
    with plt.rc_context(STYLE):
        cols = min(3, len(shown))
        rows = -(-len(shown) // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(PAGE_IN, 2.3 * rows), squeeze=False)
        for ax, metric in zip(axes.flat, shown):
            _boxes(ax, [per[g][metric].dropna() for g in strategies], x, 0.6, colors)
            ax.set_xticks(x, labels, rotation=30, ha="right")
            ax.set_title(canvas.label(metric))
            if metric.startswith("network") or metric == "negotiations":
                _log_counts(ax)
        for ax in list(axes.flat)[len(shown) :]:
            ax.set_visible(False)
        fig.tight_layout()
        return [canvas.save(fig, "fig_boxplots")]


def _scatter(df: pd.DataFrame, figure: Figure, canvas: Canvas) -> list[Path]:
    y, x_metric = figure.metrics[:2]
    if not {y, x_metric} <= set(df.columns):
        return []
    strategies, *_ = _strategies(df)
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_IN, 2.8))
        for g in strategies:
            rows = df[df[ALLOCATOR] == g]
            ax.scatter(
                rows[x_metric],
                rows[y],
                s=10,
                color=strategy_color(g),
                label=strategy_label(g),
                alpha=0.8,
                linewidths=0,
            )
        if x_metric.startswith("network"):
            _log_counts(ax, "x")
            ax.set_xlabel(canvas.label(x_metric) + " (symlog: 0 shown)")
        else:
            ax.set_xlabel(canvas.label(x_metric))
        ax.set_ylabel(canvas.label(y))
        ax.legend(frameon=False, ncol=2)
        short = {"network.messages_sent": "messages", "network.bytes_sent": "bytes"}
        return [canvas.save(fig, f"fig_{y}_vs_{short.get(x_metric, x_metric.replace('.', '_'))}")]


def _against_count(df: pd.DataFrame, figure: Figure, canvas: Canvas) -> list[Path]:
    """Each metric's mean per allocator against each count the sweeps vary, on log axes."""
    written = []
    strategies, *_ = _strategies(df)
    with plt.rc_context(STYLE):
        for key in figure.over:
            counts = df.get("agents" if key == AGENTS else key)
            if counts is None or counts.nunique() < 2:
                continue
            name = key.split(".")[-1] if key != AGENTS else "robots"
            for metric in figure.metrics:
                if metric not in df:
                    continue
                fig, ax = plt.subplots(figsize=(COLUMN_IN, 2.6))
                for g in strategies:
                    groups = df[df[ALLOCATOR] == g].groupby(counts)[metric]
                    means = groups.mean()
                    cis = [ci95(v) for _, v in groups]
                    err = [[m - lo for m, (lo, _) in zip(means, cis)], [hi - m for m, (_, hi) in zip(means, cis)]]
                    ax.errorbar(
                        means.index,
                        means.to_numpy(),
                        yerr=np.nan_to_num(err),
                        marker="o",
                        ms=3,
                        capsize=2,
                        color=strategy_color(g),
                        label=strategy_label(g),
                    )
                counted = metric.startswith("network") or metric == "negotiations"
                if counted:
                    _log_counts(ax)
                ax.set_xscale("log")
                ticks = sorted(counts.dropna().unique())
                ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
                ax.xaxis.set_minor_locator(NullLocator())
                ax.set_xlabel(f"{name} (log)")
                ax.set_ylabel(canvas.label(metric) + (" (symlog)" if counted else " (mean, 95 % CI)"))
                ax.legend(frameon=False, ncol=2)
                short = {"network.messages_sent": "messages", "network.bytes_sent": "bytes"}
                stem = short.get(metric, metric.replace(".", "_"))
                written.append(canvas.save(fig, f"fig_{stem}_vs_{name}"))
    return written


def _against_factor(df: pd.DataFrame, figure: Figure, canvas: Canvas) -> list[Path]:
    """For each numeric factor a sweep varies other than the allocator and the counts (the tick
    length of the dt study, a failure rate): the metric per allocator against it, mean and 95 % CI."""
    metric = figure.metrics[0]
    if metric not in df:
        return []
    strategies, *_ = _strategies(df)
    written = []
    skip = (ALLOCATOR, "allocator.name", AGENTS, *canvas.counts)
    factors = [f for f in df.attrs.get("factors", []) if f in df and f not in skip]
    with plt.rc_context(STYLE):
        for factor in factors:
            values = pd.to_numeric(df[factor], errors="coerce")
            if values.isna().any() or values.nunique() < 2:
                continue
            fig, ax = plt.subplots(figsize=(COLUMN_IN, 2.6))
            for g in strategies:
                sub = df[df[ALLOCATOR] == g]
                xs = sorted(values[sub.index].unique())
                means = [sub.loc[values[sub.index] == v, metric].mean() for v in xs]
                cis = [ci95(sub.loc[values[sub.index] == v, metric]) for v in xs]
                ax.errorbar(
                    xs,
                    means,
                    yerr=np.nan_to_num(
                        [[m - lo for m, (lo, _) in zip(means, cis)], [hi - m for m, (_, hi) in zip(means, cis)]]
                    ),
                    marker="o",
                    ms=3,
                    capsize=2,
                    color=strategy_color(g),
                    label=strategy_label(g),
                )
            ax.set_xlabel(factor)
            ax.set_ylabel(canvas.label(metric) + " (mean, 95 % CI)")
            ax.legend(frameon=False)
            written.append(canvas.save(fig, f"fig_{metric}_vs_{factor.replace('.', '_')}"))
    return written


DRAW = {
    "by_range": _by_range,
    "means": _means,
    "boxes": _boxes_figure,
    "scatter": _scatter,
    "against_count": _against_count,
    "against_factor": _against_factor,
}


def scenario_class(kind: Any, trusted: bool = False) -> type[Scenario]:
    """The registered class of a sweep's ``scenario_kind``; the base class for one not registered here
    (its runs still get the summary table and a box per allocator of each outcome metric). A name read
    from a results folder is never imported: see :func:`registered_scenario`."""
    return registered_scenario(kind, trusted)


def figures_of(cls: type[Scenario]) -> tuple[Figure, ...]:
    """The figures a scenario names, or one box per allocator of each of its outcome metrics."""
    return cls.figures or (Figure("boxes", tuple(cls.outcome_metrics)),)


def analyze(
    sweep_dirs: list[Path] | Path,
    control: str | None = None,
    mixed_versions_ok: bool = False,
    trusted: bool = False,
    progress: bool = False,
) -> list[Path]:
    """Tables and figures from sweep directories, written to the first. The figures and the metric
    labels are the ones each scenario names (``Scenario.figures``, ``Scenario.metric_labels``).
    ``control``: the allocator the others are compared with (default: the scenario's
    ``control_allocator`` where the sweeps have it); one the sweeps do not have is refused before
    anything is written. Runs of one scenario or allocator made in two versions are refused unless
    ``mixed_versions_ok``."""
    dirs = [sweep_dirs] if isinstance(sweep_dirs, Path) else list(sweep_dirs)
    out = dirs[0]
    df = load(dirs, mixed_versions_ok, trusted)
    if control is not None and control not in set(df[ALLOCATOR]):
        raise AnalyzeError(
            f"--control {control}: no such strategy in these sweeps "
            f"(they have: {', '.join(sorted(set(df[ALLOCATOR])))})"
        )
    for stale in ("statistics.csv", "statistics.md"):  # never leave an earlier analysis's statistics
        safefiles.remove(out / stale)
    if "scenario_kind" not in df:
        df["scenario_kind"] = ""
    _group_by_setting(df)
    kinds = sorted(df["scenario_kind"].fillna("").astype(str).unique())
    summaries, tables, written = [], [], []
    total = sum(len(figures_of(scenario_class(kind, trusted))) for kind in kinds)
    bar = Progress(total, "analyze", "figures", enabled=progress)
    for kind in kinds:
        rows = df[df["scenario_kind"].fillna("").astype(str) == kind].copy()
        rows.attrs = df.attrs
        cls = scenario_class(kind, trusted)
        labels = {**(cls.metric_labels or {m: m.replace("_", " ") for m in cls.outcome_metrics}), **NETWORK_LABELS}
        summaries.append(scenario_summary(rows, labels, cls.capped_by))
        chosen = control or cls.control_allocator
        if chosen is not None:
            for sweep, group in rows.groupby("group", sort=True):
                if group[ALLOCATOR].nunique() > 1 and chosen in set(group[ALLOCATOR]):
                    t = compare(group, ALLOCATOR, _numeric(group, tuple(labels)), chosen)
                    t.insert(0, "sweep", sweep)
                    tables.append(t)
        figures = figures_of(cls)
        counts = tuple(k for f in figures for k in f.over)
        canvas = Canvas(out, f"{kind}_" if len(kinds) > 1 else "", labels, counts)
        for figure in figures:
            written += DRAW[figure.kind](rows, figure, canvas)
            bar.update(bar.done + 1, figure.kind)
    bar.close()
    summary = pd.concat(summaries, ignore_index=True)
    safefiles.write_text(out / "scenario_summary.csv", summary.to_csv(index=False))
    safefiles.write_text(out / "scenario_summary.md", to_markdown(summary))
    head = [out / "scenario_summary.csv", out / "scenario_summary.md"]
    if tables:
        table = pd.concat(tables, ignore_index=True)
        safefiles.write_text(out / "statistics.csv", table.to_csv(index=False))
        safefiles.write_text(out / "statistics.md", to_markdown(table))
        head += [out / "statistics.csv", out / "statistics.md"]
    return head + written
