"""Kinematic limits and the MT-SR bookkeeping (no processes needed)."""

import math
from pathlib import Path

import numpy as np
import pytest

from swarmbed.config import resolve_experiment
from swarmbed.extension.scenario import within
from swarmbed.scenarios import sar
from swarmbed.scenarios.kinematics import Limits, step
from swarmbed.scenarios.sar import ALIVE
from tests.conftest import ROOT, experiment

ROOT_EXPERIMENTS = ROOT / "experiments"


def MTSRWorld(exp, rng):
    return resolve_experiment(exp).scenario().make_world(rng)


def test_kinematics_honour_speed_acceleration_and_turn_rate():
    lim = Limits(max_speed=0.25, max_accel=0.01, max_turn_rate=0.25)
    rng = np.random.default_rng(3)
    x, y, h, v = 0.0, 0.0, 0.0, 0.0
    target = (0.0, 0.0)
    for k in range(3000):
        if k % 200 == 0:
            target = (float(rng.uniform(-50, 50)), float(rng.uniform(-50, 50)))
        nx, ny, nh, nv = step(x, y, h, v, target, lim, 1.0)
        assert nv <= lim.max_speed + 1e-12
        assert abs(nv - v) <= lim.max_accel + 1e-12
        dh = (nh - h + math.pi) % (2 * math.pi) - math.pi
        assert abs(dh) <= lim.max_turn_rate + 1e-12
        assert math.hypot(nx - x, ny - y) <= nv + 1e-9
        x, y, h, v = nx, ny, nh, nv


def test_agent_reaches_its_target_and_stops():
    lim = Limits(2.0, 0.5, 0.5)
    x, y, h, v = 0.0, 0.0, math.pi, 0.0  # facing away
    for _ in range(200):
        x, y, h, v = step(x, y, h, v, (30.0, 40.0), lim, 1.0)
    assert math.hypot(x - 30, y - 40) < 1e-6 and v < 0.6


def test_approach_radius_slows_an_agent_as_the_formula_says():
    """Within r of its target, facing it, with acceleration to spare, the speed is max_speed * d / r:
    d shrinks by the factor (1 - v dt / r) per step, and as dt shrinks it converges on SPACE's
    continuous slow-down d(t) = d0 exp(-v t / r)."""
    v_max, r, d0, horizon = 0.25, 50.0, 40.0, 100.0
    for dt, tol in ((1.0, 1e-9), (0.1, 1e-9)):
        lim = Limits(max_speed=v_max, max_accel=10.0, max_turn_rate=1.0, approach_radius=r)
        x, v = 0.0, v_max * d0 / r
        steps = round(horizon / dt)
        for _ in range(steps):
            x, _, _, v = step(x, 0.0, 0.0, v, (d0, 0.0), lim, dt)
        assert d0 - x == pytest.approx(d0 * (1 - v_max * dt / r) ** steps, rel=tol)
    exact = d0 * math.exp(-v_max * horizon / r)
    coarse = [d0 * (1 - v_max * dt / r) ** round(horizon / dt) for dt in (1.0, 0.1, 0.01)]
    errors = [abs(c - exact) for c in coarse]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-3 * exact
    # without the radius the same agent closes at full speed
    lim = Limits(max_speed=v_max, max_accel=10.0, max_turn_rate=1.0)
    x, v = 0.0, v_max
    for _ in range(200):
        x, _, _, v = step(x, 0.0, 0.0, v, (d0, 0.0), lim, 1.0)
    assert x == pytest.approx(d0)


@pytest.mark.parametrize(("per_workload", "works"), [(0.0, False), (1 / 3, True)])
def test_work_radius_grows_with_the_task_workload(per_workload, works):
    """SPACE's code works a task from within threshold + amount / 3: 10 + 30 / 3 = 20 here."""
    exp = experiment(
        "agents.count=1",
        "scenario.initial_tasks=1",
        "scenario.workload=[30, 30]",
        "scenario.task_positions=[[50, 50]]",
        "scenario.agent_positions=[[69.5, 50]]",
        "scenario.arrival_radius=10",
        f"scenario.work_radius_per_workload={per_workload}",
    )
    w = MTSRWorld(exp, np.random.default_rng(0))
    w.apply({0: ["goto_task", 0]})
    assert bool(w.remaining[0] < 30.0) is works


