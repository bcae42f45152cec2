"""``swarmbed analyze SWEEP_DIR [SWEEP_DIR ...]``: tables and figures from sweeps' ``sweep.parquet`` (or ``sweep.csv``).

- ``scenario_summary.csv`` / ``.md``: per scenario and metric, n, mean, sd, median and the 95 %
  confidence interval of the mean (Student t).
- MT-SR sweeps: SPACE Fig. 3 panels, one PNG per metric (mission time and time to 99 %: one value
  per run; travel distance and workload per agent: one value per agent, pooled over the runs):
  boxplots by communication range, one group per algorithm, one panel per agent count. Sweeps
  without those factors get one box per scenario instead.
- Search-and-rescue sweeps (CBBA-ETC Section 5.4): ``statistics.csv`` / ``.md`` (one-way ANOVA
  across strategies, Dunnett's test and Cohen's d against a control strategy, cbba-etc by
  default), mean rescued and expired per trial with 95 % CI bars, boxplots per trial, rescued
  against messages sent; given several sweeps (e.g. the victim-count or robot-count series),
  messages per trial on a log scale against victim count and robot count.

With several directories, the first one receives the outputs.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import yaml  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import NullLocator  # noqa: E402
from scipy import stats  # noqa: E402

from swarmbed.experiments.folders import PARQUET, SPEC, TABLE, read_table  # noqa: E402
from swarmbed.experiments.views.colours import STRATEGY_ORDER, strategy_color, strategy_label  # noqa: E402
from swarmbed.experiments.views.pooling import mixed_configurations, mixed_versions  # noqa: E402
from swarmbed.experiments.views.stats import compare  # noqa: E402

METRICS = {
    "mission_time": "mission completion time (s)",
    "time_99": "time to 99 % of tasks (s)",
    "distance_per_agent_mean": "average distance per agent",
    "work_per_agent_mean": "average work per agent",
    "tasks_completed": "tasks completed",
    "network.messages_sent": "messages sent",
    "network.bytes_sent": "payload bytes sent",
}
# SPACE's per-agent panels: one value per agent, pooled over a scenario's runs (read from each run's
# summary.json). A run's mean work per agent is its total work over N, the same for every allocator
# that completes the mission; how the work is shared out is what tells allocators apart.
PER_AGENT = {"distance_per_agent": "travel distance per agent", "work_per_agent": "workload per agent"}
AGENTS, RANGE, ALLOCATOR = "agents.count", "network.range", "allocator"
SAR_METRICS = {
    "rescued": "victims rescued per trial",
    "expired": "victims expired per trial",
    "failed_rescues": "failed rescues (mismatch found) per trial",
    "negotiations": "negotiations per trial",
    "network.messages_sent": "messages sent per trial",
    "network.bytes_sent": "payload bytes sent per trial",
}


DEFAULT_CONTROL = "cbba-etc"


class AnalyzeError(ValueError):
    pass


def load(sweep_dirs: list[Path], mixed_versions_ok: bool = False) -> pd.DataFrame:
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
        df = read_table(sweep_dir)
        mixed = mixed_configurations(sweep_dir, df)
        if mixed:
            raise AnalyzeError(
                f"{sweep_dir}: {mixed}; a scenario's runs may differ only in their seed "
                "(redo them with swarmbed sweep ... --redo-mismatched)"
            )
        meta = json.loads(spec.read_text())
        df["sweep"] = meta["name"]
        df["run_dir"] = [str(sweep_dir / str(sc) / f"run_{int(r):03d}") for sc, r in zip(df["scenario"], df["run"])]
        _resolve_series_keys(df, sweep_dir)
        factors += [f for f in meta.get("factors", []) if f not in factors]
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
    if len(sweep_dirs) > 1:
        df["scenario"] = df["sweep"] + "/" + df["scenario"]
    df.attrs["factors"] = factors
    return df


SERIES_KEYS = ("scenario.victims",)  # read from each run's config where a sweep does not vary them


def _resolve_series_keys(df: pd.DataFrame, sweep_dir: Path) -> None:
    """A sweep that leaves a series key at its base's value (the V100 of a victim-count series) gets
    the value its runs used, from their resolved ``config.yaml``, so that series line up."""
    for key in SERIES_KEYS:
        if key in df and df[key].notna().all():
            continue
        first_run = df.groupby("scenario")["run"].min()  # a scenario's runs differ only in their seed
        used = {
            scenario: _config_value(sweep_dir / str(scenario) / f"run_{int(run):03d}" / "config.yaml", key)
            for scenario, run in first_run.items()
        }
        values = df["scenario"].map(used)
        df[key] = df[key].fillna(values) if key in df else values


def _config_value(config: Path, key: str) -> Any:
    """The value of dotted ``key`` in a run's resolved config, or NaN where it cannot be read."""
    try:
        value: Any = yaml.safe_load(config.read_text())
        for part in key.split("."):
            value = value[part]
    except (OSError, KeyError, TypeError, yaml.YAMLError):
        return np.nan
    return value


