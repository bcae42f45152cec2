"""The CBBA-ETC strategies in-process: the adaptive interval (Eqs. 2-4), each event trigger on a
case built for it, C-CBBA's clustering and who talks to whom, and lost robots' claims lapsing."""

import math

import numpy as np
import pytest

from swarmbed.checks.allocator_kit import random_instance, simulate
from swarmbed.extension import LocalView, Message, TaskInfo
from swarmbed.plugins.consensus import consensus_message
from swarmbed.plugins.registry import make
from swarmbed.plugins.sar.ccbba import ClusteringCBBA, kmeans_pp
from swarmbed.plugins.sar.interval import IntervalParams, next_interval, omega, sigmoid
from swarmbed.scenarios.sar import SARObservation
from swarmbed.wire.codec import EMPTY_INBOX, TASK_DTYPE

P = IntervalParams()  # the paper's values: rho 1, theta 3/1, mu 10, kappa 0.1, lambda 6, gamma 0.001, phi 3..8


def test_interval_shrinks_slowly_under_high_conflict():
    lost = 5
    expected = P.kappa * sigmoid(lost - P.theta_high, P.mu) * (1 + P.gamma)  # rising conflict
    assert omega(lost, +2, P) == pytest.approx(expected)
    mid = P.base_interval * 6  # inside [phi_min, phi_max] x I_base
    assert next_interval(mid, lost, +2, P) == pytest.approx(mid * (P.rho_base - expected))
    falling = P.kappa * sigmoid(lost - P.theta_high, P.mu) * (1 - P.gamma)
    assert omega(lost, -1, P) == pytest.approx(falling)


def test_interval_holds_in_the_dead_zone():
    assert omega(2, 1, P) == 0.0
    mid = P.base_interval * 5
    assert next_interval(mid, 2, 1, P) == mid


def test_interval_stretches_fast_when_calm():
    expected = -P.lam * sigmoid(P.theta_low - 0, P.mu) * (1 + P.gamma)  # sign(-dLc) = +1 for dLc < 0
    assert omega(0, -1, P) == pytest.approx(expected)
    start = P.base_interval * 3.5
    stretched = min(start * (1 - expected), P.base_interval * P.phi_max)
    assert next_interval(start, 0, -1, P) == pytest.approx(stretched)


def test_interval_is_clipped_to_both_bounds():
    low, high = P.base_interval * P.phi_min, P.base_interval * P.phi_max
    assert next_interval(high, 0, 0, P) == high  # calm would stretch it past phi_max
    assert next_interval(low, 10, 5, P) == low  # conflict would shrink it below phi_min
    assert next_interval(high * 10, 2, 0, P) == high
    assert next_interval(low / 100, 2, 0, P) == low


# -- event triggers ------------------------------------------------------------------------------


def view(t, x, y, victims, inbox=(), agent=0, color=0, busy=0):
    tasks = {v: TaskInfo(v, vx, vy, 100.0, c) for v, (vx, vy, c) in victims.items()}
    obs = SARObservation(
        float(t),
        x,
        y,
        0.0,
        0.0,
        np.empty(0, TASK_DTYPE),
        color=color,
        reach=5.0,
        robots=[],
        inspected=[],
        rescued=[],
        busy=busy,
    )
    return LocalView(
        agent, 4, int(t), float(t), x, y, 0.0, 0.0, 1.0, tasks, list(inbox), 11.1, math.inf, 2 * math.pi, obs
    )


def etc(**params):
    return make("cbba-etc", {"max_tasks": 1, **params}, 0, np.random.default_rng(0), 0, "sar")


def fire(strategy, v):
    strategy.observe(v)
    strategy.build_bundle(v)
    return strategy.should_trigger(v), strategy.last_triggers


def run_round(strategy, v):
    strategy.run_consensus(v)
    strategy.adapt_interval()


def test_tr_init_fires_on_a_new_plan_and_stays_quiet_after():
    s = etc()
    on, fired = fire(s, view(0, 0, 0, {1: (5, 0, 0)}))
    assert on and fired["tr_init"]
    run_round(s, view(0, 0, 0, {1: (5, 0, 0)}))
    _, fired = fire(s, view(1, 0, 0, {1: (5, 0, 0)}))
    assert fired == {"tr_init": False, "tr_delta_bid": False, "tr_conflict": False, "tr_fallback": False}


