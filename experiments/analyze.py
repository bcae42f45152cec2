"""``swarmbed analyze SWEEP_DIR``: tables and figures from a sweep's ``sweep.csv``.

- ``scenario_summary.csv`` / ``.md``: per scenario and metric, n, mean, sd, median and the 95 %
  confidence interval of the mean (Student t).
- SPACE Fig. 3 panels, one PNG per metric (mission time, time to 99 %, distance per agent, work per
  agent): boxplots by communication range, one group per algorithm, one panel per agent count.
  Sweeps without those factors get one box per scenario instead.
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

from experiments.sweep import SPEC, TABLE  # noqa: E402

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


class AnalyzeError(ValueError):
    pass


def load(sweep_dir: Path) -> tuple[pd.DataFrame, dict]:
    table, spec = sweep_dir / TABLE, sweep_dir / SPEC
    if not table.exists() or not spec.exists():
        raise AnalyzeError(f"{sweep_dir}: no {TABLE} / {SPEC}; run `swarmbed sweep` into it first")
    df = pd.read_csv(table)
    meta = json.loads(spec.read_text())
    df = df[df["status"] == "ok"].copy()
    if df.empty:
        raise AnalyzeError(f"{sweep_dir}: no completed run to analyze")
    df[ALLOCATOR] = df["allocator"] if "allocator" in df else df.get("allocator.name", "")
    return df, meta


def _ci(values: pd.Series) -> tuple[float, float]:
    v = values.dropna().to_numpy(dtype=float)
    if len(v) < 2:
        return (float("nan"), float("nan"))
    half = stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v))
    return float(v.mean() - half), float(v.mean() + half)


def scenario_summary(df: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for scenario, group in df.groupby("scenario", sort=True):
        for metric in METRICS:
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
        algos = sorted(df[ALLOCATOR].map(_allocator_label).unique())
        counts = sorted(df[AGENTS].unique())
        ranges = sorted(df[RANGE].unique())
        fig, axes = plt.subplots(1, len(counts), figsize=(4.2 * len(counts), 4), sharey=True, squeeze=False)
        width = 0.8 / len(algos)
        colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for ax, n in zip(axes[0], counts):
            sub = df[df[AGENTS] == n]
            for a, algo in enumerate(algos):
                data = [sub.loc[(sub[RANGE] == r) & (sub[ALLOCATOR].map(_allocator_label) == algo), metric].dropna()
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


def analyze(sweep_dir: Path) -> list[Path]:
    df, _meta = load(sweep_dir)
    written = []
    summary = scenario_summary(df)
    summary.to_csv(sweep_dir / "scenario_summary.csv", index=False)
    (sweep_dir / "scenario_summary.md").write_text(to_markdown(summary))
    written += [sweep_dir / "scenario_summary.csv", sweep_dir / "scenario_summary.md"]
    for metric in ("mission_time", "time_99", "distance_per_agent_mean", "work_per_agent_mean"):
        path = fig3(df, metric, sweep_dir)
        if path:
            written.append(path)
    return written
