"""GRAPE (Jang, Shin, Tsourdos 2018, IEEE T-RO 34(6)): task allocation as an anonymous hedonic game,
with SPACE's additions for dynamic MT-SR scenarios.

Each agent holds a partition (agent -> task, or the void task), an evolution number and a random
timestamp. Each tick: (1) distributed mutex (Algorithm 2): adopt the partition with the highest
evolution number among its own and its neighbours' (ties: the higher timestamp); if the adopted
partition differs from the one it held, the agent becomes unsatisfied; (2) if unsatisfied, the
decision (Algorithm 1): join the coalition of highest utility among the tasks it sees; a move
increments the evolution number and draws a fresh timestamp; then the agent is satisfied; (3)
broadcast its (evolution number, timestamp, partition).

As SPACE's MT-SR plugin does (the defaults): there is no void task, so an agent joins the visible
task of highest utility even when that utility is negative (with Eq. 1, R_j in [6, 60] and
distances in the hundreds, it mostly is), and an agent holds still on a tick where its partition
was not converged (the mutex changed it, or it decided), stopping at once (SPACE's code resets its
movement: ``converging_stop: halt``; ``brake`` slows it within its acceleration limit, as swarmbed
did before). ``void_task: true`` offers the original GRAPE's void task (utility 0: an agent farther
from every task than their workloads are worth wanders instead); ``hold_while_converging: false``
lets agents move toward their task meanwhile. Restarting at the nearest task after a completion
is not a move of the agent's own (no new evolution number, as in SPACE's code; the published
section 7 had one: ``restart_bumps_evolution: true``). One difference stays: SPACE's code decides
and runs the mutex on alternate ticks, ours does both in one tick.

Utility (SPACE Eq. 1): ``u_i(t_j, |S_j|) = R_j / |S_j| - cost_weight * d_ij * |S_j| ** social_inhibition``
with R_j the task's remaining workload and d_ij the distance to it; a task that needs a team of k
(ST-MR, GRAPE's original setting) peaks at k members instead (:func:`utility`). SPACE's additions: the initial
partition puts the agent on its nearest task, and it does so again when its task completes;
convergence is judged locally (satisfied and unchanged by the mutex). As in SPACE's plugin, an
agent whose task completed is unsatisfied, and one that sees no task to decide on stays so
until it does: otherwise an agent that finished its task out of sight of any other would wander
satisfied with no task, and a task seen only by such agents (the last one of a mission, say)
would never be taken.

Messages carry the whole partition unless ``full_every`` > 1: then the message of every
``full_every``-th tick does, and those between carry only the agents whose task changed since the
message before (an agent that left the partition as ``VOID``), or the whole partition where that is
no larger; a tick with nothing changed sends nothing. Each message is numbered; a receiver
rebuilds a sender's partition from the whole one and the deltas that follow it, and a delta that
does not follow what it holds of that sender (one was lost, or the sender just came into range) is
not used until the next whole message makes it good. The whole messages of ``full_every = 1`` are
SPACE's: (evolution number, timestamp, partition).
"""

from __future__ import annotations

import math
from collections import Counter
from typing import ClassVar, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmbed.extension import HALT, HOLD, Allocator, LocalView
from swarmbed.extension.presets import Preset
from swarmbed.plugins.packed import pack_rows, read_tuples
from swarmbed.plugins.taskbook import TaskBook

KIND = "grape"
VOID = -1

#: a message's partition: (agent, task) pairs packed in the narrowest of these declared dtypes that
#: holds them (VOID, -1, marks an agent that left, in a delta): the bytes alone for the first,
#: ``[code, bytes]`` for the others (every byte of a message is counted)
PAIR_DTYPES = (
    (0, np.dtype([("agent", "i1"), ("task", "i1")])),
    (1, np.dtype([("agent", "i1"), ("task", "<i2")])),
    (2, np.dtype([("agent", "<i2"), ("task", "<i2")])),
    (3, np.dtype([("agent", "<i2"), ("task", "<i4")])),
)


