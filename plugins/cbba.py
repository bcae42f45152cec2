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
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmbed.extension import Allocator, LocalView, TaskInfo
from swarmbed.plugins.consensus import ConsensusState
from swarmbed.plugins.taskbook import TaskBook

KIND = "cbba"


class CBBAParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
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

    # the consensus state, under CBBA's own names
    bundle = property(lambda self: self.state.bundle)
    path = property(lambda self: self.state.path)
    y = property(lambda self: self.state.y)
    z = property(lambda self: self.state.z)

    def decide(self, view: LocalView) -> int | None:
        st = self.state
        every = self.params.stamp_every
        st.now = view.time if every is None else math.floor(view.time / every) * every
        for task in self.book.update(view):
            st.forget(task)
        before = list(st.bundle)
        within = None
        if self.params.consensus_scope == "local_bids":
            within = {t for t in view.tasks if t in st.bid_on}
        for msg in view.inbox:
            if msg.kind == KIND:
                st.receive(msg.sender, msg.data, ignore=self.book.done, within=within)
        st.release()
        settled = bool(before) and st.bundle == before
        self.build_bundle(view)
        self._reset_if_idle(view.time)
        view.broadcast(KIND, st.message())
        if not st.path or (self.params.execute == "settled" and not settled):
            return None
        return st.path[0]

    # -- bundle building (Algorithm 3) -----------------------------------------------------------
    def _task(self, view: LocalView, task: int) -> TaskInfo:
        return view.tasks.get(task) or self.book.known[task]

    def build_bundle(self, view: LocalView) -> None:
        st = self.state
        while len(st.bundle) < self.params.max_tasks:
            cands = sorted(t for t in view.tasks if t not in st.bundle)
            if not cands:
                return
            gains, positions = self._marginal_gains(view, cands)
            eligible = np.array([st.eligible(t, g) for t, g in zip(cands, gains)])
            masked = np.where(eligible & (gains > 0), gains, -np.inf)
            best = int(np.argmax(masked))
            if not np.isfinite(masked[best]):
                return
            st.add(cands[best], float(gains[best]), int(positions[best]))

    def _marginal_gains(self, view: LocalView, cands: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Best marginal score of each candidate over every insertion position, and that position."""
        p, v, rate = self.params, view.max_speed, view.work_rate
        log_l = math.log(p.discount)
        info = [view.tasks[t] for t in cands]
        cx = np.array([t.x for t in info])
        cy = np.array([t.y for t in info])
        cr = np.array([t.remaining for t in info])
        if p.score == "distance_discounted":
            d = np.hypot(cx - view.x, cy - view.y)
            return np.exp(log_l * d / v) * cr, np.full(len(cands), len(self.state.path))
        path = [self._task(view, t) for t in self.state.path]
        nx = np.array([view.x] + [t.x for t in path])
        ny = np.array([view.y] + [t.y for t in path])
        seg = np.hypot(np.diff(nx), np.diff(ny))  # node n -> n+1
        work = np.array([t.remaining / rate for t in path])
        arrive = np.concatenate([[0.0], np.cumsum(seg / v + work) - work])  # tau of path task k (index k)
        finish = np.concatenate([[0.0], arrive[1:] + work])  # when the agent leaves node n
        disc = np.exp(log_l * arrive[1:]) * np.array([t.remaining for t in path])
        suffix = np.concatenate([np.cumsum(disc[::-1])[::-1], [0.0]])  # suffix[n] = sum of disc[k >= n]
        d = np.hypot(cx[:, None] - nx[None, :], cy[:, None] - ny[None, :])  # candidate x node
        tau = finish[None, :] + d / v
        delay = np.zeros_like(d)
        if len(path):
            delay[:, :-1] = (d[:, :-1] + d[:, 1:] - seg[None, :]) / v + (cr / rate)[:, None]
        gain = np.exp(log_l * tau) * cr[:, None] + (np.exp(log_l * delay) - 1.0) * suffix[None, :]
        return gain.max(axis=1), gain.argmax(axis=1)

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
