"""An agent's behavior tree as Groot2 sees it: the tree's XML with BehaviorTree.CPP's node uids,
and the status changes of every tick (the file format and the wire sample: :mod:`swarmbed.wire.btlog`)."""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from swarmbed.bt.blackboard import Blackboard
from swarmbed.bt.node import ControlNode, DecoratorNode, TreeNode
from swarmbed.bt.node_types import BUILTIN_TYPES
from swarmbed.bt.palette import model_lines
from swarmbed.bt.status import Status
from swarmbed.bt.tree import SubTree, Tree
from swarmbed.wire.btlog import MAX_ENTRIES, MAX_ITEMS, MAX_TEXT, BlackboardValue

STATUS_CODE = {Status.IDLE: 0, Status.RUNNING: 1, Status.SUCCESS: 2, Status.FAILURE: 3}


def tree_xml(tree: Tree) -> str:
    """The tree as BehaviorTree.CPP's WriteTreeToXML shows it to Groot2: the main tree, then every
    SubTree instance as its own BehaviorTree (by ``_fullpath``), nodes with ``name`` and ``_uid``,
    then the models of the node types that BehaviorTree.CPP does not ship."""
    lines = ['<root BTCPP_format="4">']
    trees: list[tuple[str, str, TreeNode]] = [("", tree.main_id or "MainTree", tree.root)]
    for node in tree.nodes:
        if isinstance(node, SubTree):
            trees.append((node.fullpath, node.tree_id, node.child))
    for fullpath, tree_id, root in trees:
        lines.append(f"    <BehaviorTree ID={quoteattr(tree_id)} _fullpath={quoteattr(fullpath)}>")
        _node_lines(root, "        ", lines)
        lines.append("    </BehaviorTree>")
    builtin = {t.ID for t in BUILTIN_TYPES} | {SubTree.ID}
    custom = {type(n).ID: type(n) for n in tree.nodes if type(n).ID not in builtin}
    lines += model_lines([custom[i] for i in sorted(custom)], "    ")
    lines.append("</root>")
    return "\n".join(lines) + "\n"


def _node_lines(node: TreeNode, indent: str, lines: list[str]) -> None:
    if isinstance(node, SubTree):
        attrs = f"ID={quoteattr(node.tree_id)} _fullpath={quoteattr(node.fullpath)} _uid={quoteattr(str(node.uid))}"
        lines.append(f"{indent}<SubTree {attrs}/>")
        return
    ports = "".join(f" {k}={quoteattr(v)}" for k, v in node.config.ports.items())
    head = f"{indent}<{type(node).ID} name={quoteattr(node.name)}{ports} _uid={quoteattr(str(node.uid))}"
    children = node.children() if isinstance(node, ControlNode | DecoratorNode) else []
    if not children:
        lines.append(head + "/>")
        return
    lines.append(head + ">")
    for child in children:
        _node_lines(child, indent + "    ", lines)
    lines.append(f"{indent}</{type(node).ID}>")


class ChangeRecorder:
    """Collects a tree's status changes as ``(uid, status code)``, in the order they happen;
    :meth:`take` hands over those of the last tick."""

    def __init__(self, tree: Tree) -> None:
        self.changes: list[tuple[int, int]] = []
        tree.watch(self._heard)

    def _heard(self, node: TreeNode, _prev: Status, new: Status) -> None:
        self.changes.append((node.uid, STATUS_CODE[new]))

    def take(self) -> list[tuple[int, int]]:
        changes, self.changes = self.changes, []
        return changes


def shown_value(value: object) -> BlackboardValue:
    """A blackboard value as Groot2 is shown it: numbers and text as they are (a bool as 1 or 0, as
    BehaviorTree.CPP stores it), a short list or tuple of those as a list, anything else nil
    (BehaviorTree.CPP, too, shows an entry of a type it cannot export as null)."""
    if isinstance(value, bool | np.bool_):
        return int(value)
    if isinstance(value, int | np.integer):
        return int(value) if -(2**63) <= value < 2**64 else None
    if isinstance(value, float | np.floating):
        return float(value)
    if isinstance(value, str):
        return value if len(value) <= MAX_TEXT else None
    if isinstance(value, list | tuple) and len(value) <= MAX_ITEMS:
        items = [shown_value(v) for v in value]
        scalars = [v for v in items if not isinstance(v, list)]
        return scalars if len(scalars) == len(items) else None
    return None


def tree_blackboards(tree: Tree) -> list[tuple[str, Blackboard]]:
    """Every blackboard of the tree by the name Groot2 asks for it: the main tree's ID, then each
    SubTree instance's ``_fullpath``."""
    out = [(tree.main_id or "MainTree", tree.blackboard)]
    out += [(n.fullpath, n.config.blackboard) for n in tree.nodes if isinstance(n, SubTree)]
    return out


class BlackboardWatch:
    """What Groot2 sees of a tree's blackboards: :meth:`take` gives those whose content changed
    since the last call (all of them the first time), each whole, nil if it holds nothing."""

    def __init__(self, tree: Tree) -> None:
        self.boards = tree_blackboards(tree)
        self.last: dict[str, dict[str, BlackboardValue] | None] = {}

    def take(self, everything: bool = False) -> dict[str, dict[str, BlackboardValue] | None]:
        changed = {}
        for name, board in self.boards:
            shown = {k: shown_value(v) for k, v in sorted(board.items().items())[:MAX_ENTRIES]} or None
            if everything or name not in self.last or self.last[name] != shown:
                changed[name] = self.last[name] = shown
        return changed
