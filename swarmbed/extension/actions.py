"""A scenario's actions: the names an agent may send each tick and the types of their arguments.

An action travels as a list, ``[name, *arguments]`` (``["goto", 12.5, 40.0]``). A scenario declares
its vocabulary in ``Scenario.actions``; the coordinator checks every action an agent sent against
it before the world sees it, and hands the world :data:`INVALID` for one that does not conform (an
unknown name, the wrong number of arguments, an argument of the wrong type, a coordinate that is
not finite), which the world counts as it counts any action it cannot carry out. So a world reads
its actions' arguments without checking their shapes again, and a crafted action cannot put a
NaN into the world's positions.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

#: name -> the types of its arguments; ``float`` accepts any finite real number, ``int`` an integer
ActionSpec = Mapping[str, tuple[type, ...]]

#: moving and choosing a task: what SPACE's nodes send (``stop``, ``goto x y``, ``goto_task id``)
MOVE_ACTIONS: ActionSpec = {"stop": (), "halt": (), "goto": (float, float), "goto_task": (int,)}

#: what a world is given in place of an action that does not conform to its scenario's declaration
INVALID: list = ["invalid"]


def _is(value: Any, kind: type) -> bool:
    if kind is float:
        return isinstance(value, (int, float)) and math.isfinite(value)
    return isinstance(value, kind)


def conforms(action: Any, spec: ActionSpec) -> bool:
    """Whether ``action`` is ``[name, *arguments]`` with a declared name and arguments of its types."""
    if not isinstance(action, list) or not action or not isinstance(action[0], str):
        return False
    kinds = spec.get(action[0])
    if kinds is None or len(action) != 1 + len(kinds):
        return False
    return all(_is(value, kind) for value, kind in zip(action[1:], kinds))


def admit(action: Any, spec: ActionSpec) -> list:
    """``action`` where it conforms to ``spec``, else :data:`INVALID`: what a world is handed."""
    return action if conforms(action, spec) else INVALID
