"""Algorithm properties on random static instances with full connectivity (fixed seeds)."""

import itertools
import json
import math

import numpy as np
import pytest

from swarmbed import kernels
from swarmbed.checks.allocator_kit import CLEAN_NETWORK as CLEAN
from swarmbed.checks.allocator_kit import random_instance, run_all, simulate
from swarmbed.extension import HALT, HOLD, LocalView, Message, TaskInfo
from swarmbed.plugins import consensus
from swarmbed.plugins.cbba import CBBA
from swarmbed.plugins.consensus import NONE, ConsensusState, consensus_message, read_message, table, table_masks
from swarmbed.plugins.grape import VOID, pack_pairs, read_pairs
from swarmbed.plugins.registry import entries, make
from swarmbed.schema.experiment import NetworkSection
from swarmbed.wire.codec import pack, unpack
from tests.conftest import experiment

LOSSY = NetworkSection(loss=0.3)


@pytest.mark.parametrize("name, scenario", [(n, "mtsr" if k == "*" else k) for n, k in entries()])
def test_every_registered_allocator_passes_the_kit(name, scenario):
    run_all(name, scenario=scenario)


def test_grape_with_messages_of_what_changed_passes_the_kit():
    run_all("grape", {"full_every": 10})


def _state(a: CBBA):
    return (tuple(a.bundle), tuple(sorted(a.z.items())), tuple(sorted(a.y.items())))


def sequential_greedy(inst, max_tasks, discount, speed):
    """Centralized SGA with a path-independent score: repeatedly give the best (agent, task) pair."""
    score = {
        (i, j): discount ** (math.hypot(tx - ax, ty - ay) / speed) * w
        for i, (ax, ay) in enumerate(inst.agents)
        for j, (tx, ty, w) in inst.tasks.items()
    }
    load = dict.fromkeys(range(len(inst.agents)), 0)
    assigned = {}
    while True:
        free = [(s, -i, -j) for (i, j), s in score.items() if j not in assigned and load[i] < max_tasks and s > 0]
        if not free:
            return assigned
        s, i, j = max(free)
        assigned[-j] = -i
        load[-i] += 1


@pytest.mark.parametrize("score", ["time_discounted", "distance_discounted"])
def test_cbba_converges_conflict_free_within_the_bound(score):
    rng = np.random.default_rng(2009)
    for case in range(150):
        n_a, n_t, l_t = int(rng.integers(2, 7)), int(rng.integers(1, 13)), int(rng.integers(1, 5))
        inst = random_instance(case, n_a, n_t)
        bound = min(n_t, l_t * n_a) * 1  # diameter 1: full connectivity
        params = {"max_tasks": l_t, "score": score, "reset_after": None}
        # round 0 builds bundles before any message can arrive, so CBBA's iteration t ends at round t+1
        trace = simulate("cbba", params, inst, bound + 1, seed=case)
        agents = trace.allocators
        # converged: nothing changes in the extra rounds after the bound
        states = [_state(a) for a in agents]
        extra = simulate("cbba", params, inst, bound + 12, seed=case).allocators
        assert states == [_state(a) for a in extra], f"case {case}: still changing after {bound} rounds"
        owners = {}
        for a in agents:
            for t in a.bundle:
                assert t not in owners, f"case {case}: task {t} in the bundles of {owners[t]} and {a.agent_id}"
                owners[t] = a.agent_id
        for a in agents:
            assert a.z == agents[0].z, f"case {case}: agents disagree on winners"
        assert dict(agents[0].z.items()) == owners
        # every task is taken unless every bundle is full
        if len(owners) < n_t:
            assert all(len(a.bundle) == l_t for a in agents), f"case {case}: tasks left while bundles had room"


@pytest.mark.parametrize("full_every, lossy", [(1, False), (10, False), (1, True), (10, True)])
def test_cbba_matches_sequential_greedy_with_a_path_independent_score(full_every, lossy):
    """With whole messages, and with messages of what changed between whole ones (the default);
    on a clean network and with 30 % of the copies lost (given more rounds: a lost delta is made
    good only by the sender's next whole message)."""
    for case in range(200 if not lossy else 50):
        rng = np.random.default_rng(case)
        n_a, n_t, l_t = int(rng.integers(2, 6)), int(rng.integers(1, 15)), int(rng.integers(1, 4))
        inst = random_instance(1000 + case, n_a, n_t)
        params = {
            "max_tasks": l_t,
            "score": "distance_discounted",
            "discount": 0.99,
            "reset_after": None,
            "full_every": full_every,
        }
        rounds = min(n_t, l_t * n_a) + (100 if lossy else 4)
        agents = simulate("cbba", params, inst, rounds, seed=case, network=LOSSY if lossy else CLEAN).allocators
        got = {t: a.agent_id for a in agents for t in a.bundle}
        assert got == sequential_greedy(inst, l_t, 0.99, inst.max_speed), f"case {case}"


