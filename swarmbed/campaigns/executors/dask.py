"""``--executor dask --scheduler tcp://HOST:PORT``: each run a task on a Dask cluster.

A run's task asks for the abstract resources ``cores`` and ``mem_gb`` sized to its agents
(:func:`~swarmbed.campaigns.executors.resources_for`), so a worker started with
``--resources "cores=16,mem_gb=64"`` takes as many runs at once as fit. Resources that no worker
declares are not asked for (a task asking for one would wait forever); each worker then runs as many
runs at once as it has threads. Dask runs a task again elsewhere when its worker dies (up to its
``allowed-failures``); the claim file keeps two tasks of one run from overlapping.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator, Sequence
from typing import Any
from urllib.parse import urlsplit

import distributed

from swarmbed.campaigns.executors import Executor, ExecutorError, Outcome, Resources, RunFunction


class DaskExecutor(Executor):
    name = "dask"

    def __init__(self, scheduler: str | distributed.LocalCluster, timeout: float = 30.0) -> None:
        if isinstance(scheduler, str):
            _refuse_unreachable(scheduler, timeout)
        try:
            self.client = distributed.Client(scheduler, timeout=timeout, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise ExecutorError(f"--scheduler {scheduler}: cannot reach the Dask scheduler: {exc}") from None
        self.scheduler = scheduler
        self.futures: list[distributed.Future] = []
        self.declared: set[str] = set()

    def _declared_resources(self) -> set[str]:
        workers = self.client.scheduler_info().get("workers", {}).values()
        return {name for w in workers for name in (w.get("resources") or {})}

    def map(
        self, fn: RunFunction, items: Sequence[Any], resources: Sequence[Resources]
    ) -> Iterator[tuple[int, Outcome]]:
        self.declared = self._declared_resources()
        index: dict[Any, int] = {}
        for i, (item, need) in enumerate(zip(items, resources)):
            ask = {k: v for k, v in (("cores", need.cpus), ("mem_gb", need.mem_gb)) if k in self.declared}
            fut = self.client.submit(fn, item, pure=False, resources=ask or None)
            self.futures.append(fut)
            index[fut.key] = i
        for fut in distributed.as_completed(self.futures, loop=self.client.loop):
            try:
                yield index[fut.key], fut.result()
            except distributed.KilledWorker as exc:
                yield index[fut.key], ("lost", f"Dask gave up after its workers died: {exc}")
            except distributed.client.FutureCancelledError:
                yield index[fut.key], ("lost", "the Dask task was cancelled")

    def describe(self) -> str:
        where = getattr(self.scheduler, "scheduler_address", self.scheduler)
        sized = (
            f"tasks sized by {', '.join(sorted(self.declared))}"
            if self.declared
            else "workers declare no cores/mem_gb resources: a run per worker thread"
        )
        return f"dask ({where}; {sized})"

    def cancel(self) -> None:
        self.client.cancel(self.futures, force=True)

    def close(self) -> None:
        self.client.close()


def _refuse_unreachable(scheduler: str, timeout: float) -> None:
    """Fail at once on an address nobody listens at: Dask's client retries a refused connection
    until its timeout (30 s), which a mistyped port should not cost."""
    parts = urlsplit(scheduler)
    if parts.scheme not in ("tcp", "") or not parts.hostname or parts.port is None:
        return  # another transport (tls://, inproc://): Dask's own connect says what is wrong
    try:
        with socket.create_connection((parts.hostname, parts.port), timeout=timeout):
            pass
    except OSError as exc:
        raise ExecutorError(f"--scheduler {scheduler}: cannot reach the Dask scheduler: {exc}") from None


def make(scheduler: str | None = None, **_ignored: Any) -> DaskExecutor:
    if not scheduler:
        raise ExecutorError("--executor dask needs --scheduler tcp://HOST:PORT (the address `dask scheduler` prints)")
    return DaskExecutor(scheduler)