@pytest.mark.parametrize("work_motion", ["brake", "close_in"])
def test_a_working_agent_brakes_or_closes_in_on_the_task_as_spaces_code_does(work_motion):
    """SPACE's TaskExecutingNode calls follow() on every tick it works, so its agent drives on toward
    the task's centre (close_in); ours brakes by default. The work done is the same either way."""
    exp = experiment(
        "agents.count=1",
        "scenario.initial_tasks=1",
        "scenario.workload=[60, 60]",
        "scenario.task_positions=[[50, 50]]",
        "scenario.agent_positions=[[75, 50]]",
        "scenario.work_radius_per_workload=0.3333333333333333",
        "scenario.approach_radius=50",
        f"scenario.work_motion={work_motion}",
    )
    w = MTSRWorld(exp, np.random.default_rng(0))
    for _ in range(40):
        w.apply({0: ["goto_task", 0]})
    assert w.remaining[0] == pytest.approx(20.0)  # worked from the first tick: within 10 + 60 / 3
    moved = math.hypot(w.ax[0] - 75.0, w.ay[0] - 50.0)
    if work_motion == "brake":
        assert moved == 0.0 and w.distance[0] == 0.0
    else:
        assert math.hypot(w.ax[0] - 50.0, w.ay[0] - 50.0) < 24.0 and w.distance[0] >= moved > 0.5


def test_collaborative_work_adds_rates_and_never_overcounts():
    exp = experiment(
        "agents.count=3",
        "scenario.initial_tasks=1",
        "scenario.workload=[5, 5]",
        "scenario.task_positions=[[50, 50]]",
        "scenario.agent_positions=[[50, 50], [51, 50], [50, 51]]",
    )
    w = MTSRWorld(exp, np.random.default_rng(0))
    ticks = 0
    while not w.finished:
        w.apply({i: ["goto_task", 0] for i in range(3)})
        ticks += 1
    assert ticks == 2  # 3 agents at rate 1: 3 + 2 (of 3 possible)
    assert w.work.sum() == 5.0 and w.remaining[0] == 0.0
    assert w.done_at[0] == 2.0


def test_mission_time_is_when_the_last_task_was_done_even_if_the_run_goes_on():
    """stop_when_done: false keeps ticking after the last task; mission_time still says when every
    task was done (here at 2 s), not how long the run went on."""
    exp = experiment(
        "agents.count=3",
        "scenario.initial_tasks=1",
        "scenario.workload=[5, 5]",
        "scenario.task_positions=[[50, 50]]",
        "scenario.agent_positions=[[50, 50], [51, 50], [50, 51]]",
        "run.stop_when_done=false",
    )
    w = MTSRWorld(exp, np.random.default_rng(0))
    for _ in range(10):
        w.apply({i: ["goto_task", 0] for i in range(3)})
    summary = w.summary()
    assert summary["all_tasks_completed"] and summary["mission_time"] == 2.0 and w.time == 10.0


def test_generations_add_tasks_on_schedule():
    exp = experiment("scenario.initial_tasks=4", "scenario.generations={interval: 10, count: 2, tasks: 3}")
    w = MTSRWorld(exp, np.random.default_rng(0))
    sizes = []
    for _ in range(25):
        w.apply({})
        sizes.append(len(w.remaining))
    assert sizes[8] == 4 and sizes[9] == 7 and sizes[19] == 10 and sizes[-1] == 10
    assert w.tasks_total_planned == 10


def test_invalid_actions_are_counted_and_treated_as_stop():
    exp = experiment("agents.count=2")
    w = MTSRWorld(exp, np.random.default_rng(0))
    w.apply({0: ["fly", 1], 1: ["goto_task", 9999]})
    assert list(w.invalid_actions) == [1, 1]


SAR_BASE = Path(__file__).resolve().parent.parent / "experiments" / "sar" / "_base.yaml"


def _sar_world(dt, seed=0, *overrides):
    exp = experiment(f"run.dt={dt}", *overrides, base=SAR_BASE)
    return resolve_experiment(exp).scenario().make_world(np.random.default_rng(seed))


def _one_robot_at_one_victim(*overrides):
    """One robot standing on one victim that is never replaced, inspections of 10 s, dt 0.25."""
    w = _sar_world(
        0.25,
        0,
        "agents.count=1",
        "scenario.victims=1",
        "scenario.replace=false",
        "scenario.inspect_time=10",
        *overrides,
    )
    w.vx[0], w.vy[0] = w.ax[0], w.ay[0]
    return w


