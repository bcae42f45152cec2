"""The SPACE behavior-tree nodes. They reach the agent through ``config.context`` (a
:class:`~swarmbed.extension.context.NodeContext`): this tick's view, the allocator, the action."""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

from swarmbed.agent_runtime.bt import InputPort, NodeRegistry, OutputPort, StatefulAction, Status, SyncAction
from swarmbed.extension.allocator import HALT, HOLD


class LocalSensingNode(SyncAction):
    """Publishes what the agent senses this tick (visible tasks, inbox) on the blackboard."""

    ID = "LocalSensingNode"

    @classmethod
    def provided_ports(cls):
        return {
            "tasks": OutputPort(default="{local_tasks}", description="visible open tasks {id: TaskInfo}"),
            "messages": OutputPort(default="{messages}", description="messages received this tick"),
        }

    def tick(self):
        view = self.config.context.view
        self.set_output("tasks", view.tasks)
        self.set_output("messages", view.inbox)
        return Status.SUCCESS


class DecisionMakingNode(SyncAction):
    """Runs the allocator plugin; SUCCESS with the chosen task, FAILURE when it chose none."""

    ID = "DecisionMakingNode"

    @classmethod
    def provided_ports(cls):
        return {"task_id": OutputPort(default="{assigned_task}", description="task chosen by the allocator")}

    def tick(self):
        ctx = self.config.context
        task = ctx.allocator.decide(ctx.view)
        if task in (HOLD, HALT):  # stay put: no task to execute, and no exploring either
            self.set_output("task_id", None)
            if task == HALT:
                ctx.act(["halt"])  # and stop at once (the executing node, with no task, leaves it)
            return Status.SUCCESS
        self.set_output("task_id", task)
        return Status.FAILURE if task is None else Status.SUCCESS


class TaskExecutingNode(StatefulAction):
    """Moves to the assigned task and works on it (RUNNING). The decision node before it runs every
    tick and changes or drops the task; with no task it returns SUCCESS."""

    ID = "TaskExecutingNode"

    @classmethod
    def provided_ports(cls):
        return {"task_id": InputPort(int, "{assigned_task}", "task to execute")}

    def on_start(self):
        return self.on_running()

    def on_running(self):
        task = self.get_input("task_id")
        ctx = self.config.context
        if task is None:
            return Status.SUCCESS
        ctx.act(["goto_task", int(task)])
        return Status.RUNNING


class ExplorationNode(StatefulAction):
    """Heads to a random waypoint in the area; SUCCESS when there or after ``duration`` seconds."""

    ID = "ExplorationNode"

    @classmethod
    def provided_ports(cls):
        return {
            "duration": InputPort(float, "{exploration_duration}", "seconds before a new waypoint"),
            "reach": InputPort(float, "{arrival_radius}", "distance at which the waypoint counts as reached"),
        }

    def on_start(self):
        ctx = self.config.context
        self.waypoint = ctx.scenario.random_point(ctx.rng)
        self.until = ctx.view.time + self.get_input("duration")
        return self.on_running()

    def on_running(self):
        ctx = self.config.context
        view = ctx.view
        near = math.hypot(self.waypoint[0] - view.x, self.waypoint[1] - view.y) <= self.get_input("reach")
        if view.time >= self.until or near:
            return Status.SUCCESS
        ctx.act(["goto", *self.waypoint])
        return Status.RUNNING


SPACE_NODES = (LocalSensingNode, DecisionMakingNode, TaskExecutingNode, ExplorationNode)
#: SPACE's tree over these nodes: what an agent runs when neither its allocator nor its scenario names one
SPACE_TREE = Path(str(resources.files("swarmbed.agent_runtime") / "trees" / "space_default.xml"))


def space_registry() -> NodeRegistry:
    registry = NodeRegistry()
    for node in SPACE_NODES:
        registry.register(node)
    return registry
