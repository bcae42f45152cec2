"""Kinematic limits and the MT-SR bookkeeping (no processes needed)."""

import math

import numpy as np

from swarmbed.coordinator.kinematics import Limits, step
from swarmbed.experiments.config import resolve_experiment
from tests.conftest import experiment


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


def test_collaborative_work_adds_rates_and_never_overcounts():
    exp = experiment("agents.count=3", "scenario.initial_tasks=1", "scenario.workload=[5, 5]",
                     "scenario.task_positions=[[50, 50]]", "scenario.agent_positions=[[50, 50], [51, 50], [50, 51]]")
    w = MTSRWorld(exp, np.random.default_rng(0))
    ticks = 0
    while not w.finished:
        w.apply({i: ["goto_task", 0] for i in range(3)})
        ticks += 1
    assert ticks == 2  # 3 agents at rate 1: 3 + 2 (of 3 possible)
    assert w.work.sum() == 5.0 and w.remaining[0] == 0.0
    assert w.done_at[0] == 2.0


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
