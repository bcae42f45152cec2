"""Nearest task, no communication: each agent pursues the nearest task it sees (ties to the lower
id) and sends nothing. The baseline every allocator with a radio should beat, and the policy the
ROS 2 example node (``docs/ros2/nearest_node.py``) plays through the ``ros2`` allocator."""

from __future__ import annotations

from swarmbed.extension import Allocator, LocalView


class NearestTask(Allocator):
    def decide(self, view: LocalView) -> int | None:
        if not view.tasks:
            return None  # the tree explores
        return min(view.tasks.values(), key=lambda t: (view.distance_to(t), t.id)).id
