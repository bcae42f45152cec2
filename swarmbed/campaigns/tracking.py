"""``swarmbed sweep --mlflow [URI]``: each completed run of a sweep logged to MLflow.

The sweep is an MLflow experiment (its name); each run is an MLflow run named after its folder in
the sweep (``<scenario>/run_<k>``), with the resolved configuration (``config.yaml``, flattened to
dotted keys) as parameters, the summary's figures (``summary.json``, numbers only, dotted keys) as
metrics, and the run's folder as artifacts under ``run/``. A run is logged as it completes and,
when a sweep resumes, only if no MLflow run carries its tag yet, so a resumed sweep never logs a run
twice. By default the store is a local folder, ``<sweep>/mlruns`` (MLflow's file store, which MLflow
3 keeps in maintenance mode behind ``MLFLOW_ALLOW_FILE_STORE``: set here for a ``file:`` URI, and
needed by anyone who reads the store back, ``MLFLOW_ALLOW_FILE_STORE=true mlflow ui``); ``--mlflow
URI`` names a tracking server (``http(s)://``) instead, or a database (``sqlite:``, ``postgresql:``
...) where the full ``mlflow`` package is installed. Needs the ``tracking`` extra (``mlflow-skinny``).

A run folder is data: only its regular files inside it are logged as artifacts (a link to
``/etc/shadow`` is left behind), and its keys are made safe as MLflow keys (``../../x`` becomes
``_/_/x``). A server that does not answer fails the sweep within seconds, not after MLflow's minutes
of retries; a password in the URI is never printed.
"""

from __future__ import annotations

import math
import os
import re
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit, urlunsplit

from swarmbed.files import safefiles
from swarmbed.records.run_folder import RunDir, RunFileError

#: the tag that names a run by its folder in the sweep, how a resumed sweep knows it was logged
TAG = "swarmbed.run"
#: MLflow's limits on a parameter's value and a key's length
MAX_VALUE, MAX_KEY = 6000, 250
#: how long and how often a tracking server is asked before the sweep gives up on it (MLflow's own
#: defaults, 120 s and 7 retries with back-off, leave a sweep silent for minutes); the environment's
#: MLFLOW_HTTP_REQUEST_TIMEOUT / MLFLOW_HTTP_REQUEST_MAX_RETRIES win where set
HTTP_TIMEOUT_S, HTTP_RETRIES = 10, 1
#: database schemes that mlflow-skinny (the tracking extra) cannot open; the full mlflow package can
DATABASES = ("sqlite", "postgresql", "mysql", "mssql")


class TrackingError(RuntimeError):
    """MLflow cannot be reached or used; the message says why in one line."""


def redacted(uri: str) -> str:
    """``uri`` as it may be printed: a password in it is replaced by ``***``."""
    parts = urlsplit(uri)
    if parts.password is None:
        return uri
    host = parts.hostname or ""
    netloc = f"{parts.username}:***@{host}" + (f":{parts.port}" if parts.port else "")
    return urlunsplit(parts._replace(netloc=netloc))


def safe_key(key: str) -> str:
    """``key`` as MLflow takes it, in any store: letters, digits and ``_-. `` only (a ``/`` is a
    folder in MLflow's file store, where ``a`` and ``a/b`` cannot both be: it becomes ``.``), no
    empty step and no ``..``; at most :data:`MAX_KEY` characters."""
    key = re.sub(r"[^A-Za-z0-9_\-. /]", "_", key)
    steps = [step for step in re.split(r"[/.]", key) if step]  # no empty step: a//b, a/, .x
    return ".".join(steps)[:MAX_KEY].rstrip(".") or "_"


def safe_keys(values: dict[str, Any], what: str) -> dict[str, Any]:
    """``values`` under :func:`safe_key`'s keys; where two keys become one (``x?`` and ``x!`` are
    both ``x_``), the first is kept and the other named on stderr, never merged silently."""
    out: dict[str, Any] = {}
    origin: dict[str, str] = {}
    for key in sorted(values):
        safe = safe_key(key)
        if safe in out:
            print(
                f"mlflow: {what} {key!r} and {origin[safe]!r} are both {safe!r} to MLflow: {key!r} not logged",
                file=sys.stderr,
            )
            continue
        out[safe], origin[safe] = values[key], key
    return out


def default_uri(sweep_dir: Path) -> str:
    return (Path(sweep_dir).resolve() / "mlruns").as_uri()


