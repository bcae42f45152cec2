"""An experiment resolved, in one place: YAML, ``--set dotted.key=value`` overrides, presets, and
every check before any process starts; the launcher, the sweeps and the API are handed what
:func:`load` gives.

The schema itself lives below the processes (``swarmbed.schema.experiment``); this is the only
place where names are resolved: ``scenario.kind`` and ``allocator.name`` to
their classes, whose ``Params`` models check their sections. The sections are written back fully
resolved, so that ``config.yaml`` and every process see complete parameters. The behavior tree is
loaded here too, with the node set the agents will have. An error names the file (or ``--set``)
and the dotted key.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args, get_origin

import yaml
from pydantic import BaseModel, ValidationError

from swarmbed.bt import BTError, load_tree
from swarmbed.engine import refusals
from swarmbed.extension.allocator import Allocator
from swarmbed.extension.node_sets import node_registry, tree_path
from swarmbed.extension.scenario import Scenario
from swarmbed.files.yamlfile import YamlFileError, non_finite, parse_yaml, read_yaml
from swarmbed.plugins.registry import (
    PluginError,
    allocator_target,
    check_params,
    resolve,
    resolve_scenario,
    scenario_target,
)
from swarmbed.schema.experiment import (
    AgentsSection,
    AllocatorSection,
    Experiment,
    NetworkSection,
    RunSection,
    ScenarioSection,
    Targets,
    carriers,
    hosts_of,
)
from swarmbed.schema.obstacles import PolygonEntry, WallEntry
from swarmbed.wire.targets import file_digests
from swarmbed.wire.validation import validation_lines

__all__ = [
    "ConfigError",
    "Experiment",
    "Resolved",
    "load",
    "resolve_experiment",
    "to_yaml",
    "from_yaml",
    "parse_override",
    "apply_overrides",
    "validate",
    "describe",
    "SECTIONS",
]

#: the generic sections, for ``swarmbed params``
SECTIONS: dict[str, type[BaseModel]] = {"run": RunSection, "agents": AgentsSection, "network": NetworkSection}


class ConfigError(ValueError):
    """A bad experiment file or override; the message names the file and the dotted key."""


@dataclass(frozen=True)
class Resolved:
    """An experiment with the classes its names resolved to: what the launcher runs."""

    exp: Experiment
    scenario_cls: type[Scenario]
    allocator_cls: type[Allocator]
    targets: Targets

    def scenario(self) -> Scenario:
        sc = self.scenario_cls
        return sc(
            sc.Params.model_validate(self.exp.scenario.params()), self.exp.agents, self.exp.run.dt, self.exp.obstacles
        )


#: the key that says which plugin a section is for: a section naming another replaces the old one
IDENTITY = {"allocator": "name", "scenario": "kind"}


def _merged(old: Any, new: Any, key: str) -> Any:
    """``new`` set over ``old``: a mapping over a mapping is merged key by key (``agents={count: 3}``
    keeps the section's other keys), except a plugin's section that names another plugin."""
    if not (isinstance(old, dict) and isinstance(new, dict)):
        return new
    ident = IDENTITY.get(key)
    if ident and ident in new and new[ident] != old.get(ident):
        return new
    return {**old, **{k: _merged(old.get(k), v, k) for k, v in new.items()}}


def _set_dotted(data: dict, dotted: str, value: Any, where: str) -> None:
    keys = dotted.split(".")
    node = data
    for k in keys[:-1]:
        nxt = node.setdefault(k, {})
        if not isinstance(nxt, dict):
            raise ConfigError(f"{where}: --set {dotted}: '{k}' is not a section")
        node = nxt
    node[keys[-1]] = _merged(node.get(keys[-1]), value, keys[-1])


def apply_overrides(data: dict, pairs: list[tuple[str, Any]], where: str) -> None:
    """Set each dotted key. Naming another allocator drops the file's parameters of the old one
    (they belong to that plugin); parameters given alongside the new name are kept."""
    alloc = data.get("allocator")
    old_name = alloc.get("name", "fcg") if isinstance(alloc, dict) else None
    new_name = dict(pairs).get("allocator.name")
    if new_name is not None and new_name != old_name:
        data["allocator"] = {"name": new_name}
    for key, value in pairs:
        _set_dotted(data, key, value, where)


def parse_override(text: str) -> tuple[str, Any]:
    """``a.b=value`` with ``value`` read as YAML (so numbers, booleans, lists and null work)."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"--set {text!r}: expected dotted.key=value")
    try:
        value = parse_yaml(raw, f"--set {text}") if raw.strip() else ""
    except YamlFileError as exc:
        raise ConfigError(str(exc)) from None
    return key.strip(), value


def _origin(line: str, where: str, overridden: dict[str, Any], origin: str = "--set") -> str:
    """``line`` (``dotted.key: message``, or a message about several keys that starts with the one
    it is about) prefixed by where that key came from: the flag that gave it (``--set key=value`` as
    the user wrote the value, ``--seed N``) or the file."""
    key, _, message = line.partition(": ")
    for set_key, value in overridden.items():
        flag = f"--seed {value}" if set_key == SEED_FLAG else f"{origin} {set_key}={_as_written(value)}"
        set_key = "run.seed" if set_key == SEED_FLAG else set_key
        if key == set_key:
            return f"{flag}: {message}"
        if key.startswith(set_key + ".") or set_key.startswith(key + ".") or line.startswith(set_key + " "):
            return f"{flag}: {line}"
    return f"{where}: {line}"


#: the key under which ``--seed`` is listed among the overridden ones (errors then name ``--seed``)
SEED_FLAG = "<--seed>"


def _as_written(value: Any) -> str:
    """A value as YAML writes it (``null``, ``true``, ``[1, 2]``), the way a user typed it after ``=``."""
    return value if isinstance(value, str) else json.dumps(value)


def validate(
    data: dict,
    where: str,
    overridden: dict[str, Any] | None = None,
    origin: str = "--set",
    every_map_problem: bool = True,
) -> Experiment:
    """Check ``data`` in full (sections, plugin parameters, the behavior tree) and return the
    experiment with its scenario and allocator sections fully resolved. ``overridden``: the keys
    that ``--set`` gave, so that an error about one of them names ``--set``, not the file."""
    overridden = overridden or {}

    def fail(lines: list[str]) -> ConfigError:
        return ConfigError("\n".join(_origin(line, where, overridden, origin) for line in lines))

    bad = non_finite(data)
    if bad:
        raise fail([f"{key}: infinite and NaN numbers are not accepted" for key in bad])
    try:
        # strict: `seed: true` or `loss: "0.1"` is refused, not read as 1 and 0.1 (a plugin's own
        # parameters are checked by its Params model below, which may convert YAML lists to tuples)
        exp = Experiment.model_validate(data, strict=True)
    except ValidationError as exc:
        first = fail(validation_lines(exc, Experiment))
        more = _more_map_problems(data, where, overridden, origin, str(first).splitlines()) if every_map_problem else []
        raise ConfigError("\n".join([str(first), *more])) from None
    try:
        kind = exp.scenario.kind  # each name resolved once here, its class used for every check below
        scenario_cls = resolve_scenario(kind)
        scenario_params = check_params(scenario_cls.Params, exp.scenario.params(), "scenario")
        allocator_cls = resolve(exp.allocator.name, kind)
        allocator_params = check_params(allocator_cls.Params, exp.allocator.params(), "allocator")
    except PluginError as exc:
        lines = str(exc).splitlines()
        # a name that does not resolve (a line naming its key already is the parameters' own error)
        if not lines[0].startswith(("scenario.", "allocator.", "scenario:", "allocator:")):
            lines = [
                f"{'scenario.kind' if lines[0].startswith(('scenario', 'unknown scenario')) else 'allocator.name'}"
                f": {line}"
                for line in lines
            ]
        raise fail(lines) from None
    exp = exp.model_copy(
        update={
            "scenario": ScenarioSection(kind=kind, **scenario_params.model_dump(mode="json")),
            "allocator": AllocatorSection(name=exp.allocator.name, **allocator_params.model_dump(mode="json")),
        }
    )
    problems = scenario_cls.check(exp, scenario_params) + allocator_cls.check(exp, allocator_params)
    for check in (lambda: hosts_of(exp.placement, exp.agents.count), lambda: carriers(exp)):
        try:
            check()
        except ValueError as exc:
            problems.append(str(exc))
    problems += [
        f"swaps[{k}].agent: {s.agent} is outside 0..{exp.agents.count - 1}"
        for k, s in enumerate(exp.swaps)
        if s.agent >= exp.agents.count
    ]
    # a driver (the learning environment) may supply decisions: what no run can do is refused here
    problems += refusals(exp, allocator_cls.decision_source, "processes", driven=True)
    if exp.swaps and not allocator_cls.snapshottable:
        problems.append(
            f"swaps: allocator {exp.allocator.name} cannot move between processes "
            f"({allocator_cls.__name__}.snapshottable is False)"
        )
    if problems:
        raise fail(problems)
    tree_problem = _check_tree(exp, scenario_cls, allocator_cls)
    if tree_problem:
        raise fail([f"agents.behavior_tree: {tree_problem}"])
    # the names were resolved once, here: the experiment carries what they resolved to
    scenario, allocator = scenario_target(kind), allocator_target(exp.allocator.name, kind)
    targets = Targets(scenario=scenario, allocator=allocator, digests=file_digests(scenario, allocator))
    exp._resolved = (kind, exp.allocator.name, scenario_cls, allocator_cls, targets)
    return exp


def _more_map_problems(data: dict, where: str, overridden: dict[str, Any], origin: str, known: list[str]) -> list[str]:
    """The problems of the ``obstacles:`` section that a first check could not reach: with a wall or
    polygon refused on its own, the arena and free-room checks never ran. They run here on the
    entries that passed, so a map's every problem is reported at once (indices as written)."""
    obstacles = data.get("obstacles")
    if not isinstance(obstacles, dict) or not any(
        line.split(": ", 2)[-2:][0].startswith("obstacles") for line in known
    ):
        return []
    kept, plain, index = dict(obstacles), dict(obstacles), {}
    for key, model in (("walls", WallEntry), ("polygons", PolygonEntry)):
        entries = obstacles.get(key) or []
        if not isinstance(entries, list):
            return []
        good = []
        for i, entry in enumerate(entries):
            try:
                model.model_validate(entry, strict=True)
            except ValidationError:
                continue
            good.append(i)
        index[key], kept[key] = good, [entries[i] for i in good]
        plain[key] = [{k: v for k, v in entries[i].items() if k != "material"} for i in good]

    def as_written(match: re.Match) -> str:
        return f"obstacles.{match[1]}[{index[match[1]][int(match[2])]}]"

    more: list[str] = []
    # the entries that passed, with their materials (a material's problem), then without them (the
    # arena and free-room checks, which a material's problem would stop)
    for trial in (kept, plain):
        try:
            validate({**data, "obstacles": trial}, where, overridden, origin, every_map_problem=False)
        except ConfigError as exc:
            for line in str(exc).splitlines():
                line = re.sub(r"obstacles\.(walls|polygons)\[(\d+)\]", as_written, line)
                if "obstacles" in line and line not in known and line not in more:
                    more.append(line)
    return more


def _check_tree(exp: Experiment, scenario_cls: type[Scenario], allocator_cls: type[Allocator]) -> str | None:
    """Load the agents' behavior tree with the node set they will have, so that a bad tree stops
    the run here, before any process starts. The problem, or None."""
    path = tree_path(exp.agents.behavior_tree, scenario_cls, allocator_cls)
    if not path.is_file():
        return f"file {path} does not exist"
    try:
        load_tree(path, node_registry([scenario_cls, allocator_cls]))
    except BTError as exc:
        return str(exc)
    return None


def resolve_experiment(exp: Experiment) -> Resolved:
    """The classes and targets of a validated experiment (what the launcher hands its processes):
    those :func:`validate` resolved its names to, while its names are the same and every plugin
    file named by path is the file it checked (its digest); else resolved anew."""
    kind, name = exp.scenario.kind, exp.allocator.name
    cached = exp._resolved
    if cached is not None and cached[:2] == (kind, name):
        _, _, scenario_cls, allocator_cls, targets = cached
        if file_digests(targets.scenario, targets.allocator) == targets.digests:
            return Resolved(exp, scenario_cls, allocator_cls, targets)
    scenario, allocator = scenario_target(kind), allocator_target(name, kind)
    targets = Targets(scenario=scenario, allocator=allocator, digests=file_digests(scenario, allocator))
    return Resolved(exp, resolve_scenario(kind), resolve(name, kind), targets)


#: keys whose values may be file paths: relative ones resolve from the experiment file's folder
#: when written in the file, and from the current directory when given with ``--set``
PATH_KEYS = ("agents.behavior_tree", "allocator.name", "scenario.kind", "obstacles")


def _absolute(key: str, value: Any, base: Path) -> Any:
    """A relative path (a behavior tree, or the file of ``file.py:Class``) made absolute from ``base``."""
    if not isinstance(value, str) or value == "default":
        return value
    ref, sep, cls = value.rpartition(":") if ".py:" in value else (value, "", "")
    if sep or key in ("agents.behavior_tree", "obstacles"):
        path = Path(ref)
        try:
            return str(path if path.is_absolute() else (base / path).resolve()) + (sep + cls)
        except (OSError, RuntimeError):  # a loop of links: left as written, its reader says so in one line
            return str(base / path) + (sep + cls)
    return value


def _get_dotted(data: dict, dotted: str) -> Any:
    node: Any = data
    for k in dotted.split("."):
        if not isinstance(node, dict):
            return None
        node = node.get(k)
    return node


def load(
    path: str | Path, overrides: list[str] | tuple[str, ...] = (), seed: int | None = None, origin: str = "--set"
) -> Experiment:
    """The experiment in ``path`` with ``overrides`` (``dotted.key=value``) applied and checked; an
    error about an overridden key names it as ``<origin> key=value`` (a sweep names its scenario)."""
    path = Path(path)
    try:
        data = read_yaml(path)
    except YamlFileError as exc:
        raise ConfigError(str(exc)) from None
    if data is None:
        raise ConfigError(
            f"{path}: the file is empty; an experiment names at least its scenario or allocator "
            "(see experiments/quickstart.yaml)"
        )
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of sections")
    if "base" in data and "run" not in data:
        raise ConfigError(
            f"{path}: this is a sweep file (it names a base experiment): run it with `swarmbed sweep {path}`"
        )
    for key in PATH_KEYS:  # paths in the file are relative to the file
        value = _get_dotted(data, key)
        if value is not None:
            _set_dotted(data, key, _absolute(key, value, path.parent), str(path))
    pairs = [parse_override(text) for text in overrides]
    pairs = [(k, _absolute(k, v, Path.cwd()) if k in PATH_KEYS else v) for k, v in pairs]  # from the shell: from here
    apply_overrides(data, pairs, str(path))
    if isinstance(data.get("obstacles"), str):  # one the user typed may be anywhere; a file's stays by it
        typed = origin == "--set" and any(k == "obstacles" for k, _ in pairs)
        data["obstacles"] = _map_file(data["obstacles"], str(path), None if typed else path.parent)
    overridden: dict[str, Any] = dict(pairs)
    if seed is not None:
        _set_dotted(data, "run.seed", seed, str(path))
        overridden = {k: v for k, v in overridden.items() if k != "run.seed"} | {SEED_FLAG: seed}
    return validate(data, str(path), overridden, origin)


def _map_file(name: str, where: str, folder: Path | None) -> Any:
    """The obstacles of a map file (``obstacles: rooms.yaml``): a YAML file whose top level is the
    ``obstacles:`` section, or a mapping with that key; written into the resolved config in full.
    ``folder``: where a map named in a file must be (the experiment's folder or below), so that a
    received experiment cannot make a command read, and quote, any file of the user's; None for
    one typed with ``--set``."""
    if folder is not None:
        try:
            outside = folder.resolve(strict=True) not in Path(name).resolve(strict=True).parents
        except (OSError, RuntimeError):
            outside = False  # missing or a loop of links: the reader below says so
        if outside:
            raise ConfigError(
                f"{where}: obstacles: {name} is outside the experiment's folder {folder.resolve()}; a map file named "
                "in an experiment must be in its folder (give another with --set obstacles=PATH)"
            )
    try:
        data = read_yaml(Path(name))
    except YamlFileError as exc:
        raise ConfigError(f"{where}: obstacles: {exc}") from None
    if isinstance(data, dict) and set(data) == {"obstacles"}:
        data = data["obstacles"]
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: obstacles: {name} must hold a mapping with walls and/or polygons")
    return data


def to_yaml(exp: Experiment) -> str:
    return yaml.safe_dump(exp.model_dump(mode="json"), sort_keys=False)


def from_yaml(text: str, where: str = "<resolved config>") -> Experiment:
    try:
        data = parse_yaml(text, where)
    except YamlFileError as exc:
        raise ConfigError(str(exc)) from None
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: the top level must be a mapping of sections")
    return validate(data, where)


def _type_name(annotation: Any) -> str:
    if get_origin(annotation) is Literal:
        return " | ".join(str(a) for a in get_args(annotation))
    if isinstance(annotation, type):
        return annotation.__name__
    return str(annotation).replace("typing.", "").replace("NoneType", "null")


def describe(model: type[BaseModel], prefix: str = "") -> list[tuple[str, str, str, str]]:
    """(dotted key, type, default, meaning) of every key of ``model``, nested models walked."""
    rows: list[tuple[str, str, str, str]] = []
    for name, field in model.model_fields.items():
        ann = field.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            rows += describe(ann, f"{prefix}{name}.")
            continue
        section = [a for a in get_args(ann) if isinstance(a, type) and issubclass(a, BaseModel)]
        if section and get_origin(ann) is list:  # a list of entries (swaps): each entry's keys below
            rows.append((f"{prefix}{name}", "list", "[]", field.description or ""))
            rows += describe(section[0], f"{prefix}{name}[].")
            continue
        if section:  # an optional section (network.propagation): off unless given, its keys below
            rows.append((f"{prefix}{name}", "section | null", "null", field.description or ""))
            rows += describe(section[0], f"{prefix}{name}.")
            continue
        if field.is_required():
            default = "required"
        else:
            value = field.get_default(call_default_factory=True)
            default = json.dumps(value.model_dump(mode="json") if isinstance(value, BaseModel) else value)
        rows.append((f"{prefix}{name}", _type_name(ann), default, field.description or ""))
    return rows