def test_cbba_messages_between_whole_ones_carry_what_changed_and_a_missed_one_is_made_good():
    a, b = ConsensusState(0, full_every=3), ConsensusState(1, full_every=3)
    a.add(10, 5.0)
    a.add(11, 4.0)
    a.s.update({2: 1.0, 3: 1.0})
    whole = a.message()
    _t, winners, stamps, is_delta = read_message(whole)
    assert not is_delta and len(winners) == 2 and len(stamps) == 2
    b.receive(0, whole)
    assert b.z == {10: 0, 11: 0}
    a.now, a.s[3] = 1.0, 2.0
    a.reset(10)
    a.add(12, 3.0)
    delta = a.message()
    assert read_message(delta) == (1, [(10, NONE, 0.0), (12, 0, 3.0)], [(3, 2.0)], True)
    a.now = 2.0
    a.add(13, 2.0)
    missed = a.message()  # lost on the way to b
    assert read_message(missed)[1:3] == ([(13, 0, 2.0)], [])
    b.now = 2.0
    b.receive(0, delta)
    assert b.z == {11: 0, 12: 0} and b.s == {0: 1, 2: 1.0, 3: 2}
    a.now = 3.0
    b.now = 3.0
    b.receive(0, a.message())  # the third message is whole again
    assert b.z == a.z == {11: 0, 12: 0, 13: 0} and b.y == a.y


def test_cbba_receiver_table_entries():
    """A few of Table 1's 17 cases, receiver i=0, sender k=1, third agent m=2, fourth n=3."""
    t = table
    newer_all = lambda m: 1  # noqa: E731  sender's information is newer about everyone
    older_all = lambda m: -1  # noqa: E731
    assert t(0, 1, 1, 5.0, 0, 4.0, older_all) == "update"  # 1: sender outbids
    assert t(0, 1, 1, 4.0, 0, 4.0, older_all) == "leave"  # 1: tie goes to the lower id (receiver 0)
    assert t(0, 1, 0, 1.0, 1, 9.0, older_all) == "reset"  # 6
    assert t(0, 1, -1, 0.0, 1, 9.0, older_all) == "update"  # 15
    assert t(0, 1, -1, 0.0, 0, 9.0, newer_all) == "leave"  # 14
    assert t(0, 1, 2, 3.0, 1, 9.0, older_all) == "reset"  # 10
    assert t(0, 1, 2, 3.0, 1, 9.0, newer_all) == "update"  # 10
    assert t(0, 1, 2, 3.0, 3, 9.0, newer_all) == "update"  # 12
    assert t(0, 1, 2, 3.0, 3, 9.0, lambda a: 1 if a == 3 else -1) == "reset"  # 12
    assert t(0, 1, 2, 3.0, 3, 9.0, older_all) == "leave"  # 12


def test_table_1_over_arrays_takes_the_scalar_tables_action_in_every_case():
    """Every combination of sender and receiver belief (agents NONE, 0-3; bids 0-2) and of how the
    sender's news of the two winners named compares with the receiver's (older, same, newer), for
    receiver 0 and sender 1: :func:`table_masks` gives :func:`table`'s action in all 3,600 cases."""
    agents, bids, cmps = (NONE, 0, 1, 2, 3), (0.0, 1.0, 2.0), (-1, 0, 1)
    cases = list(itertools.product(agents, bids, agents, bids, cmps, cmps))
    zk, yk, zi, yi, cm, cn = (np.array(col) for col in zip(*cases))
    # a winner named on both sides is one agent: its comparison is the same
    cn = np.where(zi == zk, cm, cn)
    update, reset = table_masks(0, 1, zk, yk, zi, yi, cm > 0, cm < 0, cn > 0)
    for n, (a, ya, b, yb, _m, _n) in enumerate(cases):
        compare = {a: int(cm[n]), b: int(cn[n])}.get
        want = table(0, 1, a, ya, b, yb, lambda m: compare(m, 0))  # noqa: B023 (called at once)
        want = "reset" if want == "update" and a == NONE else want  # an update to nobody is a reset
        got = "update" if update[n] else "reset" if reset[n] else "leave"
        assert got == want, (a, ya, b, yb, int(cm[n]), int(cn[n]))
        assert not (update[n] and reset[n])


def random_receive(rng: np.random.Generator, trial: int) -> tuple[ConsensusState, dict, set | tuple, set | None]:
    """Receiver 0's random beliefs and stamps, and a random neighbour's message to it: whole on even
    trials, a delta on odd ones; tasks to ignore on every fifth, a scope (``within``) on every third."""
    tasks = int(rng.integers(1, 80))
    receiver = ConsensusState(0)
    receiver.now = float(rng.integers(0, 4))
    for t in range(tasks):
        if rng.random() < 0.7:
            receiver.z[t], receiver.y[t] = int(rng.integers(0, 5)), float(rng.integers(0, 3))
    for a in range(1, 5):
        if rng.random() < 0.8:
            receiver.s[a] = float(rng.integers(0, 4))
    sender = ConsensusState(1)
    sender.z.update({t: int(w) for t, w in zip(range(tasks), rng.integers(0, 5, tasks)) if rng.random() < 0.7})
    sender.y.update({t: float(rng.integers(0, 3)) for t in sender.z})
    sender.s.update({a: float(rng.integers(0, 4)) for a in (0, 2, 3, 4) if rng.random() < 0.8})
    sender.now = float(rng.integers(0, 4))
    msg = sender.message()
    if trial % 2:
        msg["d"] = 1
    ignore = {t for t in range(tasks) if rng.random() < 0.1} if trial % 5 == 0 else ()
    within = {t for t in range(tasks) if rng.random() < 0.5} if trial % 3 == 1 else None
    return receiver, msg, ignore, within


