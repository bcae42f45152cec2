"""The CBBA-family strategies of the CBBA-ETC evaluation: ``cbba`` (reactive state machine),
``cbba-tree`` (periodic consensus inside a behavior tree) and ``cbba-etc`` (event-triggered,
Algorithms 1 to 4), on one shared base.

Bundle (CBBA-ETC Algorithm 3): greedily add the remembered victim of highest utility
``U = 1 / (d + epsilon)``, times ``mismatch_factor`` when its colour is known not to match, while
the bid beats the known winning bid (ties to the lower id) and the bundle has room (``max_tasks``).
Colours are known when bidding ("bid-then-verify"), but the robot still inspects before rescuing.

A consensus round: the robot broadcasts its winners, bids and timestamps once ("completed in a
single communication round"). Receiving is passive: every robot applies CBBA's receiver table
(plugins.consensus) to whatever reaches it, then releases the bundle tasks it lost. Winners not
heard from for ``winner_timeout`` seconds are forgotten, so the claims of a lost robot stop
mattering. ``negotiations`` counts the rounds a robot starts.
"""

from __future__ import annotations

import logging
import math
from typing import ClassVar, Literal

from pydantic import Field

from swarmbed.extension import LocalView
from swarmbed.extension.space_nodes import ExplorationNode
from swarmbed.plugins.consensus import ConsensusState
from swarmbed.plugins.sar.base import TREES, SARStrategy, StrategyParams
from swarmbed.plugins.sar.interval import IntervalParams, next_interval
from swarmbed.plugins.sar.nodes import SAR_NODES

BIDS = "bids"
log = logging.getLogger("swarmbed.agent.cbba_etc")


class ConsensusParams(StrategyParams):
    max_tasks: int = Field(3, ge=1, description="L_i: victims per bundle")
    epsilon: float = Field(1e-3, gt=0, description="the utility's epsilon")
    mismatch_factor: float = Field(0.1, ge=0, description="utility factor for a known colour mismatch")
    period: float = Field(100.0, gt=0, description="cbba: forced round after this many seconds; cbba-tree: period")
    winner_timeout: float = Field(300.0, gt=0, description="forget wins by robots silent this long (s)")
    full_every: int = Field(
        1,
        ge=1,
        description="every n-th round's message carries the whole state, those between "
        "only what changed (1, the paper's rounds: always whole)",
    )
    bundle_build: Literal["top_up", "rebuild"] = Field(
        "rebuild",
        description="Algorithm 3: rebuild starts each build from B_i <- empty, as the algorithm is written; "
        "top_up keeps the bundle and adds to it (docs/reproduction.md section 4)",
    )
    available: Literal["own", "known"] = Field(
        "own",
        description="Algorithm 3's T_available = T minus the tasks already in a bundle: own (this robot's) or "
        "known (any bundle it knows of, which forbids outbidding a known winner)",
    )
    consensus_wait: Literal["free", "round", "agree"] | None = Field(
        None,
        description="what a consensus costs the robot in simulated time (docs/reproduction.md sections 1 and 5): "
        "free (nothing: it acts in the tick it announced), round (one "
        "communication round: it stands still round_ticks ticks listening, then acts on what came back), "
        "agree (rounds until one brings nothing new, a local agreement, at most max_rounds); "
        "None: as the text has it, agree for cbba and cbba-tree, round for cbba-etc",
    )
    round_ticks: int = Field(
        2, ge=1, description="ticks a round listens for replies (2: a neighbour's answer, out and back)"
    )
    max_rounds: int = Field(
        10, ge=1, description="consensus_wait agree (and a c-cbba leader's exchange): rounds at most before acting"
    )


class ReactiveParams(ConsensusParams):
    while_busy: Literal["hold", "negotiate"] = Field(
        "hold",
        description="cbba and c-cbba, state machines whose action cycle is build, consensus, execute in "
        "turn: hold (an inspection or rescue under way is the cycle's execute step; the robot builds and "
        "starts a round again once it ends) or negotiate (it keeps building and starting rounds while it "
        "holds to the action). Only while it holds (allocator.monitor off)",
    )


