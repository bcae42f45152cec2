"""Reading a finished run's files for a view, as data anyone may have crafted.

A run folder may come from another machine or another person. Every view (report, replay, MCAP
recording) reads it through these functions, which refuse a link out of the folder or a file that is
not a regular one, bound what they read, and check what the view will allocate or draw from:
``dt`` finite and positive, ticks whole and within the run's own count, coordinates finite. Each
refusal is a :class:`~swarmbed.wire.rundir.RunFileError` naming the file and what is wrong with it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from swarmbed.wire.errors import WireError
from swarmbed.wire.rundir import CONFIG, SUMMARY, RunFileError, check_finite, member, read_member
from swarmbed.wire.summary import read_summary

#: the most ticks a view believes a run has: far beyond any run's (a day at 1 ms)
MAX_TICKS = 10**9


#: the most agents a view believes a run has (it draws matrices of agents by agents)
MAX_AGENTS = 100_000


def summary_of(run: Path) -> dict[str, Any]:
    try:
        summary = read_summary(run / SUMMARY)
    except WireError as exc:
        raise RunFileError(str(exc)) from None
    if summary["agents"] > MAX_AGENTS:
        raise RunFileError(f"{run / SUMMARY}: {summary['agents']} agents, more than a view draws ({MAX_AGENTS})")
    return summary


def config_of(run: Path) -> dict[str, Any]:
    """The run's ``config.yaml`` as a mapping."""
    text = read_member(run, CONFIG).decode(errors="replace")
    try:
        config = yaml.safe_load(text)
    except (yaml.YAMLError, RecursionError) as exc:
        raise RunFileError(f"{run / CONFIG}: not YAML ({str(exc).splitlines()[0][:80]})") from None
    if not isinstance(config, dict) or not isinstance(config.get("run"), dict):
        raise RunFileError(f"{run / CONFIG}: no run section")
    return config


def dt_of(run: Path) -> float:
    """The run's tick length in simulated seconds: finite and positive."""
    dt = check_finite(config_of(run)["run"].get("dt"), f"{run / CONFIG}: run.dt")
    if dt <= 0:
        raise RunFileError(f"{run / CONFIG}: run.dt is {dt}; a tick must last more than 0 s")
    return dt


def ticks_of(run: Path) -> int:
    """The ticks the run's summary says it ran (bounded by :data:`MAX_TICKS`)."""
    ticks = summary_of(run)["ticks"]  # checked against the summary's model: a whole number
    if not 0 <= ticks <= MAX_TICKS:
        raise RunFileError(f"{run / SUMMARY}: ticks {ticks} is beyond what any run has")
    return int(ticks)


def table(
    run: Path,
    name: str,
    ticks: int | None = None,
    finite: tuple[str, ...] = (),
    columns: tuple[str, ...] = (),
    **read: Any,
) -> pd.DataFrame:
    """A CSV or Parquet table of the run, with at least ``columns``. With ``ticks``: its ``tick``
    column must hold whole numbers from 0 to ``ticks``; the columns ``finite`` must hold finite
    numbers."""
    path = member(run, name)
    try:
        frame = pd.read_parquet(path) if name.endswith(".parquet") else pd.read_csv(path, **read)
    except Exception as exc:  # pandas and pyarrow raise many kinds for a torn or foreign file
        raise RunFileError(f"{run / name}: cannot be read as a table ({type(exc).__name__})") from None
    for column in columns:
        if column not in frame:
            raise RunFileError(f"{run / name}: no column {column!r}")
    if ticks is not None:
        _whole_ticks(frame, run / name, ticks)
    for column in finite:
        if column not in frame:
            raise RunFileError(f"{run / name}: no column {column!r}")
        values = pd.to_numeric(frame[column], errors="coerce").to_numpy(dtype=float)
        if not np.isfinite(values).all():
            raise RunFileError(f"{run / name}: column {column!r} holds a value that is not a finite number")
    return frame


def _whole_ticks(frame: pd.DataFrame, path: Path, ticks: int) -> None:
    if "tick" not in frame:
        raise RunFileError(f"{path}: no column 'tick'")
    values = pd.to_numeric(frame["tick"], errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(values) | (values != np.round(values)) | (values < 0) | (values > ticks)
    if bad.any():
        raise RunFileError(
            f"{path}: tick {frame['tick'].iloc[int(np.argmax(bad))]!r} is not a tick of this run (0 to {ticks})"
        )
    frame["tick"] = values.astype(np.int64)
