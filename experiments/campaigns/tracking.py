"""``swarmbed sweep --mlflow [URI]``: each completed run of a sweep logged to MLflow.

The sweep is an MLflow experiment (its name); each run is an MLflow run named after its folder in
the sweep (``<scenario>/run_<k>``), with the resolved configuration (``config.yaml``, flattened to
dotted keys) as parameters, the summary's figures (``summary.json``, numbers only, dotted keys) as
metrics, and the run's folder as artifacts under ``run/``. A run is logged as it completes and,
when a sweep resumes, only if no MLflow run carries its tag yet, so a resumed sweep never logs a run
twice. By default the store is a local folder, ``<sweep>/mlruns`` (MLflow's file store, which MLflow
3 keeps in maintenance mode behind ``MLFLOW_ALLOW_FILE_STORE``: set here for a ``file:`` URI);
``--mlflow URI`` names any tracking server or database instead. Needs the ``tracking`` extra
(``mlflow-skinny``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from swarmbed.experiments.rundir import RunDir, RunFileError

#: the tag that names a run by its folder in the sweep, how a resumed sweep knows it was logged
TAG = "swarmbed.run"
#: MLflow's limits on a parameter's value and a key's length
MAX_VALUE, MAX_KEY = 6000, 250


class TrackingError(RuntimeError):
    """MLflow cannot be reached or used; the message says why in one line."""


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
        self.uri, self.sweep_name = uri, sweep_name
        try:
            self.client = MlflowClient(tracking_uri=uri)
            found = self.client.get_experiment_by_name(sweep_name)
            self.experiment_id = found.experiment_id if found else self.client.create_experiment(sweep_name)
        except Exception as exc:  # MLflow's own errors, a server that does not answer
            raise TrackingError(f"MLflow at {uri}: {str(exc).splitlines()[0]}") from None

    def logged(self, key: str) -> bool:
        """Whether a run tagged ``key`` is already in the experiment."""
        quoted = key.replace("'", "\\'")
        runs = self.client.search_runs([self.experiment_id], filter_string=f"tags.`{TAG}` = '{quoted}'", max_results=1)
        return bool(runs)

    def log(self, run_dir: Path, key: str) -> bool:
        """Log the completed run in ``run_dir`` as ``key``, unless it is logged already (returns
        whether it logged). A folder that is not a completed run is left alone."""
        from mlflow.entities import Metric, Param, RunTag

        folder = RunDir(run_dir)
        if not folder.complete or self.logged(key):
            return False
        try:
            config, summary = folder.config(), folder.json("summary.json")
        except RunFileError as exc:
            raise TrackingError(str(exc)) from None
        params = [Param(k[:MAX_KEY], v[:MAX_VALUE]) for k, v in sorted(flatten(config).items())]
        stamp = int(os.path.getmtime(Path(run_dir) / "summary.json") * 1000)
        metrics = [
            Metric(k[:MAX_KEY], float(v), stamp, 0) for k, v in sorted(numbers(summary).items()) if math.isfinite(v)
        ]
        tags = [RunTag(TAG, key), RunTag("swarmbed.sweep", self.sweep_name)]
        run = self.client.create_run(self.experiment_id, run_name=key, tags={t.key: t.value for t in tags})
        run_id = run.info.run_id
        for start in range(0, len(params), 100):  # MLflow takes at most 100 parameters a batch
            self.client.log_batch(run_id, params=params[start : start + 100])
        for start in range(0, len(metrics), 1000):
            self.client.log_batch(run_id, metrics=metrics[start : start + 1000])
        self.client.log_artifacts(run_id, str(run_dir), artifact_path="run")
        self.client.set_terminated(run_id)
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
