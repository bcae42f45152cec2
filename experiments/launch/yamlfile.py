"""Reading the YAML files users hand us (experiments, sweeps, chaos plans), as hostile input.

A file is capped in size before it is read, must be UTF-8 text, and is parsed by libyaml's safe
loader where PyYAML has it (pure-Python PyYAML spends minutes on a few megabytes). Aliases are
refused (a sweep file of a few hundred bytes of nested aliases expands tenfold per level), and so
is nesting deeper than any experiment needs. Every failure is one line naming the file and, where
the parser knows it, the line.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

#: larger than any experiment, sweep or chaos file we know of by two orders of magnitude
MAX_YAML_BYTES = 1 << 20
MAX_DEPTH = 32

_Loader: type = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class YamlFileError(ValueError):
    """A file that is not acceptable YAML; the message is one line naming the file."""


def _where(path: str, mark: Any) -> str:
    return f"{path}, line {mark.line + 1}" if mark is not None else path


def parse_yaml(text: str, where: str) -> Any:
    """``text`` parsed safely: no aliases, nesting at most :data:`MAX_DEPTH` deep."""
    try:
        depth = 0
        for event in yaml.parse(text, Loader=_Loader):
            if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None):
                raise YamlFileError(
                    f"{_where(where, event.start_mark)}: YAML anchors and aliases (&name, *name) "
                    "are not accepted; write the values out"
                )
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                depth += 1
                if depth > MAX_DEPTH:
                    raise YamlFileError(f"{_where(where, event.start_mark)}: nested more than {MAX_DEPTH} levels deep")
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                depth -= 1
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - a safe loader (C or Python)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise YamlFileError(f"{_where(where, mark)}: not valid YAML: {problem}") from None


def read_yaml(path: str | Path, max_bytes: int = MAX_YAML_BYTES) -> Any:
    """The YAML document in ``path``; a :class:`YamlFileError` says what is wrong in one line."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise YamlFileError(f"{path}: {size:,} bytes, larger than the {max_bytes:,} a YAML file may have")
        raw = path.read_bytes()
    except OSError as exc:
        raise YamlFileError(f"{path}: cannot read: {exc.strerror}") from None
    if b"\0" in raw:
        raise YamlFileError(f"{path}: a binary file, not YAML text")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise YamlFileError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    return parse_yaml(text, str(path))


def non_finite(data: Any, prefix: str = "") -> list[str]:
    """Dotted keys of every infinite or NaN number in ``data`` (``.inf``, ``.nan`` in YAML)."""
    if isinstance(data, float) and not math.isfinite(data):
        return [prefix or "<value>"]
    if isinstance(data, dict):
        return [k for key, v in data.items() for k in non_finite(v, f"{prefix}.{key}" if prefix else str(key))]
    if isinstance(data, list):
        return [k for i, v in enumerate(data) for k in non_finite(v, f"{prefix}[{i}]")]
    return []
