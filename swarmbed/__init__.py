"""swarmbed: a Zenoh-networked emulation testbed for decentralized multi-robot task allocation.

The public API (:mod:`swarmbed.api`), for running experiments from Python::

    import swarmbed

    exp = swarmbed.load("experiments/quickstart.yaml", overrides=["agents.count=8"])
    result = swarmbed.run(exp, "runs/demo", engine="inprocess")
    print(result.summary.ticks, len(result.folder.ledger()))

``load``, ``run``, ``open_run``, ``register_allocator``, ``register_scenario``, and the types they
take and give (``Experiment``, ``Results``, ``RunDir``, ``InProcessRun``, ``ConfigError``,
``PluginError``). They are imported on first use, so the processes of a run, which import only
the packages below, never load the launcher. docs/ARCHITECTURE.md maps the packages.
"""

from __future__ import annotations

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING, Any

try:
    __version__ = version("swarmbed")
except PackageNotFoundError:  # a checkout that was never installed
    __version__ = "0+unknown"

if TYPE_CHECKING:
    from swarmbed.api import (
        ConfigError,
        Experiment,
        InProcessRun,
        PluginError,
        Results,
        RunDir,
        load,
        open_run,
        register_allocator,
        register_scenario,
        run,
    )

__all__ = [
    "ConfigError",
    "Experiment",
    "InProcessRun",
    "PluginError",
    "Results",
    "RunDir",
    "load",
    "open_run",
    "register_allocator",
    "register_scenario",
    "run",
]


def __getattr__(name: str) -> Any:
    if name in __all__:  # loaded by name, on first use: the package root itself imports nothing of ours
        return getattr(import_module("swarmbed.api"), name)
    raise AttributeError(f"module 'swarmbed' has no attribute {name!r}")
