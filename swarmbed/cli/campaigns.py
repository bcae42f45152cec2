"""``swarmbed sweep``, ``analyze``, ``report`` and ``replay``: many runs and what they left."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from swarmbed import config as cfg
from swarmbed.cli.common import add_engine, engine_prefix, positive, refusals
from swarmbed.files import safefiles
from swarmbed.plugins import registry

if TYPE_CHECKING:
    from swarmbed.campaigns.executors import Executor
    from swarmbed.cli.common import Subparsers

#: a sweep planning more runs than this asks for --yes
CONFIRM_RUNS = 1000


def _sweep_executor(args: argparse.Namespace, out: Path) -> Executor:
    from swarmbed.campaigns import executors

    if args.executor != "slurm" and (args.slurm_partition or args.slurm_cluster or args.detach):
        raise executors.ExecutorError("--slurm-*, --detach: only with --executor slurm")
    if args.executor != "dask" and args.scheduler:
        raise executors.ExecutorError("--scheduler: only with --executor dask")
    submitit = out / ".submitit"  # submitit's scripts and pickles: a folder the helper made, never a link's
    return executors.get(
        args.executor,
        jobs=args.jobs,
        folder=safefiles.make_folder(submitit) if args.executor == "slurm" else submitit,
        partition=args.slurm_partition,
        time=args.slurm_time,
        parallel=args.jobs,
        cluster=args.slurm_cluster,
        detach=args.detach,
        scheduler=args.scheduler,
    )


def _mlflow_logger(uri: str | None, name: str, out: Path):
    """What logs each completed run of the sweep to MLflow (``--mlflow``), or None."""
    if uri is None:
        return None
    from swarmbed.campaigns.tracking import MlflowLog, default_uri

    if not uri:  # the default store, in a folder the helper made below the sweep (never a link's target)
        safefiles.make_folder(out / "mlruns")
    log = MlflowLog(uri or default_uri(out), name)

    def log_run(spec) -> None:
        log.log(Path(spec.out_dir), Path(spec.out_dir).relative_to(out).as_posix())

    return log_run


def _not_a_sweep_folder(out: Path) -> str | None:
    """Why ``out`` cannot take a sweep, or None: a folder holding one run (its config.yaml) is a run's,
    and a sweep would fill it with scenario folders and tables beside the run's files."""
    from swarmbed.records.run_folder import CONFIG, SUMMARY
    from swarmbed.results.campaign_folders import SPEC

    if out.is_dir() and not (out / SPEC).exists() and ((out / CONFIG).exists() or (out / SUMMARY).exists()):
        return f"--out {out}: holds a run (its {CONFIG}), not a sweep: give the sweep a folder of its own"
    return None


def cmd_sweep(args: argparse.Namespace) -> int:
    from swarmbed.campaigns.sweep import experiment_for, load_sweep, plan, status

    if args.status:
        try:
            table = status(Path(args.status), args.stale_after)
        except cfg.ConfigError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        table.loc["all"] = table.sum()
        print(table.fillna(0).astype(int).to_string())
        return 0
    if not args.sweep:
        print("error: give a sweep file (or --status DIR)", file=sys.stderr)
        return 2
    sweep = load_sweep(args.sweep, args.runs, args.grid, args.set, args.seed, args.scenario)
    out = Path(args.out) if args.out else Path("runs") / sweep.name
    problem = _not_a_sweep_folder(out)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    planned = plan(sweep, out)
    first = {spec.scenario.name: spec for spec in reversed(planned)}
    every = {name: experiment_for(spec.base, spec.scenario, spec.seed, spec.extra) for name, spec in first.items()}
    for name, exp in every.items():
        why = refusals(exp, args.engine)
        if why:
            print(f"error: {engine_prefix(args.engine)}scenario {name}: {why[0]}", file=sys.stderr)
            return 2
    if args.check:
        from swarmbed.launch.check import describe_sweep
        from swarmbed.records.run_folder import RunDir

        left = sum(1 for spec in planned if not RunDir(spec.out_dir).complete)
        jobs = args.jobs or os.cpu_count() or 1  # the local pool's default
        print(describe_sweep(len(planned), left, every, jobs, args.engine))
        return 0
    if len(planned) > CONFIRM_RUNS and not args.yes:
        print(
            f"error: this sweep plans {len(planned):,} runs; give --yes to start them "
            f"(--check prints the plan and an estimate of its wall time)",
            file=sys.stderr,
        )
        return 2
    with safefiles.rooted(out):  # the sweep's folder, opened once: nothing below it is reached through a link
        return _sweep_into(args, sweep, out, planned)