def test_sar_actions_take_their_duration_in_seconds_whatever_the_tick():
    """One robot on a victim of its colour: the inspection's result comes inspect_time after it
    began, the robot rescues at once, and the victim is saved rescue_time later; the same instant
    at every dt that divides the durations, and never before it at any dt."""
    for dt in (1.0, 0.5, 0.25, 0.1, 0.3):
        w = _sar_world(
            dt,
            0,
            "agents.count=1",
            "scenario.victims=1",
            "scenario.replace=false",
            "scenario.inspect_time=3",
            "scenario.rescue_time=2",
            "scenario.lifetime=1000",
        )
        w.vx[0], w.vy[0], w.vcolor[0] = w.ax[0], w.ay[0], w.color[0]
        seen = rescued_at = None
        while rescued_at is None and w.time < 20:
            if seen is None:
                w.apply({0: ["inspect", 0]})
                if w.results.get(0):
                    seen = w.time
            else:
                w.apply({0: ["rescue", 0]})
                if w.counts["rescued"]:
                    rescued_at = w.time
        exact = dt in (1.0, 0.5, 0.25, 0.1)
        assert seen == pytest.approx(3.0) if exact else 3.0 <= seen < 3.0 + dt, (dt, seen)
        assert rescued_at == pytest.approx(5.0) if exact else 5.0 <= rescued_at < 5.0 + 2 * dt, (dt, rescued_at)


def _greedy_rescues(dt, seed, seconds=600.0, *overrides):
    return _greedy_world(dt, seed, seconds, *overrides).counts["rescued"]


def _greedy_world(dt, seed, seconds=600.0, *overrides):
    """A tree-like policy with full knowledge of positions, straight on the world: nearest victim
    not known to mismatch, go, inspect, rescue if the colours match."""
    return _greedy_on(_sar_world(dt, seed, "agents.count=6", "scenario.victims=20", *overrides), seconds)


def _greedy_on(w, seconds, after_tick=None):
    target: dict[int, int] = {}
    mismatched: set[tuple[int, int]] = set()
    while w.time < seconds - 1e-9:
        actions = {}
        for i in range(w.n):
            t = target.get(i)
            if t is not None and (w._at(t) is None or w.vstatus[t - w.base] != ALIVE or (i, t) in mismatched):
                t = None
            if t is None:  # ids are rows + base (the world forgets victims long gone)
                alive = [int(r) + w.base for r in np.flatnonzero(w.vstatus == ALIVE)]
                alive = [v for v in alive if (i, v) not in mismatched]
                if not alive:
                    continue
                t = min(alive, key=lambda v: math.hypot(w.vx[v - w.base] - w.ax[i], w.vy[v - w.base] - w.ay[i]))
                target[i] = t
            if not w._in_reach(i, t):
                actions[i] = ["goto_task", t]
            elif i not in w.inspected.get(t, ()):
                actions[i] = ["inspect", t]
            elif w.vcolor[t - w.base] != w.color[i]:
                mismatched.add((i, t))
            else:
                actions[i] = ["rescue", t]
        before = (w.ax.copy(), w.ay.copy())
        w.apply(actions)
        if after_tick:
            after_tick(before)
    return w


def test_victims_long_gone_leave_the_world_arrays_and_no_outcome_changes(monkeypatch):
    """A steady-state world keeps rows for recent victims only (a soak spawns tens of thousands of
    victims); forgetting the ones gone for more than a lifetime changes nothing a robot sees."""
    kept = _greedy_world(1.0, 3, 3000.0)
    monkeypatch.setattr(sar, "FORGET_AFTER", math.inf)
    whole = _greedy_world(1.0, 3, 3000.0)
    assert kept.summary() == whole.summary() and kept.counts["rescued"] > 0
    assert kept.markers() == whole.markers() and kept.row() == whole.row()
    assert whole.base == 0 and len(whole.vstatus) >= whole.nv
    assert kept.base > 0 and len(kept.vstatus) <= 256 < kept.nv
    assert kept._at(0) is None and kept._in_reach(0, 0) is False


