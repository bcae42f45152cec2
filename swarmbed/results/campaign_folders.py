"""The files of a sweep folder and of a soak folder: one place that names them for the campaigns that
write them and the views that read them (a run folder's files are named in ``swarmbed.records.run_folder``).

A sweep folder holds ``sweep.json`` (what was planned), one folder per scenario with a ``run_NNN``
folder per run, and, once the sweep stops, ``sweep.csv`` and ``sweep.parquet`` (every run's summary
flattened, one row per run). A soak folder holds its process and run samples, its chaos events and
its verdict.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from swarmbed.records.run_folder import RunFileError, env_limit, read_table_member

# a sweep folder
SPEC = "sweep.json"  # the sweep as planned: name, base, seed, runs, scenarios and their overrides
TABLE = "sweep.csv"
PARQUET = "sweep.parquet"
ATTEMPTS = "attempts.jsonl"  # in each run folder: one line per attempt at the run
ERROR = "error.txt"  # in a run folder whose run failed

# a soak folder
SOAK_PROCESSES = "soak_processes.csv"
SOAK_RUN = "soak_run.csv"
SOAK_VERDICT = "soak_verdict.json"
CHAOS = "chaos.csv"


#: what ``analyze`` and ``report`` made from a sweep's table: stale once the table is written anew
DERIVED = ("fig_*", "scenario_summary.*", "statistics.*", "report.html")


#: the columns every sweep table has; a file without them is not one
TABLE_COLUMNS = ("scenario", "run", "status")
#: the most bytes of a sweep's table analyze and report read (a row is 1.5-4 kB: 15,000-40,000 runs;
#: a 200 MB table took minutes and 600 MB); ``SWARMBED_MAX_SWEEP_TABLE_BYTES`` raises it
MAX_SWEEP_TABLE_BYTES = 64 << 20


def max_sweep_table_bytes() -> int:
    return env_limit("SWARMBED_MAX_SWEEP_TABLE_BYTES", MAX_SWEEP_TABLE_BYTES)


def read_table(sweep_dir: Path) -> pd.DataFrame:
    """A sweep's table: ``sweep.parquet`` where it is at least as new as ``sweep.csv``, else the CSV;
    the other one where the first cannot be read (torn, a link out of the folder, another shape).
    A RunFileError naming both files when neither can."""
    parquet, csv = sweep_dir / PARQUET, sweep_dir / TABLE
    order = [PARQUET, TABLE]
    if not parquet.exists() or (csv.exists() and parquet.stat().st_mtime_ns < csv.stat().st_mtime_ns):
        order.reverse()
    problems = []
    for name in order:
        if not (sweep_dir / name).exists():
            continue
        try:
            table = read_table_member(sweep_dir, name, max_sweep_table_bytes())
        except RunFileError as exc:
            problems.append(str(exc))
            continue
        missing = [c for c in TABLE_COLUMNS if c not in table.columns]
        if missing:
            problems.append(f"{sweep_dir / name}: not a sweep table (no column {missing[0]!r})")
            continue
        return table
    raise RunFileError("; ".join(problems) or f"{sweep_dir}: no {TABLE} or {PARQUET}")


def dotted(data: Any, prefix: str = "") -> dict[str, Any]:
    """A nested mapping as one level of ``dotted.keys`` (what a config's keys look like in a sweep's columns)."""
    if isinstance(data, dict):
        return {k: v for key, value in data.items() for k, v in dotted(value, f"{prefix}{key}.").items()}
    return {prefix.rstrip("."): data}
