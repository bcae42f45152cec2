"""What it is to be one of a run's child processes: its command line, tied to its parent's life,
its memory kept from creeping over hours, its log set up; and whether another process still runs."""

from __future__ import annotations

import argparse
import ctypes
import gc
import os
import signal
import sys
import threading
from collections.abc import Callable

from swarmbed.wire.logs import setup_logging

PR_SET_PDEATHSIG = 1


def process_name(agent: int, incarnation: int = 0) -> str:
    """An agent process's name (and log file): ``agent_3``, or ``agent_3.1`` for its second process."""
    return f"agent_{agent}" if incarnation == 0 else f"agent_{agent}.{incarnation}"


def die_with_parent(parent_pid: int | None, sig: int = signal.SIGTERM) -> None:
    """Ask Linux to send us ``sig`` when the process that started us goes away (no orphans)."""
    if parent_pid is None or not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, sig)
    except OSError:
        return
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(3)


M_MMAP_THRESHOLD = -3  # glibc mallopt parameter numbers (malloc.h)
MMAP_THRESHOLD = 16 * 1024


def tune_malloc(mmap_threshold: int = MMAP_THRESHOLD) -> bool:
    """Give blocks of ``mmap_threshold`` bytes and more their own mappings, returned to the system
    when freed (glibc; elsewhere nothing happens and False is returned).

    By default glibc raises this threshold to the size of each large block freed, so that
    every message, inbox and checkpoint of a few to a few tens of KB lands inside the malloc
    arenas, between long-lived small blocks. In a process that handles such messages every tick
    for hours, the arenas' touched pages then grow although little stays allocated: the hub of a
    50-agent soak grew about 15 % an hour that way (docs/soak.md). A fixed threshold keeps those
    blocks out of the arenas."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, mmap_threshold))


#: the cyclic garbage collector's thresholds in a run's processes (Python's own: 700, 10, 10)
GC_THRESHOLDS = (10_000, 10, 10)


def tune_gc() -> None:
    """Run the cyclic garbage collector's youngest generation every 10,000 allocations instead of
    700. A tick makes many short-lived objects (decoded messages, views, task records) and few
    cycles; at Python's default the collections, and the older generations' walks they trigger
    over a large heap, took about a sixth of a 1,000-robot in-process FCG run (5.9 s -> 5.0 s, CBBA
    and GRAPE about 6 %). Collections never change what a run computes."""
    gc.set_threshold(*GC_THRESHOLDS)


_pinned_threads: set[int] = set()


def pin_thread_state() -> None:
    """Keep a Python thread state alive for the calling thread, from its first call on.

    Zenoh calls a direct callback (``Callback(..., indirect=False)``) in one of its own Rust
    threads. pyo3 attaches such a thread to Python for each call and detaches it after
    (``PyGILState_Ensure`` / ``PyGILState_Release``), so every sample created and destroyed a
    thread state (two mmap, two munmap and a gettid) and lost everything kept per thread (the
    msgpack Packer of :func:`swarmbed.wire.codec.pack`: a fresh 256 KB buffer per sample). One
    ``PyGILState_Ensure`` of our own that is never released keeps the count above zero, so the state
    outlives each call and pyo3 only takes and gives back the GIL. Measured with a raw subscriber
    doing one pack per sample: 13 us -> 3.4 us of CPU per sample. What zenoh-python would need to make
    this unnecessary: attach its runtime's threads to Python once (a thread-start hook that calls
    ``PyGILState_Ensure``), or hand samples to a thread that is attached.

    Call it first thing in every direct callback; it costs a set lookup after the first call."""
    ident = threading.get_ident()
    if ident not in _pinned_threads:
        ctypes.pythonapi.PyGILState_Ensure()  # never released: the thread's state stays
        _pinned_threads.add(ident)


def process_alive(pid: int, started: float) -> bool:
    """Whether process ``pid`` on this machine is still the one that started at ``started``
    (psutil's create time): a pid the kernel gave to another process since reads as gone, and so
    does a zombie (killed, not yet reaped)."""
    import psutil  # here: agents import this module and never call this

    try:
        proc = psutil.Process(pid)
        # a killed process that its parent has not reaped yet (a zombie) is gone: it holds nothing
        return abs(proc.create_time() - started) <= 1.0 and proc.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def child_args(
    prog: str, description: str, add_args: Callable[[argparse.ArgumentParser], object], argv: list[str] | None
) -> argparse.Namespace:
    """Parse a child process's command line (its own flags, ``--run-id``, ``--parent-pid``, the log
    rotation and the zenoh flags), tie it to its parent and set up logging to stderr."""
    from swarmbed.wire.zenoh_session import add_zenoh_args

    ap = argparse.ArgumentParser(prog=prog, description=description)
    ap.add_argument("--run-id", required=True, help="the run to join (see the run's timings.json)")
    add_args(ap)
    ap.add_argument("--parent-pid", type=int, help="exit when this process exits (set by the launcher)")
    ap.add_argument("--log-max-mb", type=int, help="rotate this process's log file at this size (MB)")
    ap.add_argument("--log-backups", type=int, default=2, help="rotated log files kept (name.log.1, ...)")
    add_zenoh_args(ap)
    args = ap.parse_args(argv)
    die_with_parent(args.parent_pid)
    tune_malloc()
    tune_gc()
    setup_logging(args.log_max_mb, args.log_backups)
    return args
