"""Where a sweep's runs execute: this machine's process pool, a Slurm cluster (submitit) or a Dask
cluster. Every executor calls the same run function on each run, so a run's result files do not
depend on where it ran; the sweep command keeps the plan, the claims and the result store.

An executor is chosen by name (:func:`get`); its module is imported only then, so a missing optional
dependency is reported by name with the extra that installs it.
"""

from __future__ import annotations

import importlib
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

#: what one run returns: ("ok" | "failed" | "claimed" | "lost", detail)
Outcome = tuple[str, str]
RunFunction = Callable[[Any], Outcome]

NAMES = {"local": "local", "slurm": "slurm", "dask": "dask"}  # executor name -> module
EXTRAS = {"slurm": ("submitit", "slurm"), "dask": ("distributed", "dask")}  # module needed, extra


class ExecutorError(RuntimeError):
    """An executor that cannot be used: a missing extra, an unreachable scheduler, bad options."""


@dataclass(frozen=True)
class Resources:
    """What one run asks of a node."""

    cpus: int
    mem_gb: int


def resources_for(agents: int) -> Resources:
    """Cores and memory for a run of ``agents`` agents (measured on 2-core machines: a run of 50
    agents keeps 2 cores busy in lock-step, an agent forked from the fork server costs ~13 MB of its
    own plus the shared pages, and the coordinator and proxy grow with the run; see docs/campaigns.md, "Sweeps
    on a cluster"): 2 cores up to 50 agents, one more per further 50 agents, up to 16; 1 GB plus
    50 MB per agent, rounded up."""
    cpus = min(16, 2 + max(0, math.ceil((agents - 50) / 50)))
    return Resources(cpus, math.ceil(1 + 0.05 * agents))


class Executor(ABC):
    """Runs items through a run function somewhere and reports each outcome as it arrives."""

    name: str = ""

    @abstractmethod
    def map(
        self, fn: RunFunction, items: Sequence[Any], resources: Sequence[Resources]
    ) -> Iterator[tuple[int, Outcome]]:
        """Start ``fn(item)`` for every item; yield ``(index, outcome)`` as each ends. A run whose
        worker was lost (killed, node gone) yields ``("lost", why)``."""

    def cancel(self) -> None:
        """Ctrl-C: start nothing new and stop what is running (its claims are then stale)."""
        return

    def close(self) -> None:
        """Release the executor's own resources (pools, clients)."""
        return

    def describe(self) -> str:
        return self.name


def get(name: str, **options: Any) -> Executor:
    """The executor called ``name`` with its options (``jobs`` for local; ``partition``, ``time_min``
    and ``folder`` for slurm; ``scheduler`` for dask)."""
    if name not in NAMES:
        raise ExecutorError(f"--executor {name!r}: choose one of {', '.join(NAMES)}")
    if name in EXTRAS:
        needed, extra = EXTRAS[name]
        try:
            importlib.import_module(needed)
        except ImportError:
            raise ExecutorError(
                f"--executor {name} needs the {needed!r} package: pip install 'swarmbed[{extra}]'"
            ) from None
    module = importlib.import_module(f"{__name__}.{NAMES[name]}")
    executor: Executor = module.make(**options)
    return executor
