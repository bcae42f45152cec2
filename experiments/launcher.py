"""Starting and stopping the child processes of a run (the netem proxy and the agents).

Children are spawned (never forked from a process holding a Zenoh session), in their own session
so that Ctrl-C reaches only the launcher, and they ask the kernel to terminate them if the launcher
dies. Each writes its output to ``logs/<name>.log`` in the run directory.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import psutil


class ChildExited(RuntimeError):
    pass


def _peak_rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    raise ValueError("no VmHWM")


class Children:
    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.procs: dict[str, subprocess.Popen] = {}
        self.started_at: dict[str, float] = {}

    def spawn(self, name: str, module: str, args: list[str]) -> subprocess.Popen:
        log = open(self.log_dir / f"{name}.log", "wb")
        cmd = [sys.executable, "-m", module, *args, "--parent-pid", str(os.getpid())]
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True, close_fds=True)
        log.close()
        self.procs[name] = proc
        self.started_at[name] = time.monotonic()
        return proc

    def log_tail(self, name: str, lines: int = 15) -> str:
        try:
            text = (self.log_dir / f"{name}.log").read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return "\n".join("    " + line for line in text[-lines:])

    def check(self) -> None:
        """Raise if a child has already exited (used while waiting for everyone to join)."""
        for name, proc in self.procs.items():
            rc = proc.poll()
            if rc is not None:
                raise ChildExited(f"{name} exited with code {rc} before the run started; "
                                  f"logs/{name}.log ends with:\n{self.log_tail(name)}")

    def _each(self, read) -> dict[str, float]:
        """``read(pid)`` for every child still there."""
        out = {}
        for name, proc in self.procs.items():
            try:
                out[name] = read(proc.pid)
            except (psutil.Error, OSError, ValueError):
                pass
        return out

    def rss_mb(self) -> dict[str, float]:
        return self._each(lambda pid: psutil.Process(pid).memory_info().rss / 2**20)

    def cpu_s(self) -> dict[str, float]:
        """CPU seconds (user + system) each child has used so far."""
        return self._each(lambda pid: sum(psutil.Process(pid).cpu_times()[:2]))

    def peak_rss_mb(self) -> dict[str, float]:
        """Each child's peak resident set so far (Linux VmHWM)."""
        return self._each(_peak_rss_mb)

    def wait(self, timeout: float) -> dict[str, int]:
        """Wait for every child to exit; terminate (then kill) whatever is left at ``timeout``."""
        deadline = time.monotonic() + timeout
        for proc in self.procs.values():
            try:
                proc.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
        self.kill_all()
        return {name: proc.returncode for name, proc in self.procs.items()}

    def kill_all(self, grace: float = 3.0) -> None:
        alive = [p for p in self.procs.values() if p.poll() is None]
        for p in alive:
            p.terminate()
        deadline = time.monotonic() + grace
        for p in alive:
            try:
                p.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
