"""``--executor slurm``: one Slurm array job per sweep, one array task per run, through submitit.

Each task unpickles the run function and its run and calls it in a fresh Python on the node, the
same function the local pool calls. An array job asks one size of node for every task, so the
request is the largest run's (:func:`~swarmbed.campaigns.executors.resources_for`). submitit keeps
its scripts and each task's log in ``<sweep>/.submitit/``. ``cluster="local"`` is submitit's own
stand-in (a subprocess per task on this machine): the tests use it, no Slurm needed.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import submitit
from submitit.core.utils import UncompletedJobError

from swarmbed.campaigns.executors import Executor, ExecutorError, Outcome, Resources, RunFunction


def parse_time_min(text: str | int) -> int:
    """Slurm's ``--time`` formats, in whole minutes (seconds round up): ``M``, ``M:S``, ``H:M:S``,
    ``D-H``, ``D-H:M`` and ``D-H:M:S``."""
    value = str(text).strip()
    days, _, clock = value.rpartition("-")
    try:
        parts = [int(p) for p in clock.split(":")]
        d = int(days) if days else 0
    except ValueError:
        parts = []
    if not parts or len(parts) > 3 or min(parts) < 0 or (days and d < 0):
        raise ExecutorError(f"--slurm-time {value!r}: minutes, H:MM:SS or D-HH:MM:SS")
    if days:  # D-H, D-H:M, D-H:M:S
        h, m, s = (parts + [0, 0])[:3]
    elif len(parts) == 3:
        h, m, s = parts
    else:  # M or M:S
        h, m, s = 0, parts[0], parts[1] if len(parts) == 2 else 0
    return max(1, d * 1440 + h * 60 + m + (1 if s else 0))


class SlurmExecutor(Executor):
    name = "slurm"

    def __init__(
        self,
        folder: Path,
        partition: str | None = None,
        time_min: int = 120,
        parallel: int | None = None,
        cluster: str | None = None,
        detach: bool = False,
    ) -> None:
        self.folder = folder
        self.partition = partition
        self.time_min = time_min
        self.parallel = parallel
        self.cluster = cluster
        self.detach = detach
        self.jobs: list[Any] = []

    def map(
        self, fn: RunFunction, items: Sequence[Any], resources: Sequence[Resources]
    ) -> Iterator[tuple[int, Outcome]]:
        if not items:
            return
        executor = submitit.AutoExecutor(folder=self.folder / "%j", cluster=self.cluster)
        largest = Resources(max(r.cpus for r in resources), max(r.mem_gb for r in resources))
        params: dict[str, Any] = {
            "name": "swarmbed-sweep",
            "timeout_min": self.time_min,
            "cpus_per_task": largest.cpus,
            "mem_gb": largest.mem_gb,
            "tasks_per_node": 1,
            "nodes": 1,
        }
        if self.partition:
            params["slurm_partition"] = self.partition
        if self.parallel:
            params["slurm_array_parallelism"] = self.parallel
        executor.update_parameters(**params)
        try:
            self.jobs = executor.map_array(fn, list(items))
        except Exception as exc:  # sbatch refused: say what it said
            raise ExecutorError(f"Slurm refused the array job: {exc}") from None
        if self.detach:
            return
        index = {id(job): i for i, job in enumerate(self.jobs)}
        for job in submitit.helpers.as_completed(self.jobs, poll_frequency=2 if self.cluster == "local" else 15):
            try:
                yield index[id(job)], job.result()
            except UncompletedJobError as exc:  # killed, timed out, node failure
                yield index[id(job)], ("lost", f"Slurm job {job.job_id}: {str(exc).splitlines()[0]}")

    def describe(self) -> str:
        first = self.jobs[0].job_id.split("_")[0] if self.jobs else "?"
        return f"slurm (array job {first}, logs in {self.folder})"

    def cancel(self) -> None:
        for job in self.jobs:
            try:
                job.cancel(check=False)
            except Exception:  # a job that already ended
                pass


def make(
    folder: Path,
    partition: str | None = None,
    time: str | int = 120,
    parallel: int | None = None,
    cluster: str | None = None,
    detach: bool = False,
    **_ignored: Any,
) -> SlurmExecutor:
    for flag, value in (("--slurm-partition", partition), ("--slurm-cluster", cluster), ("--out", str(folder))):
        if value is not None and any(ord(c) < 32 or ord(c) == 127 for c in value):
            raise ExecutorError(f"{flag} {value[:40]!r}: a control character would become a line of the batch script")
    return SlurmExecutor(folder, partition, parse_time_min(time), parallel, cluster, detach)