def test_tr_delta_bid_fires_when_the_primary_utility_moves():
    s = etc(theta_bid_change=0.05)
    fire(s, view(0, 0, 0, {1: (20, 0, 0)}))
    run_round(s, view(0, 0, 0, {1: (20, 0, 0)}))
    _, fired = fire(s, view(1, 1, 0, {1: (20, 0, 0)}))  # 1/20 -> 1/19: a small change
    assert not fired["tr_delta_bid"]
    _, fired = fire(s, view(2, 15, 0, {1: (20, 0, 0)}))  # 1/19 -> 1/5
    assert fired["tr_delta_bid"]


def test_tr_conflict_fires_when_a_known_winner_can_be_outbid():
    s = etc(theta_outbid_margin=0.05)
    victims = {1: (2, 0, 0), 2: (4, 0, 0)}  # victim 1 fills the one-task bundle; victim 2 is won by robot 3
    fire(s, view(0, 0, 0, victims))
    run_round(s, view(0, 0, 0, victims))
    weak = Message(3, "bids", consensus_message(0.5, [(2, 3, 0.01)], []))
    _, fired = fire(s, view(1, 0, 0, victims, [weak]))
    assert fired["tr_conflict"] and not fired["tr_init"] and not fired["tr_fallback"]
    mine = 1 / (4 + s.params.epsilon)  # this robot's utility for victim 2
    within_margin = Message(3, "bids", consensus_message(1.5, [(2, 3, mine - 0.02)], []))
    _, fired = fire(s, view(2, 0, 0, victims, [within_margin]))
    assert not fired["tr_conflict"]  # it would win, but not by theta_outbid_margin
    strong = Message(3, "bids", consensus_message(2.5, [(2, 3, 5.0)], []))
    _, fired = fire(s, view(3, 0, 0, victims, [strong]))
    assert not fired["tr_conflict"]


def test_tr_fallback_fires_when_the_adaptive_interval_elapses():
    s = etc()
    fire(s, view(0, 0, 0, {1: (5, 0, 0)}))
    run_round(s, view(0, 0, 0, {1: (5, 0, 0)}))
    interval = s.interval
    assert P.base_interval * P.phi_min <= interval <= P.base_interval * P.phi_max
    _, fired = fire(s, view(interval - 1, 0, 0, {1: (5, 0, 0)}))
    assert not fired["tr_fallback"]
    _, fired = fire(s, view(interval, 0, 0, {1: (5, 0, 0)}))
    assert fired["tr_fallback"]


# -- C-CBBA ----------------------------------------------------------------------------------------


def test_kmeans_clustering_is_deterministic_under_a_seed():
    points = np.random.default_rng(1).uniform(-30, 30, (20, 2))
    a = kmeans_pp(points, 2, np.random.default_rng(7))
    b = kmeans_pp(points, 2, np.random.default_rng(7))
    assert (a == b).all() and len(set(a)) == 2
    team = [[i, x, y] for i, (x, y) in enumerate(points)]
    robots = [make("c-cbba", {}, i, np.random.default_rng(i), 42, "sar") for i in range(20)]
    for r in robots:
        r.setup(team)
    assert len({tuple(r.leaders) for r in robots}) == 1  # everyone agrees on the leaders
    for r in robots:
        assert r.leader == min([r.leader] + r.members) and (r.is_leader or r.agent_id not in r.leaders)


def test_ccbba_members_talk_only_to_their_leader():
    inst = random_instance(3, 12, 30, scenario="sar")
    trace = simulate("c-cbba", {}, inst, 40, seed=9, scenario="sar")
    robots: list[ClusteringCBBA] = trace.allocators
    leader_of = {r.agent_id: r.leader for r in robots}
    sent_by_members = 0
    for rnd in trace.messages:
        for sender, kind, _ in rnd:
            if leader_of[sender] != sender:
                sent_by_members += 1
                assert kind == "bids"
    assert sent_by_members > 0
    # and each of those went to that member's leader alone (the radio's ledger: one copy each)
    for sender, row in trace.radio.ledger.per_sender().items():
        if leader_of[sender] != sender:
            assert row["copies"] == row["messages"]


def test_ccbba_leaders_relay_news_not_echoes():
    """Once the clusters agree (a static instance converges in a few rounds), a leader sends the
    other leader nothing until something changes or its period passes: the two leaders once echoed
    the same state to each other every tick."""
    inst = random_instance(3, 12, 30, scenario="sar")
    trace = simulate("c-cbba", {"period": 100.0}, inst, 100, seed=9, scenario="sar")
    leaders = {r.agent_id for r in trace.allocators if r.is_leader}
    assert len(leaders) == 2
    relays = [sum(1 for sender, kind, _ in rnd if sender in leaders and kind == "leaders") for rnd in trace.messages]
    assert sum(relays[:10]) > 0  # they did talk while the views differed
    assert sum(relays[40:]) == 0, relays


