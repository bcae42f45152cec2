"""A pydantic ValidationError in the words a user of the YAML reads, one line per error: the one place
that turns one into a message (experiments, sweeps, chaos plans and plugin parameters alike)."""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from typing import Any, get_args

from pydantic import BaseModel, ValidationError


def _message(error: Any, model: type[BaseModel] | None = None) -> str:
    """A validation error in words a user of the YAML reads: never an internal class name nor
    pydantic's own prefix. ``model``: the top model, to name the closest known key for an unknown one."""
    if error["type"] == "extra_forbidden":
        near = _closest_key(model, tuple(error["loc"])) if model is not None else None
        return "unknown key" + (f" (did you mean {near!r}?)" if near else "")
    if error["type"] in ("model_type", "dict_type", "model_attributes_type"):
        given = error["input"]  # text is not quoted back: it may be any file's content (a map file)
        return "must be a section (a mapping of keys), not " + ("text" if isinstance(given, str) else repr(given))
    if error["type"] == "value_error" and "error" in error.get("ctx", {}):
        return str(error["ctx"]["error"])  # a validator's own words, without "Value error, "
    return str(error["msg"])


def did_you_mean(given: str, known: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the name in ``known`` closest to ``given`` (difflib's ratio), or ''."""
    near = difflib.get_close_matches(str(given), list(known), n=1, cutoff=0.6)
    return f" (did you mean {near[0]!r}?)" if near else ""


def _closest_key(model: type[BaseModel], loc: tuple) -> str | None:
    """The dotted key nearest to the unknown ``loc`` among its section's keys (difflib's ratio)."""
    for part in loc[:-1]:
        field = model.model_fields.get(str(part))
        if field is None:
            return None
        nested = [a for a in (field.annotation, *get_args(field.annotation)) if isinstance(a, type)]
        models = [a for a in nested if issubclass(a, BaseModel)]
        if not models:
            return None
        model = models[0]
    near = difflib.get_close_matches(str(loc[-1]), list(model.model_fields), n=1, cutoff=0.6)
    return ".".join([*map(str, loc[:-1]), near[0]]) if near else None


def validation_lines(exc: ValidationError, model: type[BaseModel] | None = None, prefix: str = "") -> list[str]:
    """Each error of ``exc`` as ``dotted.key: message`` (a model-level error: its message alone, which
    names its keys), every key under ``prefix`` (``allocator``: a plugin's own parameters)."""
    lines = []
    for e in exc.errors():
        where = ".".join([*([prefix] if prefix else []), *(str(p) for p in e["loc"])])
        lines.append(f"{where}: {_message(e, model)}" if where else _message(e, model))
    return lines
