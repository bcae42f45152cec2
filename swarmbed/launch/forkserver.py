"""A fork server for agent processes: import once, fork many.

An agent process spends most of its start-up importing (numpy, pydantic, zenoh, the behavior-tree
engine, the allocators) and holds those modules' memory privately. The fork server is a process
started fresh (never forked from one that holds a Zenoh session) that imports all of it once, opens
no session, and forks one child per agent on request: the child starts with everything imported,
and shares the imported pages with its siblings until it writes to them.

The server is single-threaded (so that forking it is safe): it reads spawn requests from stdin
and writes one event per line to stdout (the messages of :mod:`.forkmessages`): ``ready`` once,
``spawned`` (name, pid) or ``failed`` (name, error) per request, and ``exited`` (pid, code;
negative: killed by that signal, as subprocess reports it) when it reaps a child. Its children
die with it (PR_SET_PDEATHSIG), and it dies with the launcher.
"""

from __future__ import annotations

import gc
import os
import select
import signal
import sys

import setproctitle

from swarmbed.files.safefiles import create_fresh
from swarmbed.launch.forkmessages import (
    Event,
    Exited,
    Failed,
    ForkProtocolError,
    Ready,
    Spawned,
    decode_request,
    encode,
)

# agents do no linear algebra: one BLAS thread, and no thread pool alive when the server forks
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

PRELOAD = ("swarmbed.agent_runtime.process", "swarmbed.plugins")


def _preload() -> None:
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    from swarmbed.plugins import registry

    for name, _kind in registry.entries():  # every shipped allocator's module
        try:
            registry.resolve(name, _kind)
        except Exception:  # a broken optional plugin is the child's to report, with its name
            pass


def _child(argv: list[str], log_path: str) -> None:
    """In the forked child: own session, stdio to the log, default signals; run the agent; never
    return into the server's loop."""
    code = 1
    try:
        os.setsid()
        fd = create_fresh(log_path)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
        os.close(null)
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGCHLD):
            signal.signal(sig, signal.SIG_DFL)
        sys.stdin = open(0, closefd=False)
        sys.stdout = open(1, "w", buffering=1, closefd=False)
        sys.stderr = open(2, "w", buffering=1, closefd=False)
        argv = [*argv, "--parent-pid", str(os.getppid())]
        # what ps and psutil show: the command line the agent would have had as a fresh interpreter
        setproctitle.setproctitle(" ".join([sys.executable, "-m", "swarmbed.agent_runtime", *argv]))
        from swarmbed.agent_runtime.process import main

        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BaseException:
        import traceback

        traceback.print_exc()
        code = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code if isinstance(code, int) else 1)


def _say(event: Event) -> None:
    sys.stdout.buffer.write(encode(event))
    sys.stdout.flush()


def _reap(children: set[int]) -> None:
    while children:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        children.discard(pid)
        code = -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)
        _say(Exited(pid, code))


def serve() -> int:
    from swarmbed.wire.child_process import die_with_parent

    parent = int(sys.argv[1]) if len(sys.argv) > 1 else None
    die_with_parent(parent)
    # Ctrl-C reaches the launcher's process group; the launcher stops us (and we our children)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: _stop(children))
    _preload()
    # what was imported stays as it is: out of the collector's sight, so that no collection in a
    # child walks (and so copies) the pages it shares with its siblings
    gc.collect()
    gc.freeze()
    children: set[int] = set()
    _say(Ready(os.getpid()))
    stdin = sys.stdin.buffer
    pending = b""
    while True:
        readable, _, _ = select.select([stdin], [], [], 0.05)
        _reap(children)
        if not readable:
            continue
        chunk = os.read(stdin.fileno(), 65536)
        if not chunk:  # the launcher closed the pipe: stop every child, then leave
            _stop(children)
        pending += chunk
        while b"\n" in pending:
            line, pending = pending.split(b"\n", 1)
            try:
                request = decode_request(line)
            except ForkProtocolError as exc:
                _say(Failed("?", str(exc)))
                continue
            try:
                pid = os.fork()
            except OSError as exc:
                _say(Failed(request.name, str(exc)))
                continue
            if pid == 0:
                _child(request.argv, request.log)
            children.add(pid)
            _say(Spawned(request.name, pid))


def _stop(children: set[int]) -> None:
    for pid in list(children):
        try:
            os.kill(pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
    os._exit(0)


if __name__ == "__main__":
    sys.exit(serve())
