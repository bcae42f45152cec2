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


# The members as plain names: ``Status.RUNNING`` is a look-up through the enum's metaclass (~75 ns),
# ``s.completed`` a property call (~270 ns), and the engine compares statuses a few dozen times a
# tick; ``s is RUNNING`` costs ~15 ns. Members are singletons, so ``is`` says what ``==`` says.
IDLE, RUNNING, SUCCESS, FAILURE = Status.IDLE, Status.RUNNING, Status.SUCCESS, Status.FAILURE
