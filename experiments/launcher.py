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

    def rss_mb(self) -> dict[str, float]:
        out = {}
        for name, proc in self.procs.items():
            try:
                out[name] = psutil.Process(proc.pid).memory_info().rss / 2**20
            except psutil.Error:
                pass
        return out

    def cpu_s(self) -> dict[str, float]:
        """CPU seconds (user + system) each live child has used so far."""
        out = {}
        for name, proc in self.procs.items():
            try:
                t = psutil.Process(proc.pid).cpu_times()
                out[name] = t.user + t.system
            except psutil.Error:
                pass
        return out

    def peak_rss_mb(self) -> dict[str, float]:
        """Each live child's peak resident set so far (Linux VmHWM)."""
        out = {}
        for name, proc in self.procs.items():
            try:
                with open(f"/proc/{proc.pid}/status") as f:
                    for line in f:
                        if line.startswith("VmHWM:"):
                            out[name] = int(line.split()[1]) / 1024
            except OSError:
                pass
        return out

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
