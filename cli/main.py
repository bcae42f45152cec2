"""The ``swarmbed`` command."""

from __future__ import annotations

import argparse
import json
import logging
import os
import shutil
import signal
import sys
import textwrap
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from swarmbed.bt import BTError, load_tree, palette_xml
from swarmbed.engine.errors import RunError
from swarmbed.extension.node_sets import node_registry
from swarmbed.launch import config as cfg
from swarmbed.plugins import registry
from swarmbed.wire.session import add_zenoh_args

if TYPE_CHECKING:
    from swarmbed.campaigns.executors import Executor

    Subparsers = argparse._SubParsersAction[argparse.ArgumentParser]  # what add_subparsers returns


def _keys_epilog() -> str:
    return (
        "Any key of the experiment can be overridden with --set KEY=VALUE (read as YAML).\n"
        "`swarmbed params` lists the run, agents and network keys; `swarmbed params NAME` the keys of a\n"
        f"scenario ({', '.join(registry.scenario_names())}) or an allocator "
        f"({', '.join(registry.names())})."
    )


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:,.1f}"
    if isinstance(v, int):
        return f"{v:,}"
    return "-" if v is None else str(v)


def print_summary(summary: dict, out_dir: Path, scenario, stream=sys.stdout) -> None:
    """The run's outcome (as its scenario words it), its network totals, and any agent it lost."""
    net = summary["network"]
    rows = scenario.summary_rows(summary)
    if summary.get("invalid_actions"):  # what the allocator asked that the world could not do
        rows.append(("invalid actions (refused by the world)", summary["invalid_actions"]))
    rows += [
        ("messages sent", net["messages_sent"]),
        ("payload bytes sent", net["bytes_sent"]),
        ("copies delivered / total", f"{net['delivered']:,} / {net['copies']:,}"),
        ("copies dropped", ", ".join(f"{k} {v:,}" for k, v in net["dropped"].items() if v) or "0"),
    ]
    transport = out_dir / "transport.json"
    wire = json.loads(transport.read_text())["totals"] if transport.exists() else {}
    if wire.get("agent_tcp_bytes_sent") is not None:
        ratio = f" ({wire['overhead_ratio']:,.1f} x payload)" if wire.get("overhead_ratio") else ""
        rows.append(("TCP bytes agents sent", f"{wire['agent_tcp_bytes_sent']:,}{ratio}"))
    width = max(len(r[0]) for r in rows)
    print(f"results: {out_dir}", file=stream)
    for label, value in rows:
        print(f"  {label:<{width}}  {_fmt(value)}", file=stream)
    lost = summary["agents_lost"]
    if lost:
        text = ", ".join(f"{a} at tick {t}" for a, t in sorted(lost.items(), key=lambda kv: int(kv[0])))
        print(
            textwrap.fill(
                f"agents lost: {text} (their logs: logs/agent_<id>.log)",
                width=100,
                initial_indent="  ",
                subsequent_indent="    ",
            ),
            file=stream,
        )


#: a sweep planning more runs than this asks for --yes
CONFIRM_RUNS = 1000


def _taken(out: Path, force: bool) -> str | None:
    """Why ``out`` cannot take a new run, or None. A folder that holds anything is refused (a finished
    run would be overwritten and its extra logs left beside the new ones) unless ``force``, which
    clears it whole first."""
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        return f"--out {out}: exists and is not a folder"
    if not out.exists() or not any(out.iterdir()):
        return None
    if not force:
        from swarmbed.results.run_folder import RunDir

        if RunDir(out).complete:
            what = "a finished run"
        elif (out / "config.yaml").exists() or any(out.glob("partial_*")) or any(out.glob("*.part")):
            what = "an interrupted run (no summary.json: it did not finish)"
        else:
            what = "files"
        return f"--out {out}: holds {what} already; give another --out, or --force to clear it first"
    shutil.rmtree(out)
    return None


