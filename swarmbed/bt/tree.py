"""A loaded tree, the SubTree node, and the BehaviorTree.CPP v4 XML loader.

Every load error names the file, the line and the node, e.g.
``trees/main.xml:7 <DecisionMakingNode>: unknown port 'taks' (ports: task_id)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.parsers import expat

from swarmbed.bt.blackboard import Blackboard
from swarmbed.bt.node import (
    BTError,
    ControlNode,
    DecoratorNode,
    NodeConfig,
    Port,
    StatusWatcher,
    TreeNode,
    blackboard_key,
    convert_port,
    watch_node,
)
from swarmbed.bt.node_types import NodeRegistry
from swarmbed.bt.status import FAILURE, IDLE, RUNNING, SUCCESS, Status
from swarmbed.files.safefiles import UnreadableFile, read_regular
from swarmbed.wire.validation import did_you_mean

#: the most a behavior tree file may hold (Groot2's largest example trees are a few kB)
MAX_TREE_BYTES = 4 << 20

GENERIC_TAGS = ("Action", "Condition", "Control", "Decorator")
SPECIAL_ATTRS = ("name", "ID")


class SubTree(DecoratorNode):
    """Runs another BehaviorTree with its own (remapped) blackboard."""

    ID = "SubTree"
    KIND = "SubTree"
    tree_id = ""  # the BehaviorTree it runs
    fullpath = ""  # Groot2's name of this instance: parent instances' paths, then its name or ID::uid

    def tick(self) -> Status:
        if self.status is IDLE:
            self.status = RUNNING
        s = self.child.execute_tick()
        if s is SUCCESS or s is FAILURE:
            self.reset_child()
        return s


class Tree:
    def __init__(self, root: TreeNode, blackboard: Blackboard, nodes: list[TreeNode], main_id: str = "") -> None:
        self.root = root
        self.blackboard = blackboard
        self.nodes = nodes  # in the order they were built: node.uid is its place here, from 1
        self.main_id = main_id  # the BehaviorTree ID it runs

    def tick_once(self) -> Status:
        """Tick the root exactly once (BT.CPP ``tickExactlyOnce``)."""
        status = self.root.execute_tick()
        if status is SUCCESS or status is FAILURE:
            self.root.reset_status()
        return status

    def halt(self) -> None:
        self.root.halt()

    def watch(self, watcher: StatusWatcher | None) -> None:
        """Hand every node's status changes to ``watcher`` (None: to no one)."""
        for node in self.nodes:
            watch_node(node, watcher)


@dataclass
class _Element:
    tag: str
    attrs: dict[str, str]
    line: int
    children: list[_Element] = field(default_factory=list)


