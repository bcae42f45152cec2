"""Writing a run's result files so that a crash never leaves a half-written file looking complete:
each file goes to a temporary name and is renamed into place; ``summary.json`` is written last."""

from __future__ import annotations

import csv
import json
import os
import threading
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from swarmbed.wire.rowfile import write_error
from swarmbed.wire.rundir import (  # noqa: F401 - the run directory's names, read as results.<NAME>
    AGENTS,
    CONFIG,
    MARKERS,
    SUMMARY,
    TIMESERIES,
    TIMINGS,
    TRAJECTORIES,
    TRANSPORT,
)


def temp_beside(path: Path) -> Path:
    """Where to write ``path`` before renaming it into place: a name of this process and thread
    alone, so that two writers of one file (two sweep commands on one directory) never rename
    each other's half-written file."""
    return path.with_name(f"{path.name}.{os.getpid()}-{threading.get_ident()}.part")


def write_atomic(path: Path, text: str) -> None:
    tmp = temp_beside(path)
    try:
        with open(tmp, "w", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:  # a full disk: no half-written temporary left behind, one line of why
        tmp.unlink(missing_ok=True)
        raise write_error(exc, path.parent) from None


def write_json(path: Path, data: Any) -> None:
    write_atomic(path, json.dumps(data, indent=2, sort_keys=True) + "\n")


def write_csv(path: Path, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> None:
    tmp = temp_beside(path)
    try:
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(columns)
            w.writerows(rows)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise write_error(exc, path.parent) from None
