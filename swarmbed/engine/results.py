"""Writing a run's result files so that a crash never leaves a half-written file looking complete:
each file goes to a temporary name and is renamed into place; ``summary.json`` is written last."""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from swarmbed.files import safefiles
from swarmbed.records.rowfile import write_error
from swarmbed.records.run_folder import (  # noqa: F401 - the run directory's names, read as results.<NAME>
    AGENTS,
    CONFIG,
    MARKERS,
    SUMMARY,
    TIMESERIES,
    TIMINGS,
    TRAJECTORIES,
    TRANSPORT,
)


def write_atomic(path: Path, text: str) -> None:
    """``text`` as the whole of ``path``, complete or not at all; a link standing at ``path`` is
    replaced, never written through (``wire.safefiles``)."""
    try:
        safefiles.write_text(path, text, fsync=True)
    except safefiles.LinkRefused:
        raise
    except OSError as exc:  # a full disk: no half-written temporary left behind, one line of why
        raise write_error(exc, path.parent) from None


def write_json(path: Path, data: Any) -> None:
    write_atomic(path, json.dumps(data, indent=2, sort_keys=True) + "\n")


def write_csv(path: Path, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> None:
    try:
        with safefiles.replacing(path) as tmp, open(tmp, "w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(columns)
            w.writerows(rows)
            f.flush()
            os.fsync(f.fileno())
    except safefiles.LinkRefused:
        raise
    except OSError as exc:
        raise write_error(exc, path.parent) from None
