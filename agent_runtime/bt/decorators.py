"""Decorators: Inverter, ForceSuccess, ForceFailure, Repeat, RetryUntilSuccessful,
KeepRunningUntilFailure (BehaviorTree.CPP v4). SubTree lives in ``tree``.

Repeat and RetryUntilSuccessful yield RUNNING between cycles when the child finished within the
same tick it started (BT.CPP returns control to the tree there so the loop stays interruptible);
with one tick per control step, as here, that means one cycle per tick for synchronous children.
"""

from __future__ import annotations

from swarmbed.agent_runtime.bt.node import DecoratorNode, InputPort, Port
from swarmbed.agent_runtime.bt.status import Status


class Inverter(DecoratorNode):
    ID = "Inverter"

    def tick(self) -> Status:
        self.status = Status.RUNNING
        s = self.child.execute_tick()
        if s == Status.SUCCESS:
            self.reset_child()
            return Status.FAILURE
        if s == Status.FAILURE:
            self.reset_child()
            return Status.SUCCESS
        return s


class _Force(DecoratorNode):
    RESULT = Status.SUCCESS

    def tick(self) -> Status:
        self.status = Status.RUNNING
        s = self.child.execute_tick()
        if s.completed:
            self.reset_child()
            return self.RESULT
        return s


class ForceSuccess(_Force):
    ID = "ForceSuccess"
    RESULT = Status.SUCCESS


class ForceFailure(_Force):
    ID = "ForceFailure"
    RESULT = Status.FAILURE


class _Loop(DecoratorNode):
    """Shared loop of Repeat (continues on SUCCESS) and RetryUntilSuccessful (continues on FAILURE)."""

    PORT = ""
    CONTINUE_ON = Status.SUCCESS

    def __init__(self, name, config):
        super().__init__(name, config)
        self.count = 0

    def tick(self) -> Status:
        limit = self.get_input(self.PORT)
        do_loop = limit == -1 or self.count < limit
        self.status = Status.RUNNING
        while do_loop:
            prev = self.child.status
            s = self.child.execute_tick()
            if s == Status.RUNNING:
                return Status.RUNNING
            if s != self.CONTINUE_ON:
                self.count = 0
                self.reset_child()
                return s
            self.count += 1
            do_loop = limit == -1 or self.count < limit
            self.reset_child()
            if prev == Status.IDLE and do_loop:
                return Status.RUNNING
        self.count = 0
        return self.CONTINUE_ON

    def halt(self) -> None:
        self.count = 0
        super().halt()


class Repeat(_Loop):
    ID = "Repeat"
    PORT = "num_cycles"
    CONTINUE_ON = Status.SUCCESS

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {"num_cycles": InputPort(int, description="repetitions (-1: forever)")}


class RetryUntilSuccessful(_Loop):
    ID = "RetryUntilSuccessful"
    PORT = "num_attempts"
    CONTINUE_ON = Status.FAILURE

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {"num_attempts": InputPort(int, description="attempts (-1: forever)")}


class KeepRunningUntilFailure(DecoratorNode):
    ID = "KeepRunningUntilFailure"

    def tick(self) -> Status:
        self.status = Status.RUNNING
        s = self.child.execute_tick()
        if s == Status.FAILURE:
            self.reset_child()
            return Status.FAILURE
        if s == Status.SUCCESS:
            self.reset_child()
        return Status.RUNNING


DECORATORS = (Inverter, ForceSuccess, ForceFailure, Repeat, RetryUntilSuccessful, KeepRunningUntilFailure)
