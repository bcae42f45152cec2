"""Allocators by name, like Gymnasium's environment registry.

``allocator.name`` in an experiment is either a registered name (``fcg``) or a ``module:Class``
reference, where ``module`` is an importable module or a path to a ``.py`` file, so that a user's
own algorithm needs no change to swarmbed. A name may have one implementation per scenario kind
(``cbba`` is SPACE's CBBA in MT-SR and the CBBA-ETC paper's reactive CBBA in search and rescue).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from pydantic import BaseModel, ValidationError

from swarmbed.plugins.base import Allocator

ANY = "*"
_REGISTRY: dict[str, dict[str, str]] = {}  # name -> scenario kind (or ANY) -> "module:Class"


class PluginError(ValueError):
    """An allocator that cannot be found, loaded or configured."""


def register(name: str, target: str, scenario: str = ANY) -> None:
    """Register ``target`` (``"package.module:Class"``) under ``name`` for one scenario kind (or
    all); imported only when used."""
    known = _REGISTRY.setdefault(name, {})
    if known.get(scenario, target) != target:
        raise PluginError(f"allocator {name!r} is already registered as {known[scenario]}")
    known[scenario] = target


def names() -> list[str]:
    return sorted(_REGISTRY)


def entries() -> list[tuple[str, str]]:
    """(name, scenario kind) of every registration."""
    return sorted((n, k) for n, kinds in _REGISTRY.items() for k in kinds)


def _import_module(ref: str):
    if ref.endswith(".py"):
        path = Path(ref).resolve()
        if not path.is_file():
            raise PluginError(f"plugin file {ref} does not exist")
        mod_name = f"swarmbed_user_plugin_{path.stem}"
        if mod_name in sys.modules:
            return sys.modules[mod_name]
        spec = importlib.util.spec_from_file_location(mod_name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[mod_name] = module
        spec.loader.exec_module(module)
        return module
    return importlib.import_module(ref)


def resolve(name: str, scenario: str | None = None) -> type[Allocator]:
    kinds = _REGISTRY.get(name, {})
    if kinds and scenario is not None and scenario not in kinds and ANY not in kinds:
        raise PluginError(f"allocator {name!r} has no implementation for scenario {scenario!r} "
                          f"(it has: {', '.join(sorted(kinds))})")
    target = kinds.get(scenario, kinds.get(ANY)) if kinds else name
    if target is None:  # no scenario given: the only (or first) implementation
        target = kinds[sorted(kinds)[0]]
    if ":" not in target:
        raise PluginError(f"unknown allocator {name!r}; registered: {', '.join(names())}; "
                          "or give 'module:Class' / 'path/to/file.py:Class'")
    module_ref, _, cls_name = target.rpartition(":")
    try:
        module = _import_module(module_ref)
    except ImportError as exc:
        raise PluginError(f"cannot import allocator module {module_ref!r}: {exc}") from exc
    cls = getattr(module, cls_name, None)
    if not (isinstance(cls, type) and issubclass(cls, Allocator)):
        raise PluginError(f"{target} is not an Allocator subclass")
    return cls


def validate_params(name: str, params: Mapping[str, Any], scenario: str | None = None) -> BaseModel:
    cls = resolve(name, scenario)
    try:
        return cls.Params.model_validate(dict(params))
    except ValidationError as exc:
        problems = "; ".join(
            f"allocator.{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()
        )
        raise PluginError(problems) from None


def make(name: str, params: Mapping[str, Any], agent_id: int, rng: np.random.Generator,
         run_seed: int = 0, scenario: str | None = None) -> Allocator:
    cls = resolve(name, scenario)
    return cls(agent_id, validate_params(name, params, scenario), rng, run_seed)


register("fcg", "swarmbed.plugins.fcg:FirstClaimedGreedy", "mtsr")
register("noop", "swarmbed.plugins.noop:NoopAllocator")
register("cbba", "swarmbed.plugins.cbba:CBBA", "mtsr")
register("grape", "swarmbed.plugins.grape:GRAPE", "mtsr")
# the six coordination strategies of the CBBA-ETC evaluation (search and rescue)
register("tree", "swarmbed.plugins.sar.reactive:TreeStrategy", "sar")
register("comm", "swarmbed.plugins.sar.reactive:CommStrategy", "sar")
register("cbba", "swarmbed.plugins.sar.consensus:ReactiveCBBA", "sar")
register("cbba-tree", "swarmbed.plugins.sar.consensus:CBBATree", "sar")
register("cbba-etc", "swarmbed.plugins.sar.consensus:CBBAETC", "sar")
register("c-cbba", "swarmbed.plugins.sar.ccbba:ClusteringCBBA", "sar")