def test_sar_results_converge_as_the_tick_shrinks():
    """Mean rescues over 8 seeds at dt 1, 0.5, 0.25, 0.1, 0.05: the last two agree within 5 % and
    closer than the first two; and no run beats the bound the durations set (each rescue takes a
    robot at least one inspection: 6 robots x 600 s / inspect_time). 10-s inspections: with the
    default 33 s a trial rescues about 25, and 8 seeds cannot tell 5 % apart."""
    inspect = 10.0
    runs = {
        dt: [_greedy_rescues(dt, seed, 600.0, f"scenario.inspect_time={inspect}") for seed in range(8)]
        for dt in (1.0, 0.5, 0.25, 0.1, 0.05)
    }
    means = [np.mean(r) for r in runs.values()]
    assert abs(means[-1] - means[-2]) <= 0.05 * means[-1], means
    assert abs(means[-1] - means[-2]) < abs(means[0] - means[1]), means
    assert max(max(r) for r in runs.values()) <= 6 * 600 / inspect, runs


def test_the_time_budget_books_every_robot_tick_once_and_agrees_with_the_counts():
    """Six greedy robots for 600 s, half their moves failing, no action interrupted: each live tick is booked to one
    activity (shares sum to one over 6 x 600 robot-seconds); the moving ticks are the ticks in
    which a robot's position changed, seen from outside; inspecting is inspect_time per completed
    inspection plus the lost ones (whole inspections too) plus what is under way at the end; the
    penalty is move_penalty per failed move, but for one cut by the end."""
    w = _sar_world(
        0.25, 4, "agents.count=6", "scenario.victims=20", "scenario.move_fail=0.5", "scenario.interrupt=never"
    )
    moved = np.zeros(w.n)

    def count_moves(before):
        moved[:] += (w.ax != before[0]) | (w.ay != before[1])

    budget = _greedy_on(w, 600.0, count_moves).summary()["time_budget"]
    shares = ("moving", "inspecting", "rescuing", "penalty", "idle")
    assert sum(budget[k] for k in shares) == pytest.approx(1.0, abs=1e-5)
    total = budget["robot_seconds"]
    assert total == 6 * 600.0
    assert budget["moving"] * total == pytest.approx(moved.sum() * 0.25, abs=1e-2)
    inspect_time = w.sc.inspect_time
    under_way = sum((w.tick - p[3]) * 0.25 for p in w.pending.values() if p[0] == "inspect")
    lost = budget["inspecting_lost"] * total
    assert lost / inspect_time == pytest.approx(round(lost / inspect_time), abs=1e-3) and lost > 0
    assert (budget["inspecting"] - budget["inspecting_lost"]) * total - under_way == pytest.approx(
        inspect_time * w.counts["inspections"], abs=1e-2
    )
    failed_moves = w.counts["move_failures"]
    assert failed_moves > 10 and budget["idle"] > 0 and budget["rescuing"] > 0
    assert 0 <= failed_moves * w.sc.move_penalty - budget["penalty"] * total <= w.sc.move_penalty + 1e-6


@pytest.mark.parametrize("interrupt", ["never", "on_change"])
def test_a_busy_robot_that_turns_to_something_else_stops_its_inspection_only_if_interrupts_are_on(interrupt):
    """A robot inspects a victim for 10 s (40 ticks) and after 5 ticks asks to go elsewhere: with
    interrupt on_change it goes in that very tick, no colour ever comes, the interruption is counted
    and its 5 ticks are booked lost; with never it stays until the inspection's end and learns the
    colour, as before the key existed."""
    w = _one_robot_at_one_victim("scenario.lifetime=1000", f"scenario.interrupt={interrupt}")
    start = float(w.ax[0])
    w.apply({0: ["inspect", 0]})
    for _ in range(4):
        w.apply({0: ["inspect", 0]})  # going on with it
    moved_at = None
    while w.tick < 60:
        w.apply({0: ["goto", start + 100.0, float(w.ay[0])]})
        if moved_at is None and w.ax[0] != start:
            moved_at = w.tick - 1
    budget = w.summary()["time_budget"]
    if interrupt == "on_change":
        assert moved_at == 5 and w.counts["interrupted"] == 1 and w.counts["inspections"] == 0
        assert budget["inspecting"] * budget["robot_seconds"] == pytest.approx(5 * 0.25, abs=1e-3)
        assert budget["inspecting_lost"] == budget["inspecting"]
    else:
        assert moved_at == 40 and w.counts["interrupted"] == 0 and w.counts["inspections"] == 1
        assert budget["inspecting"] * budget["robot_seconds"] == pytest.approx(10.0, abs=1e-3)
        assert budget["inspecting_lost"] == 0