# -- a lost robot's claims stop mattering -----------------------------------------------------------


def test_comm_claims_of_a_silent_robot_lapse():
    b = make("comm", {"claim_ttl": 30.0}, 1, np.random.default_rng(0), 0, "sar")
    victims = {7: (3, 0, -1)}
    b.observe(view(0, 0, 0, victims, [Message(0, "claim", 7)], agent=1))
    assert not b.acquire(view(0, 0, 0, victims, agent=1))  # robot 0 claimed it
    b.observe(view(31, 0, 0, victims, agent=1))
    assert b.acquire(view(31, 0, 0, victims, agent=1)) and b.target == 7


def test_cbba_wins_of_a_silent_robot_lapse():
    b = make("cbba-etc", {"winner_timeout": 100.0}, 1, np.random.default_rng(0), 0, "sar")
    victims = {7: (3, 0, -1)}
    won = Message(0, "bids", consensus_message(0.0, [(7, 0, 50.0)], []))
    b.observe(view(0, 0, 0, victims, [won], agent=1))
    assert not b.build_bundle(view(0, 0, 0, victims, agent=1))  # outbid by robot 0's 50.0
    b.observe(view(101, 0, 0, victims, agent=1))
    assert b.build_bundle(view(101, 0, 0, victims, agent=1)) and b.state.bundle == [7]


# -- Algorithm 3's two readings (issue 31 item 3) -----------------------------------------------------


def test_rebuild_starts_each_build_from_an_empty_bundle_and_top_up_keeps_the_old_order():
    """A robot that moved: its old first victim is now the farther one. Topping up keeps the bundle
    as built; B_i <- empty builds it again, nearest first."""
    victims = {1: (10, 0, 0), 2: (20, 0, 0)}
    for build, expected in (("top_up", [1, 2]), ("rebuild", [2, 1])):
        s = make("cbba", {"max_tasks": 2, "bundle_build": build}, 0, np.random.default_rng(0), 0, "sar")
        first = view(0, 0, 0, victims)
        s.observe(first)
        s.build_bundle(first)
        assert s.state.bundle == [1, 2]
        moved = view(1, 19, 0, victims)
        s.observe(moved)
        s.build_bundle(moved)
        assert s.state.bundle == expected, build
        assert all(s.state.z[v] == 0 for v in expected)


def test_available_known_never_bids_on_a_victim_another_robot_is_known_to_win():
    """T_available = T minus the tasks in any bundle the robot knows of: robot 3's weak claim on the
    nearest victim is outbid under 'own' and left alone under 'known'."""
    victims = {1: (2, 0, 0), 2: (30, 0, 0)}
    for available, expected in (("own", [1]), ("known", [2])):
        s = make("cbba", {"max_tasks": 1, "available": available}, 0, np.random.default_rng(0), 0, "sar")
        s.state.z[1], s.state.y[1], s.state.s[3] = 3, 0.01, 0.0  # robot 3, heard at time 0, claims victim 1 low
        v = view(0, 0, 0, victims)
        s.observe(v)
        s.build_bundle(v)
        assert s.state.bundle == expected, available


# -- a state machine busy with its action (issue 44 item 4) -----------------------------------------


@pytest.mark.parametrize("while_busy", ["hold", "negotiate"])
def test_a_cbba_robot_holding_an_inspection_builds_and_negotiates_only_if_asked(while_busy):
    """cbba's action cycle is build, consensus, execute in turn: while an inspection runs (the robot
    holds to it: monitor off) a new victim nearer than its bundle's changes nothing with ``hold``;
    with ``negotiate`` its bundle changes and it starts a round at once. Once the action ends it
    builds and negotiates either way."""
    params = {"max_tasks": 2, "while_busy": while_busy, "consensus_wait": "free"}
    s = make("cbba", params, 0, np.random.default_rng(0), 0, "sar")
    first = {1: (3, 0, 0), 2: (40, 0, 0)}
    s.observe(view(0, 0, 0, first))
    assert s.fsm_step(view(0, 0, 0, first)) == ["inspect", 1] and s.events == {"negotiations": 1}
    s.events = {}
    more = {**first, 3: (4, 0, 0)}  # a nearer second victim comes into view while robot 0 inspects 1
    s.observe(view(1, 0, 0, more, busy=5))
    assert s.fsm_step(view(1, 0, 0, more, busy=5)) == ["inspect", 1]  # it holds to its inspection either way
    assert s.events == ({} if while_busy == "hold" else {"negotiations": 1}), s.events
    assert s.state.bundle == ([1, 2] if while_busy == "hold" else [1, 3])
    s.events = {}
    s.observe(view(2, 0, 0, more))  # the inspection is over
    s.fsm_step(view(2, 0, 0, more))
    assert s.state.bundle == [1, 3] and s.events == ({"negotiations": 1} if while_busy == "hold" else {})


