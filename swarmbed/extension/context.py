"""What a behavior-tree node may reach: its agent's id, this tick's view, the allocator, the
agent's random generator, the scenario's helpers, and the one action it sets for this tick.

Nodes get this narrow context (``self.config.context``), not the agent runtime: what they can
touch is what a tree needs, so nodes written against it also run in tests and in other hosts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from swarmbed.extension.allocator import Allocator
from swarmbed.extension.view import LocalView

if TYPE_CHECKING:
    from swarmbed.extension.scenario import Scenario


@dataclass
class NodeContext:
    agent_id: int
    rng: np.random.Generator  # the agent's own stream (exploration waypoints and other node choices)
    scenario: Scenario  # helpers such as random_point(rng)
    allocator: Allocator
    view: LocalView = field(init=False)  # this tick's view, set before the tree is ticked
    action: list = field(default_factory=lambda: ["stop"])

    def act(self, action: list) -> None:
        """The one action this agent sends for this tick (the last call wins)."""
        self.action = action
