"""Node status, as in BehaviorTree.CPP."""

import enum

from swarmbed.wire.state import state_type


@state_type
class Status(enum.Enum):
    IDLE = "IDLE"
    RUNNING = "RUNNING"
    SUCCESS = "SUCCESS"
    FAILURE = "FAILURE"

    @property
    def completed(self) -> bool:
        return self in (Status.SUCCESS, Status.FAILURE)
