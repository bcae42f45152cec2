"""Allocators by name, like Gymnasium's environment registry.

``allocator.name`` in an experiment is either a registered name (``fcg``) or a ``module:Class``
reference, where ``module`` is an importable module or a path to a ``.py`` file, so that a user's
own algorithm needs no change to swarmbed.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from pydantic import BaseModel, ValidationError

from plugins.base import Allocator

_REGISTRY: dict[str, str] = {}


class PluginError(ValueError):
    """An allocator that cannot be found, loaded or configured."""


def register(name: str, target: str) -> None:
    """Register ``target`` (``"package.module:Class"``) under ``name``; imported only when used."""
    if name in _REGISTRY and _REGISTRY[name] != target:
        raise PluginError(f"allocator {name!r} is already registered as {_REGISTRY[name]}")
    _REGISTRY[name] = target


def names() -> list[str]:
    return sorted(_REGISTRY)


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


def resolve(name: str) -> type[Allocator]:
    target = _REGISTRY.get(name, name)
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


def validate_params(name: str, params: Mapping[str, Any]) -> BaseModel:
    cls = resolve(name)
    try:
        return cls.Params.model_validate(dict(params))
    except ValidationError as exc:
        problems = "; ".join(
            f"allocator.{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()
        )
        raise PluginError(problems) from None


def make(name: str, params: Mapping[str, Any], agent_id: int, rng: np.random.Generator,
         run_seed: int = 0) -> Allocator:
    cls = resolve(name)
    return cls(agent_id, validate_params(name, params), rng, run_seed)


register("fcg", "plugins.fcg:FirstClaimedGreedy")
register("noop", "plugins.noop:NoopAllocator")
register("cbba", "plugins.cbba:CBBA")
register("grape", "plugins.grape:GRAPE")