def _ci(values: pd.Series) -> tuple[float, float]:
    v = values.dropna().to_numpy(dtype=float)
    if len(v) < 2:
        return (float("nan"), float("nan"))
    half = stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v))
    return float(v.mean() - half), float(v.mean() + half)


def scenario_summary(df: pd.DataFrame, metrics: dict) -> pd.DataFrame:
    rows = []
    for scenario, group in df.groupby("scenario", sort=True):
        for metric in metrics:
            if metric not in group:
                continue
            v = group[metric].dropna().astype(float)
            lo, hi = _ci(v)
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
        return json.loads(value).get("name", value)
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
    for ext in ("pdf", "svg"):
        fig.savefig(out / f"{stem}.{ext}")
    fig.savefig(out / f"{stem}.png", dpi=200)
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
    """One value per run, or for a :data:`PER_AGENT` metric one per agent of every run."""
    if metric not in PER_AGENT:
        return rows[metric].dropna()
    values: list[float] = []
    for run_dir in rows["run_dir"]:
        values += json.loads((Path(run_dir) / "summary.json").read_text()).get(metric, [])
    return pd.Series(values, dtype=float)


def fig3(df: pd.DataFrame, metric: str, out: Path) -> Path | None:
    if metric not in PER_AGENT and (metric not in df or df[metric].dropna().empty):
        return None
    label = PER_AGENT.get(metric) or METRICS[metric]
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
            ranges = sorted(df[RANGE].unique())
            fig, axes = plt.subplots(1, len(counts), figsize=(PAGE_IN, 2.4), sharey=True, squeeze=False)
            width = 0.8 / len(algos)
            for ax, n in zip(axes[0], counts):
                sub = df[df[AGENTS] == n]
                for a, algo in enumerate(algos):
                    data = [_values(sub[(sub[RANGE] == r) & (sub[ALLOCATOR] == algo)], metric) for r in ranges]
                    pos = np.arange(len(ranges)) + (a - (len(algos) - 1) / 2) * width
                    _boxes(ax, data, pos, width * 0.85, [strategy_color(algo)] * len(ranges))
                    ax.plot([], [], color=strategy_color(algo), lw=5, alpha=0.75, label=strategy_label(algo))
                ax.set_xticks(range(len(ranges)), [str(r) for r in ranges])
                ax.set_xlabel("communication range")
                ax.set_title(f"{n} agents")
            axes[0][0].set_ylabel(label)
            axes[0][-1].legend(frameon=False)
        return _save(fig, out, f"fig_{metric.replace('.', '_')}")