class MlflowLog:
    """Logs a sweep's completed runs to the MLflow experiment named after the sweep."""

    def __init__(self, uri: str, sweep_name: str) -> None:
        try:
            from mlflow.tracking import MlflowClient
        except ImportError:
            raise TrackingError("--mlflow needs MLflow: pip install 'swarmbed[tracking]'") from None
        if uri.startswith("file:"):
            os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
        os.environ.setdefault("MLFLOW_HTTP_REQUEST_TIMEOUT", str(HTTP_TIMEOUT_S))
        os.environ.setdefault("MLFLOW_HTTP_REQUEST_MAX_RETRIES", str(HTTP_RETRIES))
        self.uri, self.sweep_name = uri, sweep_name
        scheme = urlsplit(uri).scheme.split("+")[0]
        if scheme in DATABASES and not _full_mlflow():
            raise TrackingError(
                f"--mlflow {redacted(uri)}: a {scheme} database needs the full MLflow package "
                "(pip install mlflow); the tracking extra's mlflow-skinny speaks to servers and file stores"
            )
        try:
            self.client = MlflowClient(tracking_uri=uri)
            found = self.client.get_experiment_by_name(sweep_name)
            self.experiment_id = found.experiment_id if found else self.client.create_experiment(sweep_name)
        except Exception as exc:  # MLflow's own errors, a server that does not answer
            raise TrackingError(f"MLflow at {redacted(uri)}: {_first_line(exc, uri)}") from None

    def logged(self, key: str) -> bool:
        """Whether a run tagged ``key`` is already in the experiment."""
        quoted = key.replace("'", "\\'")
        runs = self.client.search_runs([self.experiment_id], filter_string=f"tags.`{TAG}` = '{quoted}'", max_results=1)
        return bool(runs)

    def log(self, run_dir: Path, key: str) -> bool:
        """Log the completed run in ``run_dir`` as ``key``, unless it is logged already (returns
        whether it logged). A folder that is not a completed run is left alone."""
        try:
            return self._log(run_dir, key)
        except TrackingError:
            raise
        except Exception as exc:  # MLflow's own errors, a server that went away: one line
            raise TrackingError(f"MLflow at {redacted(self.uri)}, run {key}: {_first_line(exc, self.uri)}") from None

    def _log(self, run_dir: Path, key: str) -> bool:
        from mlflow.entities import Metric, Param, RunTag

        folder = RunDir(run_dir)
        if not folder.complete or self.logged(key):
            return False
        try:
            config, summary = folder.config(), folder.json("summary.json")
        except RunFileError as exc:
            raise TrackingError(str(exc)) from None
        params = [Param(k, v[:MAX_VALUE]) for k, v in safe_keys(flatten(config), "parameter").items()]
        stamp = int(os.path.getmtime(Path(run_dir) / "summary.json") * 1000)
        measured = {k: v for k, v in numbers(summary).items() if math.isfinite(v)}
        metrics = [Metric(k, float(v), stamp, 0) for k, v in safe_keys(measured, "metric").items()]
        tags = [RunTag(TAG, key), RunTag("swarmbed.sweep", self.sweep_name)]
        run = self.client.create_run(self.experiment_id, run_name=key, tags={t.key: t.value for t in tags})
        run_id = run.info.run_id
        for start in range(0, len(params), 100):  # MLflow takes at most 100 parameters a batch
            self.client.log_batch(run_id, params=params[start : start + 100])
        for start in range(0, len(metrics), 1000):
            self.client.log_batch(run_id, metrics=metrics[start : start + 1000])
        for path in safefiles.regular_files(Path(run_dir)):  # never what a link in the folder names
            where = path.parent.relative_to(run_dir).as_posix()
            self.client.log_artifact(run_id, str(path), artifact_path="run" if where == "." else f"run/{where}")
        self.client.set_terminated(run_id)
        return True


def _first_line(exc: BaseException, uri: str) -> str:
    """The first line of ``exc``'s message, without the password of ``uri`` (MLflow's messages
    quote the URL it was given)."""
    lines = str(exc).strip().splitlines()
    line = lines[0][:300] if lines else type(exc).__name__
    password = urlsplit(uri).password
    return line.replace(password, "***") if password else line


def _full_mlflow() -> bool:
    """Whether the full mlflow package (with its database stores) is installed, not mlflow-skinny."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        version("mlflow")
    except PackageNotFoundError:
        return False
    return True


def leaves(value: Any, prefix: str = "") -> dict[str, Any]:
    """The leaves of a nested mapping, by dotted key."""
    if not isinstance(value, Mapping):
        return {prefix.rstrip("."): value}
    out: dict[str, Any] = {}
    for k, v in value.items():
        out.update(leaves(v, f"{prefix}{k}."))
    return out


def flatten(value: Any) -> dict[str, str]:
    """A nested mapping as dotted keys and text values (lists as their text, None as null)."""
    return {k: "null" if v is None else str(v) for k, v in leaves(value).items()}


def numbers(value: Any) -> dict[str, float]:
    """The numbers of a nested mapping (booleans as 0/1), as dotted keys."""
    return {k: float(v) for k, v in leaves(value).items() if isinstance(v, (bool, int, float))}
