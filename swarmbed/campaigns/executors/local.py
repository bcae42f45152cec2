"""``--executor local``: this machine's process pool, one run per worker (the default).

Workers are spawned, never forked (the sweep process may hold Zenoh state), and leave Ctrl-C to the
sweep: a run is never recorded as failed because the user interrupted it. A worker that dies (an
out-of-memory kill, say) breaks the pool; the runs it and the other workers had under way are
reported lost; the sweep tells those that never started (no claim) from those under way (a claim
whose process is gone) and starts the former again.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal
from collections.abc import Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import psutil

from swarmbed.campaigns.executors import Executor, Outcome, Resources, RunFunction
from swarmbed.wire.child_process import die_with_parent

_stopping = False  # in a pool worker: SIGTERM came


def _exit(signum: int, _frame: object) -> None:
    global _stopping
    _stopping = True
    raise SystemExit(128 + signum)


def _unless_stopping(fn: RunFunction, item: Any) -> Outcome:
    """A worker's SIGTERM ends the run in hand, but the pool catches that exit as the run's result
    and hands the worker the run queued behind it: that one must not start."""
    if _stopping:
        return "lost", "the sweep was stopping before this run began"
    return fn(item)


def _leave_interrupts_to_the_sweep(sweep_pid: int) -> None:
    """Pool workers: Ctrl-C is the sweep's to handle (a Python-level handler, not SIG_IGN: the
    runs' own children get the default action back), and SIGTERM from the sweep ends the run
    through its cleanup (children stopped, partial files gone). A sweep process that dies
    without stopping its workers (killed, say) takes them with it: the pool would otherwise go
    on with the runs already queued, unseen, and its run's processes die with the worker."""
    die_with_parent(sweep_pid, signal.SIGKILL)
    signal.signal(signal.SIGINT, lambda *_: None)
    signal.signal(signal.SIGTERM, _exit)


def _cmdline(p: psutil.Process) -> list[str]:
    try:
        return p.cmdline()
    except psutil.Error:
        return []


def stop_descendants(grace: float = 10.0) -> None:
    """Stop every process this one started. The pool workers are asked first (SIGTERM: each ends
    its run through the runner's cleanup, which stops that run's processes); whatever is left
    after ``grace`` seconds is killed."""
    family = [
        p
        for p in psutil.Process().children(recursive=True)
        if "multiprocessing.resource_tracker" not in " ".join(_cmdline(p))
    ]
    workers = [p for p in psutil.Process().children() if p in family]
    for procs, stop in ((workers, psutil.Process.terminate), (family, psutil.Process.kill)):
        for p in procs:
            try:
                stop(p)
            except psutil.NoSuchProcess:
                pass
        psutil.wait_procs(procs, timeout=grace)


class LocalExecutor(Executor):
    name = "local"

    def __init__(self, jobs: int | None = None) -> None:
        self.jobs = jobs or os.cpu_count() or 1
        self.pool: cf.ProcessPoolExecutor | None = None

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        self.pool = cf.ProcessPoolExecutor(
            max_workers=self.jobs,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_leave_interrupts_to_the_sweep,
            initargs=(os.getpid(),),
        )
        return self.pool

    def map(
        self, fn: RunFunction, items: Sequence[Any], resources: Sequence[Resources]
    ) -> Iterator[tuple[int, Outcome]]:
        pool = self._new_pool()
        futures = {pool.submit(_unless_stopping, fn, item): i for i, item in enumerate(items)}
        for fut in cf.as_completed(futures):
            try:
                yield futures[fut], fut.result()
            except BrokenProcessPool:
                yield futures[fut], ("lost", "a worker process of the pool died")
        pool.shutdown(wait=True)

    def describe(self) -> str:
        return f"local ({self.jobs} at once)"

    def cancel(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=False, cancel_futures=True)  # nothing new starts
        stop_descendants()  # and what runs stops now

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True)


def make(jobs: int | None = None, **_ignored: Any) -> LocalExecutor:
    return LocalExecutor(jobs)
