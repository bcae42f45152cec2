"""Consensus-Based Bundle Algorithm (Choi, Brunet, How 2009, IEEE T-RO 25(4)), with SPACE's
dynamic-task addition.

Each tick: (1) forget tasks learnt to be done; (2) consensus: apply the receiver action table
(Table 1, 17 cases) to every neighbour's winners, bids and information timestamps; (3) release:
the first bundle task no longer won by this agent and everything after it leave the bundle, the
ones after it with their bid and winner reset (Eqs. 6-7); (4) bundle building (Algorithm 3): add
the task of highest marginal score over every insertion position in the path, while the bid beats
the known winning bid and the bundle holds fewer than ``max_tasks``; (5) broadcast.

Score: time-discounted reward ``sum(discount ** tau_j * R_j)`` along the path (SPACE Eq. 2), where
``tau_j`` is the travel time along the path to j at ``max_speed`` plus the work time of the tasks
before j, and R_j is the task's remaining workload. ``score: distance_discounted`` uses
``discount ** (d_ij / v) * R_j`` instead, a score that does not depend on the path. Timestamps are
simulated time. Equal bids go to the lower agent id.

SPACE's addition: when the bundle has stayed empty for ``reset_after`` seconds, the agent resets
every winning bid and winner it knows, so that tasks left with stale high bids can be bid on again.

What an agent works on: SPACE's code (``plugins/cbba/cbba.py``) alternates building a bundle and a
consensus round, and hands its agent the first task of its path only after a consensus round that
left the bundle as it was; on the other ticks the agent has no task and its tree explores
(``execute: settled``, the default). ``execute: first`` heads for the first task of the path on
every tick, as swarmbed's published section 7 did.

Information timestamps: simulated seconds, new every tick. SPACE's code stamps with
``int(time.time())``, whole wall-clock seconds, which at the hundreds of simulated seconds it runs
per wall second stay equal for hundreds of ticks, so Table 1's rules that need newer information
seldom fire; ``stamp_every: S`` stamps with whole multiples of S simulated seconds instead (a
simulated clock keeps lock-step runs reproducible, which a wall clock would not).

Which tasks a consensus round touches: Table 1 is applied to every task a neighbour's message
names (``consensus_scope: all``, the CBBA paper). SPACE's code applies it only to the tasks the agent
senses, and of those only to the ones both it and the neighbour hold a bid for (``if y_k.get(j) is
None or y_i.get(j) is None: continue``; an agent's ``y`` gains keys only by its own bids):
``consensus_scope: local_bids`` does that, with what our messages carry: the tasks in view that this
agent has bid on since its knowledge was last cleared and that the message names. (SPACE's message
also names the tasks a sender bid on and has since reset; ours does not carry those.)

Team tasks (ST-MR, a task that needs k robots at once; :meth:`LocalView.coalitions`): the task is
bid on as k slots (:func:`slot_id`), each won by one agent through the same consensus, each worth
1/k of the task's workload and its work time; an agent holds at most one slot of a task, and a
slot of a team task goes last in its path and closes its bundle, so that agents waiting for their
teams never wait on each other (the slot expansion of coupled-constraint CBBA without its timing
constraints: a team forms where its slots' winners meet). A team may never form (a slot nobody
wins, a winner that never comes): after ``team_patience`` seconds with its team slot first and the
team not all on the task, a robot gives the slot up.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import ConfigDict, Field

from swarmbed import kernels
from swarmbed.extension import Allocator, LocalView, TaskInfo
from swarmbed.extension.presets import Preset
from swarmbed.plugins.consensus import ConsensusState
from swarmbed.plugins.taskbook import TaskBook
from swarmbed.plugins.teams import slot_id, task_of
from swarmbed.schema.experiment import QuietDefaults

KIND = "cbba"


class CBBAParams(QuietDefaults):
    model_config = ConfigDict(extra="forbid")
    #: a key for team tasks only: at its default, runs without them write the config.yaml they did
    QUIET: ClassVar[dict[str, Any]] = {"team_patience": 600.0}
    #: the CBBA paper's consensus and SPACE's code's (the module's docstring says what each key follows)
    presets: ClassVar[dict[str, Preset]] = {
        "cbba_paper": Preset(
            {"consensus_scope": "all", "stamp_every": None},
            "Choi, Brunet, How 2009: Table 1 on every task a neighbour names, timestamps of the time itself",
        ),
        "space_code": Preset(
            {"execute": "settled", "consensus_scope": "local_bids", "stamp_every": 300.0},
            "SPACE's code: plugins/cbba/cbba.py works only on a settled bundle, applies Table 1 to sensed "
            "tasks both sides bid on, and stamps with whole wall-clock seconds (300 simulated seconds: the "
            "calibration of docs/reproduction.md section 7)",
        ),
    }
    max_tasks: int = Field(5, ge=1, description="L_t: tasks per bundle")
    discount: float = Field(0.999, gt=0, le=1, description="lambda of the time-discounted reward")
    score: Literal["time_discounted", "distance_discounted"] = "time_discounted"
    reset_after: float | None = Field(500.0, gt=0, description="seconds of empty bundle before resetting bids")
    execute: Literal["settled", "first"] = Field(
        "settled",
        description="settled: work on the path's first task only on a tick whose consensus left a non-empty "
        "bundle as it was (SPACE's code), else explore; first: on every tick (the published section 7)",
    )
    consensus_scope: Literal["all", "local_bids"] = Field(
        "all",
        description="all: Table 1 on every task a neighbour names (the CBBA paper); local_bids: only on tasks in "
        "view that this agent bid on and the neighbour names (SPACE's code)",
    )
    stamp_every: float | None = Field(
        None,
        gt=0,
        description="None: information timestamps in simulated seconds, new every tick (the CBBA paper); a "
        "number: stamps of that many simulated seconds each, as SPACE's code's whole wall-clock seconds "
        "last a few hundred simulated seconds (docs/reproduction.md section 7)",
    )
    team_patience: float | None = Field(
        600.0,
        gt=0,
        description="team tasks: simulated seconds a robot keeps a team task first in its path while fewer robots "
        "than it needs are on it, before it gives its slot up and leaves the task alone as long again "
        "(None: for ever); no effect where every task needs one robot",
    )
    full_every: int = Field(
        10,
        ge=1,
        description="every n-th message carries the whole consensus state, those "
        "between only what changed since the one before (1: always whole)",
    )


class CBBA(Allocator):
    Params = CBBAParams
    params: CBBAParams
    message_kinds = (KIND,)
    version = "2"  # 2: messages carry packed arrays (plugins/consensus.py); the same decisions

    def __init__(self, agent_id, params, rng, run_seed=0):
        super().__init__(agent_id, params, rng, run_seed)
        self.state = ConsensusState(agent_id, self.params.full_every)
        self.book = TaskBook()
        self.empty_since: float | None = None
        self.team_k: dict[int, int] = {}  # team tasks seen: task -> robots it needs
        self.done_slots: set[int] = set()  # the slot ids (s >= 1) of team tasks done
        self.waiting: tuple[int, float] | None = None  # (team slot first in the path, since when)
        self.shunned: dict[int, float] = {}  # team task -> until when this robot leaves it alone

    # the consensus state, under CBBA's own names
    bundle = property(lambda self: self.state.bundle)
    path = property(lambda self: self.state.path)
    y = property(lambda self: self.state.y)
    z = property(lambda self: self.state.z)

    def decide(self, view: LocalView) -> int | None:
        st = self.state
        every = self.params.stamp_every
        st.now = view.time if every is None else math.floor(view.time / every) * every
        for task, (k, _on) in view.coalitions().items():
            self.team_k[task] = k
        for task in self.book.update(view):
            st.forget(task)
            k = self.team_k.pop(task, 1)
            for slot in range(1, k):
                st.forget(slot_id(task, slot))
                self.done_slots.add(slot_id(task, slot))
        before = list(st.bundle)
        within = None
        if self.params.consensus_scope == "local_bids":
            within = {t for t in st.bid_on if task_of(t) in view.tasks}
        ignore = self.book.done | self.done_slots if self.done_slots else self.book.done
        for msg in view.inbox:
            if msg.kind == KIND:
                st.receive(msg.sender, msg.data, ignore=ignore, within=within)
        st.release()
        if self.team_k:
            self._give_up_waiting(view)
        settled = bool(before) and st.bundle == before
        self.build_bundle(view)
        self._reset_if_idle(view.time)
        view.broadcast(KIND, st.message())
        if not st.path or (self.params.execute == "settled" and not settled):
            return None
        return task_of(st.path[0])

    def _give_up_waiting(self, view: LocalView) -> None:
        """A team slot first in the path for ``team_patience`` seconds while its team is not all on
        the task (its other slots unwon, or their winners busy elsewhere) is given up: a team may
        never form, and a robot that waited for it for ever would do nothing else (its bundle is
        closed by the slot). It leaves the task alone as long again; its dropped bid reaches the
        others through the consensus (a sender that names no winner where the receiver had it)."""
        st, patience = self.state, self.params.team_patience
        head = st.path[0] if st.path else None
        k = 1 if head is None else self.team_k.get(task_of(head), 1)
        if patience is None or head is None or k == 1 or view.coalitions().get(task_of(head), (k, 0))[1] >= k:
            self.waiting = None
            return
        if self.waiting is None or self.waiting[0] != head:
            self.waiting = (head, view.time)
        elif view.time - self.waiting[1] >= patience:
            st.forget(head)
            self.shunned[task_of(head)] = view.time + patience
            self.waiting = None

    # -- bundle building (Algorithm 3) -----------------------------------------------------------
    def _task(self, view: LocalView, item: int) -> TaskInfo:
        """The task of a bid item as this agent knows it; a team task's slot carries its share of
        the task's workload (each of its k robots does 1/k of it)."""
        task = task_of(item)
        info = view.tasks.get(task) or self.book.known[task]
        k = self.team_k.get(task, 1)
        return info if k == 1 else info._replace(remaining=info.remaining / k)

    def _candidates(self, view: LocalView) -> list[int]:
        """The bid items this agent may add: tasks in view not in its bundle and, for a team task
        (ST-MR), one of its k slots while the bundle holds no team task. A team slot closes the
        bundle (it goes last): an agent waits for a team only at the end of its path, so no two
        agents can each wait at a task the other has still to reach. A team task it gave up on
        (:meth:`_give_up_waiting`) is left alone for a while."""
        st = self.state
        if not self.team_k:
            return sorted(t for t in view.tasks if t not in st.bundle)
        held = {task_of(t) for t in st.bundle}
        if any(self.team_k.get(t, 1) > 1 for t in held):
            return []
        cands = []
        for t in view.tasks:
            if t in held or self.shunned.get(t, -math.inf) > view.time:
                continue
            k = self.team_k.get(t, 1)
            cands.extend([t] if k == 1 else [slot_id(t, s) for s in range(k)])
        return sorted(cands)

    def build_bundle(self, view: LocalView) -> None:
        st = self.state
        while len(st.bundle) < self.params.max_tasks:
            cands = self._candidates(view)
            if not cands:
                return
            gains, positions = self._marginal_gains(view, cands)
            best = kernels.best_bid(self.agent_id, cands, gains, st.z, st.y)
            if best < 0:
                return
            st.add(cands[best], float(gains[best]), int(positions[best]))

    def _marginal_gains(self, view: LocalView, cands: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Best marginal score of each candidate over every insertion position, and that position
        (:func:`swarmbed.kernels.path_gains`, compiled where it could be built)."""
        p, v, rate = self.params, view.max_speed, view.work_rate
        log_l = math.log(p.discount)
        info = [self._task(view, t) for t in cands] if self.team_k else [view.tasks[t] for t in cands]
        cx, cy, cr = kernels.task_columns(info)
        if p.score == "distance_discounted":
            gains = kernels.distance_gains(view.x, view.y, v, log_l, cx, cy, cr)
            return gains, np.full(len(cands), len(self.state.path))
        px, py, pr = kernels.task_columns([self._task(view, t) for t in self.state.path])
        at_end = np.zeros(len(cands), np.uint8)
        if self.team_k:  # a team slot goes at the end of the path
            at_end[[self.team_k.get(task_of(t), 1) > 1 for t in cands]] = 1
        return kernels.path_gains(view.x, view.y, v, rate, log_l, cx, cy, cr, px, py, pr, at_end)

    def _reset_if_idle(self, now: float) -> None:
        st = self.state
        if st.bundle or self.params.reset_after is None:
            self.empty_since = None
            return
        if self.empty_since is None:
            self.empty_since = now
        elif now - self.empty_since >= self.params.reset_after:
            st.y.clear()
            st.z.clear()
            st.bid_on.clear()
            self.empty_since = now
