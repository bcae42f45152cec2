"""A paired table of two cells of a sweep, allocator by allocator, run r of one against run r of the
other (the same seed): docs/walls.md's walls against no walls, docs/reproduction.md's time-sink
levels against today's world. From the sweep's table (sweep.csv); a cell is ``<name>_allocator-<a>``.
Each entry: the two means, then the paired difference with its 95 % confidence interval (t) and
the Wilcoxon signed-rank test's p.

    python docs/scripts/paired_table.py runs/walls_office_sweep walls open
    python docs/scripts/paired_table.py runs/walls_rubble_sweep rubble open
    python docs/scripts/paired_table.py runs/timesink_m3 abandon5 abandon0
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

from swarmbed.results.analyze import ci95
from swarmbed.results.stats import paired_p

MTSR = {
    "mission_time": "mission time (s)",
    "time_95": "time to 95 % (s)",
    "network.messages_sent": "messages",
    "network.bytes_sent": "payload bytes",
    "network.delivered": "copies delivered",
}
SAR = {
    "rescued": "rescued",
    "failed_rescues": "failed rescues",
    "expired": "expired",
    "network.messages_sent": "messages",
    "network.dropped.blocked_by_wall": "blocked by wall",
    "network.delivered": "copies delivered",
}


def table(sweep: Path, walled: str, open_: str) -> str:
    runs = pd.read_csv(sweep / "sweep.csv")
    runs = runs[runs["status"] == "ok"]
    metrics = SAR if (runs["scenario_kind"] == "sar").all() else MTSR
    metrics = {key: label for key, label in metrics.items() if key in runs}  # no wall column without walls
    heads = " | ".join(f"{label}: {walled} / {open_}" for label in metrics.values())
    lines = [
        f"| allocator | n | {heads} |",
        "| --- | ---: | " + " | ".join("---" for _ in metrics) + " |",
    ]
    done = "all_tasks_completed" in runs
    for allocator in dict.fromkeys(runs["allocator"]):
        a = runs[runs["scenario"] == f"{walled}_allocator-{allocator}"].set_index("run")
        b = runs[runs["scenario"] == f"{open_}_allocator-{allocator}"].set_index("run")
        if a.empty or b.empty:
            continue
        both = a.index.intersection(b.index)
        cells = []
        for key in metrics:
            x, y = a.loc[both, key].astype(float).fillna(0), b.loc[both, key].astype(float).fillna(0)
            d = x - y
            half = d.mean() - ci95(d)[0]
            p = paired_p(x.to_numpy(), y.to_numpy())[1]
            cells.append(f"{x.mean():,.0f} / {y.mean():,.0f} ({d.mean():+,.0f} ± {half:,.0f}; p {p:.3f})")
        finished = (
            f" ({int(a.loc[both, 'all_tasks_completed'].sum())} / {int(b.loc[both, 'all_tasks_completed'].sum())} done)"
            if done
            else ""
        )
        lines.append(f"| {allocator} | {len(both)}{finished} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(table(Path(sys.argv[1]), sys.argv[2], sys.argv[3]))
