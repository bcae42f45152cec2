"""Which code made a result: ``provenance.json`` beside every run's ``config.yaml``.

It records swarmbed's version, the git commit of the checkout it ran from and whether that tree
had uncommitted changes, the scenario's and the allocator's class and ``version``, and the versions
of Python and of the libraries that shape results (numpy, zenoh, msgpack, pydantic). Nothing in it
depends on the machine, the time or where agents ran: the same code gives the same file, so lock-step
runs stay byte-identical across placements. Sweep tables carry it as ``provenance.*`` columns and
``swarmbed analyze`` refuses to pool runs whose scenario or allocator versions differ.
"""

from __future__ import annotations

import functools
import platform
import subprocess
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import swarmbed
from swarmbed.extension.allocator import Allocator
from swarmbed.records.run_folder import PROVENANCE

FILE = PROVENANCE
LIBRARIES = ("numpy", "eclipse-zenoh", "msgpack", "pydantic")


@functools.lru_cache(maxsize=1)
def code_state() -> dict[str, Any]:
    """swarmbed's version, its checkout's commit and dirtiness (None outside a git checkout), and
    the versions of Python and the libraries results depend on. Computed once per process."""
    checkout = Path(swarmbed.__file__).resolve().parent.parent
    git: dict[str, Any] | None = None
    if not all((checkout / name).is_dir() for name in ("wire", "netem", "coordinator")):
        return _versions(git)  # an installed copy: whatever repository encloses site-packages is not its source
    try:
        head = subprocess.run(
            ["git", "-C", str(checkout), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10
        )
        if head.returncode == 0:
            status = subprocess.run(
                ["git", "-C", str(checkout), "status", "--porcelain", "--untracked-files=no"],
                capture_output=True,
                text=True,
                timeout=10,
            )
            git = {"commit": head.stdout.strip(), "dirty": bool(status.stdout.strip())}
    except (OSError, subprocess.SubprocessError):
        git = None
    return _versions(git)


def _versions(git: dict[str, Any] | None) -> dict[str, Any]:
    libraries: dict[str, str | None] = {}
    for name in LIBRARIES:
        try:
            libraries[name] = version(name)
        except PackageNotFoundError:
            libraries[name] = None
    return {"swarmbed": swarmbed.__version__, "git": git, "python": platform.python_version(), "libraries": libraries}


def provenance(scenario_cls: type, scenario_target: str, allocator_cls: type[Allocator], allocator_target: str) -> dict:
    """What ``provenance.json`` holds for a run of this scenario and allocator."""
    return {
        **code_state(),
        "scenario": {"target": scenario_target, "version": str(getattr(scenario_cls, "version", "1"))},
        "allocator": {"target": allocator_target, "version": allocator_cls.version},
    }
