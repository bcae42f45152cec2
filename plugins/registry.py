"""Allocators and scenarios by name, like Gymnasium's environment registry.

``allocator.name`` and ``scenario.kind`` in an experiment are either registered names (``fcg``,
``sar``) or targets (``module:Class``, where ``module`` is an importable module or a path to a
``.py`` file), so a user's own code needs no change to swarmbed. An allocator name may have one
implementation per scenario (``cbba`` is SPACE's CBBA in MT-SR and the CBBA-ETC paper's reactive
CBBA in search and rescue).

Other installed packages add theirs through entry points, read on first use:

- group ``swarmbed.scenarios``: ``name = "package.module:Class"``;
- group ``swarmbed.allocators``: ``name = "package.module:Class"`` for every scenario, or
  ``name@scenario = ...`` for one.

Only the launcher resolves names (``swarmbed.config``); the processes it starts load
the targets it hands them.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib.metadata import entry_points
from typing import Any

import numpy as np
from pydantic import BaseModel, ValidationError

from swarmbed.extension.allocator import Allocator
from swarmbed.extension.presets import PresetError, apply_preset
from swarmbed.extension.scenario import Scenario
from swarmbed.wire.targets import TargetError, is_target, load_target
from swarmbed.wire.validation import did_you_mean, validation_lines

ANY = "*"
ALLOCATOR_GROUP = "swarmbed.allocators"
SCENARIO_GROUP = "swarmbed.scenarios"

_ALLOCATORS: dict[str, dict[str, str]] = {}  # name -> scenario (or ANY) -> target
_SCENARIOS: dict[str, str] = {}  # name -> target
_entry_points_read = False


class PluginError(ValueError):
    """An allocator or scenario that cannot be found, loaded or configured."""


def register(name: str, target: str, scenario: str = ANY) -> None:
    """Register allocator ``target`` under ``name`` for one scenario (or all); imported only when used."""
    known = _ALLOCATORS.setdefault(name, {})
    if known.get(scenario, target) != target:
        raise PluginError(f"allocator {name!r} for scenario {scenario!r} is already registered as {known[scenario]}")
    known[scenario] = target


def register_scenario(name: str, target: str) -> None:
    """Register scenario ``target`` under ``name``; imported only when used."""
    if _SCENARIOS.get(name, target) != target:
        raise PluginError(f"scenario {name!r} is already registered as {_SCENARIOS[name]}")
    _SCENARIOS[name] = target


def _read_entry_points() -> None:
    global _entry_points_read
    if _entry_points_read:
        return
    _entry_points_read = True
    for ep in entry_points(group=SCENARIO_GROUP):
        register_scenario(ep.name, ep.value)
    for ep in entry_points(group=ALLOCATOR_GROUP):
        name, _, scenario = ep.name.partition("@")
        register(name, ep.value, scenario or ANY)


def names() -> list[str]:
    _read_entry_points()
    return sorted(_ALLOCATORS)


def entries() -> list[tuple[str, str]]:
    """(name, scenario) of every allocator registration."""
    _read_entry_points()
    return sorted((n, k) for n, kinds in _ALLOCATORS.items() for k in kinds)


def scenario_names() -> list[str]:
    _read_entry_points()
    return sorted(_SCENARIOS)


def scenario_target(kind: str) -> str:
    """The target of scenario ``kind`` (a registered name or already a target)."""
    _read_entry_points()
    if kind in _SCENARIOS:
        return _SCENARIOS[kind]
    if is_target(kind):
        return kind
    raise PluginError(
        f"unknown scenario {kind!r}{did_you_mean(kind, scenario_names())}; registered: {', '.join(scenario_names())}; "
        "or give 'module:Class' / 'path/to/file.py:Class'"
    )


def only_scenario(name: str) -> str | None:
    """The one scenario a registered allocator is implemented for, if it is for one only (``cbba-etc``:
    ``sar``); None for an allocator of any scenario, of several, or not registered."""
    _read_entry_points()
    kinds = _ALLOCATORS.get(name, {})
    return next(iter(kinds)) if len(kinds) == 1 and ANY not in kinds else None


def allocator_target(name: str, scenario: str | None = None) -> str:
    """The target of allocator ``name`` for ``scenario`` (a registered name or already a target)."""
    _read_entry_points()
    kinds = _ALLOCATORS.get(name)
    if not kinds:
        if is_target(name):
            return name
        raise PluginError(
            f"unknown allocator {name!r}{did_you_mean(name, names())}; registered: {', '.join(names())}; "
            "or give 'module:Class' / 'path/to/file.py:Class'"
        )
    if scenario is None:
        return kinds.get(ANY) or kinds[sorted(kinds)[0]]
    target = kinds.get(scenario, kinds.get(ANY))
    if target is None:
        raise PluginError(
            f"allocator {name!r} has no implementation for scenario {scenario!r} (it has: {', '.join(sorted(kinds))})"
        )
    return target


def resolve(name: str, scenario: str | None = None) -> type[Allocator]:
    try:
        return load_target(allocator_target(name, scenario), Allocator)
    except TargetError as exc:
        raise PluginError(f"allocator {name!r}: {exc}") from None


def resolve_scenario(kind: str) -> type[Scenario]:
    try:
        return load_target(scenario_target(kind), Scenario)
    except TargetError as exc:
        raise PluginError(f"scenario {kind!r}: {exc}") from None


def registered_scenario(kind: object, trusted: bool = False) -> type[Scenario]:
    """The scenario class registered as ``kind`` (here or by an entry point), for readers of results:
    a run or sweep folder is data that anyone may have crafted, so the name it holds is looked up among
    the registered names only, never imported as a target; for any other name (a user's own
    ``module:Class``, a name registered elsewhere, garbage) the generic :class:`Scenario`, whose views
    still table every run. ``trusted``: the user vouches for the folder (``--trust-plugins``): a
    target it names is imported too."""
    _read_entry_points()
    target = _SCENARIOS.get(kind) if isinstance(kind, str) else None
    if target is None and trusted and isinstance(kind, str) and is_target(kind):
        target = kind
    if target is None:
        return Scenario
    try:
        return load_target(target, Scenario)
    except TargetError:
        return Scenario


def check_params(model: type[BaseModel], params: Mapping[str, Any], section: str) -> BaseModel:
    """``params`` validated by a plugin's ``Params``, the preset they name filled in first.
    Validated laxly (YAML lists become tuples where a field is a tuple), then refused where lax
    validation changed a value's kind: ``true`` read as 1, ``'3'`` as 3, ``'false'`` as False are
    errors here as they are in every other section."""
    try:
        params = apply_preset(model, params, section)
    except PresetError as exc:
        raise PluginError(str(exc)) from None
    try:
        checked = model.model_validate(dict(params))
    except ValidationError as exc:
        raise PluginError("\n".join(validation_lines(exc, model, prefix=section))) from None
    loose = _loose(dict(params), checked, section)
    if loose:
        raise PluginError("\n".join(loose))
    return checked


def _loose(given: Any, made: Any, where: str) -> list[str]:
    """Where validation turned ``given`` into a value of another kind (bool to number, text to
    number or bool): one line each."""
    if isinstance(given, bool):
        return [] if isinstance(made, bool) else [f"{where}: {given!r} is a boolean; write a number"]
    if isinstance(given, str):
        if isinstance(made, (bool, int, float)):
            return [f"{where}: {given!r} is text; write a {'boolean' if isinstance(made, bool) else 'number'}"]
        return []
    if isinstance(given, Mapping):
        out = []
        for key, value in given.items():
            inner = made.get(key) if isinstance(made, Mapping) else getattr(made, str(key), None)
            out += _loose(value, inner, f"{where}.{key}")
        return out
    if isinstance(given, (list, tuple)) and isinstance(made, (list, tuple)) and len(given) == len(made):
        return [
            line for i, (g, m) in enumerate(zip(given, made, strict=True)) for line in _loose(g, m, f"{where}[{i}]")
        ]
    return []


def validate_params(name: str, params: Mapping[str, Any], scenario: str | None = None) -> BaseModel:
    return check_params(resolve(name, scenario).Params, params, "allocator")


def validate_scenario_params(kind: str, params: Mapping[str, Any]) -> BaseModel:
    return check_params(resolve_scenario(kind).Params, params, "scenario")


def make(
    name: str,
    params: Mapping[str, Any],
    agent_id: int,
    rng: np.random.Generator,
    run_seed: int = 0,
    scenario: str | None = None,
) -> Allocator:
    """An allocator instance outside a run (tests, the conformance kit)."""
    cls = resolve(name, scenario)
    return cls(agent_id, validate_params(name, params, scenario), rng, run_seed)


register_scenario("mtsr", "swarmbed.scenarios.mtsr:MTSR")
register_scenario("sar", "swarmbed.scenarios.sar:SAR")

register("fcg", "swarmbed.plugins.fcg:FirstClaimedGreedy", "mtsr")
register("noop", "swarmbed.plugins.noop:NoopAllocator")
register("nearest", "swarmbed.plugins.nearest:NearestTask")
register("ros2", "swarmbed.plugins.external:Ros2Allocator")
register("external", "swarmbed.plugins.external:ExternalAllocator")
register("cbba", "swarmbed.plugins.cbba:CBBA", "mtsr")
register("grape", "swarmbed.plugins.grape:GRAPE", "mtsr")
# centralized baselines: a leader solves the assignment from what reaches it over the radio
register("sga", "swarmbed.plugins.central:SGA", "mtsr")
register("hungarian", "swarmbed.plugins.central:Hungarian", "mtsr")
register("central-grape", "swarmbed.plugins.central:CentralGRAPE", "mtsr")
# the six coordination strategies of the CBBA-ETC evaluation (search and rescue)
register("tree", "swarmbed.plugins.sar.reactive:TreeStrategy", "sar")
register("comm", "swarmbed.plugins.sar.reactive:CommStrategy", "sar")
register("cbba", "swarmbed.plugins.sar.reactive_cbba:ReactiveCBBA", "sar")
register("cbba-tree", "swarmbed.plugins.sar.reactive_cbba:CBBATree", "sar")
register("cbba-etc", "swarmbed.plugins.sar.reactive_cbba:CBBAETC", "sar")
register("c-cbba", "swarmbed.plugins.sar.ccbba:ClusteringCBBA", "sar")
