"""Starting and stopping the child processes of a run (the netem proxy and the agents).

Children are spawned (never forked from a process holding a Zenoh session), in their own session
so that Ctrl-C reaches only the launcher, and they ask the kernel to terminate them if the launcher
dies. Each writes its output to ``logs/<name>.log`` in the run directory. Agents come from a fork
server (:mod:`.forkserver`) where one is running: a process that imported everything once.
"""

from __future__ import annotations

import logging
import os
import queue
import resource
import signal
import site
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from pathlib import Path

import psutil

import swarmbed
from swarmbed.files.safefiles import open_fresh
from swarmbed.launch.forkmessages import (
    Exited,
    Failed,
    ForkProtocolError,
    Ready,
    Spawned,
    SpawnRequest,
    decode_event,
    encode,
)
from swarmbed.wire.zenoh_session import RUNTIMES

log = logging.getLogger("swarmbed.launcher")

AGENT_MODULE = "swarmbed.agent_runtime"


class ChildExited(RuntimeError):
    pass


def zenoh_env(threads: str) -> dict[str, str]:
    """The environment that gives a run's processes ``run.zenoh_threads``."""
    return {"ZENOH_RUNTIME": RUNTIMES[threads]} if threads in RUNTIMES else {}


def python_env(extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment of the Python processes a run starts (``python -m ...``): they import the
    swarmbed this process runs, and the current directory only where this process has it on its
    path too. ``-m`` alone would put the current directory first, so a run started beside a folder
    named ``swarmbed`` (another checkout, say) would run its agents and proxy on that code while
    the launcher ran this one."""
    env = {**os.environ, **(extra or {})}
    env["PYTHONSAFEPATH"] = "1"  # no current directory first on the path
    front = []
    root = os.path.dirname(os.path.dirname(os.path.abspath(swarmbed.__file__)))
    if root not in {*site.getsitepackages(), site.getusersitepackages()}:  # a checkout, not an install
        front.append(root)
    cwd = os.getcwd()
    if any(entry in ("", cwd) for entry in sys.path):
        front.append(cwd)  # as for this process (``python -m swarmbed`` in a project with its own plugins)
    if env.get("PYTHONPATH"):
        front.append(env["PYTHONPATH"])
    if front:
        env["PYTHONPATH"] = os.pathsep.join(front)
    return env


def peak_rss_mb(pid: int) -> float:
    """A process's peak resident set (Linux VmHWM), since it started or since :func:`reset_peak_rss`."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    raise ValueError("no VmHWM")


def own_cpu_s() -> float:
    """CPU seconds (user + system) this process has used, all its threads included."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def wakeups(pid: int) -> int:
    """Voluntary context switches of every thread of a process so far (each one a wake-up after
    waiting: for a sample, a lock, a timer), from /proc/<pid>/task/*/status. A count, not a time:
    it does not move with the machine's load the way wall and CPU times do."""
    total = 0
    for task in os.scandir(f"/proc/{pid}/task"):
        try:
            with open(f"{task.path}/status") as f:
                for line in f:
                    if line.startswith("voluntary_ctxt_switches:"):
                        total += int(line.split()[1])
                        break
        except OSError:  # the thread ended while we looked
            continue
    return total


def reset_peak_rss() -> None:
    """Start this process's VmHWM afresh (a sweep's pool worker hosts one run after another, and a
    run's peak is its own). Best effort: kernels before 4.0 keep the lifetime peak."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


class ForkedProcess:
    """A child of the fork server, with the part of :class:`subprocess.Popen`'s interface the
    launcher uses (the server reaps it and reports its exit code)."""

    def __init__(self, server: ForkServer, pid: int) -> None:
        self.server = server
        self.pid = pid
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.returncode = self.server.exit_code(self.pid)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if deadline is not None and time.monotonic() > deadline:
                raise subprocess.TimeoutExpired(f"agent pid {self.pid}", timeout or 0.0)
            time.sleep(0.01)
        assert self.returncode is not None
        return self.returncode

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            try:
                os.kill(self.pid, sig)
            except ProcessLookupError:
                pass

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class ForkServerError(RuntimeError):
    pass


class ForkServer:
    """The launcher's end of :mod:`.forkserver`: start it, ask it for agents, learn their ends."""

    def __init__(self, log_path: Path, timeout: float = 60.0, env: Mapping[str, str] | None = None) -> None:
        self.log = open_fresh(log_path)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "swarmbed.launch.forkserver", str(os.getpid())],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.log,
            start_new_session=True,
            close_fds=True,
            env=python_env(env),
        )
        self.replies: queue.SimpleQueue = queue.SimpleQueue()
        self.exits: dict[int, int] = {}
        self.lock = threading.Lock()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        try:
            ready = self.replies.get(timeout=timeout)
        except queue.Empty:
            ready = None
        if not isinstance(ready, Ready):
            self.close()
            raise ForkServerError(f"the agents' fork server did not start; see {log_path}")

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                event = decode_event(line)
            except ForkProtocolError as exc:
                log.error("launcher: %s", exc)
                continue
            if isinstance(event, Exited):
                with self.lock:
                    self.exits[event.pid] = event.code
            else:
                self.replies.put(event)
        self.replies.put(None)  # the server is gone

    def spawn(self, name: str, argv: list[str], log: Path, timeout: float = 30.0) -> ForkedProcess:
        assert self.proc.stdin is not None
        try:
            self.proc.stdin.write(encode(SpawnRequest(name, argv, str(log))))
            self.proc.stdin.flush()
            reply = self.replies.get(timeout=timeout)
        except (OSError, queue.Empty):
            reply = None
        if not isinstance(reply, Spawned):
            why = reply.error if isinstance(reply, Failed) else "it is gone or did not answer"
            raise ForkServerError(f"the fork server could not start {name}: {why}")
        return ForkedProcess(self, reply.pid)

    def exit_code(self, pid: int) -> int | None:
        with self.lock:
            code = self.exits.get(pid)
        if code is None and self.proc.poll() is not None and not psutil.pid_exists(pid):
            return -signal.SIGTERM  # the server went first and took its children with it
        return code

    def close(self) -> None:
        """Stop the server; its children get SIGTERM from it (and from the kernel)."""
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.close()
            except OSError:
                pass
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.reader.join(timeout=5)
        self.log.close()


def describe_exit(returncode: int | None) -> str:
    """A process's exit status in words: ``exited with code 1``, ``was killed by signal SIGKILL``."""
    if returncode is None:
        return "is still running"
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = str(-returncode)
        return f"was killed by signal {name}"
    return f"exited with code {returncode}"


class Children:
    def __init__(self, log_dir: Path, fork_agents: bool = False, env: Mapping[str, str] | None = None) -> None:
        self.log_dir = log_dir
        self.env = dict(env or {})  # beside python_env(): e.g. zenoh_env(run.zenoh_threads)
        self.procs: dict[str, subprocess.Popen | ForkedProcess] = {}
        self.elsewhere: set[str] = set()  # children started on another machine (adopt)
        self.started_at: dict[str, float] = {}
        self.forked = fork_agents
        self.server: ForkServer | None = ForkServer(log_dir / "forkserver.log", env=self.env) if fork_agents else None

    def spawn(self, name: str, module: str, args: list[str]) -> subprocess.Popen | ForkedProcess:
        log_path = self.log_dir / f"{name}.log"
        proc: subprocess.Popen | ForkedProcess
        if module == AGENT_MODULE and self.server is not None:
            proc = self.server.spawn(name, args, log_path)
        else:
            proc = self._run([sys.executable, "-m", module, *args, "--parent-pid", str(os.getpid())], log_path)
        self.procs[name] = proc
        self.started_at[name] = time.monotonic()
        return proc

    def _run(self, command: list[str], log_path: Path) -> subprocess.Popen:
        """``command`` in a session of its own, its output to ``log_path``, with the children's environment."""
        with open_fresh(log_path) as log:
            return subprocess.Popen(
                command,
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                close_fds=True,
                env=python_env(self.env),
            )

    def adopt(self, name: str, command: list[str]) -> subprocess.Popen:
        """Run ``command``, which starts child ``name`` elsewhere (``srun`` on another node): its
        output goes to the child's log here, its exit is watched like any child's, and its CPU and
        memory, which are the starter's, are not counted as the child's."""
        proc = self._run(command, self.log_dir / f"{name}.log")
        self.procs[name] = proc
        self.elsewhere.add(name)
        self.started_at[name] = time.monotonic()
        return proc

    def log_tail(self, name: str, lines: int = 15) -> str:
        try:
            text = (self.log_dir / f"{name}.log").read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return "\n".join("    " + line for line in text[-lines:])

    def exit_status(self, name: str, wait: float = 2.0) -> str:
        """How child ``name`` ended, once it has (waiting up to ``wait`` s, since a process lets go
        of its token a moment before it exits): "exited with code 1" or "was killed by signal
        SIGKILL", then the end of its log; "" for a child this launcher did not start."""
        proc = self.procs.get(name)
        if proc is None:
            return ""
        try:
            proc.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            return f"{name} let go of its token but is still running; logs/{name}.log ends with:\n{self.log_tail(name)}"
        return f"{name} {describe_exit(proc.returncode)}; logs/{name}.log ends with:\n{self.log_tail(name)}"

    def check(self) -> None:
        """Raise if a child has already exited (used while waiting for everyone to join)."""
        for name, proc in self.procs.items():
            rc = proc.poll()
            if rc is not None:
                raise ChildExited(
                    f"{name} {describe_exit(rc)} before the run started; "
                    f"logs/{name}.log ends with:\n{self.log_tail(name)}"
                )

    def _each(self, read) -> dict:
        """``read(pid)`` for every child still there."""
        out = {}
        for name, proc in self.procs.items():
            if name in self.elsewhere:
                continue
            try:
                out[name] = read(proc.pid)
            except (psutil.Error, OSError, ValueError):
                pass
        return out

    def rss_mb(self) -> dict[str, float]:
        return self._each(lambda pid: psutil.Process(pid).memory_info().rss / 2**20)

    def shared_mb(self) -> dict[str, tuple[float, float]]:
        """Each child's proportional and unique set sizes (PSS, USS): what it costs the machine,
        pages shared with its siblings (imported code, the fork server's heap) counted by share or
        not at all. Reads /proc/<pid>/smaps: a few milliseconds per process."""

        def read(pid: int) -> tuple[float, float]:
            info = psutil.Process(pid).memory_full_info()
            return info.pss / 2**20, info.uss / 2**20

        return self._each(read)

    def cpu_s(self) -> dict[str, float]:
        """CPU seconds (user + system) each child has used so far."""
        return self._each(lambda pid: sum(psutil.Process(pid).cpu_times()[:2]))

    def wakeups(self) -> dict[str, int]:
        """Each child's wake-ups so far (:func:`wakeups`)."""
        return self._each(wakeups)

    def peak_rss_mb(self) -> dict[str, float]:
        """Each child's peak resident set so far (Linux VmHWM)."""
        return self._each(peak_rss_mb)

    def wait(self, timeout: float) -> dict[str, int | None]:
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
        if self.server is not None:
            self.server.close()
            self.server = None
