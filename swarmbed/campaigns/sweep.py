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
``sweep.csv`` and ``sweep.parquet``: one row per run with the scenario parameters, the seed and
every summary metric.

Where runs execute is an executor's business (:mod:`.executors`: the local pool, Slurm, Dask);
each calls :func:`execute`, which claims the run's directory first (:mod:`.claims`), so several
sweep commands, on one machine or many, can work on one directory at once.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import re
import socket
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from tqdm import tqdm

from swarmbed import config as cfg
from swarmbed.campaigns import claims
from swarmbed.campaigns.executors import Executor, Outcome, resources_for
from swarmbed.engine import results
from swarmbed.files import safefiles
from swarmbed.files.yamlfile import YamlFileError, parse_yaml, read_yaml
from swarmbed.records.run_folder import (
    MAX_CONFIG_BYTES,
    PROVENANCE,
    RunDir,
    RunFileError,
    read_json_member,
    read_member,
)
from swarmbed.results.campaign_folders import ATTEMPTS, DERIVED, ERROR, PARQUET, SPEC, TABLE, dotted
from swarmbed.schema.experiment import SAFE_NAME
from swarmbed.wire.errors import WireError
from swarmbed.wire.validation import did_you_mean, validation_lines


class ScenarioEntry(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = Field(pattern=SAFE_NAME)
    set: dict[str, Any] = Field(default_factory=dict)


class SweepFile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = Field("sweep", pattern=SAFE_NAME)
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


def _axis(key: str) -> str:
    """A grid key's part of a scenario name: its last part (``range``), or its section's where that
    says more (``allocator.name`` -> ``allocator``, ``scenario.kind`` -> ``scenario``)."""
    parts = key.split(".")
    return parts[-2] if len(parts) > 1 and parts[-1] in ("name", "kind") else parts[-1]


def _label(value: Any) -> str:
    if isinstance(value, dict):
        value = value.get("name", "-".join(f"{k}{v}" for k, v in value.items()))
    return re.sub(r"[^A-Za-z0-9_.+=-]", "-", str(value).replace(" ", ""))


def _parse_grid(text: str) -> tuple[str, list[Any]]:
    key, sep, raw = text.partition("=")
    if not sep:
        raise cfg.ConfigError(f"--grid {text!r}: expected dotted.key=v1,v2,...")
    parts = raw.split(",")
    if not key.strip() or any(not v.strip() for v in parts):
        raise cfg.ConfigError(f"--grid {text!r}: a key and values between commas, none of them empty")
    if len(set(map(str.strip, parts))) < len(parts):
        raise cfg.ConfigError(f"--grid {text!r}: a value is given twice")
    try:
        return key.strip(), [parse_yaml(v, f"--grid {text}") for v in parts]
    except YamlFileError as exc:
        raise cfg.ConfigError(str(exc)) from None


def _overlap(a: str, b: str) -> bool:
    """Whether dotted keys ``a`` and ``b`` set the same value or one sets a part of the other."""
    return a == b or a.startswith(b + ".") or b.startswith(a + ".")


def _only(entries: list[SweepScenario], only: Sequence[str], path: Path) -> list[SweepScenario]:
    """The scenarios named in ``only`` (all of them if it is empty); a name the file lacks is refused."""
    if not only:
        return entries
    known = [e.name for e in entries]
    for name in only:
        if name not in known:
            raise cfg.ConfigError(
                f"--scenario {name}: {path} has no scenario of that name{did_you_mean(name, known)}; "
                f"it has: {', '.join(known)}"
            )
    return [e for e in entries if e.name in only]


def load_sweep(
    path: str | Path,
    runs: int | None = None,
    grid: Sequence[str] = (),
    extra: Sequence[str] = (),
    seed: int | None = None,
    only: Sequence[str] = (),
) -> Sweep:
    """The sweep file ``path`` planned: its scenarios (or, with ``only``, the ones of those names),
    each crossed with the grid (the file's and ``grid``'s ``key=v1,v2`` axes), ``runs`` each."""
    path = Path(path)
    try:
        data = read_yaml(path) or {}
    except YamlFileError as exc:
        raise cfg.ConfigError(str(exc)) from None
    if not isinstance(data, dict):
        raise cfg.ConfigError(f"{path}: the top level must be a mapping")
    if "base" not in data:  # a plain experiment: sweep over it
        data = {"name": data.get("name", path.stem), "base": path.name}
    try:
        spec = SweepFile.model_validate(data)
    except ValidationError as exc:
        raise cfg.ConfigError("\n".join(f"{path}: {line}" for line in validation_lines(exc, SweepFile))) from None
    common = tuple(spec.set.items())
    grid_spec = dict(spec.grid)
    for key, values in (_parse_grid(g) for g in grid):
        # a --grid key the file's grid names (or names a part or the whole of) replaces that axis:
        # two axes over one key would multiply the cells and the later value would silently win
        for named in [k for k in grid_spec if _overlap(k, key)]:
            print(f"sweep: --grid {key} replaces the grid's {named} axis of {path}", file=sys.stderr)
            del grid_spec[named]
        grid_spec[key] = values
    entries = [SweepScenario(e.name, tuple(e.set.items())) for e in spec.scenarios] or [SweepScenario("", ())]
    entries = _only(entries, only, path)
    for entry in entries:  # an axis over a key a scenario sets would run one cell under names that differ
        for key in grid_spec:
            leaves = [leaf for k, v in entry.overrides for leaf in dotted(v, f"{k}.")]
            clash = next((leaf for leaf in leaves if _overlap(leaf, key)), None)
            if clash is not None:
                raise cfg.ConfigError(
                    f"{path}: the grid's {key} axis and scenario {entry.name}'s {clash} set the same key: its "
                    f"cells would all run the grid's value under the scenario's name; take {clash} out of the "
                    "scenario, or pick scenarios that do not set it with --scenario"
                )
    keys = list(grid_spec)
    runs_each = spec.runs if runs is None else runs
    _check_size(len(entries) * math.prod(len(v) for v in grid_spec.values()), runs_each, str(path))
    scenarios = []
    for entry in entries:
        for combo in itertools.product(*(grid_spec[k] for k in keys)):
            parts = [entry.name] if entry.name else []
            parts += [f"{_axis(k)}-{_label(v)}" for k, v in zip(keys, combo)]
            overrides = common + entry.overrides + tuple(zip(keys, combo))
            scenarios.append(SweepScenario("_".join(parts) or "base", overrides))
    names = [s.name for s in scenarios]
    if len(set(names)) != len(names):
        twice = next(n for n in names if names.count(n) > 1)
        raise cfg.ConfigError(
            f"{path}: two scenarios share the name {twice!r} (a value of the grid is named by its 'name' "
            "alone: vary the parameter that differs as its own grid key, e.g. allocator.execute)"
        )
    varying = {
        k
        for s in scenarios
        for k, _ in s.overrides
        if k not in spec.set or any(dict(s2.overrides).get(k) != spec.set[k] for s2 in scenarios)
    }
    factors = sorted(varying)
    if runs is not None and runs < 1:
        raise cfg.ConfigError(f"--runs {runs}: a sweep needs at least one run per scenario")
    return Sweep(
        spec.name,
        (path.parent / spec.base).resolve(),
        spec.seed if seed is None else seed,
        spec.runs if runs is None else runs,
        scenarios,
        factors,
        list(extra),
    )


#: the most runs a sweep plans (scenarios x runs): every planned run is an object and a folder
MAX_PLANNED_RUNS = 1_000_000
#: the most read of a run's attempts.jsonl (a line a start or end of an attempt, about 150 bytes)
MAX_ATTEMPTS_BYTES = 4 << 20


def _check_size(scenarios: int, runs: int, where: str) -> None:
    """A ConfigError naming ``where`` for a sweep of more than :data:`MAX_PLANNED_RUNS` runs, before
    any of them is planned."""
    if scenarios * max(runs, 1) > MAX_PLANNED_RUNS:
        raise cfg.ConfigError(
            f"{where}: {scenarios:,} scenarios x {runs:,} runs is more than the {MAX_PLANNED_RUNS:,} runs a sweep plans"
        )


def run_seeds(sweep_seed: int, runs: int) -> list[int]:
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(sweep_seed).spawn(runs)]


