"""The SPACE behavior-tree nodes. They reach the agent through ``config.context`` (a
:class:`~swarmbed.extension.context.NodeContext`): this tick's view, the allocator, the action."""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import numpy as np

from swarmbed.bt import (
    FAILURE,
    RUNNING,
    SUCCESS,
    InputPort,
    NodeRegistry,
    OutputPort,
    Port,
    StatefulAction,
    Status,
    SyncAction,
)
from swarmbed.extension.allocator import HALT, HOLD, DecisionError
from swarmbed.extension.context import NodeContext


class LocalSensingNode(SyncAction):
    """Publishes what the agent senses this tick (visible tasks, inbox) on the blackboard."""

    ID = "LocalSensingNode"

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {
            "tasks": OutputPort(default="{local_tasks}", description="visible open tasks {id: TaskInfo}"),
            "messages": OutputPort(default="{messages}", description="messages received this tick"),
        }

    def tick(self) -> Status:
        view = self.config.context.view
        self.set_output("tasks", view.tasks)
        self.set_output("messages", view.inbox)
        return SUCCESS


class DecisionMakingNode(SyncAction):
    """Runs the allocator plugin; SUCCESS with the chosen task, FAILURE when it chose none."""

    ID = "DecisionMakingNode"

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {"task_id": OutputPort(default="{assigned_task}", description="task chosen by the allocator")}

    def tick(self) -> Status:
        ctx = self.config.context
        task = _task_id(ctx.allocator.decide(ctx.view), ctx)
        if task in (HOLD, HALT):  # stay put: no task to execute, and no exploring either
            self.set_output("task_id", None)
            if task == HALT:
                ctx.act(["halt"])  # and stop at once (the executing node, with no task, leaves it)
            return SUCCESS
        self.set_output("task_id", task)
        return FAILURE if task is None else SUCCESS


def _task_id(value: object, ctx: NodeContext) -> int | None:
    """What ``decide`` returned, as a task id, None, HOLD or HALT; a DecisionError naming the agent, the
    tick and the value for anything else (a task id the world does not know is the world's to count,
    as an invalid action)."""
    if value is None:
        return None
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        return int(value)
    raise DecisionError(
        f"agent {ctx.agent_id}, tick {ctx.view.tick}: {type(ctx.allocator).__name__}.decide returned "
        f"{str(value)[:60]!r} ({type(value).__name__}); it must return a task id (int), None, HOLD or HALT"
    )


class TaskExecutingNode(StatefulAction):
    """Moves to the assigned task and works on it (RUNNING). The decision node before it runs every
    tick and changes or drops the task; with no task it returns SUCCESS."""

    ID = "TaskExecutingNode"

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {"task_id": InputPort(int, "{assigned_task}", "task to execute")}

    def on_start(self) -> Status:
        return self.on_running()

    def on_running(self) -> Status:
        task = self.get_input("task_id")
        ctx = self.config.context
        if task is None:
            return SUCCESS
        ctx.act(["goto_task", int(task)])
        return RUNNING


class ExplorationNode(StatefulAction):
    """Heads to a random waypoint in the area; SUCCESS when there or after ``duration`` seconds."""

    ID = "ExplorationNode"

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {
            "duration": InputPort(float, "{exploration_duration}", "seconds before a new waypoint"),
            "reach": InputPort(float, "{arrival_radius}", "distance at which the waypoint counts as reached"),
        }

    def on_start(self) -> Status:
        ctx = self.config.context
        self.waypoint = ctx.scenario.random_point(ctx.rng)
        self.until = ctx.view.time + self.get_input("duration")
        return self.on_running()

    def on_running(self) -> Status:
        ctx = self.config.context
        view = ctx.view
        near = math.hypot(self.waypoint[0] - view.x, self.waypoint[1] - view.y) <= self.get_input("reach")
        if view.time >= self.until or near:
            return SUCCESS
        ctx.act(["goto", *self.waypoint])
        return RUNNING


SPACE_NODES = (LocalSensingNode, DecisionMakingNode, TaskExecutingNode, ExplorationNode)
#: SPACE's tree over these nodes: what an agent runs when neither its allocator nor its scenario names one
SPACE_TREE = Path(str(resources.files("swarmbed.extension") / "trees" / "space_default.xml"))


def space_registry() -> NodeRegistry:
    registry = NodeRegistry()
    for node in SPACE_NODES:
        registry.register(node)
    return registry
