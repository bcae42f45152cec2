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
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from plugins.base import Allocator, LocalView, Message, TaskInfo
from plugins.taskbook import TaskBook

KIND = "cbba"
NONE = -1
_NEVER = -math.inf


class CBBAParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    max_tasks: int = Field(5, ge=1, description="L_t: tasks per bundle")
    discount: float = Field(0.999, gt=0, le=1, description="lambda of the time-discounted reward")
    score: Literal["time_discounted", "distance_discounted"] = "time_discounted"
    reset_after: float | None = Field(500.0, gt=0, description="seconds of empty bundle before resetting bids")


def _better(y1: float, z1: int, y2: float, z2: int) -> bool:
    """Bid (y1 by z1) beats bid (y2 by z2): higher, or equal and by the lower agent id."""
    return y1 > y2 or (y1 == y2 and z1 < z2)


class CBBA(Allocator):
    Params = CBBAParams
    message_kinds = (KIND,)

    def __init__(self, agent_id, params, rng):
        super().__init__(agent_id, params, rng)
        self.y: dict[int, float] = {}  # winning bids known
        self.z: dict[int, int] = {}  # winners known (absent: none)
        self.s: dict[int, float] = {}  # agent -> simulated time of the latest information from it
        self.bundle: list[int] = []
        self.path: list[int] = []
        self.book = TaskBook()
        self.empty_since: float | None = None
        self.now = 0.0

    # -- the tick ------------------------------------------------------------------------------
    def decide(self, view: LocalView) -> int | None:
        self.now = view.time
        for task in self.book.update(view):
            self._forget(task)
        for msg in view.inbox:
            if msg.kind == KIND:
                self.receive(msg)
        self.release()
        self.build_bundle(view)
        self._reset_if_idle(view.time)
        view.broadcast(KIND, self.message())
        return self.path[0] if self.path else None

    def message(self) -> dict:
        return {
            "t": self.now,
            "w": [[t, self.z[t], self.y[t]] for t in sorted(self.z)],
            "s": [[a, ts] for a, ts in sorted(self.s.items())],
        }

    # -- consensus (Table 1) ---------------------------------------------------------------------
    def receive(self, msg: Message) -> None:
        i, k = self.agent_id, msg.sender
        data = msg.data
        theirs = {int(t): (int(w), float(b)) for t, w, b in data["w"]}
        sk = {int(a): float(ts) for a, ts in data["s"]}
        sk[k] = float(data["t"])

        def compare(m: int) -> int:  # sign of s_km - s_im: whose information about m is newer
            mine = self.now if m == i else self.s.get(m, _NEVER)
            theirs_m = sk.get(m, _NEVER)
            return (theirs_m > mine) - (theirs_m < mine)

        for j in sorted(set(theirs) | set(self.z)):
            if j in self.book.done:
                continue
            zk, yk = theirs.get(j, (NONE, 0.0))
            zi, yi = self.z.get(j, NONE), self.y.get(j, 0.0)
            if zk == zi and yk == yi:
                continue  # every table entry leaves identical information unchanged
            action = self._table(i, k, zk, yk, zi, yi, compare)
            if action == "update":
                if zk == NONE:
                    self._reset(j)
                else:
                    self.z[j], self.y[j] = zk, yk
            elif action == "reset":
                self._reset(j)
        for m, ts in sk.items():
            if m != i and ts > self.s.get(m, _NEVER):
                self.s[m] = ts

    @staticmethod
    def _table(i: int, k: int, zk: int, yk: float, zi: int, yi: float, compare) -> str:
        """Receiver i's action on one task, given sender k's belief (zk, yk) and its own (zi, yi).
        ``compare(m)`` > 0 when k's information about agent m is newer than i's (s_km > s_im)."""

        def newer(m: int) -> bool:
            return compare(m) > 0

        if zk == k:  # sender thinks it wins
            if zi == i:
                return "update" if _better(yk, k, yi, i) else "leave"  # 1
            if zi == k or zi == NONE:
                return "update"  # 2, 4
            return "update" if newer(zi) or _better(yk, k, yi, zi) else "leave"  # 3
        if zk == i:  # sender thinks the receiver wins
            if zi == k:
                return "reset"  # 6
            if zi not in (i, NONE) and newer(zi):
                return "reset"  # 7
            return "leave"  # 5, 7, 8
        if zk == NONE:  # sender thinks nobody wins
            if zi == k:
                return "update"  # 15
            if zi not in (i, NONE) and newer(zi):
                return "update"  # 16
            return "leave"  # 14, 16, 17
        m = zk  # sender thinks a third agent m wins
        if zi == i:
            return "update" if newer(m) and _better(yk, m, yi, i) else "leave"  # 9
        if zi == k:
            return "update" if newer(m) else "reset"  # 10
        if zi == m or zi == NONE:
            return "update" if newer(m) else "leave"  # 11, 13
        n = zi  # 12: receiver thinks a fourth agent n wins
        if newer(m) and (newer(n) or _better(yk, m, yi, n)):
            return "update"
        if newer(n) and compare(m) < 0:
            return "reset"
        return "leave"

    def _reset(self, task: int) -> None:
        self.z.pop(task, None)
        self.y.pop(task, None)

    def _forget(self, task: int) -> None:
        self._reset(task)
        if task in self.bundle:
            self.bundle.remove(task)
            self.path.remove(task)

    # -- bundle ----------------------------------------------------------------------------------
    def release(self) -> None:
        """Eqs. 6-7: from the first task this agent no longer wins, the bundle is cut; the tasks
        after that one had bids that depended on it, so their bids and winners are reset."""
        for n, task in enumerate(self.bundle):
            if self.z.get(task) != self.agent_id:
                for later in self.bundle[n + 1:]:
                    if self.z.get(later) == self.agent_id:
                        self._reset(later)
                cut = set(self.bundle[n:])
                self.bundle = self.bundle[:n]
                self.path = [t for t in self.path if t not in cut]
                return

    def _task(self, view: LocalView, task: int) -> TaskInfo:
        return view.tasks.get(task) or self.book.known[task]

    def build_bundle(self, view: LocalView) -> None:
        i = self.agent_id
        while len(self.bundle) < self.params.max_tasks:
            cands = sorted(t for t in view.tasks if t not in self.bundle)
            if not cands:
                return
            gains, positions = self._marginal_gains(view, cands)
            eligible = np.array([g > self.y.get(t, 0.0) or (g == self.y.get(t, 0.0) and i < self.z.get(t, i + 1))
                                 for t, g in zip(cands, gains)])
            masked = np.where(eligible & (gains > 0), gains, -np.inf)
            best = int(np.argmax(masked))
            if not np.isfinite(masked[best]):
                return
            task = cands[best]
            self.bundle.append(task)
            self.path.insert(int(positions[best]), task)
            self.y[task] = float(gains[best])
            self.z[task] = i

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
            return np.exp(log_l * d / v) * cr, np.full(len(cands), len(self.path))
        path = [self._task(view, t) for t in self.path]
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
        if self.bundle or self.params.reset_after is None:
            self.empty_since = None
            return
        if self.empty_since is None:
            self.empty_since = now
        elif now - self.empty_since >= self.params.reset_after:
            self.y.clear()
            self.z.clear()
            self.empty_since = now
