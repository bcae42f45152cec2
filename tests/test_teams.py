"""Team tasks (ST-MR, issue 60 item 3): a task that needs k robots at once, in the world, on the wire,
and in every allocator that handles them; each allocator held to a reference (brute force, SGA,
a unilateral-move check of Nash stability)."""

import itertools
import math

import numpy as np
import pytest

from swarmbed.checks.allocator_kit import random_instance, simulate
from swarmbed.config import ConfigError, resolve_experiment
from swarmbed.plugins.central import least_travel, nash_stable_partition, sequential_greedy
from swarmbed.plugins.grape import utility
from swarmbed.plugins.teams import by_slots
from swarmbed.scenarios.mtsr import MTSRObservation
from swarmbed.wire.codec import TAG_TICK, pack
from swarmbed.wire.tickdecode import TickDecoder
from tests.conftest import experiment

STILL = ("agents.max_speed=0.0001",)


def _world(*overrides: str, seed: int = 1):
    return resolve_experiment(experiment(*overrides)).scenario().make_world(np.random.default_rng(seed))


def test_a_team_task_waits_for_its_team_and_every_robot_in_view_sees_who_is_on_it():
    """Task 0 needs two robots: one on it does nothing, two work it at twice one robot's rate; the
    observations show (task, needed, on it at the last tick) for it, and nothing for task 1 (one robot)."""
    places = "scenario.agent_positions=[[10,10],[12,10],[100,100]]"
    world = _world(
        "agents.count=3",
        "scenario.initial_tasks=2",
        "scenario.task_positions=[[10,10],[100,100]]",
        "scenario.robots_needed=2",
        "scenario.workload=[20,20]",
        places,
        "agents.awareness_range=1000",
        *STILL,
    )
    world.needed[1] = 1  # the second task needs one robot: it is worked alone
    world.apply({0: ["goto_task", 0], 2: ["goto_task", 1]})
    assert world.remaining[0] == 20.0 and world.present[0] == 1  # alone: waits
    assert world.summary()["team_wait_per_agent"] == [1.0, 0.0, 0.0]
    assert world.remaining[1] == 19.0  # one robot's task is worked by one
    obs = world.observations()
    assert obs[0].coalitions == [(0, 2, 1)] and obs[2].coalitions == [(0, 2, 1)]
    world.apply({0: ["goto_task", 0], 1: ["goto_task", 0], 2: ["goto_task", 1]})
    assert world.remaining[0] == 18.0 and world.present[0] == 2
    assert world.work[0] == world.work[1] == 1.0
    assert world.observations()[1].coalitions == [(0, 2, 2)]
    assert not world.invariants()


def test_tasks_that_need_one_robot_leave_the_observation_and_its_bytes_as_they_were():
    world = _world()
    for obs in world.observations().values():
        assert obs.coalitions is None and "coalitions" not in obs.to_wire()
    assert "team_wait_total" not in world.summary()


def test_a_range_of_team_sizes_draws_each_tasks_k_apart_from_the_world_and_leaves_the_rest_in_place():
    one, teams = _world(seed=5), _world("scenario.robots_needed=[1,3]", seed=5)
    assert np.array_equal(one.tx, teams.tx) and np.array_equal(one.workload, teams.workload)
    assert set(teams.needed.tolist()) == {1, 2, 3} and set(one.needed.tolist()) == {1}
    again = _world("scenario.robots_needed=[1,3]", seed=5)
    assert np.array_equal(teams.needed, again.needed)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("9", "robots_needed=9: a task may need 9 robots, the run has 5 agents"),
        ("[3,2]", "robots_needed must be a number >= 1 or [min, max] with 1 <= min <= max"),
        ("0", "robots_needed must be a number >= 1"),
    ],
)
def test_a_team_no_run_can_field_is_refused_where_the_experiment_is_loaded(value, message):
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]")):
        resolve_experiment(experiment(f"scenario.robots_needed={value}"))


def test_the_coalitions_of_an_observation_cross_the_wire_as_they_were_sent():
    table = _world("scenario.robots_needed=2").observations()[0]
    sample = pack([TAG_TICK, 3, table.to_wire(), b""])
    back = TickDecoder(MTSRObservation).decode(sample).obs
    assert back.coalitions == table.coalitions and back.coalitions
    assert MTSRObservation.from_wire(table.to_wire()).coalitions == table.coalitions


def test_the_team_utility_is_spaces_eq_1_for_one_robot_and_peaks_at_k():
    rng = np.random.default_rng(0)
    for r, d, size in zip(rng.uniform(1, 60, 200), rng.uniform(0, 300, 200), rng.integers(1, 6, 200)):
        eq1 = r / size - 0.3 * d * float(size) ** 2.0
        assert utility(r, d, int(size), 0.3, 2.0) == utility(r, d, int(size), 0.3, 2.0, 1) == eq1
    u = [utility(30.0, 10.0, s, 0.01, 100.0, needed=3) for s in range(1, 6)]
    assert u[0] < u[1] < u[2] and u[2] > u[3] > u[4]


