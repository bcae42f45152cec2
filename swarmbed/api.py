"""The public API: an experiment loaded, run on either engine, its results read; an allocator or a
scenario registered. ``import swarmbed`` hands these names on (lazily: a process that imports only
``swarmbed.wire`` pays nothing for them).

    import swarmbed

    exp = swarmbed.load("experiments/quickstart.yaml", overrides=["agents.count=8"], seed=3)
    result = swarmbed.run(exp, "runs/demo", engine="inprocess")
    print(result.summary.tasks_completed, result.folder.ledger().head())

The caller owns the loop where it wants one (``swarmbed.InProcessRun``: ``observe``/``advance``),
as PettingZoo's and Mesa's users do; :func:`run` steps a run to its end.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from swarmbed.config import ConfigError
from swarmbed.config import load as _load
from swarmbed.launch.inprocess import InProcessRun
from swarmbed.launch.runner import RunResult, run_experiment
from swarmbed.plugins.registry import PluginError, register, register_scenario
from swarmbed.records.run_folder import RunDir
from swarmbed.records.summary import RunSummary
from swarmbed.schema.experiment import Experiment

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


@dataclass(frozen=True)
class Results:
    """A finished run: its folder (every file, read safely and typed) and its summary."""

    folder: RunDir
    summary: RunSummary
    timings: dict


def load(path: str | Path, overrides: list[str] | tuple[str, ...] = (), seed: int | None = None) -> Experiment:
    """The experiment in the YAML file ``path``, with ``overrides`` (``"dotted.key=value"``, as
    ``--set`` takes them) and ``seed`` applied, every name resolved and every value checked. A bad
    file or value raises :class:`ConfigError` naming the file and the key."""
    return _load(path, list(overrides), seed)


def run(exp: Experiment, out: str | Path, engine: Literal["processes", "inprocess"] = "processes") -> Results:
    """Run ``exp`` in lock-step to its end and write its result files into the folder ``out``
    (made if missing; a finished run there is replaced). ``engine="processes"``: every agent its own
    process, the radio a netem proxy, all over Zenoh on loopback; ``"inprocess"``: the same tick in
    this process, byte-identical result files, no network."""
    out = Path(out)
    if engine == "inprocess":
        result: RunResult = InProcessRun(exp, out).run()
    elif engine == "processes":
        result = run_experiment(exp, out, progress=False)
    else:
        raise ValueError(f"engine {engine!r}: 'processes' or 'inprocess'")
    return open_run(result.out_dir, result.timings)


def open_run(folder: str | Path, timings: dict | None = None) -> Results:
    """The results in a finished run's folder (one made here or received from anyone: every read is
    bounded and refuses links out of the folder)."""
    run_dir = RunDir(Path(folder))
    return Results(run_dir, run_dir.summary(), timings or {})


def register_allocator(name: str, target: str, scenario: str = "*") -> None:
    """Make ``allocator.name: <name>`` mean the class ``target`` (``"package.module:Class"``, imported
    by every agent when a run starts), for one scenario kind or, by default, all."""
    register(name, target, scenario)
