"""``swarmbed run`` (one experiment) and ``swarmbed soak`` (one run for hours, watched)."""

from __future__ import annotations

import argparse
import json
import sys
import textwrap
import time
from pathlib import Path
from typing import TYPE_CHECKING

from swarmbed import config as cfg
from swarmbed.cli.common import add_engine, add_live_view, engine_prefix, fmt, keys_epilog, refusals, taken
from swarmbed.files import safefiles

if TYPE_CHECKING:
    from swarmbed.cli.common import Subparsers
    from swarmbed.wire.keys import Keys


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
        print(f"  {label:<{width}}  {fmt(value)}", file=stream)
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


def cmd_run(args: argparse.Namespace) -> int:
    from swarmbed.launch.hub import HubOptions
    from swarmbed.launch.runner import run_experiment
    from swarmbed.wire.credentials import CredentialsError, check_admitted, read_credentials
    from swarmbed.wire.zenoh_session import tls_from_args

    exp = cfg.load(args.experiment, args.set, args.seed)
    try:
        admitted = check_admitted(read_credentials(path) for path in args.admit)
        tls = tls_from_args(args)
    except CredentialsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path("runs") / exp.name / f"seed{exp.run.seed}-{stamp}"
    why = refusals(exp, args.engine)
    if args.engine == "inprocess" and (args.listen or args.admit or args.tls or args.slurm):
        why.append("--listen, --admit, --tls and --slurm are for a hub others join: the in-process engine has none")
    if why:
        print(f"error: {engine_prefix(args.engine)}{why[0]}", file=sys.stderr)
        return 2
    allocation = None
    if args.slurm:
        from swarmbed.launch.slurm_allocation import SlurmError, read_allocation, spread

        refused = _slurm_refusals(exp, args)
        try:
            allocation = None if refused else read_allocation()
        except SlurmError as exc:
            refused = str(exc)
        if refused:
            print(f"error: {refused}", file=sys.stderr)
            return 2
        assert allocation is not None
        exp = exp.model_copy(update={"placement": spread(allocation.nodes, exp.agents.count)})
    if args.check:
        from swarmbed.launch.check import describe_plan

        print(describe_plan(exp, out, admitted, args.engine))
        return 0
    views: list = []
    if args.foxglove is not None:  # pandas and Foxglove's SDK only for a run that shows itself live
        from swarmbed.results.recording import RecordingError

        try:  # the port is taken before the output folder is touched: a port in use leaves nothing behind
            views = _live_views(exp, args.foxglove, args.view_clients)
        except RecordingError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    problem = taken(out, args.force)
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
    if allocation is not None:
        from swarmbed.launch.slurm_allocation import SlurmError, SlurmHosts

        logs = Path("runs") / "hosts" / f"slurm-{allocation.job_id}"
        safefiles.make_folder(logs)
        try:
            with SlurmHosts(allocation, logs) as hosts:
                print(
                    f"slurm: job {allocation.job_id}, agents on {exp.placement}; hosts' logs in {logs}", file=sys.stderr
                )
                listen = (*args.listen, hosts.hub)
                hub = HubOptions(listen, True, (*admitted, *hosts.identities), tls, hosts.proxy_command)
                result = run_experiment(
                    exp, out, progress=not args.no_progress, hub=hub, views=views, on_ready=_say_where
                )
        except SlurmError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    else:
        result = run_experiment(exp, out, progress=not args.no_progress, hub=hub, views=views, on_ready=_say_where)
    print_summary(result.summary, out, cfg.resolve_experiment(exp).scenario())
    return 0


def _say_where(keys: Keys, endpoint: str) -> None:
    """Once every process joined: the run id and endpoint that ``watch``, ``swap`` and ``groot`` need."""
    print(
        f"run {keys.run_id} at {endpoint}: swarmbed watch|swap --connect {endpoint} --run {keys.run_id}",
        file=sys.stderr,
    )


def _slurm_refusals(exp, args: argparse.Namespace) -> str | None:
    """Why ``--slurm`` cannot run this experiment with these flags, or None."""
    if exp.placement or exp.swaps or exp.may_carry:
        return "--slurm places the agents itself over the allocation's nodes: leave placement, swaps and may_carry out"
    if args.no_auth:
        return "--slurm starts host daemons that present credentials: it cannot run with --no-auth"
    if args.tls:
        return "--slurm with --tls is not supported yet: the nodes' links are plain TCP with credentials"
    return None


def _live_views(exp, port: int | None, max_clients: int = 4) -> list:
    """The live views ``swarmbed run`` was asked for (``--foxglove``), each made from the run's session."""
    if port is None:
        return []
    from swarmbed.results.foxglove_live import FoxgloveLive, serve

    served = serve("127.0.0.1", port, max_clients)

    def foxglove(session):
        from swarmbed.schema.obstacles import wall_lines

        walls = wall_lines(exp.obstacles)
        view = FoxgloveLive(session.world, exp.run.dt, walls=walls, served=served)
        print(f"Foxglove: open connection {view.url}", file=sys.stderr, flush=True)
        return view

    return [foxglove]


def register_run(sub: Subparsers) -> None:
    """``swarmbed run``: its arguments, run by :func:`cmd_run`."""
    run = sub.add_parser(
        "run", help="run one experiment", epilog=keys_epilog(), formatter_class=argparse.RawDescriptionHelpFormatter
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
    add_live_view(run, "the channels of replay --mcap; the viewers extra")
    add_engine(run)
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
    run.add_argument(
        "--slurm",
        action="store_true",
        help="inside a Slurm allocation (salloc, sbatch): start a host daemon on every node with srun and "
        "spread the agents over them; the coordinator, the proxy and the results stay here (docs/machines.md)",
    )
    run.set_defaults(func=cmd_run)


def cmd_soak(args: argparse.Namespace) -> int:
    from swarmbed.campaigns.chaos import ChaosError, check_plan, load_chaos
    from swarmbed.campaigns.soak import Thresholds, format_verdict, parse_duration, soak
    from swarmbed.launch.hub import HubOptions

    try:
        duration = parse_duration(args.duration)
        plan = load_chaos(Path(args.chaos)) if args.chaos else None
    except (ValueError, ChaosError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    exp = cfg.load(args.experiment, args.set, args.seed)
    try:
        if plan is not None:
            check_plan(plan, exp)
    except ChaosError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path("runs") / f"soak-{exp.name}" / f"seed{exp.run.seed}-{stamp}"
    limits = Thresholds(args.max_rss_slope, args.max_fd_growth, args.max_stall)
    print(
        f"soak: {exp.name}, {exp.agents.count} agents, {duration:.0f} s of wall time"
        f"{f', chaos from {args.chaos}' if plan else ''}; files in {out}\n"
        "soak: a line a minute here; to watch it live, swarmbed watch with the endpoint and run id below",
        flush=True,
    )
    hub = HubOptions(auth=not args.no_auth)
    result = soak(exp, out, duration, plan, args.interval, limits, hub=hub, on_ready=_say_where)
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