def _strategy_run(out_dir, seconds, *overrides):
    """The SAR world and every robot's runtime and the radio stepped in one process (the
    in-process engine): the summary of the run."""
    from swarmbed.launch.inprocess import run_in_process

    return run_in_process(experiment(f"run.duration={seconds}", *overrides, base=SAR_BASE), out_dir).summary


@pytest.mark.slow  # no process, but 10 robots' runtimes for 560 ticks: 8-14 s each
@pytest.mark.parametrize(
    "allocator, monitor, interrupts",
    [("tree", None, True), ("cbba", None, False), ("cbba", True, True), ("tree", False, False)],
)
def test_only_a_strategy_that_watches_its_target_stops_an_inspection_of_a_victim_gone_meanwhile(
    allocator, monitor, interrupts, tmp_path
):
    """With interrupt on_change, tree (a behavior tree: its condition nodes watch the target) stops
    inspections whose victim another robot rescued or that expired; cbba (a state machine) holds to
    them, and its inspections end on a victim that is gone; allocator.monitor turns either way."""
    sets = [f"allocator.name={allocator}", "scenario.interrupt=on_change"]
    if monitor is not None:
        sets.append(f"allocator.monitor={str(monitor).lower()}")
    s = _strategy_run(tmp_path, 140.0, "agents.count=10", *sets)  # the first victims all expire at 100 s
    assert (s["interrupted"] > 0) == interrupts, s
    assert s["time_budget"]["inspecting_lost"] > 0 and s["inspections"] > 0


@pytest.mark.parametrize("first_ages", ["spread", "new"])
def test_the_first_victims_expire_one_by_one_unless_all_are_born_at_time_0(first_ages):
    """A steady state from the start: the first victims' remaining lifetimes are uniform over a
    lifetime (Kolmogorov-Smirnov against the uniform law), their ids in birth order (what lets the
    world drop old rows); with first_ages new they all have the whole lifetime left."""
    from scipy.stats import kstest

    w = _sar_world(0.25, 5, "scenario.victims=2000", f"scenario.first_ages={first_ages}")
    left = w.vspawn[: w.nv] + w.sc.lifetime - w.time
    if first_ages == "new":
        assert np.all(left == w.sc.lifetime)
        return
    assert np.all(np.diff(w.vspawn[: w.nv]) >= 0) and left.min() > 0 and left.max() <= w.sc.lifetime
    assert kstest(left / w.sc.lifetime, "uniform").pvalue > 0.01


FAILURES = ("scenario.move_fail=0.5", "scenario.inspect_fail=0.5", "scenario.rescue_fail=0.5")


@pytest.mark.slow
def test_with_failures_results_converge_as_the_tick_shrinks_when_a_move_fails_as_a_whole():
    """Half of all moves, inspections and rescues fail, and moving takes most of a robot's time
    (1-s inspections). With a move failing as a whole (at its start) a robot loses a penalty per
    move, whatever the tick: rescues, as a share of the same seeds' without failures, agree within
    10 % at dt 0.1 and 0.05. Drawn on every tick of moving instead, the penalty is paid more often
    the shorter the tick: the share falls by more than a fifth from dt 0.1 to 0.05."""

    def mean_rescues(dt, *overrides):
        return np.mean([_greedy_rescues(dt, s, 600.0, "scenario.inspect_time=1", *overrides) for s in range(6)])

    per_move, per_tick = {}, {}
    for dt in (0.1, 0.05):
        clean = mean_rescues(dt)
        per_move[dt] = mean_rescues(dt, *FAILURES) / clean
        per_tick[dt] = mean_rescues(dt, *FAILURES, "scenario.move_failure=per_tick") / clean
    assert abs(per_move[0.05] - per_move[0.1]) <= 0.1 * per_move[0.1], per_move
    assert per_tick[0.05] < 0.8 * per_tick[0.1], per_tick


