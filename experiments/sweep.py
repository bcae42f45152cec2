"""``swarmbed sweep``: Monte Carlo runs over scenarios, in parallel, resumable.

A sweep file names a base experiment, overrides for every run (``set``), the scenarios (an
explicit list, a grid over dotted keys, or both: every listed scenario crossed with every grid
point) and the runs per scenario:

    name: space_fig3
    base: space_mtsr.yaml
    seed: 0
    runs: 100
    grid:
      agents.count: [10, 30, 50]
      network.range: [100, 200, 300]
      allocator: [{name: cbba}, {name: grape}, {name: fcg}]

A plain experiment file works too, with the grid on the command line (Hydra-multirun style):
``swarmbed sweep experiments/quickstart.yaml --grid allocator.name=cbba,grape --runs 5``.

Run r of every scenario gets the same seed, the r-th child of ``SeedSequence(seed)``: the
scenarios are compared on common random numbers (paired runs), and runs within a scenario are
independent. Each run has its own directory ``<out>/<scenario>/run_<r>``; a run whose directory
holds a ``summary.json`` is complete and is kept when the sweep is started again, anything else is
redone. A failed run writes ``error.txt`` and does not stop the sweep. The sweep ends with
``sweep.csv``: one row per run with the scenario parameters, the seed and every summary metric.
"""

from __future__ import annotations

import concurrent.futures as cf
import itertools
import json
import multiprocessing
import os
import signal
import traceback
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import psutil
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from tqdm import tqdm

from swarmbed.coordinator import results
from swarmbed.experiments import config as cfg

TABLE = "sweep.csv"
SPEC = "sweep.json"
ERROR = "error.txt"


class ScenarioEntry(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    set: dict[str, Any] = Field(default_factory=dict)


class SweepFile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = "sweep"
    base: str
    seed: int = Field(0, ge=0)
    runs: int = Field(1, ge=1)
    set: dict[str, Any] = Field(default_factory=dict)  # overrides for every run
    scenarios: list[ScenarioEntry] = Field(default_factory=list)
    grid: dict[str, list[Any]] = Field(default_factory=dict)


@dataclass(frozen=True)
class SweepScenario:
    """One condition of a sweep (the papers call them scenarios): a name and its overrides."""

    name: str
    overrides: tuple[tuple[str, Any], ...]


@dataclass(frozen=True)
class RunSpec:
    base: str
    scenario: SweepScenario
    index: int
    seed: int
    out_dir: str
    extra: tuple[str, ...]  # --set overrides from the command line


@dataclass
class Sweep:
    name: str
    base: Path
    seed: int
    runs: int
    scenarios: list[SweepScenario]
    factors: list[str]
    extra: list[str]


def _label(value: Any) -> str:
    if isinstance(value, dict):
        value = value.get("name", "-".join(f"{k}{v}" for k, v in value.items()))
    return str(value).replace("/", "-").replace(" ", "")


def _parse_grid(text: str) -> tuple[str, list[Any]]:
    key, sep, raw = text.partition("=")
    if not sep:
        raise cfg.ConfigError(f"--grid {text!r}: expected dotted.key=v1,v2,...")
    return key.strip(), [yaml.safe_load(v) for v in raw.split(",")]


def load_sweep(path: str | Path, runs: int | None = None, grid: Sequence[str] = (), extra: Sequence[str] = (),
               seed: int | None = None) -> Sweep:
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise cfg.ConfigError(f"{path}: cannot read sweep: {exc}") from None
    if not isinstance(data, dict):
        raise cfg.ConfigError(f"{path}: the top level must be a mapping")
    if "base" not in data:  # a plain experiment: sweep over it
        data = {"name": data.get("name", path.stem), "base": path.name}
    try:
        spec = SweepFile.model_validate(data)
    except ValidationError as exc:
        raise cfg.ConfigError("\n".join(f"{path}: {'.'.join(map(str, e['loc']))}: {e['msg']}"
                                        for e in exc.errors())) from None
    common = tuple(spec.set.items())
    grid_spec = dict(spec.grid)
    grid_spec.update(_parse_grid(g) for g in grid)
    entries = [SweepScenario(e.name, tuple(e.set.items())) for e in spec.scenarios] or [SweepScenario("", ())]
    keys = list(grid_spec)
    scenarios = []
    for entry in entries:
        for combo in itertools.product(*(grid_spec[k] for k in keys)):
            parts = [entry.name] if entry.name else []
            parts += [f"{k.split('.')[-1]}-{_label(v)}" for k, v in zip(keys, combo)]
            overrides = common + entry.overrides + tuple(zip(keys, combo))
            scenarios.append(SweepScenario("_".join(parts) or "base", overrides))
    names = [s.name for s in scenarios]
    if len(set(names)) != len(names):
        raise cfg.ConfigError(f"{path}: two scenarios share a name")
    varying = {k for s in scenarios for k, _ in s.overrides if k not in spec.set or
               any(dict(s2.overrides).get(k) != spec.set[k] for s2 in scenarios)}
    factors = sorted(varying)
    if runs is not None and runs < 1:
        raise cfg.ConfigError(f"--runs {runs}: a sweep needs at least one run per scenario")
    return Sweep(spec.name, (path.parent / spec.base).resolve(), spec.seed if seed is None else seed,
                 spec.runs if runs is None else runs, scenarios, factors, list(extra))


def run_seeds(sweep_seed: int, runs: int) -> list[int]:
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(sweep_seed).spawn(runs)]


