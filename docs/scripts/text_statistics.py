"""The CBBA-ETC paper's statistics (Section 5.4) as a markdown table, one per sweep setting, from the
``statistics.csv`` that ``swarmbed analyze`` wrote (docs/reproduction.md, section 9 and the 50-trial
tables): one row per strategy, one column per metric, each entry "mean (sd); Dunnett's p; Welch-Holm
p; Cohen's d; TOST p", the control's row its mean alone.

    swarmbed analyze runs/base_R20_V100 && python docs/scripts/text_statistics.py runs/base_R20_V100
    python docs/scripts/text_statistics.py runs/timesink_m3 rescued network.messages_sent

With metric names after the folder, those metrics (as named in statistics.csv); else rescued,
expired, failed rescues and messages sent. ``--series METRIC`` before several analysed folders puts
one metric of each in a column of one table (a series such as the density sweeps): each entry
"mean (Dunnett's p against the control)", the control's its mean alone.

    python docs/scripts/text_statistics.py --series rescued runs/base_R20_V25 runs/base_R20_V50
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

DEFAULT = ("rescued", "expired", "failed_rescues", "network.messages_sent")
LABELS = {"failed_rescues": "failed rescues", "network.messages_sent": "messages sent"}


def _p(p: float) -> str:
    if p != p:  # NaN
        return "-"
    return "< 1e-15" if p < 1e-15 else f"{p:.2g}" if p < 0.01 else f"{p:.2f}"


def _entry(row: pd.Series) -> str:
    mean = f"{row['mean']:,.1f} ({row['sd']:,.1f})"
    tests = (_p(row["dunnett_p"]), _p(row["welch_holm_p"]), f"{row['cohens_d']:+.2f}", _p(row["tost_p"]))
    return f"{mean}; " + "; ".join(tests)


def tables(folder: Path, metrics: tuple[str, ...] = DEFAULT) -> str:
    stats = pd.read_csv(folder / "statistics.csv")
    out = []
    for sweep, rows in stats.groupby("sweep", sort=True):
        rows = rows[rows["metric"].isin(metrics)]
        if rows.empty:
            continue
        present = [m for m in metrics if m in set(rows["metric"])]
        first = rows.iloc[0]
        n = int(rows["n"].max())
        out.append(
            f"**{sweep}** ({n} trials a strategy; ANOVA p: "
            + ", ".join(f"{LABELS.get(m, m)} {_p(rows.loc[rows['metric'] == m, 'anova_p'].iloc[0])}" for m in present)
            + ")\n"
        )
        out.append("| strategy | " + " | ".join(LABELS.get(m, m) for m in present) + " |")
        out.append("| --- | " + " | ".join("---" for _ in present) + " |")
        control = [f"{rows.loc[rows['metric'] == m, 'control_mean'].iloc[0]:,.1f}" for m in present]
        out.append(f"| {first['control']} (control) | " + " | ".join(control) + " |")
        by_strategy = rows.set_index(["strategy", "metric"])
        for strategy in sorted(set(rows["strategy"])):
            cells = [
                _entry(by_strategy.loc[(strategy, m)]) if (strategy, m) in by_strategy.index else "-" for m in present
            ]
            out.append(f"| {strategy} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def series(folders: list[Path], metric: str) -> str:
    """One table, one column per folder's sweep, of ``metric``'s mean and Dunnett's p."""
    columns: dict[str, dict[str, str]] = {}
    control = ""
    for folder in folders:
        stats = pd.read_csv(folder / "statistics.csv")
        for sweep, rows in stats[stats["metric"] == metric].groupby("sweep", sort=False):
            control = str(rows["control"].iloc[0])
            cells = {str(r["strategy"]): f"{r['mean']:,.1f} ({_p(r['dunnett_p'])})" for _, r in rows.iterrows()}
            cells[control] = f"{rows['control_mean'].iloc[0]:,.1f}"
            columns[f"{sweep} (n {int(rows['n'].max())})"] = cells
    if not columns:
        sys.exit(f"no sweep in {', '.join(map(str, folders))} has the metric {metric!r}")
    strategies = [control] + sorted({s for cells in columns.values() for s in cells} - {control})
    out = ["| strategy | " + " | ".join(columns) + " |", "| --- |" + " ---: |" * len(columns)]
    for strategy in strategies:
        label = f"{strategy} (control)" if strategy == control else strategy
        out.append(f"| {label} | " + " | ".join(c.get(strategy, "-") for c in columns.values()) + " |")
    return "\n".join(out)


def _analysed(folder: Path) -> Path:
    if not (folder / "statistics.csv").is_file():
        sys.exit(f"{folder}: no statistics.csv (run swarmbed analyze {folder} first)")
    return folder


def main() -> None:
    args = sys.argv[1:]
    if args[:1] == ["--series"] and len(args) >= 3:
        print(series([_analysed(Path(a)) for a in args[2:]], args[1]))
    elif args and not args[0].startswith("-"):
        print(tables(_analysed(Path(args[0])), tuple(args[1:]) or DEFAULT))
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
