"""Writing a run's result files so that a crash never leaves a half-written file looking complete:
each file goes to a temporary name and is renamed into place; ``summary.json`` is written last."""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

SUMMARY = "summary.json"
TIMESERIES = "timeseries.csv"
AGENTS = "agents.csv"
TIMINGS = "timings.json"
TRANSPORT = "transport.json"  # measured bytes on the wire: of this machine and moment, not reproducible
CONFIG = "config.yaml"
TRAJECTORIES = "trajectories.csv"
MARKERS = "markers.csv"  # tasks or victims as they appear and vanish (with trajectories)


def write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "w", newline="") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def write_json(path: Path, data: Any) -> None:
    write_atomic(path, json.dumps(data, indent=2, sort_keys=True) + "\n")


def write_csv(path: Path, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> None:
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(columns)
        w.writerows(rows)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
