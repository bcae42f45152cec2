"""The ``swarmbed`` command."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from swarmbed.agent_runtime.bt import BTError, load_tree, palette_xml
from swarmbed.agent_runtime.nodes import space_registry
from swarmbed.coordinator.coordinator import RunError
from swarmbed.experiments import config as cfg
from swarmbed.plugins import names as allocator_names


def _keys_epilog() -> str:
    rows = cfg.describe_keys()
    width = max(len(k) for k, _, _ in rows)
    lines = ["experiment keys (override any with --set KEY=VALUE):"]
    lines += [f"  {k:<{width}}  {d:<10}  {desc}" for k, d, desc in rows]
    lines.append(f"registered allocators: {', '.join(allocator_names())}")
    return "\n".join(lines)


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:,.1f}"
    if isinstance(v, int):
        return f"{v:,}"
    return "-" if v is None else str(v)


def print_summary(summary: dict, out_dir: Path, stream=sys.stdout) -> None:
    net = summary["network"]
    if summary.get("scenario_kind") == "sar":
        rows = [
            ("rescued", summary["rescued"]),
            ("expired", summary["expired"]),
            ("failed rescues (mismatch found)", summary["failed_rescues"]),
            ("victims spawned / still alive", f"{summary['spawned']} / {summary['victims_alive']}"),
            ("negotiations", summary.get("negotiations", "-")),
            ("agents lost", len(summary["agents_lost"])),
        ]
    else:
        rows = [
            ("mission time (sim s)", summary["mission_time"]),
            ("all tasks completed", summary["all_tasks_completed"]),
            ("time to 99% of tasks", summary["time_99"]),
            ("tasks completed / total", f"{summary['tasks_completed']} / {summary['tasks_total']}"),
            ("distance, all agents", summary["distance_total"]),
            ("work, all agents", summary["work_total"]),
        ]
    rows += [
        ("messages sent", net["messages_sent"]),
        ("payload bytes sent", net["bytes_sent"]),
        ("copies delivered / total", f"{net['delivered']:,} / {net['copies']:,}"),
        ("copies dropped", ", ".join(f"{k} {v:,}" for k, v in net["dropped"].items() if v) or "0"),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"results: {out_dir}", file=stream)
    for label, value in rows:
        print(f"  {label:<{width}}  {_fmt(value)}", file=stream)


def cmd_run(args: argparse.Namespace) -> int:
    from swarmbed.experiments.runner import run_experiment

    exp = cfg.load(args.experiment, args.set, args.seed)
    out = Path(args.out) if args.out else Path("runs") / exp.name / f"seed{exp.run.seed}-{time.strftime('%Y%m%d-%H%M%S')}"
    result = run_experiment(exp, out, progress=not args.no_progress)
    print_summary(result.summary, out)
    return 0


def cmd_bt(args: argparse.Namespace) -> int:
    registry = space_registry()
    if args.bt_command == "palette":
        sys.stdout.write(palette_xml(registry))
        return 0
    for path in args.files:
        load_tree(path, registry)
        print(f"{path}: ok")
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from swarmbed.experiments.sweep import load_sweep, run_sweep

    sweep = load_sweep(args.sweep, args.runs, args.grid, args.set, args.seed)
    out = Path(args.out) if args.out else Path("runs") / sweep.name
    table = run_sweep(sweep, out, args.jobs, progress=not args.no_progress)
    ok = table[table["status"] == "ok"]
    print(f"sweep: {out}/sweep.csv  ({len(ok)} of {len(table)} runs complete, "
          f"{len(sweep.scenarios)} scenarios x {sweep.runs} runs)")
    shown = [c for c in ("mission_time", "time_99", "tasks_completed", "network.messages_sent") if c in ok]
    if shown:
        print(ok.groupby("scenario")[shown].mean().round(1).to_string())
    return 0 if len(ok) == len(table) else 1


def cmd_analyze(args: argparse.Namespace) -> int:
    from swarmbed.experiments.analyze import AnalyzeError, analyze

    try:
        written = analyze([Path(d) for d in args.sweep_dir], control=args.control)
    except (AnalyzeError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path in written:
        print(path)
    return 0


def cmd_check_allocator(args: argparse.Namespace) -> int:
    from swarmbed.plugins.conformance import GENERIC_CHECKS, ConformanceError
    from swarmbed.plugins.registry import PluginError, validate_params

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
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="swarmbed", description="Zenoh-networked MRTA emulation testbed")
    sub = ap.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="run one experiment", epilog=_keys_epilog(),
                         formatter_class=argparse.RawDescriptionHelpFormatter)
    run.add_argument("experiment", help="experiment YAML file")
    run.add_argument("--seed", type=int, help="run seed (overrides run.seed)")
    run.add_argument("--out", help="run directory (default: runs/<name>/seed<seed>-<time>)")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a dotted key")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.set_defaults(func=cmd_run)

    bt = sub.add_parser("bt", help="behavior-tree tools")
    bt_sub = bt.add_subparsers(dest="bt_command", required=True)
    bt_sub.add_parser("palette", help="print a Groot2 <TreeNodesModel> of every registered node")
    check = bt_sub.add_parser("check", help="load behavior-tree XML files and report errors")
    check.add_argument("files", nargs="+")
    bt.set_defaults(func=cmd_bt)

    sw = sub.add_parser("sweep", help="Monte Carlo runs over scenarios, in parallel and resumable")
    sw.add_argument("sweep", help="sweep YAML (base + scenarios/grid + runs) or a plain experiment")
    sw.add_argument("--out", help="sweep directory (default: runs/<name>)")
    sw.add_argument("--jobs", "-j", type=int, help="runs at once (default: one per core)")
    sw.add_argument("--runs", "-n", type=int, help="runs per scenario (overrides the file)")
    sw.add_argument("--seed", type=int, help="sweep seed (overrides the file)")
    sw.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2", help="add a grid axis")
    sw.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override for every run")
    sw.add_argument("--no-progress", action="store_true")
    sw.set_defaults(func=cmd_sweep)

    an = sub.add_parser("analyze", help="tables and figures from a sweep directory")
    an.add_argument("sweep_dir", nargs="+", help="sweep directories (outputs go to the first)")
    an.add_argument("--control", default="cbba-etc", help="control strategy for Dunnett and Cohen's d")
    an.set_defaults(func=cmd_analyze)

    chk = sub.add_parser("check-allocator", help="run the allocator conformance kit on a plugin")
    chk.add_argument("allocator", help="registered name, module:Class or path/to/file.py:Class")
    chk.add_argument("--set", action="append", default=[], metavar="PARAM=VALUE", help="an allocator parameter")
    chk.add_argument("--scenario", default="mtsr", choices=["mtsr", "sar"], help="the scenario kind it is for")
    chk.set_defaults(func=cmd_check_allocator)

    for name, module in (("agent", "swarmbed.agent_runtime.process"), ("netem", "swarmbed.netem.proxy")):
        p = sub.add_parser(name, help=f"start one {name} process by hand (e.g. on another host)", add_help=False)
        p.set_defaults(func=None, module=module)

    args, rest = ap.parse_known_args(argv)
    if args.command in ("agent", "netem"):
        import importlib

        return importlib.import_module(args.module).main(rest)
    if rest:
        ap.error(f"unrecognized arguments: {' '.join(rest)}")
    try:
        return args.func(args)
    except (cfg.ConfigError, BTError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RunError as exc:
        print(f"run failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted: every process was stopped; no summary.json was written", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of our output went away (e.g. `| head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
