"""Decorators: Inverter, ForceSuccess, ForceFailure, Repeat, RetryUntilSuccessful,
KeepRunningUntilFailure (BehaviorTree.CPP v4). SubTree lives in ``tree``.

Repeat and RetryUntilSuccessful yield RUNNING between cycles when the child finished within the
same tick it started (BT.CPP returns control to the tree there so the loop stays interruptible);
with one tick per control step, as here, that means one cycle per tick for synchronous children.
"""

from __future__ import annotations

from swarmbed.bt.node import DecoratorNode, InputPort, Port
from swarmbed.bt.status import FAILURE, IDLE, RUNNING, SUCCESS, Status


class Inverter(DecoratorNode):
    ID = "Inverter"

    def tick(self) -> Status:
        self.status = RUNNING
        s = self.child.execute_tick()
        if s is SUCCESS:
            self.reset_child()
            return FAILURE
        if s is FAILURE:
            self.reset_child()
            return SUCCESS
        return s


class _Force(DecoratorNode):
    RESULT = SUCCESS

    def tick(self) -> Status:
        self.status = RUNNING
        s = self.child.execute_tick()
        if s is SUCCESS or s is FAILURE:
            self.reset_child()
            return self.RESULT
        return s


class ForceSuccess(_Force):
    ID = "ForceSuccess"
    RESULT = SUCCESS


class ForceFailure(_Force):
    ID = "ForceFailure"
    RESULT = FAILURE


class _Loop(DecoratorNode):
    """Shared loop of Repeat (continues on SUCCESS) and RetryUntilSuccessful (continues on FAILURE)."""

    PORT = ""
    CONTINUE_ON = SUCCESS

    def __init__(self, name, config):
        super().__init__(name, config)
        self.count = 0

    def tick(self) -> Status:
        limit = self.get_input(self.PORT)
        do_loop = limit == -1 or self.count < limit
        self.status = RUNNING
        while do_loop:
            prev = self.child.status
            s = self.child.execute_tick()
            if s is RUNNING:
                return RUNNING
            if s is not self.CONTINUE_ON:
                self.count = 0
                self.reset_child()
                return s
            self.count += 1
            do_loop = limit == -1 or self.count < limit
            self.reset_child()
            if prev is IDLE and do_loop:
                return RUNNING
        self.count = 0
        return self.CONTINUE_ON

    def halt(self) -> None:
        self.count = 0
        super().halt()


class Repeat(_Loop):
    ID = "Repeat"
    PORT = "num_cycles"
    CONTINUE_ON = SUCCESS

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {"num_cycles": InputPort(int, description="repetitions (-1: forever)")}


class RetryUntilSuccessful(_Loop):
    ID = "RetryUntilSuccessful"
    PORT = "num_attempts"
    CONTINUE_ON = FAILURE

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {"num_attempts": InputPort(int, description="attempts (-1: forever)")}


class KeepRunningUntilFailure(DecoratorNode):
    ID = "KeepRunningUntilFailure"

    def tick(self) -> Status:
        self.status = RUNNING
        s = self.child.execute_tick()
        if s is FAILURE:
            self.reset_child()
            return FAILURE
        if s is SUCCESS:
            self.reset_child()
        return RUNNING


DECORATORS = (Inverter, ForceSuccess, ForceFailure, Repeat, RetryUntilSuccessful, KeepRunningUntilFailure)
