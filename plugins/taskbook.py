"""What an agent remembers about tasks: those it has seen, and those it knows are done.

Tasks do not move, so a remembered task whose position is within awareness range but that is no
longer among the visible open tasks has been completed.
"""

from __future__ import annotations

from swarmbed.extension import LocalView, TaskInfo
from swarmbed.wire.state import state_type


@state_type
class TaskBook:
    def __init__(self) -> None:
        self.known: dict[int, TaskInfo] = {}
        self.done: set[int] = set()

    def update(self, view: LocalView) -> list[int]:
        """Record what the view shows; return the ids learnt to be done at this tick (sorted)."""
        self.known.update(view.tasks)
        finished = [t for t, info in self.known.items() if t not in view.tasks and view.sees(info.x, info.y)]
        for t in finished:
            del self.known[t]
            self.done.add(t)
        return sorted(finished)

    def is_open(self, task: int) -> bool:
        return task not in self.done