def _parse(text: str, where: str) -> _Element:
    parser = expat.ParserCreate()
    top = _Element("#document", {}, 0)
    stack = [top]

    def start(tag, attrs):
        el = _Element(tag, dict(attrs), parser.CurrentLineNumber)
        stack[-1].children.append(el)
        stack.append(el)

    def end(_tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as exc:
        raise BTError(f"{where}:{exc.lineno}: malformed XML: {expat.ErrorString(exc.code)}") from None
    if len(top.children) != 1:
        raise BTError(f"{where}: expected one <root> element")
    return top.children[0]


class _Builder:
    def __init__(self, where: str, trees: dict[str, _Element], registry: NodeRegistry, context: Any) -> None:
        self.where = where
        self.trees = trees
        self.registry = registry
        self.context = context
        self.nodes: list[TreeNode] = []
        self.path = ""  # the SubTree instance being built (its fullpath), "" in the main tree

    def here(self, el: _Element, node_id: str | None = None) -> str:
        name = el.attrs.get("name")
        label = node_id or el.tag
        return f"{self.where}:{el.line} <{label}{f' name={name!r}' if name else ''}>"

    def build_tree(self, tree_id: str, bb: Blackboard, chain: tuple[str, ...]) -> TreeNode:
        el = self.trees[tree_id]
        if len(el.children) != 1:
            raise BTError(f"{self.where}:{el.line} <BehaviorTree ID={tree_id!r}>: must have exactly one root node")
        return self.build(el.children[0], bb, chain + (tree_id,))

    def build(self, el: _Element, bb: Blackboard, chain: tuple[str, ...]) -> TreeNode:
        tag = el.tag
        if tag == "SubTree":
            return self.build_subtree(el, bb, chain)
        node_id = el.attrs.get("ID") if tag in GENERIC_TAGS else tag
        if not node_id:
            raise BTError(f"{self.here(el)}: <{tag}> needs an ID attribute")
        node_type = self.registry.get(node_id)
        if node_type is None:
            hint = did_you_mean(node_id, self.registry.ids())
            raise BTError(f"{self.here(el, node_id)}: unknown node type '{node_id}'{hint}")
        where = self.here(el, node_id)
        ports = node_type.provided_ports()
        raw: dict[str, str] = {}
        for attr, value in el.attrs.items():
            if attr in SPECIAL_ATTRS:
                continue
            if attr.startswith("_"):
                raise BTError(f"{where}: attribute '{attr}' is not supported by this engine")
            if attr not in ports:
                known = ", ".join(sorted(ports)) or "none"
                raise BTError(f"{where}: unknown port '{attr}' (ports: {known})")
            raw[attr] = value
        for pname, spec in ports.items():
            if pname not in raw and spec.required:
                raise BTError(f"{where}: required port '{pname}' is missing")
            if pname in raw:
                _check_port_value(where, pname, spec, raw[pname])
        node = node_type(el.attrs.get("name", node_id), NodeConfig(bb, raw, where, self.context))
        self._add(node)
        n = len(el.children)
        if isinstance(node, ControlNode):
            if n < node.MIN_CHILDREN:
                raise BTError(f"{where}: a control node needs at least one child")
            for child in el.children:
                node.add_child(self.build(child, bb, chain))
        elif isinstance(node, DecoratorNode):
            if n != 1:
                raise BTError(f"{where}: a decorator needs exactly one child, found {n}")
            node.add_child(self.build(el.children[0], bb, chain))
        elif n:
            raise BTError(f"{where}: a leaf node cannot have children")
        return node

    def build_subtree(self, el: _Element, parent_bb: Blackboard, chain: tuple[str, ...]) -> TreeNode:
        where = self.here(el, "SubTree")
        tree_id = el.attrs.get("ID")
        if not tree_id:
            raise BTError(f"{where}: <SubTree> needs an ID attribute")
        if tree_id not in self.trees:
            raise BTError(f"{where}: no <BehaviorTree ID={tree_id!r}> in this file")
        if tree_id in chain:
            raise BTError(f"{where}: SubTree {tree_id!r} includes itself ({' -> '.join(chain + (tree_id,))})")
        if el.children:
            raise BTError(f"{where}: <SubTree> cannot have children")
        autoremap = el.attrs.get("_autoremap", "false").strip().lower()
        if autoremap not in ("true", "false", "1", "0"):
            raise BTError(f"{where}: _autoremap must be true or false")
        remap: dict[str, str] = {}
        literals: dict[str, str] = {}
        for attr, value in el.attrs.items():
            if attr in SPECIAL_ATTRS or attr == "_autoremap":
                continue
            if attr.startswith("_"):
                raise BTError(f"{where}: attribute '{attr}' is not supported by this engine")
            key = blackboard_key(value, attr)
            if key is None:
                literals[attr] = value
            else:
                remap[attr] = key
        bb = Blackboard(parent_bb, remap, autoremap in ("true", "1"))
        for k, v in literals.items():
            bb.set(k, v)
        node = SubTree(el.attrs.get("name", tree_id), NodeConfig(bb, {}, where, self.context))
        self._add(node)
        outer = self.path
        own = el.attrs.get("name", f"{tree_id}::{node.uid}")
        node.tree_id, node.fullpath = tree_id, f"{outer}/{own}" if outer else own
        self.path = node.fullpath
        try:
            node.add_child(self.build_tree(tree_id, bb, chain))
        finally:
            self.path = outer
        return node

    def _add(self, node: TreeNode) -> None:
        self.nodes.append(node)
        node.uid = len(self.nodes)


def load_tree(
    source: str | Path,
    registry: NodeRegistry,
    *,
    text: str | None = None,
    blackboard: Blackboard | None = None,
    context: Any = None,
    main: str | None = None,
) -> Tree:
    """Load a tree from a file (or from ``text``, with ``source`` naming it in errors)."""
    where = str(source)
    if text is None:
        try:
            text = read_regular(source, MAX_TREE_BYTES).decode("utf-8")
        except UnreadableFile as exc:
            raise BTError(f"{exc}") from None
        except UnicodeDecodeError as exc:
            raise BTError(f"{where}: not UTF-8 text (byte {exc.start})") from None
    root = _parse(text, where)
    if root.tag != "root":
        raise BTError(f"{where}:{root.line}: the top element must be <root>, not <{root.tag}>")
    fmt = root.attrs.get("BTCPP_format")
    if fmt != "4":
        raise BTError(f'{where}:{root.line}: <root BTCPP_format="4"> required (found {fmt!r})')
    trees: dict[str, _Element] = {}
    for el in root.children:
        if el.tag == "BehaviorTree":
            tid = el.attrs.get("ID")
            if not tid:
                raise BTError(f"{where}:{el.line}: <BehaviorTree> needs an ID")
            if tid in trees:
                raise BTError(f"{where}:{el.line}: BehaviorTree ID {tid!r} defined twice")
            trees[tid] = el
        elif el.tag != "TreeNodesModel":
            raise BTError(f"{where}:{el.line}: unsupported element <{el.tag}> under <root>")
    if not trees:
        raise BTError(f"{where}: no <BehaviorTree> in file")
    main = main or root.attrs.get("main_tree_to_execute")
    if main is None:
        if len(trees) > 1:
            raise BTError(f"{where}: several trees and no main_tree_to_execute attribute")
        main = next(iter(trees))
    if main not in trees:
        raise BTError(f"{where}: main tree {main!r} not found (trees: {', '.join(trees)})")
    bb = blackboard if blackboard is not None else Blackboard()
    builder = _Builder(where, trees, registry, context)
    root_node = builder.build_tree(main, bb, ())
    return Tree(root_node, bb, builder.nodes, main)


def _check_port_value(where: str, name: str, spec: Port, raw: str) -> None:
    """A port's value as the tree gives it, checked against its declared type when the tree is loaded
    (``<Repeat num_cycles="abc">`` is refused here, not at the first tick of a run)."""
    if blackboard_key(raw, name) is not None:
        return  # read from the blackboard when ticked
    if spec.direction == "output":
        raise BTError(f"{where}: output port '{name}' must name a blackboard key ({{key}}), not {raw!r}")
    try:
        convert_port(raw, spec.type)
    except (ValueError, TypeError):
        raise BTError(f"{where}: port '{name}': {raw[:40]!r} is not a {spec.type.__name__}") from None
