"""A table of a sweep's cells, one row per scenario and allocator, from the sweep's table
(sweep.csv): each metric's mean over the cell's completed runs with the range of its runs, and the
number of runs (docs/baselines.md, docs/teams.md).

    python docs/scripts/cell_table.py runs/central_baselines
    python docs/scripts/cell_table.py runs/space_stmr_sweep tasks_completed team_wait_total

With metric names after the folder, those columns (any column of sweep.csv); else mission time,
time to 95 %, tasks done, messages and payload megabytes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

DEFAULT = ("mission_time", "time_95", "tasks_completed", "network.messages_sent", "network.bytes_sent")
LABELS = {
    "mission_time": "mission time (s)",
    "time_95": "time to 95 % (s)",
    "tasks_completed": "tasks done",
    "network.messages_sent": "messages sent",
    "network.bytes_sent": "bytes sent (MB)",
    "team_wait_total": "robot-s waiting for a team",
    "distance_total": "distance, all robots (m)",
}
SCALE = {"network.bytes_sent": 1e-6}


def _cell(values: pd.Series, scale: float) -> str:
    v = values.dropna().astype(float) * scale
    if v.empty:
        return "-"
    digits = 1 if scale != 1 or v.abs().max() < 1000 else 0
    mean = f"{v.mean():,.{digits}f}"
    return mean if len(v) == 1 or v.min() == v.max() else f"{mean} ({v.min():,.{digits}f}-{v.max():,.{digits}f})"


def table(sweep: Path, metrics: tuple[str, ...] = DEFAULT) -> str:
    runs = pd.read_csv(sweep / "sweep.csv")
    runs = runs[runs["status"] == "ok"]
    heads = " | ".join(LABELS.get(m, m) for m in metrics)
    rule = "| --- | --- | ---: | " + " | ".join("---:" for _ in metrics) + " |"
    lines = [f"| cell | allocator | runs | {heads} |", rule]
    for scenario, rows in runs.groupby("scenario", sort=False):
        cell, allocator = str(scenario).split("_allocator-", 1)
        cells = [_cell(rows[m], SCALE.get(m, 1.0)) if m in rows else "-" for m in metrics]
        lines.append(f"| {cell} | {allocator} | {len(rows)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(table(Path(sys.argv[1]), tuple(sys.argv[2:]) or DEFAULT))
