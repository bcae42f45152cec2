"""Allocators whose decisions are made outside the agent process and handed over with each tick.

The coordinator gathers one decision per robot before it sends a tick, puts it in that robot's tick
sample, and the agent's allocator answers with it, so the decision takes the path a plugin's
decision takes: the tree runs it, the world carries it out, the radio and the result files are
those of any run. A decision is a task id, or :data:`~swarmbed.extension.allocator.HOLD` / ``HALT``;
none (-1, or no decision yet) lets the tree explore. Where the decisions come from is the class's
``decision_source``: ROS 2 topics (``ros2``: ``docs/ros2.md``) or a driver in the launching process
(``external``: a learner through ``swarmbed.envs``, ``docs/learning.md``).
"""

from __future__ import annotations

from typing import ClassVar

from swarmbed.plugins.base import Allocator, LocalView

NONE = -1  # a decision that chooses no task (the tree explores)


class ExternalAllocator(Allocator):
    """Decisions from a driver in the launching process (a PettingZoo environment's learner)."""

    decision_source: ClassVar[str] = "env"

    def decide(self, view: LocalView) -> int | None:
        return None if view.decision is None or view.decision == NONE else view.decision


class Ros2Allocator(ExternalAllocator):
    """Decisions from ``/robot_<i>/cmd`` (``swarmbed_msgs/msg/TaskCommand``), published by any ROS 2
    node that reads ``/robot_<i>/observation``. Needs the experiment's ``ros2:`` section."""

    decision_source: ClassVar[str] = "ros2"