def test_a_failed_inspection_costs_the_tick_it_was_tried_in_unless_failures_are_known_at_the_end():
    for known, busy_ticks in (("start", 1), ("end", 40)):
        w = _one_robot_at_one_victim("scenario.inspect_fail=1", f"scenario.failure_known={known}")
        w.apply({0: ["inspect", 0]})
        assert w.busy_until[0] - w.tick == busy_ticks - 1, known
        for _ in range(busy_ticks):
            w.apply({0: ["inspect", 0] if w.busy_until[0] > w.tick else ["stop"]})  # going on with it, if busy
        assert w.counts["inspect_failures"] == 1 and not w.results, known


def test_a_failed_move_stalls_the_robot_once_per_move_for_the_penalty():
    """Every move fails until the robot has tried again: the penalty, then it goes."""
    w = _sar_world(0.25, 0, "agents.count=1", "scenario.move_fail=0.5", "scenario.move_penalty=0.5")
    goal = (float(w.ax[0]) + 100.0, float(w.ay[0]))
    draws = []
    w.fail_rng = type("Rigged", (), {"random": lambda self: draws.append(1) or (0.0 if len(draws) == 1 else 0.9)})()
    start = float(w.ax[0])
    for _ in range(12):
        if w.busy_until[0] <= w.tick:
            w._move(0, *goal, ("point", *goal))
        w.tick += 1
    assert len(draws) == 2  # the failed try and the one after the penalty; none while it goes on
    assert w.counts["move_failures"] == 1
    assert float(w.ax[0]) - start == pytest.approx(w.speed * 0.25 * (12 - 2))  # 2 ticks stuck


def test_within_agrees_with_the_agents_hypot_to_the_last_bit():
    """The worlds' fast range test settles points near the edge with the standard library's hypot,
    as agents do (numpy's differs from it in the last bit now and then)."""
    rng = np.random.default_rng(1)
    for reach in (300.0, 5.0, 1e-5, 0.0, math.inf):
        angle, scale = rng.uniform(0, 2 * math.pi, 5000), reach if math.isfinite(reach) else 1.0
        on_x, on_y = np.cos(angle) * scale, np.sin(angle) * scale  # on the edge, give or take rounding
        cases = [
            (rng.uniform(-500, 500, (50, 80)), rng.uniform(-500, 500, (50, 80))),
            (on_x, on_y),
            (np.nextafter(on_x, math.inf), on_y),
            (np.nextafter(on_x, -math.inf), np.nextafter(on_y, -math.inf)),
        ]
        for dx, dy in cases:
            agent = [math.hypot(a, b) <= reach for a, b in zip(dx.ravel().tolist(), dy.ravel().tolist())]
            assert np.array_equal(within(dx, dy, reach).ravel(), agent), reach


def test_the_world_shows_a_robot_what_its_own_view_says_it_sees_even_on_the_edges():
    """A robot concludes a victim is gone when its view says it should see it and the world does not
    show it; so the world's sight must agree with the agent's ``LocalView.sees`` on every pair,
    points exactly on the edge of the range and of the cone included (where numpy's and the standard
    library's hypot and atan2 differ in the last bit now and then)."""
    from swarmbed.extension import LocalView, sight

    rng = np.random.default_rng(3)
    reach, angle = 12.0, math.pi / 2
    ox, oy, heading = rng.uniform(-30, 30, 40), rng.uniform(-30, 30, 40), rng.uniform(-math.pi, math.pi, 40)
    xs, ys = [], []
    for i in range(len(ox)):  # per observer: points on its range's edge and on its cone's two edges
        edges = [np.full(30, heading[i] + angle / 2), np.full(30, heading[i] - angle / 2)]
        turn = np.concatenate([rng.uniform(-math.pi, math.pi, 60), *edges])
        r = np.concatenate([np.full(60, reach), rng.uniform(0.5, reach, 60)])
        px, py = ox[i] + r * np.cos(turn), oy[i] + r * np.sin(turn)
        xs += [px, np.nextafter(px, math.inf), np.nextafter(px, -math.inf)]
        ys += [py, py, np.nextafter(py, math.inf)]
    x, y = np.concatenate(xs), np.concatenate(ys)
    got = sight(ox, oy, x, y, reach, heading, angle)
    for i in range(len(ox)):
        view = LocalView(i, len(ox), 0, 0.0, float(ox[i]), float(oy[i]), float(heading[i]), 0.0, 1.0, {}, [])
        view.awareness_range, view.vision_angle = reach, angle
        agent = [view.sees(a, b) for a, b in zip(x.tolist(), y.tolist())]
        assert got[i].tolist() == agent, i
    assert 0 < got.sum() < got.size


