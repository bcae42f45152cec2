"""Process lifecycle shared by swarmbed's child processes: die with the parent, seeds per component."""

from __future__ import annotations

import argparse
import ctypes
import logging
import os
import signal
import sys
from collections.abc import Callable

import numpy as np

PR_SET_PDEATHSIG = 1

# SeedSequence children of the run seed, one per component; agents get their own sub-tree.
WORLD, NETEM, AGENTS = range(3)


def component_rng(seed: int, component: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[component])


def agent_seeds(seed: int, agent_id: int, n_agents: int, parts: int) -> list[np.random.SeedSequence]:
    """``parts`` independent seed sequences for one agent (runtime, allocator, ...)."""
    agents = np.random.SeedSequence(seed).spawn(3)[AGENTS]
    return agents.spawn(n_agents)[agent_id].spawn(parts)


def die_with_parent(parent_pid: int | None) -> None:
    """Ask Linux to SIGTERM us when the process that started us goes away (no orphans)."""
    if parent_pid is None or not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except OSError:
        return
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(3)


def child_args(prog: str, description: str, add_args: Callable[[argparse.ArgumentParser], object],
               argv: list[str] | None) -> argparse.Namespace:
    """Parse a child process's command line (its own flags, ``--run-id``, ``--parent-pid`` and the
    zenoh flags), tie it to its parent and set up logging to stderr."""
    from swarmbed.wire.session import add_zenoh_args

    ap = argparse.ArgumentParser(prog=prog, description=description)
    ap.add_argument("--run-id", required=True, help="the run to join (see the run's timings.json)")
    add_args(ap)
    ap.add_argument("--parent-pid", type=int, help="exit when this process exits (set by the launcher)")
    add_zenoh_args(ap)
    args = ap.parse_args(argv)
    die_with_parent(args.parent_pid)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s", stream=sys.stderr)
    return args
