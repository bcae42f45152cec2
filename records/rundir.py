"""The files of a run directory: one place that names them for every process that writes them
(coordinator, netem proxy, launcher) and every command that reads them (sweeps, analysis, reports).

Formats: CSV tables with a header row and ``\\n`` line ends, written in whole rows (``rowfile``);
JSON objects with sorted keys; ``config.yaml`` as ``yaml.safe_dump`` writes it. A table still being
written is ``<name>.part``; one of a run that did not complete is ``partial_<name>``.
"""

from __future__ import annotations

import json
import math
import stat
from pathlib import Path
from typing import Any

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