def experiment_for(
    base: str | Path, scenario: SweepScenario, seed: int, extra: list[str] | tuple[str, ...]
) -> cfg.Experiment:
    pairs = list(scenario.overrides) + [cfg.parse_override(t) for t in extra] + [("run.seed", seed)]
    return cfg.load(base, [f"{k}={json.dumps(v)}" for k, v in pairs], origin=f"sweep scenario {scenario.name}:")


def plan(sweep: Sweep, out: Path) -> list[RunSpec]:
    seeds = run_seeds(sweep.seed, sweep.runs)
    return [
        RunSpec(str(sweep.base), sc, r, seeds[r], str(out / sc.name / f"run_{r:03d}"), tuple(sweep.extra))
        for sc in sweep.scenarios
        for r in range(sweep.runs)
    ]


def _record_attempt(run_dir: Path, **fields: Any) -> None:
    """One line of ``attempts.jsonl``: where and when a run was tried and how it ended (which node
    ran it, on a cluster; not a result file, so it never takes part in byte comparisons)."""
    line = json.dumps({"host": socket.gethostname(), "pid": os.getpid(), "ppid": os.getppid(), **fields})
    with safefiles.open_append(run_dir / ATTEMPTS) as f:
        f.write(line.encode() + b"\n")


def execute(spec: RunSpec, stale_after: float = claims.STALE_AFTER_S, in_process: bool = False) -> Outcome:
    """One run, wherever an executor placed it: claim its directory, run it, release the claim.
    Returns (status, detail); a run another process holds is left to it ("claimed"). With
    ``in_process`` the run is stepped by the in-process engine in the executor's worker (the same
    result files; for tests and calibration)."""
    from swarmbed.launch.inprocess import run_in_process
    from swarmbed.launch.runner import run_experiment

    out = Path(spec.out_dir)
    claim = claims.take(out, stale_after)
    if isinstance(claim, claims.Holder):
        return "claimed", f"held by {claim.describe()}"
    with claim:
        if RunDir(out).complete:  # completed by someone else since it was planned
            return "ok", "done elsewhere"
        safefiles.remove(out / ERROR)
        started = time.time()
        _record_attempt(out, event="start", time=started)
        try:
            exp = experiment_for(spec.base, spec.scenario, spec.seed, spec.extra)
            if in_process:
                run_in_process(exp, out)
            else:
                run_experiment(exp, out, progress=False)
            outcome: Outcome = ("ok", "")
        except Exception as exc:  # a failed run is recorded, the sweep goes on (an interrupt is not a failure)
            detail = f"{type(exc).__name__}: {exc}\n\n{traceback.format_exc()}"
            results.write_atomic(out / ERROR, detail)
            outcome = ("failed", f"{type(exc).__name__}: {exc}")
        except BaseException:  # Ctrl-C, or the sweep's SIGTERM to its pool worker: say so, then stop
            _record_attempt(
                out, event="end", time=time.time(), outcome="interrupted", wall_s=round(time.time() - started, 3)
            )
            raise
        _record_attempt(out, event="end", time=time.time(), outcome=outcome[0], wall_s=round(time.time() - started, 3))
        return outcome