def _sar_figures(df: pd.DataFrame, out: Path) -> list[Path]:
    written = []
    strategies = _ordered(df[ALLOCATOR].unique())
    labels = [strategy_label(g) for g in strategies]
    colors = [strategy_color(g) for g in strategies]
    per = {g: df[df[ALLOCATOR] == g] for g in strategies}
    x = np.arange(len(strategies))
    with plt.rc_context(STYLE):
        # mean rescued and expired per trial with 95 % CI bars: rescued filled, expired hatched; one
        # figure per sweep where there are several (a failure level's trials are not pooled with another's)
        sweeps = sorted(df["sweep"].unique()) if "sweep" in df and df["sweep"].nunique() > 1 else [None]
        for sweep in sweeps:
            chosen = per if sweep is None else {g: per[g][per[g]["sweep"] == sweep] for g in strategies}
            fig, ax = plt.subplots(figsize=(COLUMN_IN, 2.6))
            for k, metric in enumerate(("rescued", "expired")):
                means = np.array([chosen[g][metric].mean() for g in strategies])
                cis = [_ci(chosen[g][metric]) for g in strategies]
                err = [[m - lo for m, (lo, _) in zip(means, cis)], [hi - m for m, (_, hi) in zip(means, cis)]]
                ax.bar(
                    x + (k - 0.5) * 0.4,
                    means,
                    0.4,
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
            ax.set_ylabel("victims per trial (mean, 95 % CI)")
            ax.legend(
                handles=[
                    Patch(facecolor="0.5", alpha=0.85, edgecolor="0.2", linewidth=0.5, label="rescued"),
                    Patch(facecolor="0.5", alpha=0.35, hatch="///", edgecolor="0.2", linewidth=0.5, label="expired"),
                ],
                frameon=False,
            )
            if sweep is not None:
                ax.set_title(str(sweep))
            written.append(_save(fig, out, "fig_rescued_expired" + ("" if sweep is None else f"_{sweep}")))
        # boxplots per trial
        shown = [m for m in SAR_METRICS if m in df]
        cols = min(3, len(shown))
        rows = -(-len(shown) // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(PAGE_IN, 2.3 * rows), squeeze=False)
        for ax, metric in zip(axes.flat, shown):
            _boxes(ax, [per[g][metric].dropna() for g in strategies], x, 0.6, colors)
            ax.set_xticks(x, labels, rotation=30, ha="right")
            ax.set_title(SAR_METRICS[metric])
            if metric.startswith("network") or metric == "negotiations":
                _log_counts(ax)
        for ax in list(axes.flat)[len(shown) :]:
            ax.set_visible(False)
        fig.tight_layout()
        written.append(_save(fig, out, "fig_boxplots"))
        # rescued against messages sent
        fig, ax = plt.subplots(figsize=(COLUMN_IN, 2.8))
        for g in strategies:
            ax.scatter(
                per[g]["network.messages_sent"],
                per[g]["rescued"],
                s=10,
                color=strategy_color(g),
                label=strategy_label(g),
                alpha=0.8,
                linewidths=0,
            )
        _log_counts(ax, "x")
        ax.set_xlabel("messages sent per trial (symlog: 0 shown)")
        ax.set_ylabel("victims rescued per trial")
        ax.legend(frameon=False, ncol=2)
        written.append(_save(fig, out, "fig_rescued_vs_messages"))
        # messages and rescues against victim count and robot count (when the sweeps vary them)
        for key, label in (("scenario.victims", "victims"), (AGENTS, "robots")):
            counts = df.get("agents" if key == AGENTS else key)
            if counts is None or counts.nunique() < 2:
                continue
            for metric, ylabel, stem in (
                ("network.messages_sent", "messages sent per trial (symlog)", "messages"),
                ("rescued", "victims rescued per trial (mean, 95 % CI)", "rescued"),
            ):
                fig, ax = plt.subplots(figsize=(COLUMN_IN, 2.6))
                for g in strategies:
                    groups = df[df[ALLOCATOR] == g].groupby(counts)[metric]
                    means = groups.mean()
                    cis = [_ci(v) for _, v in groups]
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
                if stem == "messages":
                    _log_counts(ax)
                ax.set_xscale("log")
                ticks = sorted(counts.dropna().unique())
                ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
                ax.xaxis.set_minor_locator(NullLocator())
                ax.set_xlabel(f"{label} (log)")
                ax.set_ylabel(ylabel)
                ax.legend(frameon=False, ncol=2)
                written.append(_save(fig, out, f"fig_{stem}_vs_{label}"))
        written += _factor_figures(df, out, strategies)
    return written


def _factor_figures(df: pd.DataFrame, out: Path, strategies: list[str]) -> list[Path]:
    """For each numeric factor a sweep varies other than the agent and victim counts (the tick
    length of the dt study, a failure rate): the outcome per strategy against it, mean and 95 % CI."""
    written = []
    factors = [
        f
        for f in df.attrs.get("factors", [])
        if f in df and f not in (ALLOCATOR, "allocator.name", AGENTS, "scenario.victims")
    ]
    for factor in factors:
        values = pd.to_numeric(df[factor], errors="coerce")
        if values.isna().any() or values.nunique() < 2:
            continue
        fig, ax = plt.subplots(figsize=(COLUMN_IN, 2.6))
        for g in strategies:
            sub = df[df[ALLOCATOR] == g]
            xs = sorted(values[sub.index].unique())
            means = [sub.loc[values[sub.index] == v, "rescued"].mean() for v in xs]
            cis = [_ci(sub.loc[values[sub.index] == v, "rescued"]) for v in xs]
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
        ax.set_ylabel("victims rescued per trial (mean, 95 % CI)")
        ax.legend(frameon=False)
        written.append(_save(fig, out, f"fig_rescued_vs_{factor.replace('.', '_')}"))
    return written


def analyze(sweep_dirs: list[Path] | Path, control: str | None = None, mixed_versions_ok: bool = False) -> list[Path]:
    """Tables and figures from sweep directories, written to the first. ``control``: the strategy
    the others are compared with (default: cbba-etc where the sweeps have it); one the sweeps do
    not have is refused before anything is written. Runs of one scenario or allocator made in two
    versions are refused unless ``mixed_versions_ok``."""
    dirs = [sweep_dirs] if isinstance(sweep_dirs, Path) else list(sweep_dirs)
    out = dirs[0]
    df = load(dirs, mixed_versions_ok)
    sar = "rescued" in df
    if control is not None and control not in set(df[ALLOCATOR]):
        raise AnalyzeError(
            f"--control {control}: no such strategy in these sweeps "
            f"(they have: {', '.join(sorted(set(df[ALLOCATOR])))})"
        )
    control = control or DEFAULT_CONTROL
    for stale in ("statistics.csv", "statistics.md"):  # never leave an earlier analysis's statistics
        (out / stale).unlink(missing_ok=True)
    written = []
    summary = scenario_summary(df, SAR_METRICS if sar else METRICS)
    summary.to_csv(out / "scenario_summary.csv", index=False)
    (out / "scenario_summary.md").write_text(to_markdown(summary))
    written += [out / "scenario_summary.csv", out / "scenario_summary.md"]
    if sar:
        if "scenario.victims" not in df:
            df["scenario.victims"] = np.nan
        tables = []
        for sweep, group in df.groupby("sweep", sort=True):
            if group[ALLOCATOR].nunique() > 1 and control in set(group[ALLOCATOR]):
                t = compare(group, ALLOCATOR, [m for m in SAR_METRICS if m in group], control)
                t.insert(0, "sweep", sweep)
                tables.append(t)
        if tables:
            table = pd.concat(tables, ignore_index=True)
            table.to_csv(out / "statistics.csv", index=False)
            (out / "statistics.md").write_text(to_markdown(table))
            written += [out / "statistics.csv", out / "statistics.md"]
        written += _sar_figures(df, out)
        return written
    for metric in ("mission_time", "time_99", *PER_AGENT):
        path = fig3(df, metric, out)
        if path:
            written.append(path)
    return written
