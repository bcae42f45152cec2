"""A run folder, as its processes write it and as every reader reads it: one place for both.

The names: every file of a run folder, for every process that writes them (coordinator, netem
proxy, launcher) and every command that reads them (sweeps, analysis, reports). Formats: CSV tables
with a header row and ``\\n`` line ends, written in whole rows (``rowfile``); JSON objects with
sorted keys; ``config.yaml`` as ``yaml.safe_dump`` writes it. A table still being written is
``<name>.part``; one of a run that did not complete is ``partial_<name>``.

The reading: a run folder may come from another machine or another person. Every reader (reports,
replay, MCAP recordings, analysis, sweeps' tables, the CLI) reads it through a :class:`RunDir`,
which refuses a link out of the folder or a file that is not a regular one, bounds what it reads,
and checks what a reader will allocate or draw from: the summary against its model, ``dt`` finite
and positive, ticks whole and within the run's own count, coordinates finite. Each refusal is a
:class:`RunFileError` naming the file and what is wrong with it. pandas is imported by the table
readers only, so that the processes that merely name files never load it.
"""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import ValidationError

from swarmbed.records.summary import RunSummary
from swarmbed.schema.experiment import MAX_AGENT_COUNT
from swarmbed.schema.obstacles import ObstaclesSection, wall_lines
from swarmbed.wire.errors import WireError

if TYPE_CHECKING:
    import pandas as pd

CONFIG = "config.yaml"  # the resolved experiment
PROVENANCE = "provenance.json"  # which code made the run
SUMMARY = "summary.json"  # written last: its presence means the run completed
TIMESERIES = "timeseries.csv"
AGENTS = "agents.csv"
TRAJECTORIES = "trajectories.csv"  # with run.record_trajectories
MARKERS = "markers.csv"  # tasks or victims as they appear and vanish (with trajectories)
LEDGER = "network_ledger.csv"
RECEIVER_LEDGER = "network_ledger_receivers.parquet"  # network.ledger: per_receiver
SWAPS = "swaps.csv"
RESTARTS = "restarts.csv"
TIMINGS = "timings.json"  # wall-clock figures: of this machine and moment
TRANSPORT = "transport.json"  # measured bytes on the wire: of this machine and moment
DEPLOYMENT = "deployment.json"  # where each agent ran
LOGS = "logs"
BT = "bt"  # with run.record_bt: one Groot2-replayable file per agent


#: the columns of network_ledger.csv (one row per tick, sender, kind and outcome), of the receiver
#: ledger (one row per copy; the radio's models add their measured columns) and of markers.csv
LEDGER_COLUMNS = ("tick", "sender", "kind", "outcome", "messages", "bytes")
RECEIVER_COLUMNS = ("tick", "sender", "receiver", "kind", "outcome", "bytes")
MARKER_COLUMNS = ("tick", "marker", "x", "y", "label", "event")


def btlog_name(agent: int) -> str:
    """An agent's behavior tree log in :data:`BT` (BehaviorTree.CPP's file-logger format)."""
    return f"agent_{agent}.btlog"


def ledger_part(shard: int) -> str:
    """The file name of proxy ``shard``'s part of the ledger (merged away when the run ends)."""
    return f"network_ledger.shard{shard}.csv"


PART_SUFFIX = ".part"
PARTIAL_PREFIX = "partial_"

#: what a run that starts again into the same folder removes first, and what one that fails keeps
#: only as partial_<name> (deployment.json stays: it says where the failed run's processes were)
RESULT_FILES = (
    SUMMARY,
    TIMESERIES,
    AGENTS,
    TIMINGS,
    TRANSPORT,
    TRAJECTORIES,
    MARKERS,
    LEDGER,
    RECEIVER_LEDGER,
    DEPLOYMENT,
)

#: the files that are identical for the same configuration and seed, wherever the agents ran
REPRODUCIBLE = (
    CONFIG,
    PROVENANCE,
    SUMMARY,
    TIMESERIES,
    AGENTS,
    TRAJECTORIES,
    MARKERS,
    LEDGER,
    RECEIVER_LEDGER,
    RESTARTS,
)


# -- reading a folder someone else may have made ---------------------------------------------------
#: the most a reader takes from one JSON or YAML file of a run (a summary is a few kB)
MAX_DOCUMENT_BYTES = 16 << 20
#: the most a reader takes of ``config.yaml`` (a resolved experiment is a few kB; parsing YAML is slow)
MAX_CONFIG_BYTES = 1 << 20


class RunFileError(ValueError):
    """A file of a run or sweep folder that a reader refuses; the message names it and why."""


def member(folder: Path, name: str) -> Path:
    """``folder/name``, refused unless it is a regular file that stays inside ``folder``: a results
    folder is data anyone may have crafted, and a link in it must not make a reader open
    ``/etc/shadow``, a FIFO that never ends, or ``/dev/zero``."""
    path = Path(folder) / name
    if path.is_symlink():  # a link inside the folder may name a .gz that a reader would inflate
        raise RunFileError(f"{path}: a symbolic link, not a regular file: not read")
    try:
        real, inside = path.resolve(strict=True), Path(folder).resolve(strict=True)
        st = real.stat()
    except OSError as exc:
        raise RunFileError(f"{path}: {exc.strerror or exc}") from None
    except RuntimeError:  # a loop of links
        raise RunFileError(f"{path}: a loop of symbolic links") from None
    if real != inside and inside not in real.parents:
        raise RunFileError(f"{path}: a link to {real}, outside {folder}: not read")
    if not stat.S_ISREG(st.st_mode):
        raise RunFileError(f"{path}: not a regular file")
    return real


