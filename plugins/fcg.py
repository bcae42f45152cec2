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

Which claims a choice skips is a second such reading (``heard_claims``). By default those heard
this tick (``tick``). SPACE's code empties an agent's received messages only when it chooses, and
its sensing node appends the neighbours' claims every tick, so a choice there skips every claim
heard since the agent's previous choice (``since_choice``): an agent that worked on a task for a
thousand ticks remembers every claim it heard meanwhile, which matters where few neighbours are in
range at the moment it chooses. (When nothing is in sight SPACE's agent does not choose and keeps
what it heard; so does ours.)

A third is what an agent sees of its neighbours' choices in the same step (``same_tick_claims``).
SPACE's main loop runs its agents' trees one after another in id order within a step, each sensing
its neighbours' messages as they stand, so of two neighbours choosing in one step the later one
sees the earlier one's claim and chooses another task; two neighbours never claim one task in the
same step. Ours hear a claim a tick later, through the radio: by default (``unseen``) an agent
keeps a task a lower id claimed at the same tick (and such a pair, finishing together, tends to
choose together again); ``id_order`` gives SPACE's order back: the higher id, hearing that claim
on its task, chooses again at once, skipping it (a tick later than in SPACE).

A team task (ST-MR, one that needs k robots at once) takes k claims: it is free while fewer than k
neighbours claim it, and a claim beaten by k earlier ones is given up (in either mode: the team is
full without it). A claimant of a team task that sees a fuller team with room joins it (more
claimants than its own team, itself counted; or as many and an earlier founding claim): without
this rule, agents that each claimed a different team task at the start would wait alone forever.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field

from swarmbed.extension import Allocator, LocalView, TaskInfo
from swarmbed.extension.presets import Preset

CLAIM = "claim"


class FCGParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    #: the readings of SPACE's paper and of its code (the module's docstring quotes both)
    presets: ClassVar[dict[str, Preset]] = {
        "space_text": Preset(
            {"on_earlier_claim": "abandon"},
            "SPACE, Section IV-D: the agent 'abandons that task and tries the task selection process again "
            "in the next game loop'",
        ),
        "space_code": Preset(
            {"on_earlier_claim": "keep", "heard_claims": "since_choice", "same_tick_claims": "id_order"},
            "SPACE's code: plugins/greedy/greedy.py checks claims only when it chooses and empties its "
            "received messages then; its main loop runs the agents' trees in id order within a step",
        ),
    }
    mode: Literal["MinDist", "Random", "MaxUtil"] = "MinDist"
    cost_weight: float = 1.0  # MaxUtil: utility = remaining workload - cost_weight * distance
    on_earlier_claim: Literal["keep", "abandon"] = Field(
        "keep",
        description="on hearing an earlier claim on its task: keep it until done (SPACE's code) or abandon "
        "it and choose again at the next tick (SPACE's Section IV-D, as written)",
    )
    same_tick_claims: Literal["unseen", "id_order"] = Field(
        "unseen",
        description="a lower-id neighbour's claim on this agent's task made at the same tick as its own: kept "
        "beside (unseen), or seen as SPACE's main loop shows it, whose agents choose one after another in id "
        "order within a step: the agent chooses again, skipping it (id_order)",
    )
    heard_claims: Literal["tick", "since_choice"] = Field(
        "tick",
        description="the claims a choice skips: those heard this tick, or every claim heard since the agent's "
        "previous choice (SPACE's code: plugins/greedy/greedy.py empties its received messages only when it chooses)",
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
        self.heard: dict[int, set[int]] = {}  # heard_claims since_choice: task -> agents heard claiming it

    def decide(self, view: LocalView) -> int | None:
        if self.task is not None and self.task not in view.tasks:
            self.task = None  # done, or no longer in sight
        needs = view.coalitions()
        claims: dict[int, list[tuple[int, int]]] = {}  # task -> the (claim tick, agent) heard this tick
        for msg in view.inbox:
            if msg.kind != CLAIM or not _is_claim(msg.data):
                continue  # not a claim (crafted, torn): nothing in it
            task, tick = msg.data
            claims.setdefault(task, []).append((tick, msg.sender))

        def room(task: int | None) -> int:  # robots the task takes: one, or a team task's k (ST-MR)
            return needs[task][0] if task in needs else 1

        remember = self.params.heard_claims == "since_choice"
        if remember:
            for task, heard in claims.items():
                self.heard.setdefault(task, set()).update(sender for _, sender in heard)

        def claimants(task: int) -> int:
            return len(self.heard.get(task, ())) if remember else len(claims.get(task, ()))

        mine = (self.claimed_at, self.agent_id)
        earlier = self.task is not None and sum(key < mine for key in claims.get(self.task, ())) >= room(self.task)
        if earlier and room(self.task) > 1:
            self.task = None  # a team that is full without this agent: it looks for another now
        elif self.task is not None and room(self.task) > 1:
            self._join_fuller_team(view, claims, room)
        if earlier and self.params.on_earlier_claim == "abandon":
            self.task = None
            self.abandoned += 1
            return None  # choose again at the next tick, as the paper describes
        if self._beaten_in_id_order(claims, room(self.task)):
            self.task = None  # SPACE's loop would have shown it this claim before it chose
        if self.task is None:
            free = [t for t in view.tasks.values() if claimants(t.id) < room(t.id)]
            if view.tasks:
                self.heard = {}  # SPACE's agent forgets what it heard each time it chooses
            if not free:
                return None
            self.task = self._choose(view, free)
            self.claimed_at = view.tick
        view.broadcast(CLAIM, [self.task, self.claimed_at])
        return self.task

    def _beaten_in_id_order(self, claims: dict[int, list[tuple[int, int]]], room: int) -> bool:
        """``same_tick_claims: id_order``: whether a lower id claimed this agent's (one-robot) task at
        the tick this agent did, a claim SPACE's loop, in id order, would have shown it first."""
        if self.task is None or room != 1 or self.params.same_tick_claims != "id_order":
            return False
        return any(tick == self.claimed_at and sender < self.agent_id for tick, sender in claims.get(self.task, ()))

    def _join_fuller_team(
        self, view: LocalView, claims: dict[int, list[tuple[int, int]]], room: Callable[[int | None], int]
    ) -> None:
        """A team task's claimant moves to a team in view that already has more claimants than its own
        (itself counted) and room for one more, or as many and an earlier founding claim: teams
        gather around the earliest claims instead of each agent waiting alone at its own."""
        assert self.task is not None
        own = [*claims.get(self.task, ()), (self.claimed_at, self.agent_id)]
        best_key, best = (len(own), tuple(-v for v in min(own))), None
        for task in sorted(view.tasks):
            heard = claims.get(task, ())
            if task == self.task or room(task) < 2 or not 0 < len(heard) < room(task):
                continue
            key = (len(heard), tuple(-v for v in min(heard)))
            if key > best_key:
                best_key, best = key, task
        if best is not None:
            self.task, self.claimed_at = best, view.tick

    def _choose(self, view: LocalView, free: list[TaskInfo]) -> int:
        mode = self.params.mode
        if mode == "Random":
            return free[int(self.rng.integers(len(free)))].id
        if mode == "MaxUtil":
            w = self.params.cost_weight
            return max(free, key=lambda t: (t.remaining - w * view.distance_to(t), -t.id)).id
        return min(free, key=lambda t: (view.distance_to(t), t.id)).id


def _is_claim(data: Any) -> bool:
    """Whether a message has a claim's shape: [task, claim tick], two whole numbers."""
    return isinstance(data, list) and len(data) == 2 and type(data[0]) is int and type(data[1]) is int
