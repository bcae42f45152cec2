"""Team tasks (ST-MR: a task that needs k robots at once) as the allocators that assign one robot to
one task see them: k slots of the task, each worth 1/k of its workload.

A slot s >= 1 of task j is the id ``j | s << SLOT_SHIFT``; slot 0 is ``j`` itself, so that a run
without team tasks names exactly the ids it did. Task ids stay below ``2 ** SLOT_SHIFT``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Mapping

SLOT_SHIFT = 24
_TASK_MASK = (1 << SLOT_SHIFT) - 1

Place = tuple[float, float]
TaskRow = tuple[float, float, float]  # x, y, remaining workload


def slot_id(task: int, slot: int) -> int:
    return task | (slot << SLOT_SHIFT)


def task_of(item: int) -> int:
    """The task a bid item (a task, or one slot of a team task) belongs to."""
    return item & _TASK_MASK


def by_slots(
    solve: Callable[[dict[int, Place], dict[int, TaskRow]], dict[int, int]],
    agents: dict[int, Place],
    tasks: Mapping[int, TaskRow],
    needed: Mapping[int, int],
) -> dict[int, int]:
    """``solve`` (one agent to one task, each at most once) over the tasks' slots: a task that needs
    k robots stands as k tasks with 1/k of its workload each. A team the solution leaves short
    would wait for ever, so its task is dropped and the rest solved again without it."""
    tasks = dict(tasks)
    while True:
        slots = {}
        for j, (x, y, r) in tasks.items():
            k = needed.get(j, 1)
            for s in range(k):
                slots[slot_id(j, s)] = (x, y, r / k)
        plan = {a: task_of(item) for a, item in solve(agents, slots).items()}
        on = Counter(plan.values())
        short = [j for j, n in on.items() if n < needed.get(j, 1)]
        if not short:
            return plan
        for j in short:
            del tasks[j]