def port_number(text: str) -> int:
    """A TCP port for argparse: 0 (a free one) to 65535; anything else is argparse's one-line error."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port}: a port is 0 (any free one) to 65535")
    return port


#: what Ctrl-C left, per command that starts a run (the others say only "interrupted")
INTERRUPTED = {
    "run": "interrupted: every process was stopped; no summary.json was written",
    "soak": "interrupted: every process was stopped; the soak's files so far are kept, no verdict was written",
}


def cmd_run(args: argparse.Namespace) -> int:
    from swarmbed.launch.hub import HubOptions
    from swarmbed.launch.runner import run_experiment
    from swarmbed.wire.credentials import CredentialsError, check_admitted, read_credentials
    from swarmbed.wire.session import tls_from_args

    exp = cfg.load(args.experiment, args.set, args.seed)
    try:
        admitted = check_admitted(read_credentials(path) for path in args.admit)
        tls = tls_from_args(args)
    except CredentialsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path("runs") / exp.name / f"seed{exp.run.seed}-{stamp}"
    why = _refusals(exp, args.engine)
    if args.engine == "inprocess" and (args.listen or args.admit or args.tls):
        why.append("--listen, --admit and --tls are for a hub others join: the in-process engine has none")
    if why:
        print(f"error: {_engine_prefix(args.engine)}{why[0]}", file=sys.stderr)
        return 2
    if args.check:
        from swarmbed.launch.check import describe_plan

        print(describe_plan(exp, out, admitted, args.engine))
        return 0
    from swarmbed.results.recording import RecordingError

    try:  # the port is taken before the output folder is touched: a port in use leaves nothing behind
        views = _live_views(exp, args.foxglove)
    except RecordingError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    problem = _taken(out, args.force)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    if args.engine == "inprocess":
        from swarmbed.launch.inprocess import InProcessRun
        from swarmbed.launch.runner import progress_bar

        bar, on_tick = progress_bar(exp, not args.no_progress)
        with bar:
            result = InProcessRun(exp, out, views=views).run(on_tick)
        print_summary(result.summary, out, cfg.resolve_experiment(exp).scenario())
        return 0
    hub = HubOptions(listen=args.listen, auth=not args.no_auth, admit=admitted, tls=tls)
    result = run_experiment(exp, out, progress=not args.no_progress, hub=hub, views=views)
    print_summary(result.summary, out, cfg.resolve_experiment(exp).scenario())
    return 0


def _live_views(exp, port: int | None) -> list:
    """The live views ``swarmbed run`` was asked for (``--foxglove``), each made from the run's session."""
    if port is None:
        return []
    from swarmbed.results.live import FoxgloveLive, serve

    served = serve("127.0.0.1", port)

    def foxglove(session):
        from swarmbed.wire.obstacles import wall_lines

        walls = wall_lines(exp.obstacles)
        view = FoxgloveLive(session.world, exp.run.dt, walls=walls, served=served)
        print(f"Foxglove: open connection ws://127.0.0.1:{view.port}", file=sys.stderr, flush=True)
        return view

    return [foxglove]


def _mlflow_logger(uri: str | None, name: str, out: Path):
    """What logs each completed run of the sweep to MLflow (``--mlflow``), or None."""
    if uri is None:
        return None
    from swarmbed.campaigns.tracking import MlflowLog, default_uri

    log = MlflowLog(uri or default_uri(out), name)

    def log_run(spec) -> None:
        log.log(Path(spec.out_dir), Path(spec.out_dir).relative_to(out).as_posix())

    return log_run


def _refusals(exp, engine: str) -> list[str]:
    """Why ``exp`` cannot run on ``engine`` from the command line (none: it can)."""
    from swarmbed.engine import refusals

    return refusals(exp, cfg.resolve_experiment(exp).allocator_cls.decision_source, engine)


def _engine_prefix(engine: str) -> str:
    return "--engine inprocess: " if engine == "inprocess" else ""


def _add_engine(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--engine",
        choices=["processes", "inprocess"],
        default="processes",
        help="processes (default): every agent its own OS process over Zenoh and the netem proxy; inprocess: "
        "every agent and the radio stepped in this process, the same result files byte for byte, faster for "
        "light allocators (lock-step, one machine, no ROS 2, no tree logs): develop and sweep in-process, "
        "validate in processes",
    )


def register_run(sub: Subparsers) -> None:
    """``swarmbed run``: its arguments, run by :func:`cmd_run`."""
    run = sub.add_parser(
        "run", help="run one experiment", epilog=_keys_epilog(), formatter_class=argparse.RawDescriptionHelpFormatter
    )
    run.add_argument("experiment", help="experiment YAML file")
    run.add_argument("--seed", type=int, help="run seed (overrides run.seed)")
    run.add_argument("--out", help="run directory (default: runs/<name>/seed<seed>-<time>); it must be empty")
    run.add_argument("--force", action="store_true", help="clear --out first if it holds anything")
    run.add_argument(
        "--check",
        action="store_true",
        help="validate everything (files, plugins, trees and port values, ticks, credentials) and print the plan "
        "with an estimate of its wall time; start nothing",
    )
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a dotted key")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.add_argument(
        "--foxglove",
        nargs="?",
        const=8765,
        type=port_number,
        metavar="PORT",
        help="serve the run live to Foxglove over its WebSocket protocol on 127.0.0.1:PORT (default 8765; "
        "the channels of replay --mcap; the viewers extra)",
    )
    _add_engine(run)
    run.add_argument(
        "--listen",
        "-l",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="also listen here, for the routers of hosts in the placement (e.g. tcp/0.0.0.0:7447)",
    )
    run.add_argument(
        "--admit",
        action="append",
        default=[],
        metavar="CREDENTIALS",
        help="a credentials file (swarmbed credentials) of a host or an operator the hub admits "
        "besides the run's own processes (repeatable)",
    )
    run.add_argument(
        "--no-auth",
        action="store_true",
        help="no authentication or access control: anyone who reaches the hub may join and publish",
    )
    run.add_argument("--tls", metavar="DIR", help="certificates (swarmbed certs) for --listen tls/HOST:PORT endpoints")
    run.add_argument(
        "--tls-name", metavar="NAME", default="hub", help="the certificate in --tls DIR the hub presents (default: hub)"
    )
    run.set_defaults(func=cmd_run)


