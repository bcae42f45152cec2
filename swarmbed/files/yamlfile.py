"""Reading the YAML files users hand us (experiments, sweeps, chaos plans), as hostile input.

A file is capped in size before it is read, must be UTF-8 text, and is parsed by libyaml's safe
loader where PyYAML has it (pure-Python PyYAML spends minutes on a few megabytes). Aliases are
refused (a sweep file of a few hundred bytes of nested aliases expands tenfold per level), and so
is nesting deeper than any experiment needs. A key given twice in one mapping is refused (PyYAML
would keep the last silently: a second ``run:`` section would replace the first whole). Scalars are
typed as YAML 1.2's core schema types them, not as PyYAML's YAML 1.1: ``010`` is 10 (not 8),
``1:00`` is text (not 60), ``1e-1`` is a number, and only ``true``/``false`` are booleans (``yes``,
``on`` are text). Every failure is one line naming the file and, where the parser knows it, the line.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import yaml

from swarmbed.files.safefiles import UnreadableFile, read_regular

#: larger than any experiment, sweep or chaos file we know of by two orders of magnitude
MAX_YAML_BYTES = 1 << 20
MAX_DEPTH = 32

_Base: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

# YAML 1.2 core schema (https://yaml.org/spec/1.2.2/#1032-tag-resolution)
_BOOL = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_INT = re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$")
_FLOAT = re.compile(
    r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"
)
_CORE = {"tag:yaml.org,2002:bool": _BOOL, "tag:yaml.org,2002:int": _INT, "tag:yaml.org,2002:float": _FLOAT}


class _Loader(_Base):
    """The safe loader with YAML 1.2's core scalar types and duplicate keys refused."""

    yaml_implicit_resolvers = {
        first: [(tag, rx) for tag, rx in resolvers if tag not in _CORE]
        for first, resolvers in _Base.yaml_implicit_resolvers.items()
    }

    def construct_mapping(self, node: Any, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, Any] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                hash(key)
            except TypeError:
                raise YamlFileError(f"line {key_node.start_mark.line + 1}: a key must be a plain value") from None
            if key in seen:
                raise YamlFileError(
                    f"line {key_node.start_mark.line + 1}: key {key!r} is given twice in one mapping "
                    f"(first on line {seen[key] + 1}); keep one"
                )
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


def _construct_int(loader: Any, node: Any) -> int:
    text = loader.construct_scalar(node)
    if text.startswith("0o"):
        return int(text[2:], 8)
    if text.startswith("0x"):
        return int(text[2:], 16)
    return int(text, 10)


def _construct_float(loader: Any, node: Any) -> float:
    text = loader.construct_scalar(node).lower()
    if text.endswith(".inf"):
        return -math.inf if text.startswith("-") else math.inf
    return math.nan if text == ".nan" else float(text)


for _tag, _rx in _CORE.items():
    _Loader.add_implicit_resolver(_tag, _rx, list("-+0123456789.tTfF"))
_Loader.add_constructor("tag:yaml.org,2002:int", _construct_int)
_Loader.add_constructor("tag:yaml.org,2002:float", _construct_float)
_Loader.add_constructor("tag:yaml.org,2002:bool", lambda loader, node: loader.construct_scalar(node).lower() == "true")


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
    except YamlFileError as exc:  # raised while constructing: it knows the line, not the file
        raise YamlFileError(f"{where}, {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise YamlFileError(f"{_where(where, mark)}: not valid YAML: {problem}") from None


def read_yaml(path: str | Path, max_bytes: int = MAX_YAML_BYTES) -> Any:
    """The YAML document in ``path``; a :class:`YamlFileError` says what is wrong in one line."""
    path = Path(path)
    try:
        raw = read_regular(path, max_bytes)
    except UnreadableFile as exc:
        raise YamlFileError(str(exc)) from None
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