# -- the leaders: a brute-force reference over the assignments that fill every team they start ----------


def _team_instance(case: int):
    rng = np.random.default_rng(case)
    needed = {j: int(rng.integers(1, 4)) for j in range(int(rng.integers(1, 4)))}
    n_agents = sum(needed.values())  # as many agents as places: the slot assignment is the whole problem
    inst = random_instance(7000 + case, n_agents, len(needed))
    return inst, needed


def _full_assignments(n_agents: int, needed: dict[int, int]):
    """Every assignment of the agents to the tasks that gives each task exactly the robots it needs."""
    places = [j for j, k in needed.items() for _ in range(k)]
    for order in set(itertools.permutations(places)):
        yield dict(enumerate(order))


def test_the_hungarian_leader_fills_every_team_with_the_least_travel_of_all_full_assignments():
    for case in range(40):
        inst, needed = _team_instance(case)
        agents = dict(enumerate(inst.agents))
        plan = by_slots(lambda a, t: least_travel(a, t, 1.0), agents, inst.tasks, needed)

        def travel(p, tasks=inst.tasks, agents=agents):
            return sum(math.dist(agents[a], tasks[j][:2]) for a, j in p.items())

        best = min(travel(p) for p in _full_assignments(len(agents), needed))
        assert sorted(plan.values()) == sorted(j for j, k in needed.items() for _ in range(k)), f"case {case}"
        assert travel(plan) <= best + 1e-9, f"case {case}"


def test_a_team_the_solution_would_leave_short_is_dropped_and_its_robots_solved_for_again():
    """Three robots, a task that needs three far away and two near ones: the slot solution leaves the
    far team short (a robot or two would wait there for ever); it is dropped and they take the near ones."""
    agents = {0: (0.0, 0.0), 1: (1.0, 0.0), 2: (2.0, 0.0)}
    tasks = {0: (900.0, 0.0, 60.0), 1: (5.0, 0.0, 10.0), 2: (6.0, 0.0, 10.0)}
    needed = {0: 4, 1: 1, 2: 1}  # four places: the three robots can never fill task 0
    for solve in (lambda a, t: least_travel(a, t, 1.0), lambda a, t: sequential_greedy(a, t, 1.0, 0.99)):
        plan = by_slots(solve, agents, tasks, needed)
        assert 0 not in plan.values() and sorted(plan.values()) == [1, 2]


@pytest.mark.parametrize("case", range(30))
def test_cbba_with_team_slots_converges_to_sequential_greedy_over_the_slots(case):
    """CBBA bids on a team task's k slots through its ordinary consensus; with one task per bundle, a
    path-independent score and as many agents as places, its converged assignment is SGA's over the
    same slots (the centralized reference), and every team is full."""
    inst, needed = _team_instance(case)
    inst.observed = {"coalitions": [(j, k, 0) for j, k in needed.items() if k > 1] or None}
    params = {"max_tasks": 1, "score": "distance_discounted", "discount": 0.99, "reset_after": None}
    n = len(inst.agents)
    trace = simulate("cbba", params, inst, n + 6, seed=case, scenario="mtsr")
    got = {a.agent_id: a.path[0] & 0xFFFFFF for a in trace.allocators if a.path}
    agents = dict(enumerate(inst.agents))
    want = by_slots(lambda a, t: sequential_greedy(a, t, inst.max_speed, 0.99), agents, inst.tasks, needed)
    assert got == want, f"case {case}"


def _stable(part, agents, tasks, needed, cost_weight, social_inhibition):
    size = {j: list(part.values()).count(j) for j in tasks}
    for a, here in part.items():

        def u(j, size_there, a=a):
            d = math.dist(agents[a], tasks[j][:2])
            return utility(tasks[j][2], d, size_there, cost_weight, social_inhibition, needed[j])

        u_here = u(here, size[here])
        if any(j != here and u(j, size[j] + 1) > u_here + 1e-9 for j in tasks):
            return False
    return True


