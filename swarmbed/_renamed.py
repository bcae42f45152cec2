"""Old module names that still import, with a DeprecationWarning that names the new one.

Issue 30 moved the extension contract and the worlds below and beside the process roles. Plugins,
scenarios and experiment files written against the old names (``swarmbed.coordinator.scenario``,
``scenario: {kind: swarmbed.coordinator.sar:SAR}``) keep working: importing an old name returns
the module under its new name. The aliases go in the release after next.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType

RENAMED = {
    "swarmbed.coordinator.scenario": "swarmbed.extension.scenario",
    "swarmbed.coordinator.mtsr": "swarmbed.scenarios.mtsr",
    "swarmbed.coordinator.sar": "swarmbed.scenarios.sar",
    "swarmbed.coordinator.kinematics": "swarmbed.scenarios.kinematics",
    "swarmbed.coordinator.checker": "swarmbed.experiments.checks.scenario",
    "swarmbed.agent_runtime.allocator": "swarmbed.extension.allocator",
    "swarmbed.agent_runtime.view": "swarmbed.extension.view",
    "swarmbed.agent_runtime.context": "swarmbed.extension.context",
    "swarmbed.plugins.conformance": "swarmbed.experiments.checks.allocator",
    # issue 45: the BT engine is its own package; SPACE's nodes, the node sets and trees sit below the roles
    "swarmbed.agent_runtime.bt": "swarmbed.bt",
    **{
        f"swarmbed.agent_runtime.bt.{m}": f"swarmbed.bt.{m}"
        for m in ("blackboard", "btlog", "composites", "decorators", "leaves", "node", "palette", "registry", "status")
    },
    "swarmbed.agent_runtime.bt.tree": "swarmbed.bt.tree",
    "swarmbed.agent_runtime.nodes": "swarmbed.extension.nodes",
    "swarmbed.plugins.base": "swarmbed.extension",  # the plugin author's names, all in the extension contract
    "swarmbed.agent_runtime.node_sets": "swarmbed.extension.node_sets",
    # issue 57: the checkers sit beside the CLI, above the roles (the kit drives the radio)
    "swarmbed.plugins.checks": "swarmbed.experiments.checks",
    "swarmbed.plugins.checks.allocator": "swarmbed.experiments.checks.allocator",
    "swarmbed.plugins.checks.scenario": "swarmbed.experiments.checks.scenario",
}


class _Alias(importlib.abc.Loader):
    def __init__(self, new: str) -> None:
        self.new = new

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        return importlib.import_module(self.new)

    def exec_module(self, module: ModuleType) -> None:
        """The module under its new name is already executed."""


class RenamedFinder(importlib.abc.MetaPathFinder):
    def find_spec(
        self, fullname: str, path: object = None, target: object = None
    ) -> importlib.machinery.ModuleSpec | None:
        new = RENAMED.get(fullname)
        if new is None:
            return None
        warnings.warn(
            f"{fullname} is now {new}; the old name goes in a later release", DeprecationWarning, stacklevel=2
        )
        return importlib.machinery.ModuleSpec(fullname, _Alias(new))


def install() -> None:
    """First on the path: an old name whose parent is an alias (``swarmbed.agent_runtime.bt.btlog``)
    would otherwise be found again through the new package's folder and run as a second module."""
    if not any(isinstance(f, RenamedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, RenamedFinder())