# -- a consensus that takes simulated time (issue 44 item 2) ----------------------------------------


def run_fsm(s, steps):
    """Tick a state-machine strategy through ``steps`` (inbox per tick); its actions."""
    victims = {1: (3, 0, 0), 2: (40, 0, 0)}
    actions = []
    for tick, inbox in enumerate(steps):
        v = view(tick, 0, 0, victims, inbox, agent=s.agent_id)
        s.observe(v)
        actions.append(s.fsm_step(v))
        s.outbox = list(v.outbox)
    return actions


#: robot 1 wins victim 1 (3 m from robot 0) with a bid robot 0 cannot beat, heard at tick 2
OUTBID = [(), (), [Message(1, "bids", consensus_message(1.0, [(1, 1, 50.0)], []))], (), (), ()]


@pytest.mark.parametrize(
    "wait, expected, rounds",
    [
        # free: it acts in the tick it announces; the reply turns it to victim 2 at once
        ("free", [["inspect", 1], ["inspect", 1], ["goto_task", 2], ["goto_task", 2]], 2),
        # one round: it listens two ticks (out and back), then acts on what came: victim 1 is lost
        # and its bundle empty, so it wanders (None) until the next build
        ("round", [["stop"], ["stop"], None], 1),
        # rounds until one brings nothing new: the reply starts a second round on victim 2
        ("agree", [["stop"], ["stop"], ["stop"], ["stop"], ["goto_task", 2]], 2),
    ],
)
def test_cbba_stands_still_while_its_consensus_takes_rounds(wait, expected, rounds):
    s = make("cbba", {"max_tasks": 1, "consensus_wait": wait}, 0, np.random.default_rng(0), 0, "sar")
    actions = run_fsm(s, OUTBID[: len(expected)])
    assert actions == expected
    assert s.events["negotiations"] == rounds


def test_cbba_waits_by_default_and_agreement_is_capped_at_max_rounds():
    s = make("cbba", {"max_tasks": 1}, 0, np.random.default_rng(0), 0, "sar")
    assert s.wait == "agree" and run_fsm(s, OUTBID[:1]) == [["stop"]]
    capped = make("cbba", {"max_tasks": 1, "max_rounds": 1}, 0, np.random.default_rng(0), 0, "sar")
    assert run_fsm(capped, OUTBID[:3]) == [["stop"], ["stop"], None]  # no second round: it acts


def test_a_busy_robot_does_not_break_off_its_inspection_to_wait():
    """monitor on: the robot builds and negotiates while it inspects, but the round costs it nothing."""
    s = make("cbba", {"max_tasks": 1, "monitor": True}, 0, np.random.default_rng(0), 0, "sar")
    victims = {1: (3, 0, 0)}
    v = view(0, 0, 0, victims, busy=5)
    s.observe(v)
    assert s.fsm_step(v) == ["inspect", 1] and s.events == {"negotiations": 1}
    assert s.round_began is None


def test_cbba_etc_books_the_losses_of_its_round_when_the_round_ends():
    """Lc, the tasks lost in the last round, feeds the adaptive interval: with a round that takes
    time the reply that outbids the robot is in it; with a free round it lands in the next."""
    for wait, lost in (("round", 1), ("free", 0)):
        s = etc(consensus_wait=wait)
        victims = {1: (3, 0, 0)}
        v0 = view(0, 0, 0, victims)
        s.observe(v0)
        s.build_bundle(v0)
        waiting = s.start_consensus(v0)
        assert waiting == (wait == "round")
        for tick in (1, 2):
            inbox = OUTBID[tick]
            v = view(tick, 0, 0, victims, inbox)
            s.observe(v)
            if waiting:
                assert s.consensus_step(v) == (tick < 2)
        assert s.lost_last == lost, wait