def pack_pairs(pairs: list) -> bytes | list:
    """(agent, task) pairs as they go in a message (none: an empty list, one byte)."""
    if not pairs:
        return []
    code, packed = pack_rows(pairs, PAIR_DTYPES)
    return packed if code == 0 else [code, packed]


def read_pairs(packed: object) -> list[tuple[int, int]]:
    """The (agent, task) pairs of a message's partition; none for anything that is not one."""
    dtypes = dict(PAIR_DTYPES)
    if isinstance(packed, bytes):
        return read_tuples(packed, dtypes[0])
    if isinstance(packed, list) and len(packed) == 2 and packed[0] in dtypes:
        return read_tuples(packed[1], dtypes[packed[0]])
    return []


def utility(
    remaining: float, distance: float, size: int, cost_weight: float, social_inhibition: float, needed: int = 1
) -> float:
    """SPACE's Eq. 1: ``R_j / |S_j| - cost_weight * d_ij * |S_j| ** social_inhibition``.

    A task that needs a team of k (ST-MR, ``needed`` > 1): ``R_j / max(|S_j|, k) * min(|S_j|, k) / k -
    cost_weight * d_ij * max(1, |S_j| - k + 1) ** social_inhibition``: the reward is shared among at
    least k (more dilute it, as in GRAPE's own form), a coalition short of k is worth the part of the
    team it has filled (nothing gets done until it is full), and the inhibition falls only on members
    beyond k. At k = 1 this is Eq. 1. The preference peaks at |S_j| = k rather than at one, so GRAPE's
    convergence theorem (SPAO preferences) does not cover it; tests/test_teams.py checks that the
    partitions our runs end in leave no agent better off moving alone."""
    if needed > 1:
        excess = size - needed + 1
        try:
            inhibition = float(max(1, excess)) ** social_inhibition
        except OverflowError:
            inhibition = math.inf
        cost = cost_weight * distance
        return remaining / max(size, needed) * min(size, needed) / needed - (cost * inhibition if cost else 0.0)
    try:
        inhibition = float(size) ** social_inhibition
    except OverflowError:
        inhibition = math.inf
    cost = cost_weight * distance
    return remaining / size - (cost * inhibition if cost else 0.0)


def _well_formed(data: object, numbered: bool) -> bool:
    """Whether ``data`` has a message's shape: [evolution, stamp, partition(, number(, 1))]."""
    if not isinstance(data, list) or not 3 + numbered <= len(data) <= 5:
        return False
    for v in data[:2] + data[3:4]:  # noqa: SIM110 (a loop is faster than all() over a generator: every message heard)
        if v.__class__ is bool or not isinstance(v, (int, float)):
            return False
    return True


class GRAPEParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    #: the original GRAPE and SPACE's MT-SR adaptation of it in its code
    presets: ClassVar[dict[str, Preset]] = {
        "grape_paper": Preset(
            {"void_task": True, "hold_while_converging": False},
            "Jang et al. 2018, GRAPE: the void task offered; agents move while the partition converges",
        ),
        "space_code": Preset(
            {
                "void_task": False,
                "hold_while_converging": True,
                "converging_stop": "halt",
                "restart_bumps_evolution": False,
            },
            "SPACE's code: no void task; an agent held still (its movement reset) while the partition "
            "converges; a restart after a completion is no new evolution",
        ),
    }
    cost_weight: float = Field(1.0, ge=0, description="weight of the distance cost")
    social_inhibition: float = Field(100.0, ge=0, description="f_s: exponent on the coalition size")
    nearest_start: bool = Field(True, description="start (and restart after completion) at the nearest task")
    void_task: bool = Field(
        False, description="offer the void task (utility 0) of the original GRAPE; SPACE's MT-SR adaptation does not"
    )
    hold_while_converging: bool = Field(
        True, description="stay still on a tick where the partition was not converged (SPACE's MT-SR behaviour)"
    )
    converging_stop: Literal["halt", "brake"] = Field(
        "halt",
        description="how a held agent stops: halt (speed to zero at once, as SPACE's code resets an agent's "
        "movement) or brake (within its acceleration limit; swarmbed's published section 7)",
    )
    restart_bumps_evolution: bool = Field(
        False,
        description="whether restarting at the nearest task after a completion counts as a move (a new "
        "evolution number); SPACE's code edits the partition without one (True: the published section 7)",
    )
    full_every: int = Field(
        1,
        ge=1,
        description="every n-th tick's message carries the whole partition, those "
        "between only the agents whose task changed since the message "
        "before, and none when nothing did (1: always whole, as SPACE's)",
    )