def _sweep_into(args: argparse.Namespace, sweep: Any, out: Path, planned: list) -> int:
    """The sweep run into ``out`` (opened by the caller), its table and figures printed."""
    from swarmbed.campaigns.executors import ExecutorError
    from swarmbed.campaigns.sweep import run_sweep
    from swarmbed.campaigns.tracking import TrackingError

    try:
        executor = _sweep_executor(args, out)
        on_complete = _mlflow_logger(args.mlflow, sweep.name, out)
    except (ExecutorError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        table = run_sweep(
            sweep,
            out,
            args.jobs,
            progress=not args.no_progress and not args.detach,
            executor=executor,
            stale_after=args.stale_after,
            redo_mismatched=args.redo_mismatched,
            in_process=args.engine == "inprocess",
            on_complete=on_complete,
        )
    except (ExecutorError, TrackingError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.detach:
        print(
            f"submitted: {executor.describe()}\nprogress: swarmbed sweep --status {out}\n"
            f"when they are done, the same command again writes {out}/sweep.csv and sweep.parquet"
        )
        return 0
    ok = table[table["status"] == "ok"]
    print(
        f"sweep: {out}/sweep.csv  ({len(ok)} of {len(table)} runs complete, "
        f"{len(sweep.scenarios)} scenarios x {sweep.runs} runs; {executor.describe()})"
    )
    held = int((table["status"] == "running").sum())
    if held:
        print(f"{held} runs are held by another sweep command on {out}: swarmbed sweep --status {out}")
    metrics: list[str] = []
    for kind in ok["scenario_kind"].dropna().unique() if "scenario_kind" in ok else ():
        metrics += [m for m in registry.registered_scenario(kind).outcome_metrics if m not in metrics]
    shown = [c for c in (*metrics, "network.messages_sent") if c in ok]
    if shown:
        print("means over each scenario's completed runs (swarmbed analyze for intervals and tests):")
        print(ok.groupby("scenario")[shown].mean(numeric_only=True).round(1).to_string())
    if args.verify:
        from swarmbed.campaigns.verify import verify_in_processes

        if not verify_in_processes(planned, out, args.verify):
            return 1
    return 0 if len(ok) == len(table) else 1


def register_sweep(sub: Subparsers) -> None:
    """``swarmbed sweep``: its arguments, run by :func:`cmd_sweep`."""
    sw = sub.add_parser("sweep", help="Monte Carlo runs over scenarios, in parallel and resumable")
    sw.add_argument("sweep", nargs="?", help="sweep YAML (base + scenarios/grid + runs) or a plain experiment")
    sw.add_argument(
        "--status", metavar="DIR", help="print ok / running / failed / interrupted / missing runs per scenario"
    )
    sw.add_argument("--out", help="sweep directory (default: runs/<name>)")
    sw.add_argument(
        "--jobs",
        "-j",
        type=positive,
        help="runs at once (local: default one per core; slurm: the array's parallelism)",
    )
    sw.add_argument(
        "--executor",
        choices=["local", "slurm", "dask"],
        default="local",
        help="where runs execute (default local; slurm needs swarmbed[slurm], dask swarmbed[dask])",
    )
    sw.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="the Dask scheduler (--executor dask)")
    sw.add_argument("--slurm-partition", help="Slurm partition (--executor slurm)")
    sw.add_argument("--slurm-time", default="120", help="time limit per run: minutes or H:MM:SS (default 120)")
    sw.add_argument(
        "--slurm-cluster",
        choices=["slurm", "local"],
        help="'local': submitit's stand-in, one process per array task on this machine (a dry run)",
    )
    sw.add_argument("--detach", action="store_true", help="submit the array job and return (--executor slurm)")
    sw.add_argument(
        "--stale-after",
        type=float,
        default=120.0,
        metavar="S",
        help="a run claimed by a process that has not shown life for S seconds is taken over "
        "(default 120; a dead process on this host at once)",
    )
    sw.add_argument(
        "--mlflow",
        nargs="?",
        const="",
        metavar="URI",
        help="log each completed run to MLflow: the sweep as the experiment, the configuration as params, the "
        "summary's figures as metrics, the folder as artifacts; a local store in <out>/mlruns unless a tracking "
        "URI is given; a resumed sweep logs no run twice (the tracking extra)",
    )
    sw.add_argument(
        "--redo-mismatched",
        action="store_true",
        help="run again the completed runs in --out that were made under another configuration than "
        "this sweep plans (without it the sweep refuses to reuse or mix them)",
    )
    sw.add_argument("--runs", "-n", type=positive, help="runs per scenario (overrides the file)")
    add_engine(sw)
    sw.add_argument(
        "--verify",
        type=positive,
        metavar="K",
        help="after the sweep, run K of its completed runs again in processes (the lowest seeds) and compare "
        "every reproducible result file byte for byte; exit 1 naming any file that differs",
    )
    sw.add_argument("--seed", type=int, help="sweep seed (overrides the file)")
    sw.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2", help="add a grid axis")
    sw.add_argument(
        "--scenario",
        action="append",
        default=[],
        metavar="NAME",
        help="run only this scenario of the file (repeatable)",
    )
    sw.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override for every run")
    sw.add_argument("--no-progress", action="store_true")
    sw.add_argument("--yes", action="store_true", help=f"start a sweep of more than {1000:,} runs without asking")
    sw.add_argument(
        "--check",
        action="store_true",
        help="validate the sweep and every scenario's experiment, print the plan and a wall-time estimate; "
        "start nothing",
    )
    sw.set_defaults(func=cmd_sweep)


def cmd_analyze(args: argparse.Namespace) -> int:
    from swarmbed.results.analyze import AnalyzeError, analyze

    try:
        written = analyze(
            [Path(d) for d in args.sweep_dir],
            control=args.control,
            mixed_versions_ok=args.mixed_versions,
            trusted=args.trust_plugins,
            progress=True,
        )
    except (AnalyzeError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path in written:
        print(path)
    return 0


def register_analyze(sub: Subparsers) -> None:
    """``swarmbed analyze``: its arguments, run by :func:`cmd_analyze`."""
    an = sub.add_parser("analyze", help="tables and figures from a sweep directory")
    an.add_argument("sweep_dir", nargs="+", help="sweep directories (outputs go to the first)")
    an.add_argument("--control", help="control strategy for Dunnett and Cohen's d (default: cbba-etc where present)")
    an.add_argument(
        "--mixed-versions",
        action="store_true",
        help="pool runs of a scenario or allocator made in different versions (provenance.json)",
    )
    an.add_argument(
        "--trust-plugins",
        action="store_true",
        help="import the scenario classes the runs name as module:Class or file.py:Class (only for folders you "
        "made yourself: a received folder could name any code); registered scenarios need no trust",
    )
    an.set_defaults(func=cmd_analyze)


def cmd_report(args: argparse.Namespace) -> int:
    from swarmbed.results.report import ReportError, report

    if args.output and len(args.folders) > 1:
        print("error: -o names one file: give one folder with it", file=sys.stderr)
        return 2
    for folder in args.folders:
        try:
            t0 = time.perf_counter()
            path = report(Path(folder), Path(args.output) if args.output else None)
        except ReportError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        print(f"{path}  ({path.stat().st_size / 1e6:.1f} MB, {time.perf_counter() - t0:.1f} s)")
    return 0


def register_report(sub: Subparsers) -> None:
    """``swarmbed report``: its arguments, run by :func:`cmd_report`."""
    rep = sub.add_parser("report", help="a run's or a sweep's bandwidth accounting as one self-contained HTML page")
    rep.add_argument("folders", nargs="+", metavar="RUN_DIR|SWEEP_DIR")
    rep.add_argument("-o", "--output", help="the HTML file (default: report.html in the folder)")
    rep.set_defaults(func=cmd_report)


def cmd_replay(args: argparse.Namespace) -> int:
    from swarmbed.results.replay import ReplayError, replay

    if args.mcap:
        return _replay_mcap(Path(args.run_dir), Path(args.mcap))
    try:
        t0 = time.perf_counter()
        path, frames = replay(
            Path(args.run_dir),
            Path(args.output) if args.output else None,
            getattr(args, "from"),
            args.to,
            args.fps,
            args.every,
            progress=True,
        )
    except ReplayError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (KeyError, ValueError, TypeError) as exc:  # a file of the right shape holding the wrong things
        print(f"error: {args.run_dir}: a file of it holds what a replay cannot draw ({exc!r})", file=sys.stderr)
        return 2
    print(f"{path}  ({frames} frames, {path.stat().st_size / 1e6:.1f} MB, {time.perf_counter() - t0:.1f} s)")
    return 0


def register_replay(sub: Subparsers) -> None:
    """``swarmbed replay``: its arguments, run by :func:`cmd_replay`."""
    rp = sub.add_parser("replay", help="a movie of a run recorded with run.record_trajectories")
    rp.add_argument("run_dir", metavar="RUN_DIR")
    rp.add_argument("-o", "--output", help="run.gif or run.mp4 (mp4 needs ffmpeg; default: replay.gif in RUN_DIR)")
    rp.add_argument("--from", type=float, help="simulated second to start at")
    rp.add_argument("--to", type=float, help="simulated second to end at")
    rp.add_argument("--fps", type=positive, default=10, help="frames per second of the movie (default 10)")
    rp.add_argument("--every", type=positive, help="ticks per frame (default: at most 600 frames)")
    rp.add_argument(
        "--mcap",
        metavar="FILE.mcap",
        help="write an MCAP recording for Foxglove-class viewers instead of a movie (needs swarmbed[viewers])",
    )
    rp.set_defaults(func=cmd_replay)


def _replay_mcap(run: Path, out: Path) -> int:
    from swarmbed.results.recording import RecordingError, write_mcap

    try:
        written = write_mcap(run, out)
    except RecordingError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (KeyError, ValueError, TypeError, OverflowError) as exc:  # a file of the right shape, wrong things in it
        print(f"error: {run}: a file of it holds what a recording cannot draw ({exc!r})", file=sys.stderr)
        return 2
    topics = ", ".join(f"{topic} {n}" for topic, n in written["messages"].items() if n)
    print(f"{out}  ({written['bytes'] / 1e6:.1f} MB, {written['seconds']:.1f} s; messages: {topics})")
    return 0
