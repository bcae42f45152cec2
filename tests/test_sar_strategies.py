"""The CBBA-ETC strategies in-process: the adaptive interval (Eqs. 2-4), each event trigger on a
case built for it, C-CBBA's clustering and who talks to whom, and lost robots' claims lapsing."""

import math

import numpy as np
import pytest

from swarmbed.extension import LocalView, Message, TaskInfo
from swarmbed.plugins.checks.allocator import random_instance, simulate
from swarmbed.plugins.registry import make
from swarmbed.plugins.sar.ccbba import ClusteringCBBA, kmeans_pp
from swarmbed.plugins.sar.interval import IntervalParams, next_interval, omega, sigmoid
from swarmbed.scenarios.sar import SARObservation
from swarmbed.wire.codec import TASK_DTYPE

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
    weak = Message(3, "bids", {"t": 0.5, "w": [[2, 3, 0.01]], "s": []})
    _, fired = fire(s, view(1, 0, 0, victims, [weak]))
    assert fired["tr_conflict"] and not fired["tr_init"] and not fired["tr_fallback"]
    mine = 1 / (4 + s.params.epsilon)  # this robot's utility for victim 2
    within_margin = Message(3, "bids", {"t": 1.5, "w": [[2, 3, mine - 0.02]], "s": []})
    _, fired = fire(s, view(2, 0, 0, victims, [within_margin]))
    assert not fired["tr_conflict"]  # it would win, but not by theta_outbid_margin
    strong = Message(3, "bids", {"t": 2.5, "w": [[2, 3, 5.0]], "s": []})
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
    won = Message(0, "bids", {"t": 0.0, "w": [[7, 0, 50.0]], "s": []})
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
    s = make("cbba", {"max_tasks": 2, "while_busy": while_busy}, 0, np.random.default_rng(0), 0, "sar")
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