def read_member(folder: Path, name: str, max_bytes: int = MAX_DOCUMENT_BYTES) -> bytes:
    """The bytes of ``folder/name`` (see :func:`member`), refused beyond ``max_bytes``."""
    path = member(folder, name)
    if path.stat().st_size > max_bytes:
        raise RunFileError(f"{Path(folder) / name}: {path.stat().st_size:,} bytes, more than {max_bytes:,} read here")
    with open(path, "rb") as f:
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise RunFileError(f"{Path(folder) / name}: grew past {max_bytes:,} bytes while read")
    return data


def read_json_member(folder: Path, name: str, max_bytes: int = MAX_DOCUMENT_BYTES) -> dict[str, Any]:
    """The JSON object in ``folder/name``; a RunFileError names the file for anything else."""
    data = read_member(folder, name, max_bytes)
    try:
        value = json.loads(data)
    except (ValueError, RecursionError) as exc:
        raise RunFileError(f"{Path(folder) / name}: not JSON ({str(exc)[:80]})") from None
    if not isinstance(value, dict):
        raise RunFileError(f"{Path(folder) / name}: not a JSON object")
    return value


def check_finite(value: object, what: str) -> float:
    """``value`` as a finite float, or a RunFileError naming ``what``."""
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise RunFileError(f"{what}: {str(value)[:40]!r} is not a number") from None
    if not math.isfinite(number):
        raise RunFileError(f"{what}: {number} is not finite")
    return number


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


def env_limit(name: str, default: int) -> int:
    """The limit the environment variable ``name`` sets, or ``default`` where it is unset or empty;
    a RunFileError naming the variable for anything but a whole number in ASCII digits
    (``"²".isdigit()`` is true, and ``int("²")`` fails)."""
    given = os.environ.get(name, "").strip()
    if not given:
        return default
    if not (given.isascii() and given.isdigit()) or len(given) > 18:
        raise RunFileError(f"{name}={given[:20]!r}: not a whole number of ASCII digits; unset it for {default:,}")
    return int(given)


def max_table_rows() -> int:
    """:data:`MAX_TABLE_ROWS`, or ``SWARMBED_MAX_TABLE_ROWS`` where it is set."""
    return env_limit("SWARMBED_MAX_TABLE_ROWS", MAX_TABLE_ROWS)


def _text_table(path: Path, shown: Path) -> None:
    """Refuse at once a CSV whose first 64 kB hold a NUL byte: a table of text never does, and
    pandas would take a file of NULs up to its size cap before it fails."""
    with open(path, "rb") as f:
        if b"\0" in f.read(64 << 10):
            raise RunFileError(f"{shown}: holds NUL bytes, not a table of text: not read")


def read_table_member(folder: Path, name: str, max_bytes: int = MAX_TABLE_BYTES, **read: Any) -> pd.DataFrame:
    """The CSV or Parquet table ``folder/name`` (a regular file inside ``folder``, see
    :func:`member`), read as what its name says and nothing else: no
    decompression a name inside it or the target of a link would pick, at most
    :data:`MAX_TABLE_BYTES` on disk and :func:`max_table_rows` rows, counted before the rows are
    allocated. A RunFileError names the file for anything else."""
    import pandas as pd

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
            _text_table(path, shown)
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
            from swarmbed.files.yamlfile import YamlFileError, parse_yaml  # PyYAML only where a config is read

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
        import pandas as pd

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
        return self.table(LEDGER, self.ticks(), columns=LEDGER_COLUMNS)

    def receivers(self) -> pd.DataFrame:
        """The receiver-level ledger (``network.ledger: per_receiver``): one row per copy's outcome."""
        return self.table(RECEIVER_LEDGER, self.ticks(), columns=("sender", "receiver", "outcome"))

    def agents(self) -> pd.DataFrame:
        """``agents.csv``: one row per agent."""
        return self.table(AGENTS)

    def timeseries(self) -> pd.DataFrame:
        """``timeseries.csv``: the run's counters, one row per recorded tick."""
        return self.table(TIMESERIES, self.ticks())

    def trajectories(self) -> pd.DataFrame:
        """``trajectories.csv`` (``run.record_trajectories``): every agent's position each tick."""
        return self.table(TRAJECTORIES, self.ticks(), ("x", "y"), ("agent",), keep_default_na=False)

    def markers(self) -> pd.DataFrame:
        """``markers.csv`` (with trajectories): tasks or victims as they appear and vanish."""
        return self.table(MARKERS, self.ticks(), columns=MARKER_COLUMNS, keep_default_na=False)


def _whole_ticks(frame: pd.DataFrame, path: Path, ticks: int) -> None:
    if "tick" not in frame:
        raise RunFileError(f"{path}: no column 'tick'")
    import pandas as pd

    values = pd.to_numeric(frame["tick"], errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(values) | (values != np.round(values)) | (values < 0) | (values > ticks)
    if bad.any():
        raise RunFileError(
            f"{path}: tick {frame['tick'].iloc[int(np.argmax(bad))]!r} is not a tick of this run (0 to {ticks})"
        )
    frame["tick"] = values.astype(np.int64)


def read_summary(path: Path) -> RunSummary:
    """A run's ``summary.json``, checked against :class:`RunSummary`; a WireError naming the file for
    anything else (a link out of its folder, a huge or torn file, another shape)."""
    try:
        document = read_json_member(path.parent, path.name)
    except RunFileError as exc:
        raise WireError(str(exc)) from None
    try:
        return RunSummary.of(document)
    except WireError as exc:
        raise WireError(f"{path}: {exc}") from None
