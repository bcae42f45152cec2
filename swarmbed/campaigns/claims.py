"""Claim files: at most one process works on a sweep's run at a time, wherever it runs.

A run directory is claimed by writing ``claim.json`` (host, pid, the process's start time, a token)
while holding an exclusive ``flock`` on the directory's ``claim.lock``, so that two sweep commands
(or two cluster tasks) started on one shared directory never both run it. The holder touches the
file every few seconds; a claim is stale, and may be taken over, when its process is gone (known at
once on the same host) or when it has not been touched for ``stale_after`` seconds (a node that
died, on a cluster). Completion is still ``summary.json``: a claim only says "someone is on it".

``flock`` is atomic on a local filesystem and on NFSv4 (Linux maps it onto NFS byte-range locks).
"""

from __future__ import annotations

import fcntl
import json
import os
import secrets
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import psutil

from swarmbed.files import safefiles
from swarmbed.wire.child_process import process_alive

CLAIM = "claim.json"
#: the most read of a claim (one is about 200 bytes)
MAX_CLAIM_BYTES = 64 << 10
LOCK = "claim.lock"
STALE_AFTER_S = 120.0  # a claim not touched for this long is abandoned (its holder's node died)


@dataclass(frozen=True)
class Holder:
    """Who holds a claim, as read from its file."""

    host: str
    pid: int
    started: float  # the holding process's start time (psutil), to tell a reused pid apart
    token: str
    touched: float  # the file's mtime

    def alive(self, stale_after: float = STALE_AFTER_S, now: float | None = None) -> bool:
        if self.host == socket.gethostname() and not process_alive(self.pid, self.started):
            return False  # gone, or its pid was reused
        return (time.time() if now is None else now) - self.touched <= stale_after

    def describe(self) -> str:
        return f"pid {self.pid} on {self.host}"


def holder(run_dir: Path) -> Holder | None:
    """The claim on ``run_dir`` as its file says, or None (no claim, or an unreadable one)."""
    path = run_dir / CLAIM
    try:  # bounded and without blocking: a received folder's claim.json may be /dev/zero or a FIFO
        data = json.loads(safefiles.read_file(path, MAX_CLAIM_BYTES))
        return Holder(
            str(data["host"]), int(data["pid"]), float(data["started"]), str(data["token"]), path.lstat().st_mtime
        )
    except (OSError, ValueError, KeyError, TypeError, RecursionError):
        return None


@contextmanager
def _locked(run_dir: Path) -> Iterator[None]:
    fd = safefiles.open_lock(run_dir / LOCK)  # a link planted in a received folder is replaced, never followed
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


class Claim:
    """A claim this process holds on a run directory; touched by a thread until released."""

    def __init__(self, run_dir: Path, token: str, stale_after: float) -> None:
        self.run_dir = run_dir
        self.token = token
        self._stop = threading.Event()
        self._beat = threading.Thread(
            target=self._touch, args=(max(0.5, min(15.0, stale_after / 4)),), daemon=True, name="claim-heartbeat"
        )
        self._beat.start()

    def _touch(self, every: float) -> None:
        while not self._stop.wait(every):
            try:
                os.utime(self.run_dir / CLAIM, follow_symlinks=False)
            except OSError:
                return

    def release(self) -> None:
        self._stop.set()
        self._beat.join()
        with _locked(self.run_dir):
            now = holder(self.run_dir)
            if now is not None and now.token == self.token:
                safefiles.remove(self.run_dir / CLAIM)

    def __enter__(self) -> Claim:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.release()


def take(run_dir: Path, stale_after: float = STALE_AFTER_S) -> Claim | Holder:
    """Claim ``run_dir`` for this process: the :class:`Claim`, or the live :class:`Holder` that
    has it already."""
    safefiles.make_folder(run_dir)
    with _locked(run_dir):
        current = holder(run_dir)
        if current is not None and current.alive(stale_after):
            return current
        return _claim(run_dir, current, stale_after)


def _claim(run_dir: Path, current: Holder | None, stale_after: float) -> Claim:
    """Write this process's claim on ``run_dir`` (under its lock), taking over ``current``'s."""
    token = secrets.token_hex(8)
    me = psutil.Process()
    record = {
        "host": socket.gethostname(),
        "pid": me.pid,
        "started": me.create_time(),
        "token": token,
        "taken": time.time(),
        "took_over": current.describe() if current else None,
    }
    safefiles.write_text(run_dir / CLAIM, json.dumps(record))
    return Claim(run_dir, token, stale_after)