class SARConsensus(SARStrategy):
    Params = ConsensusParams
    params: ConsensusParams
    message_kinds: ClassVar[tuple[str, ...]] = (BIDS,)
    event_names: ClassVar[tuple[str, ...]] = ("negotiations",)
    bids_with_colors: ClassVar[bool] = True
    version = "2"  # 2: consensus messages carry packed arrays (plugins/consensus.py); the same decisions
    bt_nodes = SAR_NODES + (ExplorationNode,)

    def __init__(self, agent_id, params, rng, run_seed=0):
        super().__init__(agent_id, params, rng, run_seed)
        self.state = ConsensusState(agent_id, self.params.full_every)
        self.last_round = -math.inf
        self.bundle_at_round: list[int] | None = None
        self.lost = 0  # bundle victims lost to others' bids since the last round
        self.lost_last = 0  # Lc: lost in the last round
        self.lost_before = 0  # Lc of the round before
        self.round_began: int | None = None  # tick of the round under way, while the robot waits on it
        self.rounds_in = 0  # rounds of the consensus under way
        self.news = False  # the round under way taught the robot a winner or a bid

    # -- knowledge -------------------------------------------------------------------------------
    def observe(self, view: LocalView) -> None:
        self.state.now = view.time
        super().observe(view)

    def forget(self, victim: int) -> None:
        super().forget(victim)
        self.state.forget(victim)

    def receive(self, view: LocalView) -> None:
        listening = self.round_began is not None and bool(view.inbox)
        if listening:
            winners, bids = dict(self.state.z), dict(self.state.y)
        for msg in view.inbox:
            if msg.kind in self.consensus_kinds(msg.sender):
                self.state.receive(msg.sender, msg.data, ignore=self.gone)
        if listening and (self.state.z != winners or self.state.y != bids):
            self.news = True
        self.state.drop_stale_winners(self.now - self.params.winner_timeout)
        self.release_outbid()

    def consensus_kinds(self, sender: int) -> tuple[str, ...]:
        return (BIDS,)

    def release_outbid(self) -> None:
        st = self.state
        self.lost += sum(1 for v in st.bundle if st.z.get(v) != self.agent_id)
        st.release()

    def holds(self, v: int) -> bool:
        return self.state.z.get(v) == self.agent_id

    def released(self, victim: int, view: LocalView) -> None:
        self.state.forget(victim)  # let others bid on it; the next round says so

    # -- Algorithm 3 -------------------------------------------------------------------------------
    def utility(self, view: LocalView, v: int) -> float:
        u = 1.0 / (self.distance(view, v) + self.params.epsilon)
        known = self.colors.get(v, -1)
        return u * self.params.mismatch_factor if known >= 0 and known != self.my_color else u

    def build_bundle(self, view: LocalView) -> bool:
        st = self.state
        if self.params.bundle_build == "rebuild":  # B_i <- empty: this robot's claims go with it
            for v in list(st.bundle):
                if st.z.get(v) == self.agent_id:
                    st.reset(v)
            st.bundle.clear()
            st.path.clear()
        known_elsewhere = self.params.available == "known"
        while len(st.bundle) < self.params.max_tasks:
            best, best_u = None, 0.0
            for v in self.candidates():
                if v in st.bundle or (known_elsewhere and st.z.get(v, self.agent_id) != self.agent_id):
                    continue
                u = self.utility(view, v)
                if u > best_u and st.eligible(v, u):
                    best, best_u = v, u
            if best is None:
                break
            st.add(best, best_u)
        return bool(st.bundle)

    def select_new_target(self, view: LocalView) -> bool:
        self.target = self.state.bundle[0] if self.state.bundle else None
        return self.target is not None

    # -- consensus -----------------------------------------------------------------------------------
    #: what ``consensus_wait: None`` means for this strategy
    WAIT: ClassVar[str] = "agree"

    @property
    def wait(self) -> str:
        return self.WAIT if self.params.consensus_wait is None else self.params.consensus_wait

    def run_consensus(self, view: LocalView) -> None:
        """Announce one round."""
        self.broadcast_round(view)
        self.count("negotiations")
        self.close_round()

    def close_round(self) -> None:
        """Book a round's start: when, and the bundle it announced."""
        self.last_round = self.now
        self.bundle_at_round = list(self.state.bundle)

    def book_losses(self) -> None:
        """A consensus ended: the tasks lost since the last one ended are its Lc (with a consensus
        that takes time, its replies are in)."""
        self.lost_before, self.lost_last, self.lost = self.lost_last, self.lost, 0

    def start_consensus(self, view: LocalView) -> bool:
        """Run a consensus; True while the robot waits on it (its action held: it stands still).
        A robot busy inspecting or rescuing (monitor on, or while_busy negotiate) does not break
        off to wait: for it a round is free."""
        if self.wait == "free" or self.busy:
            self.run_consensus(view)
            self.book_losses()
            return False
        self.round_began, self.rounds_in, self.news = view.tick, 1, False
        self.run_consensus(view)
        return True

    def consensus_step(self, view: LocalView) -> bool:
        """A tick of the consensus under way (its replies already received); True while it goes on."""
        assert self.round_began is not None, "consensus_step() outside a consensus"
        if view.tick - self.round_began < self.params.round_ticks:
            return True
        if self.wait == "agree" and self.rounds_in < self.params.max_rounds:
            announced = self.bundle_at_round
            self.build_bundle(view)
            if self.news or self.state.bundle != announced:
                self.round_began, self.news = view.tick, False
                self.rounds_in += 1
                self.run_consensus(view)
                return True
        self.end_consensus()
        return False

    def end_consensus(self) -> None:
        """The consensus is over (agreed, its rounds spent, or its node halted)."""
        if self.round_began is not None:
            self.round_began = None
            self.book_losses()

    def broadcast_round(self, view: LocalView) -> None:
        view.broadcast(BIDS, self.state.message())

    def should_trigger(self, view: LocalView) -> bool:
        raise NotImplementedError

    def adapt_interval(self) -> None:
        """Only cbba-etc adapts its interval."""

    def acquire(self, view: LocalView) -> bool:
        """The acquisition branch in one call (a consensus that takes time needs the tree's
        RunConsensus node): build, consensus if triggered, select."""
        self.build_bundle(view)
        if self.should_trigger(view):
            self.run_consensus(view)
            self.book_losses()
            self.adapt_interval()
        return self.select_new_target(view)


