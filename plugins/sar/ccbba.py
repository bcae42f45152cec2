"""``c-cbba``: Clustering-CBBA (Dong, Liu, Mai 2025) as the CBBA-ETC paper runs it.

At the start every robot clusters the team's starting positions with k-means++ into ``clusters``
groups, with a random stream drawn from the run seed, so that every robot computes the same
clusters; the lowest id of each cluster leads it. Consensus is two-tiered: a member sends its bids
only to its leader (unicast, when its bundle changed or ``period`` passed); a leader merges its
members' bids, exchanges its view with the other leaders, and sends the result back to its
members (multicast) whenever its winners or bids changed (what it heard, or its own bundle) or
``period`` passed: never on a message that taught it nothing, which would make leaders echo.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from swarmbed.extension import LocalView
from swarmbed.plugins.sar.reactive_cbba import ReactiveCBBA, ReactiveParams

BIDS, LEADERS, RESULT = "bids", "leaders", "result"
CLUSTER_STREAM = 0xCCBBA  # a fixed entropy word: every robot draws the same clustering stream


def kmeans_pp(points: np.ndarray, k: int, rng: np.random.Generator, iterations: int = 50) -> np.ndarray:
    """Cluster labels by k-means with k-means++ seeding (Arthur and Vassilvitskii 2007)."""
    n = len(points)
    k = max(1, min(k, n))
    chosen = [points[int(rng.integers(n))]]
    for _ in range(1, k):
        d2 = np.min([np.sum((points - c) ** 2, axis=1) for c in chosen], axis=0)
        total = d2.sum()
        pick = int(rng.choice(n, p=d2 / total)) if total > 0 else int(rng.integers(n))
        chosen.append(points[pick])
    centers = np.array(chosen, dtype=float)
    labels = np.zeros(n, dtype=int)
    for _ in range(iterations):
        labels = np.argmin(((points[:, None, :] - centers[None, :, :]) ** 2).sum(axis=2), axis=1)
        moved = np.array([points[labels == c].mean(axis=0) if np.any(labels == c) else centers[c] for c in range(k)])
        if np.allclose(moved, centers):
            break
        centers = moved
    return labels


class CCBBAParams(ReactiveParams):
    clusters: int = Field(2, ge=1, description="k of k-means++")
    consensus_wait: Literal["free", "leaders"] | None = Field(  # type: ignore[assignment]
        None,
        description="what a consensus costs the robot in simulated time: leaders (the text: a member that "
        "sent its bids stands still until its leader's result arrives, at most leader_wait ticks; a leader "
        "exchanges with the other leaders in rounds of round_ticks until one brings nothing new, then sends "
        "the result) or free (a member acts at once, a leader relays to both at once); "
        "None: leaders",
    )
    leader_wait: int = Field(
        20, ge=1, description="consensus_wait leaders: ticks a robot waits at most for its cluster's result"
    )


class ClusteringCBBA(ReactiveCBBA):
    """Runs as plain ``cbba`` does (its state machine, every tick: keep the bundle full, check the
    target, start a round when the bundle changed or ``period`` passed, work the first victim): the
    paper contrasts the behavior tree's execution control of cbba-tree and cbba-etc with baselines
    that have none, c-cbba among them. Only the consensus differs: two tiers through leaders."""

    Params = CCBBAParams
    params: CCBBAParams
    message_kinds = (BIDS, LEADERS, RESULT)
    #: "Once a global consensus is reached, the leaders disseminate the final, conflict-free task
    #: assignments back to the robots in their clusters" (Section 5.2)
    WAIT = "leaders"

    def __init__(self, agent_id, params, rng, run_seed=0):
        super().__init__(agent_id, params, rng, run_seed)
        self.leader: int | None = None
        self.members: list[int] = []  # the leader's cluster, itself excluded
        self.leaders: list[int] = []
        self.dirty = False
        self.last_relay = -1e18
        self.exchange_began: int | None = None  # a leader: tick of the leaders' round under way
        self.exchange_rounds = 0
        self.result_heard = False  # a member: its leader's result came while it waited

    @property
    def is_leader(self) -> bool:
        return self.leader == self.agent_id

    def setup(self, team: list) -> None:
        ids = [int(t[0]) for t in team]
        points = np.array([[t[1], t[2]] for t in team], dtype=float)
        rng = np.random.default_rng(np.random.SeedSequence([self.run_seed, CLUSTER_STREAM]))
        labels = kmeans_pp(points, self.params.clusters, rng)
        groups: dict[int, list[int]] = {}
        for agent, label in zip(ids, labels):
            groups.setdefault(int(label), []).append(agent)
        heads = {label: min(group) for label, group in groups.items()}
        self.leaders = sorted(heads.values())
        mine = next(label for label, group in groups.items() if self.agent_id in group)
        self.leader = heads[mine]
        self.members = [a for a in sorted(groups[mine]) if a != self.leader]

    def observe(self, view: LocalView) -> None:
        if self.leader is None and view.obs.team is not None:
            self.setup(view.obs.team)
        super().observe(view)
        if self.is_leader:
            self.relay(view)

    def consensus_kinds(self, sender: int) -> tuple[str, ...]:
        if self.is_leader:
            return (BIDS, LEADERS)
        return (RESULT,) if sender == self.leader else ()

    def receive(self, view: LocalView) -> None:
        """A leader relays what it heard only when it learned something: a winner or a bid it did
        not hold. Relaying on every incoming message made the two leaders echo the same state to
        each other every tick (about 96 % of c-cbba's messages, none of them news)."""
        if self.round_began is not None and any(m.kind == RESULT and m.sender == self.leader for m in view.inbox):
            self.result_heard = True
        if not (self.is_leader and any(m.kind in (BIDS, LEADERS) for m in view.inbox)):
            super().receive(view)
            return
        winners, bids = dict(self.state.z), dict(self.state.y)
        super().receive(view)
        if self.state.z != winners or self.state.y != bids:
            self.dirty = True

    def relay(self, view: LocalView) -> None:
        """Leader: pass the merged view to the other leaders and back to the cluster (with
        ``consensus_wait: leaders`` back to the cluster only once the leaders' rounds settle)."""
        if self.exchange_began is not None:
            if view.tick - self.exchange_began < self.params.round_ticks:
                return
            if self.dirty and self.exchange_rounds < self.params.max_rounds:
                self.exchange(view)
                return
            self.exchange_began = None  # a global consensus, as far as this leader hears
            self.disseminate(view)
            return
        if not (self.dirty or self.now - self.last_relay >= self.params.period):
            return
        others = self.other_leaders
        if self.wait == "free" or not others:
            message = self.state.message()
            if others:
                view.send(others, LEADERS, message)
            self.count("negotiations")
            self.disseminate(view, message)
            return
        self.exchange_rounds = 0
        self.exchange(view)

    @property
    def other_leaders(self) -> list[int]:
        return [a for a in self.leaders if a != self.agent_id]

    def exchange(self, view: LocalView) -> None:
        """A round among the leaders."""
        view.send(self.other_leaders, LEADERS, self.state.message())
        self.count("negotiations")
        self.dirty = False
        self.exchange_began = view.tick
        self.exchange_rounds += 1

    def disseminate(self, view: LocalView, message: dict | None = None) -> None:
        """Send the merged view back to the cluster."""
        if self.members:
            view.send(self.members, RESULT, message if message is not None else self.state.message())
        self.dirty = False
        self.last_relay = self.now

    def broadcast_round(self, view: LocalView) -> None:
        if self.is_leader or self.leader is None:
            self.dirty = True  # its own bundle changed: relay it
        else:
            view.send(self.leader, BIDS, self.state.message())

    def run_consensus(self, view: LocalView) -> None:
        if self.is_leader:  # a leader's rounds are its relays (counted there)
            self.broadcast_round(view)
            self.close_round()
            return
        self.result_heard = False
        super().run_consensus(view)

    def consensus_step(self, view: LocalView) -> bool:
        """A member waits for its leader's result, a leader for its exchange to settle (at most
        ``leader_wait`` ticks either way: a lost message or a leader out of range must not stall it)."""
        assert self.round_began is not None, "consensus_step() outside a consensus"
        waiting = (self.dirty or self.exchange_began is not None) if self.is_leader else not self.result_heard
        if waiting and view.tick - self.round_began < self.params.leader_wait:
            return True
        self.end_consensus()
        return False