def cmd_soak(args: argparse.Namespace) -> int:
    from swarmbed.campaigns.chaos import ChaosError, load_chaos
    from swarmbed.campaigns.soak import Thresholds, format_verdict, parse_duration, soak
    from swarmbed.launch.hub import HubOptions

    try:
        duration = parse_duration(args.duration)
        plan = load_chaos(Path(args.chaos)) if args.chaos else None
    except (ValueError, ChaosError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    exp = cfg.load(args.experiment, args.set, args.seed)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path("runs") / f"soak-{exp.name}" / f"seed{exp.run.seed}-{stamp}"
    limits = Thresholds(args.max_rss_slope, args.max_fd_growth, args.max_stall)
    print(
        f"soak: {exp.name}, {exp.agents.count} agents, {duration:.0f} s of wall time"
        f"{f', chaos from {args.chaos}' if plan else ''}; files in {out}",
        flush=True,
    )
    result = soak(exp, out, duration, plan, args.interval, limits, hub=HubOptions(auth=not args.no_auth))
    print(format_verdict(result))
    return 0 if result["passed"] else 1


def register_soak(sub: Subparsers) -> None:
    """``swarmbed soak``: its arguments, run by :func:`cmd_soak`."""
    so = sub.add_parser(
        "soak",
        help="run an experiment for a wall-clock duration under faults; every process "
        "watched; a verdict at the end (exit 1 on a breach)",
    )
    so.add_argument("experiment", help="experiment YAML file")
    so.add_argument("--duration", required=True, help="wall time: 90s, 30m, 2h, 1h30m")
    so.add_argument("--chaos", metavar="CHAOS.yaml", help="faults to inject (see docs/soak.md)")
    so.add_argument("--out", help="soak directory (default: runs/soak-<name>/seed<seed>-<time>)")
    so.add_argument("--seed", type=int, help="run seed (overrides run.seed; also seeds the chaos)")
    so.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a dotted key")
    so.add_argument("--interval", type=float, default=5.0, help="wall seconds between samples (default 5)")
    so.add_argument(
        "--max-rss-slope",
        type=float,
        default=10.0,
        metavar="PCT_PER_H",
        help="largest RSS growth of any process over the second half, %% per hour (default 10)",
    )
    so.add_argument(
        "--max-fd-growth",
        type=float,
        default=10.0,
        metavar="PER_H",
        help="largest growth of open file descriptors of any process, per hour (default 10)",
    )
    so.add_argument(
        "--max-stall", type=float, default=10.0, metavar="S", help="longest a tick may take, wall seconds (default 10)"
    )
    so.add_argument("--no-auth", action="store_true", help="no authentication or access control on the hub")
    so.set_defaults(func=cmd_soak)


def cmd_credentials(args: argparse.Namespace) -> int:
    from swarmbed.wire.credentials import CredentialsError, Identity, write_credentials

    try:
        if args.host and args.role != "host":
            raise CredentialsError("--host names the host of a host identity: give --role host too")
        path = write_credentials(
            Path(args.file), Identity.new(args.user, args.role, args.host or ""), replace=args.force
        )
    except CredentialsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{path}: {args.role} {args.user!r}; admit it with swarmbed run --admit {path}")
    return 0


def register_credentials(sub: Subparsers) -> None:
    """``swarmbed credentials``: its arguments, run by :func:`cmd_credentials`."""
    from swarmbed.wire.credentials import ROLES

    cr = sub.add_parser("credentials", help="make a credentials file for a host daemon or an operator (watch, swap)")
    cr.add_argument("file", help="the file to write (created with mode 600; an existing file only with --force)")
    cr.add_argument("--force", action="store_true", help="replace FILE if it exists")
    cr.add_argument("--user", required=True, help="the user name (letters, digits, no ':' or spaces)")
    cr.add_argument(
        "--role",
        choices=list(ROLES),
        default="operator",
        help="operator: watch a run and ask for swaps; host: a host daemon; commander: an operator that may "
        "also publish the robots' decisions on ROS 2 (allocator ros2, docs/ros2.md) (default: operator)",
    )
    cr.add_argument(
        "--host",
        help="role host: the host name the daemon runs as (swarmbed host --name); "
        "the hub lets this identity act as that host only (default: the user name)",
    )
    cr.set_defaults(func=cmd_credentials)


def cmd_certs(args: argparse.Namespace) -> int:
    from swarmbed.launch.certs import CertError, make_certs

    try:
        written = make_certs(Path(args.folder), args.machines, args.days)
    except (CertError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path in written:
        print(path)
    print("copy ca.pem and a machine's NAME.pem and NAME.key to it (never ca.key); see the README's TLS section")
    return 0


def register_certs(sub: Subparsers) -> None:
    """``swarmbed certs``: its arguments, run by :func:`cmd_certs`."""
    ce = sub.add_parser("certs", help="a certificate authority and per-machine certificates for TLS between machines")
    ce.add_argument("folder", help="where the CA (ca.pem, ca.key) and the certificates go; the CA is reused")
    ce.add_argument(
        "machines",
        nargs="+",
        metavar="NAME[=ADDR,...]",
        help="a machine and the addresses others reach it by, e.g. hub=192.0.2.10 labpc2=labpc2.lab",
    )
    ce.add_argument("--days", type=_positive, default=365, help="validity (default 365 days)")
    ce.set_defaults(func=cmd_certs)


def _node_owners(allocator: str | None, scenario: str | None) -> list[type]:
    """Scenario and allocator classes whose nodes a tree may use: the named ones, or every
    registered one (so that any shipped tree checks without naming its allocator)."""
    scenarios = [scenario] if scenario else registry.scenario_names()
    owners: list[type] = [registry.resolve_scenario(kind) for kind in scenarios]
    if allocator:
        owners.append(registry.resolve(allocator, scenario))
    else:
        owners += [
            registry.resolve(name, kind)
            for name, kind in registry.entries()
            if kind == registry.ANY or kind in scenarios
        ]
    return owners


def cmd_bt(args: argparse.Namespace) -> int:
    nodes = node_registry(_node_owners(args.allocator, args.scenario))
    if args.bt_command == "palette":
        sys.stdout.write(palette_xml(nodes))
        return 0
    bad = 0
    for path in args.files:
        try:
            load_tree(path, nodes)
            print(f"{path}: ok")
        except BTError as exc:
            bad += 1
            print(f"error: {exc}", file=sys.stderr)
    return 2 if bad else 0


def register_bt(sub: Subparsers) -> None:
    """``swarmbed bt``: its arguments, run by :func:`cmd_bt`."""
    bt = sub.add_parser("bt", help="behavior-tree tools")
    bt_sub = bt.add_subparsers(dest="bt_command", required=True)
    palette = bt_sub.add_parser("palette", help="print a Groot2 <TreeNodesModel> of the custom nodes")
    check = bt_sub.add_parser("check", help="load behavior-tree XML files and report every error")
    check.add_argument("files", nargs="+")
    for p in (palette, check):
        p.add_argument("--allocator", help="only the nodes this allocator's trees may use (default: every one)")
        p.add_argument("--scenario", help="only the nodes of this scenario (default: every one)")
    bt.set_defaults(func=cmd_bt)


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not at least 1")
    return value


def _first_line(cls: type) -> str:
    """The first sentence of a class's docstring, on one line, without reST markup."""
    text = " ".join((cls.__doc__ or cls.__name__).split()).replace("``", "")
    end = text.find(". ")
    return text if end < 0 else text[: end + 1]


def _param_groups(name: str) -> list[tuple[str, list[tuple[str, str, str, str]]]]:
    """The parameter tables of scenario and/or allocator ``name`` (a registered name or a target)."""
    groups = []
    if name in registry.scenario_names() or (":" in name and name not in registry.names()):
        try:
            cls = registry.resolve_scenario(name)
            groups.append((f"scenario.kind: {name} ({_first_line(cls)})", cfg.describe(cls.Params, "scenario.")))
        except registry.PluginError:
            if ":" not in name:
                raise
    kinds = [k for n, k in registry.entries() if n == name] or ([registry.ANY] if ":" in name and not groups else [])
    for kind in kinds:
        allocator = registry.resolve(name, None if kind == registry.ANY else kind)
        where = "any scenario" if kind == registry.ANY else f"scenario {kind}"
        groups.append(
            (
                f"allocator.name: {name} for {where} ({_first_line(allocator)})",
                cfg.describe(allocator.Params, "allocator.") or [("(no parameters)", "", "", "")],
            )
        )
    return groups


def _section_groups() -> list[tuple[str, list[tuple[str, str, str, str]]]]:
    """Every key of an experiment outside a scenario's or an allocator's own: the sections, ROS 2,
    and where agents run (placement, swaps, may_carry)."""
    from swarmbed.wire.schema import Experiment, Ros2Section

    groups = [(f"{name}:", cfg.describe(model, f"{name}.")) for name, model in cfg.SECTIONS.items()]
    groups.append(("ros2 (off unless given):", cfg.describe(Ros2Section, "ros2.")))
    hosts = [
        row
        for row in cfg.describe(Experiment)
        if row[0].split(".")[0].removesuffix("[]") in ("placement", "swaps", "may_carry")
    ]
    groups.append(("hosts (placement, swaps, may_carry: docs in the README's Several machines):", hosts))
    return groups


def cmd_params(args: argparse.Namespace) -> int:
    """Every key of the generic sections, or of a scenario or an allocator, or one key: type,
    default, meaning."""
    sections = _section_groups()
    if args.name is None:
        groups = list(sections)
        groups.append(
            (
                "scenarios (swarmbed params NAME):",
                [(n, "", "", registry.scenario_target(n)) for n in registry.scenario_names()],
            )
        )
        allocators = [
            (
                n if k == registry.ANY else f"{n} ({k})",
                "",
                "",
                registry.allocator_target(n, None if k == registry.ANY else k),
            )
            for n, k in registry.entries()
        ]
        groups.append(("allocators (swarmbed params NAME):", allocators))
    else:
        groups = [
            (title, rows)
            for title, rows in (
                (title, [r for r in rows if r[0] == args.name or r[0].startswith((args.name + ".", args.name + "[]."))])
                for title, rows in sections
            )
            if rows
        ]
        groups = groups or _param_groups(args.name)
        if not groups:
            import difflib

            keys = [r[0] for _, rows in sections for r in rows]
            near = difflib.get_close_matches(args.name, keys + registry.scenario_names() + registry.names(), n=1)
            print(
                f"error: {args.name!r} is neither a key or section (run, agents, network, ros2, placement, ...), "
                f"a scenario ({', '.join(registry.scenario_names())}) nor an allocator ({', '.join(registry.names())})"
                + (f"; did you mean {near[0]!r}?" if near else ""),
                file=sys.stderr,
            )
            return 2
    for title, rows in groups:
        print(title)
        width = [max([len(r[i]) for r in rows] + [1]) for i in range(3)]
        for key, typ, default, meaning in rows:
            print(f"  {key:<{width[0]}}  {typ:<{width[1]}}  {default:<{width[2]}}  {meaning}".rstrip())
        print()
    return 0


def register_params(sub: Subparsers) -> None:
    """``swarmbed params``: its arguments, run by :func:`cmd_params`."""
    par = sub.add_parser(
        "params", help="every key of an experiment, a scenario or an allocator: type, default, meaning"
    )
    par.add_argument(
        "name",
        nargs="?",
        help="a section (network, run, ros2, ...) or one key (network.loss), a scenario or an allocator; "
        "none: every section",
    )
    par.set_defaults(func=cmd_params)


def _sweep_executor(args: argparse.Namespace, out: Path) -> Executor:
    from swarmbed.campaigns import executors

    if args.executor != "slurm" and (args.slurm_partition or args.slurm_cluster or args.detach):
        raise executors.ExecutorError("--slurm-*, --detach: only with --executor slurm")
    if args.executor != "dask" and args.scheduler:
        raise executors.ExecutorError("--scheduler: only with --executor dask")
    return executors.get(
        args.executor,
        jobs=args.jobs,
        folder=out / ".submitit",
        partition=args.slurm_partition,
        time=args.slurm_time,
        parallel=args.jobs,
        cluster=args.slurm_cluster,
        detach=args.detach,
        scheduler=args.scheduler,
    )


def cmd_sweep(args: argparse.Namespace) -> int:
    from swarmbed.campaigns.executors import ExecutorError
    from swarmbed.campaigns.sweep import experiment_for, load_sweep, plan, run_sweep, status
    from swarmbed.campaigns.tracking import TrackingError

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
    sweep = load_sweep(args.sweep, args.runs, args.grid, args.set, args.seed)
    out = Path(args.out) if args.out else Path("runs") / sweep.name
    planned = plan(sweep, out)
    first = {spec.scenario.name: spec for spec in reversed(planned)}
    every = {name: experiment_for(spec.base, spec.scenario, spec.seed, spec.extra) for name, spec in first.items()}
    for name, exp in every.items():
        why = _refusals(exp, args.engine)
        if why:
            print(f"error: {_engine_prefix(args.engine)}scenario {name}: {why[0]}", file=sys.stderr)
            return 2
    if args.check:
        from swarmbed.launch.check import describe_sweep
        from swarmbed.results.run_folder import RunDir

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
        type=_positive,
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
    sw.add_argument("--runs", "-n", type=_positive, help="runs per scenario (overrides the file)")
    _add_engine(sw)
    sw.add_argument(
        "--verify",
        type=_positive,
        metavar="K",
        help="after the sweep, run K of its completed runs again in processes (the lowest seeds) and compare "
        "every reproducible result file byte for byte; exit 1 naming any file that differs",
    )
    sw.add_argument("--seed", type=int, help="sweep seed (overrides the file)")
    sw.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2", help="add a grid axis")
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


def cmd_check_allocator(args: argparse.Namespace) -> int:
    from swarmbed.checks.allocator import GENERIC_CHECKS, ConformanceError
    from swarmbed.plugins.registry import PluginError, only_scenario, validate_params

    args.scenario = args.scenario or only_scenario(args.allocator) or "mtsr"
    params = dict(cfg.parse_override(text) for text in args.set)
    try:
        validate_params(args.allocator, params, args.scenario)
    except PluginError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    failed = 0
    for check in GENERIC_CHECKS:
        try:
            result = check(args.allocator, params, args.scenario)
            print(f"PASS {check.__name__}: {result}")
        except ConformanceError as exc:
            failed += 1
            print(f"FAIL {check.__name__}: {exc}")
        except Exception as exc:  # the plugin raised: that check fails, the others still run
            failed += 1
            where = traceback.extract_tb(exc.__traceback__)[-1]
            print(
                f"FAIL {check.__name__}: the plugin raised {type(exc).__name__}: {exc} "
                f"({where.filename}:{where.lineno})"
            )
    return 1 if failed else 0


def register_check_allocator(sub: Subparsers) -> None:
    """``swarmbed check-allocator``: its arguments, run by :func:`cmd_check_allocator`."""
    chk = sub.add_parser("check-allocator", help="run the allocator conformance kit on a plugin")
    chk.add_argument("allocator", help="registered name, module:Class or path/to/file.py:Class")
    chk.add_argument("--set", action="append", default=[], metavar="PARAM=VALUE", help="an allocator parameter")
    chk.add_argument(
        "--scenario",
        help="the scenario it is for (a registered name; default: the one it is registered for, else mtsr)",
    )
    chk.set_defaults(func=cmd_check_allocator)


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
    rp.add_argument("--fps", type=_positive, default=10, help="frames per second of the movie (default 10)")
    rp.add_argument("--every", type=_positive, help="ticks per frame (default: at most 600 frames)")
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


def cmd_check_scenario(args: argparse.Namespace) -> int:
    from swarmbed.checks.scenario import ScenarioCheckError, check_scenario

    cls = registry.resolve_scenario(args.scenario)
    try:
        params = dict(cfg.parse_override(text) for text in args.set)
        agents = dict(cfg.parse_override(text) for text in args.agents)
        result = check_scenario(cls, params, agents, ticks=args.ticks)
    except ScenarioCheckError as exc:
        print(f"FAIL {args.scenario}: {exc}")
        return 1
    print(f"PASS {args.scenario}: {result}")
    return 0


def register_check_scenario(sub: Subparsers) -> None:
    """``swarmbed check-scenario``: its arguments, run by :func:`cmd_check_scenario`."""
    chs = sub.add_parser(
        "check-scenario", help="run the scenario checker (determinism, observations, results, conservation, robustness)"
    )
    chs.add_argument("scenario", help="registered name, module:Class or path/to/file.py:Class")
    chs.add_argument("--set", action="append", default=[], metavar="PARAM=VALUE", help="a scenario parameter")
    chs.add_argument(
        "--agents",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an agents-section key for the check (e.g. max_speed=5)",
    )
    chs.add_argument("--ticks", type=int, default=60, help="ticks per checked run (default 60)")
    chs.set_defaults(func=cmd_check_scenario)


def cmd_host(args: argparse.Namespace) -> int:
    from swarmbed.hosts.daemon import serve
    from swarmbed.launch.host_client import HostError
    from swarmbed.wire.credentials import CredentialsError
    from swarmbed.wire.logs import LOG_FORMAT
    from swarmbed.wire.session import tls_from_args

    logging.basicConfig(level=logging.INFO, format=LOG_FORMAT)
    logs = Path(args.logs) if args.logs else Path("runs") / "hosts" / args.name
    try:
        return serve(
            args.name,
            args.connect,
            args.listen,
            logs,
            args.zenoh_config,
            args.mode,
            args.credentials,
            tls_from_args(args),
            insecure=args.insecure,
        )
    except (CredentialsError, HostError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def register_host(sub: Subparsers) -> None:
    """``swarmbed host``: its arguments, run by :func:`cmd_host`."""
    host = sub.add_parser("host", help="run this machine's host daemon: a Zenoh router that starts agents for runs")
    host.add_argument("--name", required=True, help="this host's name in placements (letters, digits, _ . -)")
    host.add_argument("--logs", help="where its agents log (default: runs/hosts/<name>)")
    host.add_argument(
        "--insecure",
        action="store_true",
        help="run without --credentials: no authentication, anyone who reaches the router may start "
        "agents (their code included); allowed with loopback endpoints only",
    )
    add_zenoh_args(host, default_mode="router", retries=False)
    host.set_defaults(func=cmd_host)


def _client_session(args: argparse.Namespace, connect_timeout_s: float | None = None):
    """A client session from the shared zenoh flags, or None after printing why it cannot open
    (no route to the endpoint within ``connect_timeout_s``, refused credentials, an unreadable
    credentials file)."""
    import zenoh

    from swarmbed.wire.credentials import CredentialsError
    from swarmbed.wire.session import connect_timeout, tls_from_args, zenoh_config

    try:
        return zenoh.open(
            zenoh_config(
                "client",
                args.connect,
                [],
                args.zenoh_config,
                args.credentials,
                tls_from_args(args),
                connect_timeout_s=connect_timeout(args, connect_timeout_s),
            )
        )
    except CredentialsError as exc:
        print(f"error: {exc}", file=sys.stderr)
    except zenoh.ZError as exc:
        hint = "" if args.credentials else " (a run's hub admits only processes with credentials: give --credentials)"
        print(
            f"error: cannot reach {', '.join(args.connect) or 'any endpoint (give --connect)'}: {exc}{hint}",
            file=sys.stderr,
        )
    return None


def cmd_hosts(args: argparse.Namespace) -> int:
    from swarmbed.launch.host_client import host_info, visible_hosts

    session = _client_session(args)
    if session is None:
        return 2
    with session:
        names = visible_hosts(session, timeout=args.timeout)
        if not names:
            print(f"no host visible from {', '.join(args.connect)}")
            return 1
        for name in names:
            info = host_info(session, name)
            if info is None:
                print(f"{name}  (no answer, or not a host's information)")
                continue
            agents = ", ".join(f"{run}: {len(ids)}" for run, ids in info.agents.items()) or "none"
            print(
                f"{name}  cores {info.cores or '?'}  free {info.mem_free_mb} MB  "
                f"router {info.endpoint}  agents {agents}"
            )
    return 0


def register_hosts(sub: Subparsers) -> None:
    """``swarmbed hosts``: its arguments, run by :func:`cmd_hosts`."""
    hosts = sub.add_parser("hosts", help="list the hosts visible from an endpoint")
    hosts.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for answers")
    add_zenoh_args(hosts)
    hosts.set_defaults(func=cmd_hosts)


def cmd_watch(args: argparse.Namespace) -> int:

    from swarmbed.results.watch import WatchError, watch

    session = _client_session(args, connect_timeout_s=args.wait)  # the run may not be up yet
    if session is None:
        return 2
    live = None
    if args.foxglove is not None:
        from swarmbed.results.live import StatusFoxglove
        from swarmbed.results.recording import RecordingError

        try:
            live = StatusFoxglove(args.foxglove)
        except RecordingError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        print(f"Foxglove: open connection ws://127.0.0.1:{live.port}", file=sys.stderr, flush=True)
    with session:
        try:
            return watch(
                session, args.run, wait=args.wait, map_file=Path(args.map) if args.map else None, foxglove=live
            )
        except WatchError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        finally:
            if live is not None:
                live.close()


def register_watch(sub: Subparsers) -> None:
    """``swarmbed watch``: its arguments, run by :func:`cmd_watch`."""
    wat = sub.add_parser("watch", help="a live view of a running experiment (read-only)")
    wat.add_argument("--run", help="the run id (default: the one run visible from the endpoint)")
    wat.add_argument(
        "--wait", type=float, default=10.0, help="seconds to wait for the hub to listen and the run to answer"
    )
    wat.add_argument("--map", metavar="FILE.html", help="also keep a map of the run in FILE.html (reloads itself)")
    wat.add_argument(
        "--foxglove",
        nargs="?",
        const=8765,
        type=port_number,
        metavar="PORT",
        help="also serve the run to Foxglove on 127.0.0.1:PORT (default 8765; 0: a free port): agents, poses "
        "and markers from the run's progress samples (the viewers extra)",
    )
    add_zenoh_args(wat)
    wat.set_defaults(func=cmd_watch)


def cmd_groot(args: argparse.Namespace) -> int:
    from swarmbed.results.groot import run_gateway
    from swarmbed.results.watch import WatchError

    try:
        import zmq  # noqa: F401
    except ImportError:
        print("error: swarmbed groot needs pyzmq: pip install 'swarmbed[viewers]'", file=sys.stderr)
        return 2
    session = _client_session(args, connect_timeout_s=args.wait)  # the run may not be up yet
    if session is None:
        return 2
    with session:
        try:
            return run_gateway(session, args.run, args.agent, args.port, args.bind, wait=args.wait)
        except WatchError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2


def register_groot(sub: Subparsers) -> None:
    """``swarmbed groot``: its arguments, run by :func:`cmd_groot`."""
    gr = sub.add_parser("groot", help="watch an agent's behavior tree of a running run in Groot2, live")
    gr.add_argument("--run", help="the run id (default: the one run visible from the endpoint)")
    gr.add_argument("--agent", type=int, default=0, help="the agent to show first (type another id to switch)")
    gr.add_argument(
        "--port", type=port_number, default=1667, help="Groot2's port (and the next one), as BehaviorTree.CPP"
    )
    gr.add_argument("--bind", default="127.0.0.1", help="the address Groot2 connects to (default: this machine only)")
    gr.add_argument(
        "--wait", type=float, default=10.0, help="seconds to wait for the hub to listen and the run to answer"
    )
    add_zenoh_args(gr)
    gr.set_defaults(func=cmd_groot)


def cmd_swap(args: argparse.Namespace) -> int:
    """Ask a running run to move one agent to another host before its next tick; wait for the outcome."""
    import json

    from swarmbed.results.watch import running_runs
    from swarmbed.wire.credentials import CredentialsError, read_credentials
    from swarmbed.wire.errors import WireError
    from swarmbed.wire.keys import Keys
    from swarmbed.wire.reports import SwapAnswer, SwapQueued, SwapRecord, SwapRefused, decode_swap_answer

    if args.credentials:
        try:
            role = read_credentials(args.credentials).role
        except CredentialsError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        if role not in ("operator", "commander"):
            print(
                f"error: {args.credentials} is a {role}'s credentials: swaps are asked by an operator "
                "(swarmbed credentials FILE --user NAME, admitted with swarmbed run --admit FILE)",
                file=sys.stderr,
            )
            return 2

    def ask(request: dict) -> SwapAnswer | None:
        for reply in session.get(key, payload=json.dumps(request), timeout=5.0):
            if reply.ok is not None:
                try:
                    return decode_swap_answer(reply.ok.payload.to_bytes())
                except WireError as exc:
                    return SwapRefused(error=f"the coordinator's answer is malformed: {exc}")
        return None

    session = _client_session(args)
    if session is None:
        return 2
    with session:
        if args.run is None:  # the only run visible from here, as swarmbed watch picks it
            runs = running_runs(session)
            if len(runs) != 1:
                print(
                    f"error: {len(runs)} runs are visible ({', '.join(runs) or 'none'}): name one with --run",
                    file=sys.stderr,
                )
                return 2
            args.run = runs[0]
        key = Keys(args.run).swap
        answer = ask({"agent": args.agent, "to": args.to})
        if not isinstance(answer, SwapQueued):
            why = answer.error if isinstance(answer, SwapRefused) else "no coordinator answered"
            print(f"error: run {args.run}: {why}", file=sys.stderr)
            return 2
        print(f"swap {answer.queued} of agent {args.agent} to {args.to} queued; waiting for its outcome", flush=True)
        deadline = time.monotonic() + args.wait
        while time.monotonic() < deadline:
            record = ask({"swap": answer.queued})
            if isinstance(record, SwapRefused):
                print(f"error: run {args.run}: {record.error}", file=sys.stderr)
                return 2
            if isinstance(record, SwapRecord):
                print(
                    f"swap of agent {record.agent} from {record.from_host} to {record.to} before tick "
                    f"{record.tick}: {record.outcome}"
                    + (
                        f" ({record.reason})"
                        if record.reason
                        else f", {record.snapshot_bytes} bytes, paused {record.pause_ms:.0f} ms"
                    )
                )
                return 0 if record.outcome == "ok" else 1
            time.sleep(0.1)
    print(f"error: the swap was queued but not done within {args.wait:.0f} s", file=sys.stderr)
    return 1


def register_swap(sub: Subparsers) -> None:
    """``swarmbed swap``: its arguments, run by :func:`cmd_swap`."""
    swap = sub.add_parser("swap", help="move a running agent to another host, with its state")
    swap.add_argument("--run", help="the run id (deployment.json names it; default: the only run visible)")
    swap.add_argument("--agent", type=int, required=True, help="the agent to move")
    swap.add_argument("--to", required=True, help="the host to move it to ('local': the launching machine)")
    swap.add_argument("--wait", type=float, default=60.0, help="seconds to wait for the outcome")
    add_zenoh_args(swap)
    swap.set_defaults(func=cmd_swap)


#: every verb, in the order ``swarmbed --help`` lists them
VERBS: tuple[Callable[[Subparsers], None], ...] = (
    register_run,
    register_soak,
    register_credentials,
    register_certs,
    register_bt,
    register_params,
    register_sweep,
    register_analyze,
    register_report,
    register_replay,
    register_check_allocator,
    register_check_scenario,
    register_host,
    register_hosts,
    register_watch,
    register_groot,
    register_swap,
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="swarmbed", description="Zenoh-networked MRTA emulation testbed")
    sub = ap.add_subparsers(dest="command", required=True)
    for register in VERBS:
        register(sub)

    for name, module in (("agent", "swarmbed.agent_runtime.process"), ("netem", "swarmbed.netem.proxy")):
        p = sub.add_parser(name, help=f"start one {name} process by hand (e.g. on another host)", add_help=False)
        p.set_defaults(func=None, module=module)

    args, rest = ap.parse_known_args(argv)
    if args.command in ("agent", "netem"):
        import importlib

        return importlib.import_module(args.module).main(rest)
    if rest:
        ap.error(f"unrecognized arguments: {' '.join(rest)}")
    stopped_by = [signal.SIGINT]

    def on_sigterm(signum: int, _frame: object) -> None:  # `kill`: stop as Ctrl-C stops, cleaning up
        stopped_by[0] = signal.SIGTERM
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_sigterm)
    try:
        return args.func(args)
    except (cfg.ConfigError, BTError, registry.PluginError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RunError as exc:
        print(f"run failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        print(str(exc) or INTERRUPTED.get(args.command, "interrupted"), file=sys.stderr)
        return 128 + stopped_by[0]
    except BrokenPipeError:  # the reader of our output went away (e.g. `| head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as exc:  # a full disk, a folder that is not there: one line naming what and where
        where = f": {exc.filename}" if exc.filename else ""
        print(f"error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