def copy_state(st: ConsensusState) -> ConsensusState:
    out = ConsensusState(st.agent_id)
    out.now, out.z, out.y = st.now, dict(st.z), dict(st.y)
    out.s.update(st.s)
    return out


def beliefs(st: ConsensusState) -> tuple:
    """What a receive leaves: winners and bids with their maps' order, and the stamps."""
    return list(st.z.items()), list(st.y.items()), dict(st.s)


def test_a_receive_takes_the_same_decisions_task_by_task_and_over_arrays(monkeypatch):
    """In Python (the compiled kernels off): both paths of a receive (a few tasks decided one by one,
    many at once over numpy's masks) leave the same winners, bids and timestamps on random beliefs,
    whole messages and deltas, with tasks to ignore and a scope."""
    monkeypatch.setattr(kernels, "receive", None)
    rng = np.random.default_rng(3)
    for trial in range(300):
        receiver, msg, ignore, within = random_receive(rng, trial)
        left = []
        for few in (10**9, 0):  # task by task; over arrays
            st = copy_state(receiver)
            monkeypatch.setattr(consensus, "FEW_TASKS", few)
            st.receive(1, msg, ignore=ignore, within=within)
            left.append(beliefs(st))
        assert left[0] == left[1], trial


def _grape_utility(inst, params, agent, task, size):
    if task == VOID:
        return 0.0
    tx, ty, w = inst.tasks[task]
    ax, ay = inst.agents[agent]
    return w / size - params["cost_weight"] * math.hypot(tx - ax, ty - ay) * size ** params["social_inhibition"]


@pytest.mark.parametrize("full_every, lossy", [(1, False), (10, False), (1, True), (10, True)])
@pytest.mark.parametrize(
    "params",
    [
        {"cost_weight": 1.0, "social_inhibition": 100.0, "void_task": True},
        {"cost_weight": 0.05, "social_inhibition": 1.0, "void_task": True},
        {"cost_weight": 1.0, "social_inhibition": 100.0},  # SPACE's MT-SR: no void task
        {"cost_weight": 0.05, "social_inhibition": 1.0},
    ],
)
def test_grape_ends_in_a_nash_stable_partition(params, full_every, lossy):
    """Every agent agrees on the partition and none gains by moving alone: to another task, or,
    where the void task is offered, to it. Without it every agent holds a task. With whole
    messages and with deltas between whole ones, on a clean network and with 30 % loss."""
    void = params.get("void_task", False)
    params = {**params, "full_every": full_every}
    for case in range(150 if (full_every, lossy) == (1, False) else 20):
        rng = np.random.default_rng(case)
        inst = random_instance(500 + case, int(rng.integers(2, 9)), int(rng.integers(1, 7)), size=50.0)
        agents = simulate("grape", params, inst, 150, seed=case, network=LOSSY if lossy else CLEAN).allocators
        partition = agents[0].partition
        assert all(a.partition == partition for a in agents), f"case {case}: agents disagree"
        assert all(a.satisfied for a in agents)
        sizes = {t: sum(1 for v in partition.values() if v == t) for t in inst.tasks}
        if not void:
            assert len(partition) == len(inst.agents), f"case {case}: an agent holds no task"
        for i in range(len(inst.agents)):
            mine = partition.get(i, VOID)
            u_now = _grape_utility(inst, params, i, mine, sizes.get(mine, 0))
            for other in [VOID, *inst.tasks] if void else list(inst.tasks):
                if other != mine:
                    u = _grape_utility(inst, params, i, other, sizes[other] + 1 if other != VOID else 0)
                    assert u <= u_now + 1e-9, f"case {case}: agent {i} prefers {other} ({u}) to {mine} ({u_now})"


@pytest.mark.parametrize(("hold", "stop", "held"), [(True, "halt", HALT), (True, "brake", HOLD), (False, "halt", None)])
def test_grape_holds_its_agents_still_while_the_partition_converges(hold, stop, held):
    """SPACE's MT-SR GRAPE (the default): on a tick where an agent's partition changed it returns
    HALT (stop at once, as SPACE's code resets its movement) or, with ``converging_stop: brake``,
    HOLD; once converged, its task. Without holding it heads for its task at once."""
    inst = random_instance(7, 5, 4, size=50.0)
    trace = simulate("grape", {"hold_while_converging": hold, "converging_stop": stop}, inst, 60, seed=1)
    first, last = trace.decisions[0], trace.decisions[-1]
    assert all(d == held for d in first.values()) if hold else all(d in inst.tasks for d in first.values())
    assert all(d in inst.tasks for d in last.values())  # converged: everyone on a task


def test_a_halted_agent_stops_at_once_where_a_held_one_brakes():
    """The world's side of HALT: ``halt`` zeroes the speed this tick; ``stop`` brakes within the
    acceleration limit (the agent rolls on)."""
    from swarmbed.config import resolve_experiment
    from tests.conftest import experiment

    exp = experiment("agents.count=1", "scenario.initial_tasks=1", "run.seed=3")
    rolled = {}
    for action in ("stop", "halt"):
        world = resolve_experiment(exp).scenario().make_world(np.random.default_rng(0))
        for _ in range(20):
            world.apply({0: ["goto", 1000.0, 1000.0]})
        before = (float(world.ax[0]), float(world.ay[0]))
        world.apply({0: [action]})
        rolled[action] = math.hypot(world.ax[0] - before[0], world.ay[0] - before[1])
        assert world.invalid_actions[0] == 0
    assert rolled["halt"] == 0.0 < rolled["stop"]