def gini(values: Sequence[float]) -> float | None:
    """The Gini coefficient of non-negative values (0: all equal; (n - 1) / n: one holds all), as
    SPACE's Monte Carlo analysis reads per-agent work and distance, one value per run; None for
    negative values or a zero sum. Computed from the sorted values: 2 sum(i x_(i)) / (n sum x) - (n + 1) / n."""
    x = np.sort(np.asarray(values, dtype=float))
    if len(x) == 0 or x[0] < 0 or x.sum() <= 0:
        return None
    n = len(x)
    return float(2.0 * np.dot(np.arange(1, n + 1), x) / (n * x.sum()) - (n + 1) / n)


def flatten(summary: dict, prefix: str = "") -> dict[str, Any]:
    """Scalar metrics of a summary, nested keys dotted; per-agent lists become their mean and their
    Gini coefficient (one value per run each, as SPACE plots them)."""
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
                row[f"{name}_gini"] = gini(value)
        else:
            row[name] = value
    return row


CORRUPT = "unreadable"  # in sweep.csv: a completed run whose files cannot be read (named on stderr)


def run_status(run_dir: Path, stale_after: float = claims.STALE_AFTER_S) -> str:
    """``ok`` (summary.json), ``running`` (a live claim), ``failed`` (error.txt), ``interrupted``
    (a claim whose holder is gone: the next sweep command redoes it) or ``missing``."""
    if RunDir(run_dir).complete:
        return "ok"
    holder = claims.holder(run_dir)
    if holder is not None:
        return "running" if holder.alive(stale_after) else "interrupted"
    if (run_dir / ERROR).exists():
        return "failed"
    return "interrupted" if _last_attempt(run_dir).get("outcome") == "interrupted" else "missing"


