"""``swarmbed bt``, ``params``, ``check-allocator`` and ``check-scenario``: for those who write
experiments and extensions."""

from __future__ import annotations

import argparse
import sys
import traceback
from typing import TYPE_CHECKING

from swarmbed import config as cfg
from swarmbed.bt import BTError, load_tree, palette_xml
from swarmbed.extension.node_sets import node_registry
from swarmbed.extension.presets import PRESET_KEY, presets_of
from swarmbed.plugins import registry

if TYPE_CHECKING:
    from swarmbed.cli.common import Subparsers


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
            groups += _preset_group(cls.Params, "scenario")
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
        groups += _preset_group(allocator.Params, "allocator")
    return groups


def _preset_group(params_model: type, section: str) -> list[tuple[str, list[tuple[str, str, str, str]]]]:
    """The presets a plugin declares, each with the keys it sets and what it follows (none: no group)."""
    presets = presets_of(params_model)
    if not presets:
        return []
    rows = [
        (name, "", "", "sets " + ", ".join(f"{k}={v}" for k, v in preset.values.items()) + f" ({preset.source})")
        for name, preset in sorted(presets.items())
    ]
    return [(f"presets ({section}.{PRESET_KEY}: NAME; a key the experiment sets wins):", rows)]


def _section_groups() -> list[tuple[str, list[tuple[str, str, str, str]]]]:
    """Every key of an experiment outside a scenario's or an allocator's own: the sections, ROS 2,
    the radio's split and where agents run (placement, swaps, may_carry)."""
    from swarmbed.schema.experiment import Experiment, RadioSplit, Ros2Section

    groups = [(f"{name}:", cfg.describe(model, f"{name}.")) for name, model in cfg.SECTIONS.items()]
    groups.append(("ros2 (off unless given):", cfg.describe(Ros2Section, "ros2.")))
    split = cfg.describe(RadioSplit, "radio_split.")
    groups.append(("radio_split (the radio over several netem proxies: docs/machines.md):", split))
    hosts = [
        row
        for row in cfg.describe(Experiment)
        if row[0].split(".")[0].removesuffix("[]") in ("placement", "swaps", "may_carry")
    ]
    groups.append(("hosts (placement, swaps, may_carry: docs/machines.md):", hosts))
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


def cmd_check_allocator(args: argparse.Namespace) -> int:
    from swarmbed.checks.allocator_kit import GENERIC_CHECKS, ConformanceError
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


def cmd_check_scenario(args: argparse.Namespace) -> int:
    from swarmbed.checks.scenario_check import ScenarioCheckError, check_scenario

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