@pytest.mark.parametrize("case", range(20))
def test_grape_and_the_central_grape_leader_end_in_a_partition_stable_under_the_team_utility(case):
    """No agent gains by moving alone under the utility that peaks at k, for GRAPE's own distributed run
    on a connected graph and for the leader's partition; GRAPE's is stable for the leader too."""
    rng = np.random.default_rng(case)
    n_a, n_t = int(rng.integers(2, 8)), int(rng.integers(1, 5))
    inst = random_instance(8000 + case, n_a, n_t, size=40.0)
    needed = {j: int(rng.integers(1, 4)) for j in inst.tasks}
    inst.observed = {"coalitions": [(j, k, 0) for j, k in needed.items() if k > 1] or None}
    agents = dict(enumerate(inst.agents))
    grape = {"cost_weight": 0.01, "hold_while_converging": False}
    own = simulate("grape", grape, inst, 80, seed=case, scenario="mtsr").allocators
    assert all(a.partition == own[0].partition for a in own), f"case {case}: agents disagree"
    assert _stable(own[0].partition, agents, inst.tasks, needed, 0.01, 100.0), f"case {case}"
    leader = nash_stable_partition(agents, inst.tasks, 0.01, 100.0, needed=needed)
    assert _stable(leader, agents, inst.tasks, needed, 0.01, 100.0), f"case {case}"
    start = own[0].partition
    assert nash_stable_partition(agents, inst.tasks, 0.01, 100.0, start=start, needed=needed) == start


def test_first_claimed_greedy_gathers_its_claims_into_full_teams():
    """Four robots, four tasks that need two each, each robot beside its own task, all in reach of each
    other: each first claims the task beside it (and would wait there alone for ever); then the
    claimants gather around the earliest claims until two teams are full."""
    from swarmbed.checks.allocator_kit import Instance

    corners = [(0.0, 0.0), (50.0, 0.0), (0.0, 50.0), (50.0, 50.0)]
    inst = Instance(
        agents=corners,
        tasks={j: (x + 1.0, y + 1.0, 30.0) for j, (x, y) in enumerate(corners)},
        observed={"coalitions": [(j, 2, 0) for j in range(4)]},
    )
    trace = simulate("fcg", {}, inst, 12, seed=0, scenario="mtsr")
    assert sorted(trace.decisions[0].values()) == [0, 1, 2, 3]
    teams = sorted(trace.decisions[-1].values())
    assert teams[0] == teams[1] != teams[2] == teams[3], trace.decisions[-1]


@pytest.mark.slow
@pytest.mark.parametrize("allocator", ["fcg", "cbba", "grape", "sga", "hungarian", "central-grape"])
def test_every_team_aware_allocator_finishes_a_mission_of_team_tasks_in_processes_as_in_process(allocator, tmp_path):
    """A real run (every agent its own process over Zenoh and the proxy) of tasks that need one to three
    robots each: every task done, and the in-process engine's result files byte for byte the same."""
    from swarmbed.launch.runner import run_experiment
    from tests.conftest import reference_run, same_results

    exp = experiment(
        f"allocator.name={allocator}",
        "scenario.robots_needed=[1,3]",
        "scenario.initial_tasks=8",
        "network.range=null",
        "agents.awareness_range=1000",
        "run.duration=1500",
        *(["allocator.cost_weight=0.01"] if "grape" in allocator else []),
    )
    real = run_experiment(exp, tmp_path / "real", progress=False)
    assert real.summary["all_tasks_completed"], real.summary["tasks_completed"]
    reference_run(exp, tmp_path / "inprocess")
    same_results(tmp_path / "real", tmp_path / "inprocess")


def test_the_central_grape_leader_keeps_a_full_team_on_its_task_as_its_workload_falls():
    """A team's task is worth less with every tick of work; re-solved from scratch, the leader would pull
    the team off for a fuller task, again and again, and no team task would ever be done."""
    from swarmbed.plugins.registry import make

    leader = make("central-grape", {"cost_weight": 0.01}, 0, np.random.default_rng(0), 0, "mtsr")
    leader.needed = {0: 2, 1: 2}
    leader.tasks = {0: (10.0, 0.0, 30.0, 0.0), 1: (20.0, 0.0, 30.0, 0.0)}
    agents = {0: (0.0, 0.0), 1: (1.0, 0.0)}
    assert leader._plan(agents, 1.0) == {0: 0, 1: 0}
    leader.tasks[0] = (10.0, 0.0, 2.0, 1.0)  # nearly done
    assert leader._plan(agents, 1.0) == {0: 0, 1: 0}
    fresh = make("central-grape", {"cost_weight": 0.01}, 0, np.random.default_rng(0), 0, "mtsr")
    fresh.needed, fresh.tasks = leader.needed, leader.tasks
    assert fresh._plan(agents, 1.0) == {0: 1, 1: 1}  # what a leader with no team to keep would do


def test_a_learner_sees_each_rows_team_where_tasks_need_one():
    """The environment's observation gains ``teams`` (needed, on it) per row in a world of team tasks,
    and stays as it was in one without."""
    from swarmbed.envs import SwarmbedParallelEnv
    from swarmbed.envs.parallel import agent_view

    env = SwarmbedParallelEnv(sets=["scenario.robots_needed=[1,3]"], engine="inprocess")
    assert env.observation_space("agent_0")["teams"].shape == (8, 2)
    assert "teams" not in SwarmbedParallelEnv(engine="inprocess").observation_space("agent_0").spaces
    world = _world("scenario.robots_needed=[1,3]", "agents.awareness_range=1000")
    obs = world.observations()[0]
    view, chosen = agent_view(obs, None, 8, 5, teams=True)
    needs = {t: k for t, k, _ in obs.coalitions}
    assert [int(k) for k in view["teams"][: len(chosen), 0]] == [needs.get(t, 1) for t in chosen]
    assert env.observation_space("agent_0")["teams"].contains(view["teams"])


