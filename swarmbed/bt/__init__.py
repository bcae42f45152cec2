"""A small pure-Python behavior-tree engine that loads BehaviorTree.CPP v4 XML (as Groot2 saves it)
and follows BT.CPP's semantics for the nodes it supports; ``tests/test_bt_conformance.py`` checks
it tick by tick against BehaviorTree.CPP itself."""

from swarmbed.bt.blackboard import Blackboard
from swarmbed.bt.node import (
    BTError,
    Condition,
    InputPort,
    NodeConfig,
    OutputPort,
    Port,
    StatefulAction,
    SyncAction,
    TreeNode,
)
from swarmbed.bt.node_types import NodeRegistry
from swarmbed.bt.palette import palette_xml
from swarmbed.bt.status import FAILURE, IDLE, RUNNING, SUCCESS, Status
from swarmbed.bt.tree import Tree, load_tree

__all__ = [
    "FAILURE",
    "IDLE",
    "RUNNING",
    "SUCCESS",
    "Blackboard",
    "BTError",
    "Condition",
    "InputPort",
    "NodeConfig",
    "NodeRegistry",
    "OutputPort",
    "Port",
    "StatefulAction",
    "Status",
    "SyncAction",
    "Tree",
    "TreeNode",
    "load_tree",
    "palette_xml",
]