class GRAPE(Allocator):
    Params = GRAPEParams
    params: GRAPEParams
    message_kinds = (KIND,)
    version = "2"  # 2: the partition travels as packed pairs (plugins/packed.py); the same decisions

    def __init__(self, agent_id, params, rng, run_seed=0):
        super().__init__(agent_id, params, rng, run_seed)
        self.partition: dict[int, int] = {}  # agent -> task (absent: void)
        self.evolution = 0
        self.stamp = float(rng.random())
        self.satisfied = False
        self.book = TaskBook()
        self.started = False
        self.sent = 0  # messages made
        self.rounds = 0  # ticks a message was due (full_every > 1: one with nothing to tell sends none)
        self.told: dict[int, int] = {}  # the partition as the last message had it (full_every > 1)
        self.told_version: tuple[int, float] = (-1, 0.0)
        self.heard: dict[int, tuple[int, dict[int, int]]] = {}  # sender -> (message number, its partition)
        self.needs: dict[int, tuple[int, int]] = {}  # team tasks in view: task -> (needed, on it)

    # -- utility ----------------------------------------------------------------------------------
    def utility(self, view: LocalView, task: int, size: int) -> float:
        if task == VOID:
            return 0.0
        t = view.tasks[task]
        p = self.params
        needed = self.needs.get(task, (1, 0))[0]
        return utility(t.remaining, view.distance_to(t), size, p.cost_weight, p.social_inhibition, needed)

    def others_on(self) -> Counter[int]:
        """How many other agents the partition has on each task (a coalition's size is that, plus one
        for this agent joining it): counted once a tick, not once per task in view."""
        return Counter(t for a, t in self.partition.items() if a != self.agent_id)

    # -- the tick -------------------------------------------------------------------------------
    def decide(self, view: LocalView) -> int | None:
        me = self.agent_id
        self.needs = view.coalitions()
        finished = set(self.book.update(view))
        mine_done = self.partition.get(me, VOID) in finished
        if finished:
            for a, t in list(self.partition.items()):
                if t in finished:
                    del self.partition[a]
        if mine_done:
            self.satisfied = False  # SPACE: an agent whose task completed decides afresh
        if not self.started or (mine_done and self.params.nearest_start):
            restart = self.started
            self.started = True
            if self.params.nearest_start and view.tasks:
                nearest = min(view.tasks.values(), key=lambda t: (view.distance_to(t), t.id))
                self._move(nearest.id, bump=not restart or self.params.restart_bumps_evolution)
        self.mutex(view)
        converging = not self.satisfied
        if converging and view.tasks:  # with no task in sight it stays unsatisfied and decides on the first it sees
            self.choose(view)
        message = self.message()
        if message is not None:
            view.broadcast(KIND, message)
        task = self.partition.get(me, VOID)
        if task == VOID or task not in view.tasks:
            return None
        if converging and self.params.hold_while_converging:
            return HALT if self.params.converging_stop == "halt" else HOLD
        return task

    def _move(self, task: int, bump: bool = True) -> None:
        """This agent joins ``task``'s coalition; a move of its own (``bump``) is a new partition:
        a new evolution number and timestamp."""
        if task == VOID:
            self.partition.pop(self.agent_id, None)
        else:
            self.partition[self.agent_id] = task
        if bump:
            self.evolution += 1
            self.stamp = float(self.rng.random())

    # -- messages -------------------------------------------------------------------------------
    def message(self) -> list | None:
        """(evolution number, timestamp, partition as sorted pairs); with ``full_every`` > 1 also the
        message's number, on every ``full_every``-th tick the whole partition and between them the
        changed pairs and a delta mark, or no message at all when nothing changed (a neighbour
        learns nothing from it: it holds the same or, having missed one, can use no delta)."""
        pairs = sorted(self.partition.items())
        if self.params.full_every == 1:
            return [self.evolution, self.stamp, pack_pairs(pairs)]
        due_whole = self.rounds % self.params.full_every == 0
        self.rounds += 1
        told, told_version = self.told, self.told_version
        version = (self.evolution, self.stamp)
        self.told, self.told_version = dict(self.partition), version
        number = self.sent
        if not due_whole:
            changed = [[a, t] for a, t in pairs if told.get(a) != t]
            changed += [[a, VOID] for a in told.keys() - self.partition.keys()]
            if not changed and version == told_version:
                return None
            if len(changed) < len(pairs):
                self.sent += 1
                return [self.evolution, self.stamp, pack_pairs([tuple(c) for c in sorted(changed)]), number, 1]
        self.sent += 1
        return [self.evolution, self.stamp, pack_pairs(pairs), number]

    def partition_of(self, sender: int, data: list) -> dict[int, int] | None:
        """The sender's partition as its message gives it; None when a delta does not follow what
        this agent holds of the sender (it is forgotten until the sender's next whole message)."""
        _, _, packed, number, *delta = data
        pairs = read_pairs(packed)
        if not delta:
            partition = {int(a): int(t) for a, t in pairs}
        else:
            held = self.heard.pop(sender, None)
            if held is None or held[0] != number - 1:
                return None
            partition = held[1]
            for a, t in pairs:
                if t == VOID:
                    partition.pop(int(a), None)
                else:
                    partition[int(a)] = int(t)
        self.heard[sender] = (number, partition)
        return partition

    def mutex(self, view: LocalView) -> None:
        """Algorithm 2: the partition with the highest (evolution number, timestamp) wins."""
        best, chosen = (self.evolution, self.stamp), None
        numbered = self.params.full_every > 1  # then every message updates what this agent holds of its sender
        for msg in view.inbox:
            if msg.kind != KIND or not _well_formed(msg.data, numbered):
                continue  # not a GRAPE message (crafted, torn): nothing in it
            held = self.partition_of(msg.sender, msg.data) if numbered else msg.data[2]
            if held is not None and (msg.data[0], msg.data[1]) > best:
                best, chosen = (msg.data[0], msg.data[1]), held
        if chosen is None:
            return
        pairs = chosen.items() if isinstance(chosen, dict) else read_pairs(chosen)  # read only when chosen
        adopted = {int(a): int(t) for a, t in pairs if int(t) not in self.book.done}
        if adopted != self.partition:
            self.satisfied = False
        self.partition = adopted
        self.evolution, self.stamp = best

    def choose(self, view: LocalView) -> None:
        """Algorithm 1: move to the coalition of highest utility if it beats the current one."""
        current = self.partition.get(self.agent_id, VOID)
        others = self.others_on()
        if (current != VOID and current not in view.tasks) or (current == VOID and not self.params.void_task):
            current_u = -math.inf  # out of sight, done, or no task while there is no void task: any task is better
        else:
            current_u = self.utility(view, current, others[current] + 1)
        best_task, best_u = (VOID, 0.0) if self.params.void_task else (VOID, -math.inf)
        # :meth:`utility` for every task in view, its lookups taken out of the loop
        tasks, needs, x, y = view.tasks, self.needs, view.x, view.y
        weight, inhibition = self.params.cost_weight, self.params.social_inhibition
        for task in sorted(tasks):
            t = tasks[task]
            needed = needs[task][0] if task in needs else 1
            u = utility(t.remaining, math.hypot(t.x - x, t.y - y), others[task] + 1, weight, inhibition, needed)
            if u > best_u:
                best_task, best_u = task, u
        if best_task != current and best_u > current_u:
            self._move(best_task)
        self.satisfied = True