def _last_attempt(run_dir: Path) -> dict[str, Any]:
    """The last line of a run's ``attempts.jsonl`` ({} if none can be read)."""
    try:  # bounded and without blocking: a received folder's attempts.jsonl may be /dev/zero or a FIFO
        lines = safefiles.read_file(run_dir / ATTEMPTS, MAX_ATTEMPTS_BYTES).splitlines()
        last = json.loads(lines[-1]) if lines else {}
    except (OSError, ValueError, RecursionError):
        return {}
    return last if isinstance(last, dict) else {}


def _completed_row(run_dir: Path) -> dict[str, Any]:
    """A completed run's summary, transport totals and provenance, flattened into one table row;
    a RunFileError or WireError names the file that cannot be read."""
    run = RunDir(run_dir)
    row = flatten(run.summary().document)
    if run.has(results.TRANSPORT):  # measured, not reproducible: in its own columns
        totals = run.json(results.TRANSPORT).get("totals")
        if not isinstance(totals, dict):
            raise RunFileError(f"{run_dir / results.TRANSPORT}: no totals object")
        row.update(flatten(totals, "wire."))
    if run.has(PROVENANCE):  # which code made it (runs of older versions have none)
        row.update(flatten(run.json(PROVENANCE), "provenance."))
    return row


def collect(sweep: Sweep, out: Path, stale_after: float = claims.STALE_AFTER_S) -> pd.DataFrame:
    rows = []
    for spec in plan(sweep, out):
        run_dir = Path(spec.out_dir)
        row = {"scenario": spec.scenario.name, "run": spec.index, "seed": spec.seed}
        row.update({k: json.dumps(v) if isinstance(v, (dict, list)) else v for k, v in spec.scenario.overrides})
        row["status"] = run_status(run_dir, stale_after)
        if row["status"] == "ok":
            try:
                row.update(_completed_row(run_dir))
            except (RunFileError, WireError) as exc:  # one bad file: that run is named, the others tabled
                print(f"sweep: run {run_dir} left out of the table: {exc}", file=sys.stderr)
                row["status"], row["error"] = CORRUPT, str(exc)
        elif row["status"] == "failed":
            try:
                text = read_member(run_dir, ERROR, 1 << 20).decode(errors="replace")
            except RunFileError as exc:
                text = str(exc)
            lines = [ln for ln in text.split("\n\n", 1)[0].splitlines() if ln.strip()]
            row["error"] = " | ".join(dict.fromkeys([lines[0], lines[-1]])) if lines else "unknown error"
        rows.append(row)
    return pd.DataFrame(rows)


def _parquet_ready(table: pd.DataFrame) -> pd.DataFrame:
    """Columns Arrow can type: an object column holding more than one kind of value (a grid over
    numbers and names, say) is written as text."""
    table = table.copy()
    for name in [c for c in table.columns if table[c].dtype == object]:
        kinds = {type(v) for v in table[name].dropna()}
        if len(kinds) > 1:
            table[name] = table[name].map(
                lambda v: v if v is None or (isinstance(v, float) and np.isnan(v)) else str(v)
            )
    return table