def ccbba_robot(agent, wait, **params):
    team = [(0, 0.0, 0.0), (1, 1.0, 0.0), (2, 60.0, 60.0)]  # clusters {0, 1} led by 0, {2}
    r = make("c-cbba", {"max_tasks": 1, "consensus_wait": wait, **params}, agent, np.random.default_rng(0), 0, "sar")
    r.setup(team)
    assert r.leaders == [0, 2] and r.leader == 0
    return r


def sent(r):
    return [(out.dest, out.kind) for out in r.outbox]


def test_a_ccbba_member_stands_still_until_its_leaders_result_arrives():
    result = [Message(0, "result", consensus_message(2.0, [(1, 1, 1 / 3)], []))]
    member = ccbba_robot(1, "leaders")
    actions = run_fsm(member, [(), (), (), result, ()])
    assert actions[:3] == [["stop"]] * 3 and actions[3] == ["inspect", 1]
    free = ccbba_robot(1, "free")
    assert run_fsm(free, [()])[0] == ["inspect", 1]  # it acts as it sends
    deaf = ccbba_robot(1, "leaders", leader_wait=4)  # the result never comes: it gives up waiting
    assert run_fsm(deaf, [()] * 5) == [["stop"]] * 4 + [["inspect", 1]]


def test_a_ccbba_leader_answers_its_cluster_only_once_the_leaders_settle():
    leader = ccbba_robot(0, "leaders")
    steps = []
    for tick in range(6):
        v = view(tick, 0, 0, {1: (3, 0, 0)}, agent=0)
        leader.observe(v)
        steps.append((leader.fsm_step(v), sorted((out.dest, out.kind) for out in v.outbox)))
    assert steps == [
        (["stop"], [((2,), "leaders")]),  # its first relay (period); then its bundle changes: its own round
        (["stop"], []),  # listening to the other leader
        (["stop"], [((2,), "leaders")]),  # what changed meanwhile: a second leaders' round
        (["stop"], []),
        (["inspect", 1], [((1,), "result")]),  # nothing new from the other leader: the result goes out
        (["inspect", 1], []),
    ]
    free = ccbba_robot(0, "free")
    v0, v1 = view(0, 0, 0, {1: (3, 0, 0)}), view(1, 0, 0, {1: (3, 0, 0)})
    free.observe(v0)
    assert free.fsm_step(v0) == ["inspect", 1]
    free.observe(v1)
    assert sorted((out.dest, out.kind) for out in v0.outbox + v1.outbox) == [
        ((1,), "result"),
        ((1,), "result"),
        ((2,), "leaders"),
        ((2,), "leaders"),
    ]  # leaders and cluster told together, in the tick it relays


@pytest.mark.parametrize("strategy", ["cbba-tree", "cbba-etc"])
def test_the_trees_runconsensus_node_keeps_the_robot_still_while_its_round_runs(strategy):
    """The shipped behavior tree, in the agent runtime: a robot with no target sees a victim 20 m
    away, builds, starts a round and selects. With a round that takes time (the default) it
    stands (``stop``) for the round's two ticks before it moves; with ``free`` it moves a tick
    after it announced."""
    from swarmbed.agent_runtime.runtime import AgentRuntime
    from swarmbed.config import resolve_experiment
    from swarmbed.schema.experiment import agent_spec
    from tests.conftest import SAR_BASE, experiment

    def first_actions(wait: str) -> list:
        exp = experiment(f"allocator={{name: {strategy}, consensus_wait: {wait}}}", "agents.count=2", base=SAR_BASE)
        runtime = AgentRuntime(agent_spec(exp, resolve_experiment(exp).targets), 0)
        table = np.zeros(1, dtype=TASK_DTYPE)
        table["id"], table["x"], table["remaining"], table["color"] = 7, 20.0, 90.0, -1
        actions = []
        for tick in range(5):
            obs = SARObservation(
                tick * 0.25, 0.0, 0.0, 0.0, 0.0, table, color=0, reach=5.0, robots=[], inspected=[], rescued=[], busy=0
            )
            action, _, _ = runtime.step(tick, obs, EMPTY_INBOX)
            actions.append(action[0])
        return actions

    default = "agree" if strategy == "cbba-tree" else "round"
    assert first_actions(default) == ["stop", "stop", "stop", "goto_task", "goto_task"]
    assert first_actions("free") == ["stop", "goto_task", "goto_task", "goto_task", "goto_task"]