def test_grape_restarting_at_its_nearest_task_is_not_a_new_partition_unless_asked():
    near, other = TaskInfo(0, 10.0, 0.0, 30.0), TaskInfo(1, 40.0, 0.0, 30.0)
    for bumps, grows in ((False, False), (True, True)):
        grape = make("grape", {"restart_bumps_evolution": bumps}, 0, np.random.default_rng(0), 0)

        def decide(k, tasks, g=grape):
            return g.decide(LocalView(0, 1, k, float(k), 0.0, 0.0, 0.0, 0.0, 1.0, tasks, [], 1.0, 300.0))

        for k in range(4):
            decide(k, {0: near, 1: other})
        settled = grape.evolution
        decide(4, {1: other})  # its task completed: it restarts at the nearest one left
        assert (grape.evolution > settled) == grows and grape.partition[0] == 1


def test_grape_agent_whose_task_completed_takes_the_next_task_it_sees():
    """SPACE's GRAPE: an agent whose task completed is unsatisfied until it has decided on a task
    it sees. Here it finishes its task with nothing else in sight, explores (``None``) and must
    take the task that comes into sight later, though no message ever reaches it."""
    grape = make("grape", {}, 0, np.random.default_rng(0), 0)
    far, near = TaskInfo(1, 500.0, 0.0, 30.0), TaskInfo(0, 10.0, 0.0, 30.0)

    def decide(k, tasks):
        return grape.decide(LocalView(0, 2, k, float(k), 0.0, 0.0, 0.0, 0.0, 1.0, tasks, [], 1.0, 300.0))

    assert [decide(k, {0: near}) for k in range(3)][-1] == 0
    assert [decide(k, {}) for k in range(3, 8)] == [None] * 5  # done while in sight; nothing else seen
    seen = [decide(k, {1: far}) for k in range(8, 11)]
    assert seen[-1] == 1, seen


def test_grape_messages_between_whole_ones_carry_what_changed_and_a_missed_one_is_made_good():
    a, b = (make("grape", {"full_every": 4}, i, np.random.default_rng(i), 0) for i in (0, 1))
    sent = lambda: unpack(pack(a.message()))  # noqa: E731  as it travels
    a.partition, a.evolution = {0: 5, 1: 5, 2: 7, 3: 7, 5: 7}, 4
    whole = sent()
    assert whole[:2] == [4, a.stamp] and whole[3:] == [0]
    assert read_pairs(whole[2]) == [(0, 5), (1, 5), (2, 7), (3, 7), (5, 7)]
    assert b.partition_of(0, whole) == a.partition
    a.partition, a.evolution = {0: 5, 1: 5, 2: 8, 4: 7, 5: 7}, 5
    delta = sent()
    assert delta[:2] == [5, a.stamp] and delta[3:] == [1, 1] and read_pairs(delta[2]) == [(2, 8), (3, VOID), (4, 7)]
    assert b.partition_of(0, delta) == a.partition
    a.partition[0] = 9
    missed = sent()  # lost on the way to b
    assert read_pairs(missed[2]) == [(0, 9)] and missed[3:] == [2, 1]
    a.partition[4] = 8
    assert b.partition_of(0, sent()) is None  # a gap: not used, and b forgets a's partition
    assert b.partition_of(0, delta) is None  # nor an old delta
    a.partition[2] = 9
    assert b.partition_of(0, sent()) == a.partition  # the fifth (number 4) is whole and makes it good
    a.partition[1] = 9
    after = sent()
    assert len(after) == 5 and b.partition_of(0, after) == a.partition
    assert sent() is None  # nothing changed: no message
    a.partition[3] = 9
    last = sent()
    assert read_pairs(last[2]) == [(3, 9)] and last[3:] == [6, 1]  # numbered after the last one sent


def test_grape_agent_hears_a_partition_newer_than_its_own_only_through_what_it_can_rebuild():
    """The mutex adopts a delta's partition only when the delta follows the sender's message before."""
    a, b = (make("grape", {"full_every": 10}, i, np.random.default_rng(i), 0) for i in (0, 1))
    tasks = {0: TaskInfo(0, 10.0, 0.0, 30.0), 1: TaskInfo(1, 20.0, 0.0, 30.0)}

    def view(k, inbox):
        return LocalView(1, 2, k, float(k), 0.0, 0.0, 0.0, 0.0, 1.0, tasks, inbox, 1.0, 300.0)

    b.decide(view(0, []))
    a.partition, a.evolution = {0: 1, 1: 0}, 50
    a.sent, a.rounds, a.told = 1, 1, {0: 1}  # its first message, the whole one, never reached b
    b.mutex(view(1, [Message(0, "grape", a.message())]))
    assert b.evolution < 50
    a.rounds = 10
    b.mutex(view(2, [Message(0, "grape", a.message())]))
    assert (b.evolution, b.partition) == (50, {0: 1, 1: 0})


