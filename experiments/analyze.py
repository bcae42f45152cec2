"""``swarmbed analyze SWEEP_DIR [SWEEP_DIR ...]``: tables and figures from sweeps' ``sweep.parquet`` (or ``sweep.csv``).

- ``scenario_summary.csv`` / ``.md``: per scenario and metric, n, mean, sd, median and the 95 %
  confidence interval of the mean (Student t).
- MT-SR sweeps: SPACE Fig. 3 panels, one PNG per metric (mission time, time to 99 %, distance per
  agent, work per agent): boxplots by communication range, one group per algorithm, one panel per
  agent count. Sweeps without those factors get one box per scenario instead.
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

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy import stats  # noqa: E402

from swarmbed.experiments.stats import compare  # noqa: E402
from swarmbed.experiments.sweep import PARQUET, SPEC, TABLE, read_table  # noqa: E402

METRICS = {
    "mission_time": "mission completion time (s)",
    "time_99": "time to 99 % of tasks (s)",
    "distance_per_agent_mean": "average distance per agent",
    "work_per_agent_mean": "average work per agent",
    "tasks_completed": "tasks completed",
    "network.messages_sent": "messages sent",
    "network.bytes_sent": "payload bytes sent",
}
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


def load(sweep_dirs: list[Path]) -> pd.DataFrame:
    frames = []
    for sweep_dir in sweep_dirs:
        spec = sweep_dir / SPEC
        if not spec.exists() or not ((sweep_dir / TABLE).exists() or (sweep_dir / PARQUET).exists()):
            raise AnalyzeError(f"{sweep_dir}: no {TABLE} / {SPEC}; run `swarmbed sweep` into it first")
        df = read_table(sweep_dir)
        df["sweep"] = json.loads(spec.read_text())["name"]
        frames.append(df)
    df = pd.concat(frames, ignore_index=True)
    df = df[df["status"] == "ok"].copy()
    if df.empty:
        raise AnalyzeError(f"{', '.join(map(str, sweep_dirs))}: no completed run to analyze")
    df[ALLOCATOR] = df["allocator"].map(_allocator_label)  # every summary names its allocator
    if len(sweep_dirs) > 1:
        df["scenario"] = df["sweep"] + "/" + df["scenario"]
    return df


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
            rows.append({"scenario": scenario, "metric": metric, "n": len(v), "mean": v.mean(), "sd": v.std(ddof=1),
                         "median": v.median(), "ci95_low": lo, "ci95_high": hi})
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


def fig3(df: pd.DataFrame, metric: str, out: Path) -> Path | None:
    if metric not in df or df[metric].dropna().empty:
        return None
    have = all(c in df for c in (AGENTS, RANGE)) and df[ALLOCATOR].notna().all()
    if not have:
        fig, ax = plt.subplots(figsize=(max(4, 1.2 * df["scenario"].nunique()), 4))
        groups = sorted(df["scenario"].unique())
        ax.boxplot([df.loc[df["scenario"] == g, metric].dropna() for g in groups], tick_labels=groups)
        ax.set_ylabel(METRICS[metric])
        ax.tick_params(axis="x", rotation=30)
    else:
        algos = sorted(df[ALLOCATOR].unique())
        counts = sorted(df[AGENTS].unique())
        ranges = sorted(df[RANGE].unique())
        fig, axes = plt.subplots(1, len(counts), figsize=(4.2 * len(counts), 4), sharey=True, squeeze=False)
        width = 0.8 / len(algos)
        colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for ax, n in zip(axes[0], counts):
            sub = df[df[AGENTS] == n]
            for a, algo in enumerate(algos):
                data = [sub.loc[(sub[RANGE] == r) & (sub[ALLOCATOR] == algo), metric].dropna()
                        for r in ranges]
                pos = np.arange(len(ranges)) + (a - (len(algos) - 1) / 2) * width
                bp = ax.boxplot(data, positions=pos, widths=width * 0.9, patch_artist=True, manage_ticks=False)
                for box in bp["boxes"]:
                    box.set_facecolor(colors[a % len(colors)])
                    box.set_alpha(0.6)
                ax.plot([], [], color=colors[a % len(colors)], lw=6, alpha=0.6, label=algo)
            ax.set_xticks(range(len(ranges)), [str(r) for r in ranges])
            ax.set_xlabel("communication range")
            ax.set_title(f"{n} agents")
        axes[0][0].set_ylabel(METRICS[metric])
        axes[0][-1].legend()
    fig.tight_layout()
    path = out / f"fig_{metric.replace('.', '_')}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _sar_figures(df: pd.DataFrame, out: Path) -> list[Path]:
    written = []
    strategies = sorted(df[ALLOCATOR].unique())
    per = {g: df[df[ALLOCATOR] == g] for g in strategies}
    # mean rescued and expired per trial with 95 % CI bars
    fig, ax = plt.subplots(figsize=(1.4 * len(strategies) + 2, 4))
    x = np.arange(len(strategies))
    for k, (metric, label) in enumerate((("rescued", "rescued"), ("expired", "expired"))):
        means = [per[g][metric].mean() for g in strategies]
        cis = [_ci(per[g][metric]) for g in strategies]
        err = [[m - lo for m, (lo, _) in zip(means, cis)], [hi - m for m, (_, hi) in zip(means, cis)]]
        ax.bar(x + (k - 0.5) * 0.4, means, 0.4, yerr=np.nan_to_num(err), capsize=3, label=label)
    ax.set_xticks(x, strategies)
    ax.set_ylabel("victims per trial (mean, 95% CI)")
    ax.legend()
    fig.tight_layout()
    written.append(out / "fig_rescued_expired.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)
    # boxplots per trial
    shown = [m for m in SAR_METRICS if m in df]
    fig, axes = plt.subplots(1, len(shown), figsize=(3.2 * len(shown), 3.8), squeeze=False)
    for ax, metric in zip(axes[0], shown):
        ax.boxplot([per[g][metric].dropna() for g in strategies], tick_labels=strategies)
        ax.set_title(SAR_METRICS[metric], fontsize=9)
        ax.tick_params(axis="x", rotation=45)
        if metric.startswith("network") or metric == "negotiations":
            ax.set_yscale("symlog")
    fig.tight_layout()
    written.append(out / "fig_boxplots.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)
    # rescued against messages sent
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for g in strategies:
        ax.scatter(per[g]["network.messages_sent"] + 1, per[g]["rescued"], s=14, label=g)
    ax.set_xscale("log")
    ax.set_xlabel("messages sent per trial (+1, log)")
    ax.set_ylabel("victims rescued per trial")
    ax.legend(fontsize=8)
    fig.tight_layout()
    written.append(out / "fig_rescued_vs_messages.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)
    # messages against victim count and robot count (when the sweeps vary them)
    for key, label, name in (("scenario.victims", "victims", "fig_messages_vs_victims.png"),
                             (AGENTS, "robots", "fig_messages_vs_robots.png")):
        counts = df.get("agents" if key == AGENTS else key)
        if counts is None or counts.nunique() < 2:
            continue
        fig, ax = plt.subplots(figsize=(5.5, 4))
        for g in strategies:
            means = df[df[ALLOCATOR] == g].groupby(counts)["network.messages_sent"].mean()
            ax.plot(means.index, means.to_numpy() + 1, marker="o", label=g)
        ax.set_yscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("messages sent per trial (+1, log)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        written.append(out / name)
        fig.savefig(written[-1], dpi=110)
        plt.close(fig)
    return written


def analyze(sweep_dirs: list[Path] | Path, control: str | None = None) -> list[Path]:
    """Tables and figures from sweep directories, written to the first. ``control``: the strategy
    the others are compared with (default: cbba-etc where the sweeps have it); one the sweeps do
    not have is refused before anything is written."""
    dirs = [sweep_dirs] if isinstance(sweep_dirs, Path) else list(sweep_dirs)
    out = dirs[0]
    df = load(dirs)
    sar = "rescued" in df
    if control is not None and control not in set(df[ALLOCATOR]):
        raise AnalyzeError(f"--control {control}: no such strategy in these sweeps "
                           f"(they have: {', '.join(sorted(set(df[ALLOCATOR])))})")
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
    for metric in ("mission_time", "time_99", "distance_per_agent_mean", "work_per_agent_mean"):
        path = fig3(df, metric, out)
        if path:
            written.append(path)
    return written