def experiment_for(base: str | Path, scenario: SweepScenario, seed: int,
                   extra: list[str] | tuple[str, ...]) -> cfg.Experiment:
    pairs = list(scenario.overrides) + [cfg.parse_override(t) for t in extra] + [("run.seed", seed)]
    return cfg.load(base, [f"{k}={json.dumps(v)}" for k, v in pairs])


def plan(sweep: Sweep, out: Path) -> list[RunSpec]:
    seeds = run_seeds(sweep.seed, sweep.runs)
    return [RunSpec(str(sweep.base), sc, r, seeds[r], str(out / sc.name / f"run_{r:03d}"), tuple(sweep.extra))
            for sc in sweep.scenarios for r in range(sweep.runs)]


def _execute(spec: RunSpec) -> tuple[str, str]:
    """One run, in a worker process. Returns (status, detail)."""
    from swarmbed.experiments.runner import run_experiment

    out = Path(spec.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / ERROR).unlink(missing_ok=True)
    try:
        run_experiment(experiment_for(spec.base, spec.scenario, spec.seed, spec.extra), out, progress=False)
        return "ok", ""
    except Exception as exc:  # a failed run is recorded, the sweep goes on (an interrupt is not a failure)
        detail = f"{type(exc).__name__}: {exc}\n\n{traceback.format_exc()}"
        results.write_atomic(out / ERROR, detail)
        return "failed", f"{type(exc).__name__}: {exc}"


def flatten(summary: dict, prefix: str = "") -> dict[str, Any]:
    """Scalar metrics of a summary, nested keys dotted; per-agent lists become their mean."""
    row: dict[str, Any] = {}
    for key, value in summary.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            if key in ("per_kind", "agents_lost"):
                continue
            row.update(flatten(value, f"{name}."))
        elif isinstance(value, list):
            if value and all(isinstance(v, (int, float)) for v in value):
                row[f"{name}_mean"] = float(np.mean(value))
        else:
            row[name] = value
    return row