@pytest.mark.parametrize("on_earlier_claim", ["keep", "abandon"])
def test_fcg_keeps_its_task_on_an_earlier_claim_as_spaces_code_does_or_abandons_it_as_the_paper_says(
    on_earlier_claim,
):
    """SPACE's plugins/greedy/greedy.py keeps a claimed task until it is done (the default); the
    paper's Section IV-D abandons it on hearing an earlier claim and chooses again next tick."""
    fcg = make("fcg", {"on_earlier_claim": on_earlier_claim}, 0, np.random.default_rng(0), 0)
    near, far = TaskInfo(0, 10.0, 0.0, 30.0), TaskInfo(1, 50.0, 0.0, 30.0)
    tasks = {0: near, 1: far}

    def decide(k, inbox=()):
        return fcg.decide(LocalView(0, 2, k, float(k), 0.0, 0.0, 0.0, 0.0, 1.0, tasks, list(inbox), 1.0, 300.0))

    assert decide(5) == 0  # claims the nearest at tick 5
    earlier = Message(1, "claim", [0, 2])  # agent 1 claimed it at tick 2
    if on_earlier_claim == "keep":
        assert [decide(6, [earlier]), decide(7, [earlier])] == [0, 0]
    else:
        assert decide(6, [earlier]) is None  # abandons; chooses again next tick, skipping the claimed task
        assert decide(7, [earlier]) == 1


@pytest.mark.parametrize("heard_claims", ["tick", "since_choice"])
def test_fcg_skips_the_claims_of_this_tick_or_every_claim_since_its_last_choice_as_spaces_code_does(
    heard_claims,
):
    """SPACE's plugins/greedy/greedy.py empties the agent's received messages only when it chooses:
    a claim heard while the agent worked on another task still keeps it off that task at its next
    choice (``since_choice``); by default only this tick's claims do (``tick``)."""
    fcg = make("fcg", {"heard_claims": heard_claims}, 0, np.random.default_rng(0), 0)
    tasks = {0: TaskInfo(0, 10.0, 0.0, 30.0), 1: TaskInfo(1, 50.0, 0.0, 30.0), 2: TaskInfo(2, 90.0, 0.0, 30.0)}

    def decide(k, inbox=()):
        return fcg.decide(LocalView(0, 3, k, float(k), 0.0, 0.0, 0.0, 0.0, 1.0, tasks, list(inbox), 1.0, 300.0))

    assert decide(5) == 0  # claims the nearest
    assert decide(6, [Message(1, "claim", [1, 6])]) == 0  # agent 1 claims task 1 while 0 works on task 0
    del tasks[0]  # task 0 done; agent 1 is out of range now
    assert decide(7) == (1 if heard_claims == "tick" else 2)
    if heard_claims == "since_choice":
        del tasks[2]  # done too; the choice of tick 7 emptied what the agent heard: task 1 is free again
        assert decide(8) == 1


@pytest.mark.parametrize("same_tick_claims", ["unseen", "id_order"])
def test_fcg_sees_a_lower_ids_claim_of_the_same_tick_as_spaces_loop_order_shows_it(same_tick_claims):
    """SPACE's main loop runs its agents one after another in id order within a step, so an agent
    sees the claims its lower-id neighbours made in that step before it chooses (``id_order``):
    hearing one on its own task, made at the tick of its own claim, it chooses again skipping that
    task; a later claim, or a higher id's, it keeps beside (SPACE's code keeps a task until done)."""
    fcg = make("fcg", {"same_tick_claims": same_tick_claims}, 2, np.random.default_rng(0), 0)
    tasks = {0: TaskInfo(0, 10.0, 0.0, 30.0), 1: TaskInfo(1, 50.0, 0.0, 30.0), 2: TaskInfo(2, 90.0, 0.0, 30.0)}

    def decide(k, inbox=()):
        return fcg.decide(LocalView(2, 4, k, float(k), 0.0, 0.0, 0.0, 0.0, 1.0, tasks, list(inbox), 1.0, 300.0))

    assert decide(5) == 0  # claims the nearest at tick 5
    assert decide(6, [Message(3, "claim", [0, 5]), Message(1, "claim", [0, 6])]) == 0  # a higher id; a later claim
    assert decide(7, [Message(1, "claim", [0, 5])]) == (0 if same_tick_claims == "unseen" else 1)
    if same_tick_claims == "id_order":
        assert decide(8, [Message(1, "claim", [0, 5])]) == 1  # its new claim is of tick 7: kept


@pytest.mark.parametrize("execute", ["settled", "first"])
def test_cbba_works_only_on_a_bundle_a_consensus_round_left_alone_as_spaces_code_does(execute):
    """SPACE's CBBA hands its agent a task only after a consensus round that did not change the
    bundle (else the tree explores); ``execute: first`` heads for the path's first task every tick."""
    cbba = make("cbba", {"execute": execute}, 0, np.random.default_rng(0), 0)
    tasks = {0: TaskInfo(0, 10.0, 0.0, 30.0), 1: TaskInfo(1, 20.0, 0.0, 30.0)}

    def decide(k, inbox=()):
        return cbba.decide(LocalView(0, 2, k, float(k), 0.0, 0.0, 0.0, 0.0, 1.0, tasks, list(inbox), 1.0, 300.0))

    built, settled = decide(0), decide(1)
    assert settled == cbba.path[0] and built == (None if execute == "settled" else cbba.path[0])
    assert decide(2) == cbba.path[0]  # nothing heard: still settled