def _losing_world(per: str, robots: int, p: float, dt: float, seed: int):
    """A search-and-rescue world of ``robots`` robots lost with probability ``p`` per ``per`` from the start."""
    exp = experiment(
        f"agents.count={robots}",
        "scenario.kind=sar",
        f"run.dt={dt}",
        f"scenario.agent_loss={p}",
        "scenario.agent_loss_grace=0",
        f"scenario.agent_loss_per={per}",
        "scenario.victims=1",
        "allocator.name=tree",
        base=ROOT_EXPERIMENTS / "sar" / "_base.yaml",
    )
    return resolve_experiment(exp).scenario().make_world(np.random.default_rng(seed))


def _assert_survival(survived: float, expected: float, robots: int) -> None:
    """A binomial share within 4.5 standard deviations of its expectation."""
    assert abs(survived - expected) <= 4.5 * math.sqrt(expected * (1 - expected) / robots), (survived, expected)


@pytest.mark.parametrize("dt", [0.25, 1.0])
def test_agent_loss_per_second_loses_robots_at_the_same_rate_per_simulated_second_at_any_tick(dt):
    """``agent_loss_per: second``: a robot survives a simulated second with probability 1 - p whatever
    run.dt is (the formula); per tick (the default) it would at dt = 0.25 lose four times as often."""
    p, robots, seconds = 0.02, 400, 60
    world = _losing_world("second", robots, p, dt, seed=1)
    for _ in range(int(round(seconds / dt))):
        for lost in world.draw_losses():
            world.kill(lost)
        world.tick += 1
    _assert_survival(world.alive.sum() / robots, (1 - p) ** seconds, robots)


def test_agent_loss_per_decision_draws_once_for_each_new_choice_of_a_robot():
    """``agent_loss_per: decision``: a robot that keeps doing one thing draws once, one that changes
    its action every tick draws every tick: survival is (1 - p)^decisions (the formula), whatever the
    number of ticks. A timed action forgets the last choice, so the next one is a decision."""
    p, robots, ticks = 0.02, 600, 40
    world = _losing_world("decision", robots, p, 0.25, seed=3)
    steady, restless = range(0, robots, 2), range(1, robots, 2)
    for k in range(ticks):
        for lost in world.draw_losses():
            world.kill(lost)
        acts = {i: ["stop"] for i in steady} | {i: ["goto", float(k % 2), 0.0] for i in restless}
        world.apply({i: a for i, a in acts.items() if world.alive[i]})
    for group, decisions in ((steady, 1), (restless, ticks - 1)):  # the last tick's choices draw at the next
        _assert_survival(world.alive[list(group)].mean(), (1 - p) ** decisions, len(group))
    world.decisions.chosen[0] = ["stop"]
    world._busy(0, 1.0)  # a timed action: the robot's next choice is a decision even if it is "stop" again
    world.decisions.last_tick = []
    world.decisions.note(0, ["stop"])
    assert world.decisions.last_tick == [0]


@pytest.mark.parametrize("abandon_time", [0.0, 5.0])
def test_abandoning_takes_abandon_time_during_which_the_robot_stays_put(abandon_time):
    """``scenario.abandon_time``: the robot that abandons a victim is busy that long (whole ticks),
    booked as penalty; 0 (the default) leaves it free the next tick, as before."""
    exp = experiment(
        "scenario.kind=sar",
        "agents.count=2",
        "run.dt=0.25",
        f"scenario.abandon_time={abandon_time}",
        "allocator.name=tree",
        base=ROOT_EXPERIMENTS / "sar" / "_base.yaml",
    )
    world = resolve_experiment(exp).scenario().make_world(np.random.default_rng(2))
    world.apply({0: ["abandon", world.base], 1: ["stop"]})  # tick 0
    assert world.counts["abandons"] == 1
    first_move = None
    for _ in range(40):
        before = world.distance[0]
        tick = world.tick
        world.apply({0: ["goto", 30.0, 0.0], 1: ["stop"]})
        if first_move is None and world.distance[0] > before:
            first_move = tick
    assert first_move == (round(abandon_time / 0.25) if abandon_time else 1)
    assert (world.budget.summary(0.25)["penalty"] > 0) == (abandon_time > 0)