@pytest.mark.slow
def test_the_environment_of_team_tasks_passes_pettingzoos_api_test():
    from pettingzoo.test import parallel_api_test

    from swarmbed.envs import SwarmbedParallelEnv

    env = SwarmbedParallelEnv(sets=["scenario.robots_needed=[1,3]", "run.duration=60"], engine="inprocess")
    try:
        parallel_api_test(env, num_cycles=40)
    finally:
        env.close()


def test_a_cbba_robot_gives_up_a_team_that_does_not_form_and_leaves_it_alone_as_long():
    """Alone at a task that needs two, a robot keeps its slot first for ``team_patience`` seconds, then
    drops it (its bundle was closed by the slot: waiting for ever it would do nothing else) and bids
    on that task again only once as long has passed."""
    from swarmbed.extension import LocalView, TaskInfo
    from swarmbed.plugins.registry import make
    from swarmbed.wire.observation import empty_tasks

    robot = make("cbba", {"team_patience": 5.0, "execute": "first"}, 0, np.random.default_rng(0), 0, "mtsr")
    tasks = {0: TaskInfo(0, 1.0, 0.0, 30.0)}

    def decide(t: float):
        obs = MTSRObservation(t, 0.0, 0.0, 0.0, 0.0, empty_tasks(), [(0, 2, 1)])
        return robot.decide(LocalView(0, 2, int(t), t, 0.0, 0.0, 0.0, 0.0, 1.0, dict(tasks), [], 1.0, 300.0, obs=obs))

    assert [decide(float(t)) for t in range(6)] == [0] * 6  # first in its path from t = 1
    assert decide(6.0) is None and not robot.bundle  # given up 5 s later
    assert [decide(float(t)) for t in range(7, 11)] == [None] * 4  # left alone
    assert decide(11.0) == 0  # and taken again


def test_a_leader_hears_teams_of_more_than_255_robots_and_a_follower_refuses_a_goal_no_run_has():
    """Issue 74 item 11: a report packs a team of 300 (two-byte rows, flagged 2; teams of up to 255
    keep their one-byte rows and bytes); a follower does not follow its leader to (1e30, 1e30), nor to
    a task it sees somewhere else than the leader says."""
    from types import SimpleNamespace

    from swarmbed.extension.view import LocalView, Message, TaskInfo
    from swarmbed.plugins.central import ASSIGN, ASSIGN_ROW, REPORT, _pack
    from swarmbed.plugins.registry import make

    def view(agent, inbox, tasks, teams=None):
        obs = SimpleNamespace(coalitions=[(t, k, 0) for t, k in (teams or {}).items()])
        return LocalView(agent, 400, 1, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, tasks, inbox, awareness_range=1.0, obs=obs)

    task = TaskInfo(7, 5.0, 5.0, 30.0)
    follower = make("sga", {"leader": 0}, 1, np.random.default_rng(0), 0, "mtsr")
    mine = view(1, [], {7: task}, teams={7: 300})
    follower.decide(mine)
    (sent,) = [o for o in mine.outbox if o.kind == REPORT]
    assert sent.data[3] == 2
    leader = make("sga", {"leader": 0}, 0, np.random.default_rng(0), 0, "mtsr")
    leader.decide(view(0, [Message(1, REPORT, sent.data)], {}, teams={}))
    assert leader.needed == {7: 300}
    small = view(1, [], {7: task}, teams={7: 3})
    make("sga", {"leader": 0}, 1, np.random.default_rng(0), 0, "mtsr").decide(small)
    assert [o.data[3] for o in small.outbox if o.kind == REPORT] == [1]
    for goal in ((1e30, 1e30), (50.0, 50.0)):  # nowhere, and not where the follower sees task 7
        lied = _pack([(1, 7, *goal)], ASSIGN_ROW)
        follower = make("sga", {"leader": 0}, 1, np.random.default_rng(0), 0, "mtsr")
        assert follower.decide(view(1, [Message(0, ASSIGN, lied)], {7: task})) is None
    honest = _pack([(1, 7, 5.0, 5.0)], ASSIGN_ROW)
    follower = make("sga", {"leader": 0}, 1, np.random.default_rng(0), 0, "mtsr")
    assert follower.decide(view(1, [Message(0, ASSIGN, honest)], {7: task})) == 7