def test_cbba_consensus_scope_of_spaces_code_touches_only_sensed_tasks_both_sides_bid_on():
    """SPACE's code skips a task in a consensus round unless it is in the agent's local tasks and
    both it and the neighbour hold a bid for it (``consensus_scope: local_bids``); the CBBA paper's
    round (``all``, the default) takes every task the neighbour names."""
    theirs = consensus_message(1, [(10, 1, 9.0), (11, 1, 9.0), (12, 1, 9.0)], [])
    paper, space = ConsensusState(0), ConsensusState(0)
    for st in (paper, space):
        st.add(10, 5.0)
        st.add(11, 4.0)  # bid on, but out of view below
    paper.receive(1, theirs)
    in_view = {10, 12, 13}
    space.receive(1, theirs, within=in_view & space.bid_on)
    assert paper.z == {10: 1, 11: 1, 12: 1}
    assert space.z == {10: 1, 11: 0}  # 11: not sensed; 12: never bid on by agent 0

    tasks = {0: TaskInfo(0, 10.0, 0.0, 30.0), 1: TaskInfo(1, 200.0, 0.0, 30.0)}
    heard = [Message(1, "cbba", consensus_message(0, [(0, 1, 0.5), (1, 1, 9.0)], []))]
    winners = {}
    for scope in ("all", "local_bids"):
        cbba = make("cbba", {"consensus_scope": scope, "max_tasks": 1}, 0, np.random.default_rng(0), 0)
        view = LocalView(0, 2, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, tasks, [], 1.0, 300.0)
        cbba.decide(view)  # bids on task 0, the nearer
        assert cbba.bundle == [0]
        view = LocalView(0, 2, 1, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, tasks, heard, 1.0, 300.0)
        cbba.decide(view)
        winners[scope] = dict(cbba.z)
    assert winners["all"][1] == 1  # learnt who wins task 1, which it never bid on
    assert 1 not in winners["local_bids"] and winners["local_bids"][0] == 0  # 0 kept: its bid is higher


def test_cbba_coarse_stamps_of_spaces_wall_clock_keep_the_newer_information_rules_from_firing():
    """SPACE's code stamps information with whole wall-clock seconds, which last hundreds of
    simulated seconds; ``stamp_every`` stamps with whole multiples of it in simulated time. Within
    one stamp Table 1's rules that need newer information (here: both think agent 2 wins, with
    other bids) leave the receiver's view as it is; with the paper's stamps they update it."""
    tasks = {0: TaskInfo(0, 10.0, 0.0, 30.0)}
    coarse = make("cbba", {"stamp_every": 300.0}, 0, np.random.default_rng(0), 0)
    fine = make("cbba", {}, 0, np.random.default_rng(0), 0)
    for k, t in enumerate((0.0, 150.0, 299.9, 300.0, 612.5)):
        for cbba, stamp in ((coarse, 300.0 * math.floor(t / 300.0)), (fine, t)):
            view = LocalView(0, 2, k, t, 0.0, 0.0, 0.0, 0.0, 1.0, tasks, [], 1.0, 300.0)
            cbba.decide(view)
            assert view.outbox[-1].data["t"] == stamp
    for their_stamp_of_2, updated in ((0.0, False), (7.5, True)):
        st = ConsensusState(0)
        st.z[5], st.y[5], st.s[2] = 2, 3.0, 0.0
        st.receive(1, consensus_message(0.0, [(5, 2, 4.0)], [(2, their_stamp_of_2)]))
        assert st.y[5] == (4.0 if updated else 3.0)


def test_consensus_messages_are_packed_arrays_of_the_narrowest_declared_dtype_and_read_back_exactly():
    small = consensus_message(3, [(1, 2, 0.1 + 0.2), (300, 7, 1e-300)], [(4, 5.0), (9, 12.0)])
    assert set(small) == {"t", "w", "s"} and len(small["w"]) == 2 * 11 and len(small["s"]) == 2 * 3
    assert read_message(small) == (3, [(1, 2, 0.1 + 0.2), (300, 7, 1e-300)], [(4, 5.0), (9, 12.0)], False)
    wide = consensus_message(2.5, [(70_000, 300, 2.0), (70_001, NONE, 0.0)], [(200, 0.25), (3, 1e6)], delta=True)
    assert set(wide) == {"t", "d", "u", "p"}  # task ids past 65,535, a stamp that is not whole
    assert read_message(wide) == (2.5, [(70_000, 300, 2.0), (70_001, NONE, 0.0)], [(200, 0.25), (3, 1e6)], True)
    assert set(consensus_message(0, [(1, 200, 1.0)], [(200, 70_000.0)])) == {"t", "v", "q"}
    assert consensus_message(1) == {"t": 1}  # empty vectors are left out


def test_a_crafted_consensus_message_names_nothing_and_changes_nothing():
    st = ConsensusState(0)
    st.add(4, 2.0)
    before = (dict(st.z), dict(st.y), dict(st.s))
    for crafted in (
        {"t": 1, "w": b"\x01\x02\x03"},  # not a whole number of entries
        {"t": 1, "w": [[4, 1, 9.0]], "s": "x"},  # not packed bytes
        {"t": "soon", "w": consensus_message(1, [(4, 1, 9.0)])["w"]},  # a stamp that is not a number
        [4, 1, 9.0],
        None,
    ):
        st.receive(1, crafted)
        assert (st.z, st.y) == before[:2], crafted
    # a task named twice: the first entry counts (ours never repeat one)
    twice = consensus_message(1, [(5, 1, 1.0), (5, 2, 9.0)])
    st.receive(1, twice)
    assert st.z[5] == 1 and st.y[5] == 1.0


