"""Built-in leaves shared with BehaviorTree.CPP: AlwaysSuccess, AlwaysFailure, SetBlackboard."""

from __future__ import annotations

from swarmbed.bt.node import BTError, InputPort, Port, SyncAction
from swarmbed.bt.status import FAILURE, SUCCESS, Status


class AlwaysSuccess(SyncAction):
    ID = "AlwaysSuccess"

    def tick(self) -> Status:
        return SUCCESS


class AlwaysFailure(SyncAction):
    ID = "AlwaysFailure"

    def tick(self) -> Status:
        return FAILURE


class SetBlackboard(SyncAction):
    """Writes ``value`` into the blackboard entry named by ``output_key`` (as BT.CPP: ``output_key="goal"``)."""

    ID = "SetBlackboard"

    @classmethod
    def provided_ports(cls) -> dict[str, Port]:
        return {
            "value": InputPort(str, description="value to write (literal or {key})"),
            "output_key": Port("inout", str, None, "name of the blackboard entry to write"),
        }

    def tick(self) -> Status:
        key = str(self.get_input("output_key")).strip()
        if not key:
            raise BTError(f"{self.config.path}: output_key is empty")
        self.config.blackboard.set(key, self.get_input("value"))
        return SUCCESS


LEAVES = (AlwaysSuccess, AlwaysFailure, SetBlackboard)