class ReactiveCBBA(SARConsensus):
    """``cbba``: a state machine. Each tick it keeps its bundle full, starts a round whenever the
    bundle changed since its last one (or ``period`` seconds passed), and works its first victim."""

    Params = ReactiveParams
    params: ReactiveParams
    default_tree = str(TREES / "cbba_fsm.xml")
    #: "structured as a state machine within the robot's main action cycle rather than a Behavior
    #: Tree" (Section 5.2): no condition node watches its target while it acts
    MONITORS = False

    def should_trigger(self, view: LocalView) -> bool:
        return self.state.bundle != self.bundle_at_round or self.now - self.last_round >= self.params.period

    def fsm_step(self, view: LocalView) -> list | None:
        if self.round_began is not None:  # negotiating: "achieving consensus" before executing
            if self.consensus_step(view):
                return ["stop"]
            if not self.target_valid(view):
                self.select_new_target(view)
            return self.execute(view)
        if self.holding and self.params.while_busy == "hold":
            # "a continuous loop of building a bundle, achieving consensus, and executing the
            # highest-priority task remaining" (Section 5.2): while the action runs, the loop is in
            # its execute step
            return self.execute(view)
        self.build_bundle(view)
        if not self.target_valid(view):
            self.select_new_target(view)
        if self.should_trigger(view) and self.start_consensus(view):
            return ["stop"]
        return self.execute(view)


class CBBATree(SARConsensus):
    """``cbba-tree``: CBBA inside the behavior tree; consensus only when ``period`` has elapsed."""

    default_tree = str(TREES / "cbba_tree.xml")

    def should_trigger(self, view: LocalView) -> bool:
        return self.now - self.last_round >= self.params.period


class ETCParams(ConsensusParams, IntervalParams):
    theta_bid_change: float = Field(0.1, ge=0, description="Tr_delta_bid: utility change of the primary task")
    theta_outbid_margin: float = Field(0.05, ge=0, description="Tr_conflict: margin over a known winning bid")
    trace_rounds: bool = Field(
        False,
        description="log every round (time, triggers fired, Lc, dLc, interval) to the "
        "agent's log, for audits (docs/reproduction.md)",
    )


class CBBAETC(SARConsensus):
    """``cbba-etc``: consensus only on events (Algorithm 4). Tr_init: a new non-empty bundle after
    an empty one; Tr_delta_bid: the primary task's utility moved more than ``theta_bid_change``
    since the last cycle; Tr_conflict: this robot could outbid a known winner by more than
    ``theta_outbid_margin``; Tr_fallback: the adaptive interval has elapsed."""

    Params = ETCParams
    params: ETCParams
    #: "configured to be completed in a single communication round to facilitate rapid
    #: decision-making" (Section 4)
    WAIT = "round"
    event_names = ("negotiations", "tr_init", "tr_delta_bid", "tr_conflict", "tr_fallback")
    default_tree = str(TREES / "cbba_etc.xml")

    def __init__(self, agent_id, params, rng, run_seed=0):
        super().__init__(agent_id, params, rng, run_seed)
        self.interval = params.base_interval * params.phi_min
        self.u_prev: dict[int, float] = {}
        self.last_triggers: dict[str, bool] = {}

    def triggers(self, view: LocalView) -> dict[str, bool]:
        p, st = self.params, self.state
        bundle = st.bundle
        primary = bundle[0] if bundle else None
        return {
            "tr_init": bool(bundle) and not self.bundle_at_round,
            "tr_delta_bid": primary is not None
            and primary in self.u_prev
            and abs(self.utility(view, primary) - self.u_prev[primary]) > p.theta_bid_change,
            "tr_conflict": any(
                v not in bundle
                and st.z.get(v, self.agent_id) != self.agent_id
                and self.utility(view, v) > st.y[v] + p.theta_outbid_margin
                for v in self.candidates()
            ),
            "tr_fallback": self.now - self.last_round >= self.interval,
        }

    def should_trigger(self, view: LocalView) -> bool:
        fired = self.triggers(view)
        self.last_triggers = fired
        for name, on in fired.items():
            if on:
                self.count(name)
        self.u_prev = {v: self.utility(view, v) for v in self.state.bundle}  # Algorithm 4, line 16
        return any(fired.values())

    def adapt_interval(self) -> None:
        before = self.interval
        self.interval = next_interval(self.interval, self.lost_last, self.lost_last - self.lost_before, self.params)
        if self.params.trace_rounds:
            fired = ",".join(name for name, on in self.last_triggers.items() if on)
            log.info(
                "round t=%.3f triggers=%s Lc=%d dLc=%d interval=%.3f->%.3f",
                self.now,
                fired,
                self.lost_last,
                self.lost_last - self.lost_before,
                before,
                self.interval,
            )
