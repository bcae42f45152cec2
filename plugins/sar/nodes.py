"""Behavior-tree nodes of the search-and-rescue strategies (CBBA-ETC paper, Figures 1, 2, 4, 5).

Each node asks the agent's strategy (``config.context.allocator``) and, for actions, sets the
robot's action for this tick (``config.context.act``). Wandering reuses the SPACE ExplorationNode.
"""

from __future__ import annotations

from swarmbed.bt import (
    FAILURE,
    RUNNING,
    SUCCESS,
    Condition,
    NodeConfig,
    StatefulAction,
    Status,
    SyncAction,
)


def _ok(flag: bool) -> Status:
    return SUCCESS if flag else FAILURE


class _SARNode:
    config: NodeConfig  # provided by the node class it is mixed into

    @property
    def strategy(self):
        return self.config.context.allocator

    @property
    def view(self):
        return self.config.context.view


class IsTargetValid(_SARNode, Condition):
    """The robot has a target that is still there, not found incompatible, and still its own."""

    ID = "IsTargetValid"

    def tick(self):
        return _ok(self.strategy.target_valid(self.view))


class NeedsInspection(_SARNode, Condition):
    ID = "NeedsInspection"

    def tick(self):
        return _ok(self.strategy.needs_inspection())


class ColorMatch(_SARNode, Condition):
    ID = "ColorMatch"

    def tick(self):
        return _ok(self.strategy.color_match())


class MoveToTarget(_SARNode, StatefulAction):
    """RUNNING while heading to the target; SUCCESS once within inspection distance."""

    ID = "MoveToTarget"

    def on_start(self):
        return self.on_running()

    def on_running(self):
        if self.strategy.in_reach(self.view):
            return SUCCESS
        self.config.context.act(["goto_task", self.strategy.target])
        return RUNNING


class Inspect(_SARNode, SyncAction):
    """Inspect the target; the colour arrives with the next observation (or not, if it failed)."""

    ID = "Inspect"

    def tick(self):
        self.config.context.act(["inspect", self.strategy.target])
        return SUCCESS


class Rescue(_SARNode, SyncAction):
    ID = "Rescue"

    def tick(self):
        self.config.context.act(["rescue", self.strategy.target])
        return SUCCESS


class Abandon(_SARNode, SyncAction):
    ID = "Abandon"

    def tick(self):
        target = self.strategy.target
        self.strategy.abandon(self.view)
        self.config.context.act(["abandon", target])
        return SUCCESS


class SelectNearestVictim(_SARNode, SyncAction):
    """tree / comm: choose the nearest suitable victim."""

    ID = "SelectNearestVictim"

    def tick(self):
        return _ok(self.strategy.acquire(self.view))


class BuildBundle(_SARNode, SyncAction):
    """Algorithm 3: greedy bundle by utility; FAILURE when it stays empty."""

    ID = "BuildBundle"

    def tick(self):
        return _ok(self.strategy.build_bundle(self.view))


class ShouldTrigger(_SARNode, Condition):
    """cbba-tree: the period has elapsed; cbba-etc: any of the four event triggers fires."""

    ID = "ShouldTrigger"

    def tick(self):
        return _ok(self.strategy.should_trigger(self.view))


class RunConsensus(_SARNode, StatefulAction):
    """RUNNING while the consensus takes its rounds (``consensus_wait``), the robot standing still."""

    ID = "RunConsensus"

    def on_start(self):
        return RUNNING if self.strategy.start_consensus(self.view) else SUCCESS

    def on_running(self):
        return RUNNING if self.strategy.consensus_step(self.view) else SUCCESS

    def on_halted(self):
        self.strategy.end_consensus()


class AdaptInterval(_SARNode, SyncAction):
    """cbba-etc: adapt the fallback interval to the conflict of the last round (Eqs. 2-4)."""

    ID = "AdaptInterval"

    def tick(self):
        self.strategy.adapt_interval()
        return SUCCESS


class SelectNewTarget(_SARNode, SyncAction):
    ID = "SelectNewTarget"

    def tick(self):
        return _ok(self.strategy.select_new_target(self.view))


class StateMachine(_SARNode, SyncAction):
    """The reactive CBBA baseline is a state machine, not a tree: one node runs it whole."""

    ID = "CBBAStateMachine"

    def tick(self):
        ctx = self.config.context
        action = self.strategy.fsm_step(self.view)
        if action is None:  # nothing to do: wander toward a random point until there
            if getattr(self, "waypoint", None) is None or self._reached():
                self.waypoint = ctx.scenario.random_point(ctx.rng)
            action = ["goto", *self.waypoint]
        else:
            self.waypoint = None
        ctx.act(action)
        return SUCCESS

    def _reached(self) -> bool:
        v = self.view
        return abs(self.waypoint[0] - v.x) + abs(self.waypoint[1] - v.y) < 1e-6


SAR_NODES = (
    IsTargetValid,
    NeedsInspection,
    ColorMatch,
    MoveToTarget,
    Inspect,
    Rescue,
    Abandon,
    SelectNearestVictim,
    BuildBundle,
    ShouldTrigger,
    RunConsensus,
    AdaptInterval,
    SelectNewTarget,
    StateMachine,
)