def collect(sweep: Sweep, out: Path) -> pd.DataFrame:
    rows = []
    for spec in plan(sweep, out):
        run_dir = Path(spec.out_dir)
        row = {"scenario": spec.scenario.name, "run": spec.index, "seed": spec.seed}
        row.update({k: json.dumps(v) if isinstance(v, (dict, list)) else v for k, v in spec.scenario.overrides})
        summary = run_dir / results.SUMMARY
        if summary.exists():
            row["status"] = "ok"
            row.update(flatten(json.loads(summary.read_text())))
            transport = run_dir / results.TRANSPORT  # measured, not reproducible: in its own columns
            if transport.exists():
                row.update(flatten(json.loads(transport.read_text())["totals"], "wire."))
        else:
            row["status"] = "failed" if (run_dir / ERROR).exists() else "missing"
            if (run_dir / ERROR).exists():
                lines = [ln for ln in (run_dir / ERROR).read_text().split("\n\n", 1)[0].splitlines() if ln.strip()]
                row["error"] = " | ".join(dict.fromkeys([lines[0], lines[-1]])) if lines else "unknown error"
        rows.append(row)
    return pd.DataFrame(rows)


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep; the message says what completed and how to resume."""


def _exit(signum: int, _frame: object) -> None:
    raise SystemExit(128 + signum)


def _leave_interrupts_to_the_main_process() -> None:
    """Pool workers: Ctrl-C is the sweep's to handle, so that a run never records it as a failure
    (a Python-level handler, not SIG_IGN: the runs' own children get the default action back), and
    SIGTERM from the sweep ends the run through its cleanup (children stopped, partial files gone)."""
    signal.signal(signal.SIGINT, lambda *_: None)
    signal.signal(signal.SIGTERM, _exit)


def _stop_descendants(grace: float = 10.0) -> None:
    """Stop every process this one started. The pool workers are asked first (SIGTERM: each ends
    its run through the runner's cleanup, which stops that run's processes); whatever is left
    after ``grace`` seconds is killed."""
    family = [p for p in psutil.Process().children(recursive=True)
              if "multiprocessing.resource_tracker" not in " ".join(_cmdline(p))]
    workers = [p for p in psutil.Process().children() if p in family]
    for procs, stop in ((workers, psutil.Process.terminate), (family, psutil.Process.kill)):
        for p in procs:
            try:
                stop(p)
            except psutil.NoSuchProcess:
                pass
        psutil.wait_procs(procs, timeout=grace)


def _cmdline(p: psutil.Process) -> list[str]:
    try:
        return p.cmdline()
    except psutil.Error:
        return []


def _complete(specs: list[RunSpec]) -> int:
    return sum(1 for s in specs if (Path(s.out_dir) / results.SUMMARY).exists())


def run_sweep(sweep: Sweep, out: Path, jobs: int | None = None, progress: bool = True) -> pd.DataFrame:
    if jobs is not None and jobs < 1:
        raise cfg.ConfigError(f"--jobs {jobs}: at least one run must be able to go at once")
    out.mkdir(parents=True, exist_ok=True)
    specs = plan(sweep, out)
    for spec in specs[: len(sweep.scenarios)]:  # every scenario is valid before anything starts
        experiment_for(spec.base, spec.scenario, spec.seed, spec.extra)
    results.write_json(out / SPEC, {"name": sweep.name, "base": str(sweep.base), "seed": sweep.seed,
                                    "runs": sweep.runs, "factors": sweep.factors, "extra": sweep.extra,
                                    "scenarios": {s.name: dict(s.overrides) for s in sweep.scenarios}})
    todo = [s for s in specs if not (Path(s.out_dir) / results.SUMMARY).exists()]
    done_before = len(specs) - len(todo)
    jobs = jobs or os.cpu_count() or 1
    bar = tqdm(total=len(specs), initial=done_before, unit="run", desc=sweep.name, disable=not progress)
    pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                                  initializer=_leave_interrupts_to_the_main_process)
    try:
        futures = {pool.submit(_execute, s): s for s in todo}
        for fut in cf.as_completed(futures):
            status, detail = fut.result()
            if status != "ok":
                bar.write(f"failed: {futures[fut].out_dir}: {detail}")
            bar.update(1)
    except KeyboardInterrupt:
        pool.shutdown(wait=False, cancel_futures=True)  # nothing new starts
        _stop_descendants()  # and what runs stops now
        bar.close()
        for spec in specs:  # an incomplete run leaves no half-written file behind
            if not (Path(spec.out_dir) / results.SUMMARY).exists():
                for partial in Path(spec.out_dir).glob("*.part"):
                    partial.unlink(missing_ok=True)
        done = _complete(specs)
        raise SweepInterrupted(
            f"interrupted: {done} of {len(specs)} runs are complete ({done - done_before} finished in this session); "
            f"the runs under way were stopped and nothing else was started. Run the same command again to do "
            f"the other {len(specs) - done}.") from None
    finally:
        bar.close()
    pool.shutdown(wait=True)
    table = collect(sweep, out)
    tmp = out / (TABLE + ".part")
    table.to_csv(tmp, index=False)
    os.replace(tmp, out / TABLE)
    return table
