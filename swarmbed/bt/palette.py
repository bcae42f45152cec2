"""Groot2 palette: a ``<TreeNodesModel>`` describing every custom node and its ports."""

from __future__ import annotations

from collections.abc import Iterable
from xml.sax.saxutils import escape, quoteattr

from swarmbed.bt.node import TreeNode
from swarmbed.bt.node_types import NodeRegistry

_PORT_TAG = {"input": "input_port", "output": "output_port", "inout": "inout_port"}
_TYPE_NAME = {str: "std::string", int: "int", float: "double", bool: "bool"}


def palette_xml(registry: NodeRegistry) -> str:
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', '<root BTCPP_format="4">']
    lines += model_lines(registry.custom(), "  ")
    lines += ["</root>"]
    return "\n".join(lines) + "\n"


def model_lines(node_types: Iterable[type[TreeNode]], indent: str) -> list[str]:
    """The ``<TreeNodesModel>`` element of ``node_types``, one line per XML line."""
    lines = [f"{indent}<TreeNodesModel>"]
    inner = indent * 2
    for node_type in node_types:
        ports = node_type.provided_ports()
        kind = node_type.KIND if node_type.KIND != "SubTree" else "Decorator"
        if not ports:
            lines.append(f"{inner}<{kind} ID={quoteattr(node_type.ID)}/>")
            continue
        lines.append(f"{inner}<{kind} ID={quoteattr(node_type.ID)}>")
        for name, spec in ports.items():
            attrs = f"name={quoteattr(name)} type={quoteattr(_TYPE_NAME.get(spec.type, spec.type.__name__))}"
            if spec.default is not None:
                attrs += f" default={quoteattr(spec.default)}"
            tag = _PORT_TAG[spec.direction]
            lines.append(f"{inner}{indent}<{tag} {attrs}>{escape(spec.description)}</{tag}>")
        lines.append(f"{inner}</{kind}>")
    lines.append(f"{indent}</TreeNodesModel>")
    return lines