def write_tables(table: pd.DataFrame, out: Path) -> None:
    """``sweep.csv`` and ``sweep.parquet`` (every run's summary flattened, one file to read for
    thousands of runs), each written whole or not at all. Figures, summaries and reports made from
    an earlier table are removed: they may show another sweep's scenarios."""
    for pattern in DERIVED:
        for stale in out.glob(pattern):
            safefiles.remove(stale)
    with safefiles.replacing(out / TABLE) as tmp:
        table.to_csv(tmp, index=False)
    with safefiles.replacing(out / PARQUET) as tmp:
        _parquet_ready(table).to_parquet(tmp, index=False)


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep; the message says what completed and how to resume."""


def _complete(specs: list[RunSpec]) -> int:
    return sum(1 for s in specs if RunDir(s.out_dir).complete)


def write_spec(sweep: Sweep, out: Path) -> None:
    results.write_json(
        out / SPEC,
        {
            "name": sweep.name,
            "base": str(sweep.base),
            "seed": sweep.seed,
            "runs": sweep.runs,
            "factors": sweep.factors,
            "extra": sweep.extra,
            "scenarios": {s.name: dict(s.overrides) for s in sweep.scenarios},
            "order": [s.name for s in sweep.scenarios],
        },
    )  # the keys above get sorted


def _folder_name(name: object) -> str:
    """A scenario's name from a sweep.json (a folder under the sweep's): a ValueError for anything
    that is not a plain name (``../..`` would lead a reader out of the sweep)."""
    if not (isinstance(name, str) and re.fullmatch(SAFE_NAME, name)):
        raise ValueError(f"scenario name {str(name)[:40]!r} is not a folder name")
    return name


def read_spec(out: Path) -> Sweep:
    """The sweep a directory was made by, from its ``sweep.json``."""
    try:
        data = read_json_member(out, SPEC)
        order = data.get("order") or list(data["scenarios"])
        _check_size(len(order), int(data["runs"]), str(out / SPEC))
        return Sweep(
            data["name"],
            Path(data["base"]),
            int(data["seed"]),
            int(data["runs"]),
            [SweepScenario(_folder_name(name), tuple(data["scenarios"][name].items())) for name in order],
            list(data["factors"]),
            list(data["extra"]),
        )
    except cfg.ConfigError:
        raise
    except (OSError, ValueError, KeyError, TypeError, AttributeError, RunFileError) as exc:
        raise cfg.ConfigError(f"{out}: not a sweep directory (no readable {SPEC}: {exc})") from None


def status(out: Path, stale_after: float = claims.STALE_AFTER_S) -> pd.DataFrame:
    """Runs per scenario by status (ok, running, failed, interrupted, missing), one row per scenario."""
    sweep = read_spec(out)
    rows = [(spec.scenario.name, run_status(Path(spec.out_dir), stale_after)) for spec in plan(sweep, out)]
    table = pd.crosstab(
        pd.Series([r[0] for r in rows], name="scenario"), pd.Series([r[1] for r in rows], name="status")
    )
    order = [c for c in ("ok", "running", "failed", "interrupted", "missing") if c in table.columns]
    table = table.reindex(columns=order).reindex([s.name for s in sweep.scenarios])
    table.columns.name = None
    return table


def config_differences(made: str, planned: str, limit: int = 3) -> str:
    """What differs between two ``config.yaml`` texts, as ``key: made -> planned`` (at most ``limit``)."""

    def read(text: str) -> dict[str, Any]:
        try:
            return dotted(parse_yaml(text, "config.yaml") or {})
        except YamlFileError:
            return {}

    a, b = read(made), read(planned)
    keys = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
    shown = [f"{k}: {a.get(k)!r} -> {b.get(k)!r}" for k in keys[:limit]]
    return ", ".join(shown) + (f" and {len(keys) - limit} more" if len(keys) > limit else "")


def _check_completed(specs: list[RunSpec], out: Path, redo: bool) -> None:
    """A completed run is reused only if it was made under the configuration planned for it now
    (its ``config.yaml`` byte for byte). Runs made under another are refused with what differs,
    or, with ``redo``, marked to be run again."""
    mismatched = []
    for spec in specs:
        run_dir = Path(spec.out_dir)
        if not RunDir(run_dir).complete:
            continue
        planned = cfg.to_yaml(experiment_for(spec.base, spec.scenario, spec.seed, spec.extra))
        try:
            made = read_member(run_dir, results.CONFIG, MAX_CONFIG_BYTES).decode(errors="replace")
        except RunFileError:
            made = ""
        if made != planned:
            mismatched.append((spec, made, planned))
    if not mismatched:
        return
    if redo:
        for spec, _, _ in mismatched:
            safefiles.remove(Path(spec.out_dir) / results.SUMMARY)
        return
    spec, made, planned = mismatched[0]
    raise cfg.ConfigError(
        f"{out}: {len(mismatched)} completed run(s) were made under another configuration than this sweep plans "
        f"(first: {Path(spec.out_dir).relative_to(out)}: {config_differences(made, planned) or 'no config.yaml'}); "
        f"redo them with --redo-mismatched, or give --out a new folder"
    )


def _remove_parts(run_dir: Path) -> None:
    """The ``*.part`` files of an interrupted run removed (none through a link: a run folder reached
    through one is left alone)."""
    try:
        for partial_file in run_dir.glob("*.part"):
            safefiles.remove(partial_file)
    except OSError:
        pass


def run_sweep(
    sweep: Sweep,
    out: Path,
    jobs: int | None = None,
    progress: bool = True,
    executor: Executor | None = None,
    stale_after: float = claims.STALE_AFTER_S,
    redo_mismatched: bool = False,
    in_process: bool = False,
    on_complete: Callable[[RunSpec], None] | None = None,
) -> pd.DataFrame:
    """Run every incomplete run of ``sweep`` into ``out`` through ``executor`` (default: the local
    process pool with ``jobs`` workers), then write the tables (on Ctrl-C too, of what completed).
    Runs another command holds are left to it; runs that never started because a worker died are
    started again once. A completed run made under another configuration than planned is refused
    (or, with ``redo_mismatched``, run again). ``in_process``: each run on the in-process engine
    (lock-step only; the same result files as processes, for tests and calibration sweeps).
    ``on_complete``: called in this process with each run that is complete, those completed before
    first (a resumed sweep), then each as it completes (``--mlflow`` logs them)."""
    from swarmbed.campaigns import executors

    with safefiles.rooted(out):  # the sweep's folder, opened once: no run folder is reached through a link
        if jobs is not None and jobs < 1:
            raise cfg.ConfigError(f"--jobs {jobs}: at least one run must be able to go at once")
        safefiles.make_folder(out)
        specs = plan(sweep, out)
        agents: dict[str, int] = {}  # per scenario name
        try:
            for spec in specs:  # every scenario is valid before anything starts
                if spec.scenario.name not in agents:
                    exp = experiment_for(spec.base, spec.scenario, spec.seed, spec.extra)
                    agents[spec.scenario.name] = exp.agents.count
            _check_completed(specs, out, redo_mismatched)
        except KeyboardInterrupt:  # while planning: nothing started, but a resumed sweep's table is brought up to date
            done = _complete(specs)
            if done and (out / SPEC).exists():
                write_tables(collect(sweep, out, stale_after), out)
            raise SweepInterrupted(
                f"interrupted while planning: nothing was started; {done} of {len(specs)} runs are complete"
                + (f" and in {out / TABLE}" if done and (out / SPEC).exists() else "")
            ) from None
        write_spec(sweep, out)
        executor = executor or executors.get("local", jobs=jobs)
        todo = [s for s in specs if run_status(Path(s.out_dir), stale_after) != "ok"]
        for spec in todo:  # a received sweep folder's run folder that is a link is refused, not run into
            safefiles.inside(out, Path(spec.out_dir) / results.SUMMARY)
        done_before = len(specs) - len(todo)
        if on_complete is not None:
            for spec in specs:
                if spec not in todo:
                    on_complete(spec)
        bar = tqdm(total=len(specs), initial=done_before, unit="run", desc=sweep.name, disable=not progress)
        fn = partial(execute, stale_after=stale_after, in_process=in_process)
        retried: set[str] = set()
        try:
            while todo:
                again = []
                sizes = [resources_for(agents[s.scenario.name]) for s in todo]
                for index, (state, detail) in executor.map(fn, todo, sizes):
                    spec = todo[index]
                    if state == "lost" and claims.holder(Path(spec.out_dir)) is None and spec.out_dir not in retried:
                        retried.add(spec.out_dir)  # its worker died before it began: it never ran
                        again.append(spec)
                        continue
                    if state != "ok":
                        bar.write(f"{state}: {spec.out_dir}: {detail}", file=sys.stderr)
                    elif on_complete is not None:
                        on_complete(spec)
                    bar.update(1)
                todo = again
        except KeyboardInterrupt:
            executor.cancel()
            bar.close()
            for spec in specs:  # an incomplete run leaves no half-written file behind
                if not RunDir(spec.out_dir).complete:
                    _remove_parts(Path(spec.out_dir))
            done = _complete(specs)
            write_tables(collect(sweep, out, stale_after), out)  # what completed can be analyzed at once
            raise SweepInterrupted(
                f"interrupted: {done} of {len(specs)} runs are complete "
                f"({done - done_before} finished in this session) and in {out / TABLE}; the runs under way "
                f"were stopped and nothing else was started. Run the same command again to do the other "
                f"{len(specs) - done}."
            ) from None
        finally:
            bar.close()
            executor.close()
        table = collect(sweep, out, stale_after)
        write_tables(table, out)
        return table