def test_grape_partitions_travel_packed_in_the_narrowest_declared_dtype_and_crafted_ones_name_nothing():
    small = pack_pairs([(0, 5), (3, 100)])
    assert isinstance(small, bytes) and len(small) == 4  # int8 agent and task: the bytes alone
    assert read_pairs(small) == [(0, 5), (3, 100)]
    wide = pack_pairs([(200, 70_000), (201, VOID)])
    assert wide[0] == 3 and read_pairs(wide) == [(200, 70_000), (201, VOID)]
    assert pack_pairs([]) == [] and read_pairs([]) == []
    for crafted in (b"\x01", [9, b"\x00\x00"], [3, "x"], None, 7, [[0, 5]]):
        assert read_pairs(crafted) == [], crafted


def test_a_crafted_grape_message_is_ignored_and_changes_nothing():
    for every in (1, 4):
        b = make("grape", {"full_every": every}, 1, np.random.default_rng(1), 0)
        tasks = {0: TaskInfo(0, 10.0, 0.0, 30.0)}
        b.decide(LocalView(1, 2, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, tasks, [], 1.0, 300.0))
        before = (b.evolution, b.stamp, dict(b.partition))
        crafted = [None, 7, [], [10**9], [10**9, 0.5], ["x", 0.5, []], [10**9, 0.5, b"", "n"], [10**9] * 9]
        inbox = [Message(0, "grape", data) for data in crafted]
        b.mutex(LocalView(1, 2, 1, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, tasks, inbox, 1.0, 300.0))
        assert (b.evolution, b.stamp, b.partition) == before, every


def test_a_crafted_claim_is_ignored_and_changes_nothing():
    """FCG reads a claim only where it is [task, claim tick]: anything else names no task (it raised
    on a message that did not unpack into two values)."""
    tasks = {0: TaskInfo(0, 10.0, 0.0, 30.0), 1: TaskInfo(1, 20.0, 0.0, 30.0)}
    crafted = [None, 7, [], [0], [0, 1, 2], ["x", 1], [[0], 1], [0, 1.5], [True, 0], {"a": 1}]
    a = make("fcg", {}, 1, np.random.default_rng(1), 0)
    inbox = [Message(0, "claim", data) for data in crafted]
    assert a.decide(LocalView(1, 2, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, tasks, inbox, 1.0, 300.0)) == 0


# -- centralized allocators through a leader (issue 60) ------------------------------------------------


def _leader_rounds(n_agents: int) -> int:
    """Round 0: every agent leads itself; round 1: the lowest id leads, followers report; round 2: the
    leader solves with every report; round 3: every follower acts on it."""
    return 4


@pytest.mark.parametrize("case", range(60))
def test_sga_through_a_leader_is_sequential_greedy_and_converged_cbba(case):
    """On a clean radio with everyone in range, the leader's sequential greedy assignment (solved
    afresh each tick) is the reference SGA of this file, and CBBA's converged assignment with one task
    per bundle and the same path-independent score."""
    rng = np.random.default_rng(case)
    n_a, n_t = int(rng.integers(2, 7)), int(rng.integers(1, 12))
    inst = random_instance(3000 + case, n_a, n_t)
    params = {"discount": 0.99, "commit": False}
    trace = simulate("sga", params, inst, _leader_rounds(n_a), seed=case)
    got = {j: i for i, j in trace.decisions[-1].items() if j is not None}
    assert got == sequential_greedy(inst, 1, 0.99, inst.max_speed), f"case {case}"
    cbba = {"max_tasks": 1, "score": "distance_discounted", "discount": 0.99, "reset_after": None}
    agents = simulate("cbba", cbba, inst, min(n_t, n_a) + 4, seed=case).allocators
    assert got == {t: a.agent_id for a in agents for t in a.bundle}, f"case {case}"


def test_the_hungarian_leaders_assignment_travels_least_of_all_assignments():
    """Brute force on small instances: no assignment of min(agents, tasks) pairs travels less in all
    than the one the leader sends (SciPy's linear_sum_assignment), which every agent then acts on."""
    import itertools

    from swarmbed.plugins.central import least_travel

    for case in range(40):
        rng = np.random.default_rng(case)
        n_a, n_t = int(rng.integers(1, 6)), int(rng.integers(1, 6))
        inst = random_instance(4000 + case, n_a, n_t)
        agents = dict(enumerate(inst.agents))
        plan = least_travel(agents, inst.tasks, inst.max_speed)

        def travel(pairs, agents=agents, tasks=inst.tasks):
            return sum(math.dist(agents[a], tasks[t][:2]) for a, t in pairs)

        k = min(n_a, n_t)
        best = min(
            travel(zip(chosen, order))
            for chosen in itertools.combinations(range(n_a), k)
            for order in itertools.permutations(inst.tasks, k)
        )
        assert len(plan) == k and travel(plan.items()) <= best + 1e-9, f"case {case}"
        trace = simulate("hungarian", {"commit": False}, inst, _leader_rounds(n_a), seed=case)
        assert {a: t for a, t in trace.decisions[-1].items() if t is not None} == plan, f"case {case}"


