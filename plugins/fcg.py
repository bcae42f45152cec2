"""First-Claimed Greedy (SPACE paper, Section IV-D).

Each agent picks a task among those it sees that no neighbour has claimed (the nearest, a random
one, or the one of highest utility) and broadcasts its claim every tick: the task and the tick at
which it claimed it.

What it does on hearing that another agent claimed the same task first (earlier claim tick; ties
to the lower agent id) is where SPACE's paper and SPACE's code read differently. The paper: "If the
agent realizes that the chosen task has already been assigned to another agent, it abandons that
task and tries the task selection process again in the next game loop" (``on_earlier_claim:
abandon``). SPACE's code (``plugins/greedy/greedy.py``) checks claims only when it chooses, and an
agent keeps its task until the task is done (``keep``, the default: the Fig. 3 results come from
that code). Either way the choice itself skips tasks a neighbour claims.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from swarmbed.extension import Allocator, LocalView, TaskInfo

CLAIM = "claim"


class FCGParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    mode: Literal["MinDist", "Random", "MaxUtil"] = "MinDist"
    cost_weight: float = 1.0  # MaxUtil: utility = remaining workload - cost_weight * distance
    on_earlier_claim: Literal["keep", "abandon"] = Field(
        "keep",
        description="on hearing an earlier claim on its task: keep it until done (SPACE's code) or abandon "
        "it and choose again at the next tick (SPACE's Section IV-D, as written)",
    )


class FirstClaimedGreedy(Allocator):
    Params = FCGParams
    params: FCGParams
    message_kinds = (CLAIM,)

    def __init__(self, agent_id, params, rng, run_seed=0):
        super().__init__(agent_id, params, rng, run_seed)
        self.task: int | None = None
        self.claimed_at = 0
        self.abandoned = 0

    def decide(self, view: LocalView) -> int | None:
        if self.task is not None and self.task not in view.tasks:
            self.task = None  # done, or no longer in sight
        claims: dict[int, tuple[int, int]] = {}  # task -> earliest (claim tick, agent) heard this tick
        for msg in view.inbox:
            if msg.kind != CLAIM:
                continue
            task, tick = msg.data
            key = (tick, msg.sender)
            if task not in claims or key < claims[task]:
                claims[task] = key
        earlier = self.task is not None and self.task in claims and claims[self.task] < (self.claimed_at, self.agent_id)
        if earlier and self.params.on_earlier_claim == "abandon":
            self.task = None
            self.abandoned += 1
            return None  # choose again at the next tick, as the paper describes
        if self.task is None:
            free = [t for t in view.tasks.values() if t.id not in claims]
            if not free:
                return None
            self.task = self._choose(view, free)
            self.claimed_at = view.tick
        view.broadcast(CLAIM, [self.task, self.claimed_at])
        return self.task

    def _choose(self, view: LocalView, free: list[TaskInfo]) -> int:
        mode = self.params.mode
        if mode == "Random":
            return free[int(self.rng.integers(len(free)))].id
        if mode == "MaxUtil":
            w = self.params.cost_weight
            return max(free, key=lambda t: (t.remaining - w * view.distance_to(t), -t.id)).id
        return min(free, key=lambda t: (view.distance_to(t), t.id)).id
