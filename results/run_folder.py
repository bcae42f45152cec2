"""A finished run's folder as its readers see it: :class:`RunDir`.

A run folder may come from another machine or another person. Every reader (reports, replay, MCAP
recordings, analysis, sweeps' tables, the CLI) reads it through a ``RunDir``, which refuses a link
out of the folder or a file that is not a regular one, bounds what it reads, and checks what a
reader will allocate or draw from: the summary against its model, ``dt`` finite and positive,
ticks whole and within the run's own count, coordinates finite. Each refusal is a
:class:`~swarmbed.records.rundir.RunFileError` naming the file and what is wrong with it. The file
names are :mod:`swarmbed.records.rundir`'s, shared with the processes that write them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pydantic import ValidationError

from swarmbed.files.yamlfile import YamlFileError, parse_yaml
from swarmbed.records import rundir as names
from swarmbed.records.rundir import (
    CONFIG,
    LEDGER_COLUMNS,
    MARKER_COLUMNS,
    MAX_CONFIG_BYTES,
    SUMMARY,
    RunFileError,
    check_finite,
    member,
    read_json_member,
    read_member,
)
from swarmbed.records.summary import RunSummary, read_summary
from swarmbed.schema.experiment import MAX_AGENT_COUNT
from swarmbed.schema.obstacles import ObstaclesSection, wall_lines
from swarmbed.wire.errors import WireError

#: the most ticks a view believes a run has: far beyond any run's (a day at 1 ms)
MAX_TICKS = 10**9


#: the most agents a view believes a run has (it draws matrices of agents by agents): the most a
#: run can have (``agents.count``)
MAX_AGENTS = MAX_AGENT_COUNT

#: the most bytes on disk and rows a reader takes from one table of a run or sweep folder. A
#: Parquet file compresses equal rows to nothing (40 M rows in under 1 MB), so its rows are counted
#: from its footer before anything is read. ``SWARMBED_MAX_TABLE_ROWS`` raises the row bound for a
#: run known to be larger (10 M rows is a 500-agent trajectory of 20,000 ticks).
MAX_TABLE_BYTES = 2 << 30
MAX_TABLE_ROWS = 10_000_000


def max_table_rows() -> int:
    """:data:`MAX_TABLE_ROWS`, or ``SWARMBED_MAX_TABLE_ROWS`` where it is set to a whole number."""
    given = os.environ.get("SWARMBED_MAX_TABLE_ROWS", "")
    return int(given) if given.isdigit() else MAX_TABLE_ROWS


def read_table_member(folder: Path, name: str, max_bytes: int = MAX_TABLE_BYTES, **read: Any) -> pd.DataFrame:
    """The CSV or Parquet table ``folder/name`` (a regular file inside ``folder``, see
    :func:`~swarmbed.records.rundir.member`), read as what its name says and nothing else: no
    decompression a name inside it or the target of a link would pick, at most
    :data:`MAX_TABLE_BYTES` on disk and :func:`max_table_rows` rows, counted before the rows are
    allocated. A RunFileError names the file for anything else."""
    path, shown = member(folder, name), Path(folder) / name
    size, rows = path.stat().st_size, max_table_rows()
    if size > max_bytes:
        raise RunFileError(f"{shown}: {size:,} bytes, more than a table read here ({max_bytes:,})")
    too_many = f"{shown}: more than {rows:,} rows, more than a table read here (SWARMBED_MAX_TABLE_ROWS raises it)"
    try:
        if name.endswith(".parquet"):
            import pyarrow.parquet as pq

            if pq.ParquetFile(path).metadata.num_rows > rows:
                raise RunFileError(too_many)
            frame = pd.read_parquet(path)
        else:
            frame = pd.read_csv(path, compression=None, nrows=rows + 1, **read)
            if len(frame) > rows:
                raise RunFileError(too_many)
    except RunFileError:
        raise
    except Exception as exc:  # pandas and pyarrow raise many kinds for a torn or foreign file
        raise RunFileError(f"{shown}: cannot be read as a table ({type(exc).__name__})") from None
    return frame


class RunDir:
    """One run's folder. ``summary()`` and ``config()`` are read once and kept; tables are read
    on each call (a view reads each once)."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self._summary: RunSummary | None = None
        self._config: dict[str, Any] | None = None

    def __repr__(self) -> str:
        return f"RunDir({str(self.path)!r})"

    @property
    def complete(self) -> bool:
        """Whether the run completed: its summary, written last, is there."""
        return (self.path / SUMMARY).exists()

    def has(self, name: str) -> bool:
        """Whether the run wrote ``name`` (optional tables: trajectories, receiver ledger, ...)."""
        return (self.path / name).exists()

    def summary(self) -> RunSummary:
        """``summary.json``, checked against its model (at most :data:`MAX_AGENTS` agents)."""
        if self._summary is None:
            try:
                summary = read_summary(self.path / SUMMARY)
            except WireError as exc:
                raise RunFileError(str(exc)) from None
            if summary.agents > MAX_AGENTS:
                raise RunFileError(
                    f"{self.path / SUMMARY}: {summary.agents} agents, more than a view draws ({MAX_AGENTS})"
                )
            self._summary = summary
        return self._summary

    def config(self) -> dict[str, Any]:
        """The run's resolved experiment, ``config.yaml``, as a mapping with a ``run`` section."""
        if self._config is None:
            text = read_member(self.path, CONFIG, MAX_CONFIG_BYTES).decode(errors="replace")
            try:
                config = parse_yaml(text, str(self.path / CONFIG))
            except YamlFileError as exc:
                raise RunFileError(str(exc).splitlines()[0][:200]) from None
            if not isinstance(config, dict) or not isinstance(config.get("run"), dict):
                raise RunFileError(f"{self.path / CONFIG}: no run section")
            self._config = config
        return self._config

    def dt(self) -> float:
        """The run's tick length in simulated seconds: finite and positive."""
        dt = check_finite(self.config()["run"].get("dt"), f"{self.path / CONFIG}: run.dt")
        if dt <= 0:
            raise RunFileError(f"{self.path / CONFIG}: run.dt is {dt}; a tick must last more than 0 s")
        return dt

    def walls(self) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        """The run's walls (its config's ``obstacles:``, checked by the schema) as line segments,
        for the views to draw; none for a run on open ground."""
        data = self.config().get("obstacles")
        if data is None:
            return []
        try:
            return wall_lines(ObstaclesSection.model_validate(data))
        except ValidationError as exc:
            raise RunFileError(f"{self.path / CONFIG}: obstacles: {str(exc).splitlines()[0][:200]}") from None

    def ticks(self) -> int:
        """The ticks the run's summary says it ran (bounded by :data:`MAX_TICKS`)."""
        ticks = self.summary().ticks  # checked against the summary's model: a whole number
        if not 0 <= ticks <= MAX_TICKS:
            raise RunFileError(f"{self.path / SUMMARY}: ticks {ticks} is beyond what any run has")
        return int(ticks)

    def json(self, name: str) -> dict[str, Any]:
        """A JSON object of the run (``timings.json``, ``transport.json``, ``provenance.json``)."""
        return read_json_member(self.path, name)

    def table(
        self,
        name: str,
        ticks: int | None = None,
        finite: tuple[str, ...] = (),
        columns: tuple[str, ...] = (),
        **read: Any,
    ) -> pd.DataFrame:
        """A CSV or Parquet table of the run, with at least ``columns``. With ``ticks``: its ``tick``
        column must hold whole numbers from 0 to ``ticks``; the columns ``finite`` must hold finite
        numbers."""
        frame = read_table_member(self.path, name, **read)
        for column in columns:
            if column not in frame:
                raise RunFileError(f"{self.path / name}: no column {column!r}")
        if ticks is not None:
            _whole_ticks(frame, self.path / name, ticks)
        for column in finite:
            if column not in frame:
                raise RunFileError(f"{self.path / name}: no column {column!r}")
            values = pd.to_numeric(frame[column], errors="coerce").to_numpy(dtype=float)
            if not np.isfinite(values).all():
                raise RunFileError(f"{self.path / name}: column {column!r} holds a value that is not a finite number")
        return frame

    # -- the tables, by what they hold ------------------------------------------------------------
    def ledger(self) -> pd.DataFrame:
        """``network_ledger.csv``: per tick, kind and outcome, messages and bytes."""
        return self.table(names.LEDGER, self.ticks(), columns=LEDGER_COLUMNS)

    def receivers(self) -> pd.DataFrame:
        """The receiver-level ledger (``network.ledger: per_receiver``): one row per copy's outcome."""
        return self.table(names.RECEIVER_LEDGER, self.ticks(), columns=("sender", "receiver", "outcome"))

    def agents(self) -> pd.DataFrame:
        """``agents.csv``: one row per agent."""
        return self.table(names.AGENTS)

    def timeseries(self) -> pd.DataFrame:
        """``timeseries.csv``: the run's counters, one row per recorded tick."""
        return self.table(names.TIMESERIES, self.ticks())

    def trajectories(self) -> pd.DataFrame:
        """``trajectories.csv`` (``run.record_trajectories``): every agent's position each tick."""
        return self.table(names.TRAJECTORIES, self.ticks(), ("x", "y"), ("agent",), keep_default_na=False)

    def markers(self) -> pd.DataFrame:
        """``markers.csv`` (with trajectories): tasks or victims as they appear and vanish."""
        return self.table(names.MARKERS, self.ticks(), columns=MARKER_COLUMNS, keep_default_na=False)


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