def test_a_leader_knows_only_what_reached_it_and_the_lowest_id_in_reach_leads():
    """Agents 0 and 1 stand together, 2 and 3 together, far apart, range 50. With a fixed leader 0,
    agents 2 and 3 never reach it: they are never in its assignment and, hearing nothing, explore.
    With ``lowest_alive`` each group elects its own lowest id."""
    from swarmbed.checks.allocator_kit import Instance

    inst = Instance(
        agents=[(0.0, 0.0), (10.0, 0.0), (500.0, 0.0), (510.0, 0.0)],
        tasks={0: (5.0, 5.0, 30.0), 1: (505.0, 5.0, 30.0), 2: (20.0, 0.0, 30.0)},
    )
    near = NetworkSection(range=50.0)
    fixed = simulate("sga", {"leader": 0}, inst, 8, seed=1, network=near)
    leader = fixed.allocators[0]
    assert set(leader.plan) <= {0, 1} and set(leader.positions) == {0, 1}
    assert all(d.get(2) is None and d.get(3) is None for d in fixed.decisions)
    assert fixed.decisions[-1][1] is not None  # the follower in reach works
    elected = simulate("sga", {}, inst, 8, seed=1, network=near)
    assert [a.leader(a.heard[max(a.heard, key=a.heard.get)]) for a in elected.allocators] == [0, 0, 2, 2]
    assert elected.decisions[-1][2] == 1  # the far group's own leader took the task beside it


def _unilateral_gains(part, agents, tasks, cost_weight=1.0, social_inhibition=100.0):
    """The agents that would gain by moving alone to another task (none: Nash stable)."""
    from swarmbed.plugins.grape import utility

    size = {j: list(part.values()).count(j) for j in tasks}
    gains = []
    for a, here in part.items():
        u_here = utility(
            tasks[here][2], math.dist(agents[a], tasks[here][:2]), size[here], cost_weight, social_inhibition
        )
        for j in tasks:
            if j != here:
                u = utility(
                    tasks[j][2], math.dist(agents[a], tasks[j][:2]), size[j] + 1, cost_weight, social_inhibition
                )
                if u > u_here + 1e-9:
                    gains.append((a, here, j))
    return gains


@pytest.mark.parametrize("social_inhibition", [100.0, 0.5])
def test_central_grape_is_a_nash_stable_partition_and_grapes_own_result_is_one_of_its_game(social_inhibition):
    """The leader's partition leaves no agent better off moving alone (SPACE's Eq. 1), every agent
    acts on it; and the partition GRAPE's own distributed run converges to on a connected graph is
    stable under the leader's game too (the same utility): started from it, the leader moves no one."""
    from swarmbed.plugins.central import nash_stable_partition

    for case in range(25):
        rng = np.random.default_rng(case)
        n_a, n_t = int(rng.integers(2, 7)), int(rng.integers(1, 6))
        inst = random_instance(5000 + case, n_a, n_t, size=40.0)
        agents = dict(enumerate(inst.agents))
        part = nash_stable_partition(agents, inst.tasks, 1.0, social_inhibition)
        assert set(part) == set(agents) and not _unilateral_gains(part, agents, inst.tasks, 1.0, social_inhibition)
        params = {"commit": False, "social_inhibition": social_inhibition}
        trace = simulate("central-grape", params, inst, _leader_rounds(n_a), seed=case)
        assert trace.decisions[-1] == part, f"case {case}"
        grape = {"social_inhibition": social_inhibition, "hold_while_converging": False}
        own = simulate("grape", grape, inst, 60, seed=case).allocators[0].partition
        assert not _unilateral_gains(own, agents, inst.tasks, 1.0, social_inhibition), f"case {case}"
        assert nash_stable_partition(agents, inst.tasks, 1.0, social_inhibition, start=own) == own, f"case {case}"


@pytest.mark.slow
def test_a_follower_that_hears_no_leader_lets_its_fallback_allocator_decide(tmp_path):
    """A centralized allocator's ``fallback``: a follower without a fresh assignment lets a registered
    allocator decide (here FCG), which observes and talks over the radio all along; without one it
    explores. With a 1 m radio no follower hears the fixed leader, so only the fallback gets work
    done; its claims are real messages of the run."""
    from swarmbed.launch.inprocess import run_in_process

    done = {}
    for name, allocator in (
        ("alone", "{name: sga, leader: 0}"),
        ("fallback", "{name: sga, leader: 0, fallback: fcg}"),
    ):
        exp = experiment(f"allocator={allocator}", "network.range=1", "run.duration=600", "run.stop_when_done=false")
        out = tmp_path / name
        run_in_process(exp, out)
        summary = json.loads((out / "summary.json").read_text())
        done[name] = (summary["tasks_completed"], (out / "network_ledger.csv").read_text())
    assert done["fallback"][0] > done["alone"][0]
    assert ",claim," in done["fallback"][1] and ",claim," not in done["alone"][1]


def test_a_fallback_that_is_not_an_allocator_is_refused_where_the_experiment_is_loaded():
    from swarmbed.config import ConfigError

    with pytest.raises(ConfigError) as exc:
        experiment("allocator={name: hungarian, fallback: nosuch}")
    assert "allocator.fallback" in str(exc.value) and len(str(exc.value).splitlines()) == 1
