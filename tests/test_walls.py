"""Walls (issue 61): the obstacles section's checks, the geometry against brute force, the planner
against the shortest path a fine grid finds, and both worlds: robots never cross a wall, see
nothing a wall hides, spawn in free space, and still get the work done. The radio through walls is
checked against its formula in tests/test_radio_models.py."""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import lil_matrix
from scipy.sparse.csgraph import shortest_path

from swarmbed.config import ConfigError, resolve_experiment, to_yaml
from swarmbed.launch.inprocess import run_in_process
from swarmbed.scenarios.paths import Planner
from swarmbed.schema.obstacles import ObstaclesSection, segments_cross
from tests.conftest import QUICKSTART, experiment

ROOT = Path(__file__).resolve().parents[1]
OFFICE = ROOT / "experiments" / "walls" / "office.yaml"
RUBBLE = ROOT / "experiments" / "walls" / "rubble.yaml"


def test_a_world_without_obstacles_writes_the_config_it_wrote_before():
    assert "obstacles" not in to_yaml(experiment())
    assert "walls" not in to_yaml(experiment()).split("network:")[1]


@pytest.mark.parametrize(
    ("setting", "says"),
    [
        ("obstacles={walls: [{start: [0, 0], end: [0, 0]}]}", "obstacles.walls.0: a wall's start and end must differ"),
        ("obstacles={polygons: [{points: [[0, 0], [6, 6], [6, 0], [0, 5]]}]}", "edges 0 and 2 cross"),
        ("obstacles={polygons: [{points: [[0, 0], [1, 1]]}]}", "needs 3 to 256 vertices"),
        ("obstacles={walls: [{start: [0, 0], end: [5, 0], material: glass}]}", "material 'glass' has no loss"),
        ("obstacles={walls: [{start: [10, 10], end: [5000, 10]}]}", "obstacles.walls[0].end: [5000, 10] lies outside"),
        ("obstacles={walls: [{start: [1, 2, 3], end: [5, 0]}]}", "obstacles.walls.0.start"),
        ("obstacles=/nonexistent/map.yaml", "obstacles: /nonexistent/map.yaml: cannot read"),
    ],
)
def test_a_bad_obstacles_section_is_refused_in_one_line_naming_the_key(setting, says):
    with pytest.raises(ConfigError) as exc:
        experiment(setting)
    assert says in str(exc.value) and len(str(exc.value).splitlines()) == 1, str(exc.value)


def test_a_map_file_is_read_from_beside_the_experiment_and_written_in_full():
    exp = experiment(base=OFFICE)
    assert exp.obstacles is not None and len(exp.obstacles.walls) == 40
    assert "office_obstacles.yaml" not in to_yaml(exp) and "material: light" in to_yaml(exp)


def in_box(x, u, v):
    return min(u[0], v[0]) <= x[0] <= max(u[0], v[0]) and min(u[1], v[1]) <= x[1] <= max(u[1], v[1])


def test_segments_cross_agrees_with_a_brute_force_parametric_solution():
    rng = np.random.default_rng(0)
    p, q, a, b = (rng.integers(0, 6, (4000, 2)).astype(float) for _ in range(4))  # a small grid: many touches

    def brute(p, q, a, b):
        # the segments meet where p + s (q - p) = a + t (b - a) for s, t in [0, 1]; on one line, where they overlap
        d, e = q - p, b - a
        if not d.any():  # a point: on the wall's line and within its box
            w = p - a
            return (
                w[0] * e[1] - w[1] * e[0] == 0
                and min(a[0], b[0]) <= p[0] <= max(a[0], b[0])
                and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])
            )
        den = d[0] * e[1] - d[1] * e[0]
        if den == 0:
            if (a - p)[0] * d[1] - (a - p)[1] * d[0] != 0:
                return False  # parallel, apart
            return any(in_box(x, a, b) for x in (p, q)) or in_box(a, p, q) or in_box(b, p, q)
        s = ((a - p)[0] * e[1] - (a - p)[1] * e[0]) / den
        t = ((a - p)[0] * d[1] - (a - p)[1] * d[0]) / den
        return 0 <= s <= 1 and 0 <= t <= 1

    got = segments_cross(p[:, 0], p[:, 1], q[:, 0], q[:, 1], a[:, 0], a[:, 1], b[:, 0], b[:, 1])
    want = np.array([brute(*v) for v in zip(p, q, a, b)])
    assert (got == want).all(), np.flatnonzero(got != want)[:5]
    assert 0.1 < want.mean() < 0.9


def grid_shortest(walls, start, goal, lo, hi, step):
    """The shortest path over an 8-connected grid of free points that sees no wall on any edge."""
    xs = np.arange(lo, hi + 1e-9, step)
    gx, gy = np.meshgrid(xs, xs)
    pts = np.c_[gx.ravel(), gy.ravel()]
    pts = np.vstack([pts[~walls.inside(pts[:, 0], pts[:, 1])], start, goal])
    n = len(pts)
    g = lil_matrix((n, n))
    reach = step * 1.5 + 1e-9
    for i in range(n):
        d = np.hypot(*(pts - pts[i]).T)
        near = np.flatnonzero((d > 0) & (d <= reach))
        ok = walls.clear(np.full(len(near), pts[i, 0]), np.full(len(near), pts[i, 1]), pts[near, 0], pts[near, 1])
        for j in near[ok]:
            g[i, j] = d[j]
    return shortest_path(g.tocsr(), indices=n - 2)[n - 1]


def test_a_teams_sight_is_every_observers_own_one_pair_at_a_time():
    """``sight`` (both worlds' sensing, one array operation for the team) against the definition
    taken one observer and one point at a time with the standard library: within reach, inside the
    cone about the heading (a point where the observer stands is inside), no wall in between (the
    segment test itself is checked against brute force above). Random placements: no pair falls
    within rounding of an edge."""
    from swarmbed.extension.scenario import sight

    walls = ObstaclesSection(
        walls=[{"start": [20, 0], "end": [20, 70]}], polygons=[{"points": [[55, 40], [75, 40], [75, 60], [55, 60]]}]
    ).compile()
    rng = np.random.default_rng(5)
    ox, oy, heading = rng.uniform(0, 100, 12), rng.uniform(0, 100, 12), rng.uniform(-math.pi, math.pi, 12)
    x, y = np.append(rng.uniform(0, 100, 400), ox[3]), np.append(rng.uniform(0, 100, 400), oy[3])
    for angle, hidden_by in ((math.pi / 2, walls), (2 * math.pi, walls), (math.pi / 3, None)):
        got = sight(ox, oy, x, y, 30.0, heading, angle, hidden_by)
        for i in range(len(ox)):
            for j in range(len(x)):
                dx, dy = x[j] - ox[i], y[j] - oy[i]
                off = (math.atan2(dy, dx) - heading[i] + math.pi) % (2 * math.pi) - math.pi
                cone = angle >= 2 * math.pi or (dx == 0 and dy == 0) or abs(off) <= angle / 2
                clear = hidden_by is None or bool(hidden_by.clear([ox[i]], [oy[i]], [x[j]], [y[j]])[0])
                assert got[i, j] == (math.hypot(dx, dy) <= 30.0 and cone and clear), (angle, i, j)
        assert got[3, -1], "a point where the observer stands is seen"
        assert 0 < got.sum() < got.size
    with pytest.raises(ValueError, match="headings"):
        sight(ox, oy, x, y, 30.0, None, math.pi)


def test_the_planner_finds_the_way_round_no_longer_than_a_fine_grid_and_crossing_no_wall():
    obstacles = ObstaclesSection(
        walls=[{"start": [20, 0], "end": [20, 70]}, {"start": [40, 30], "end": [40, 100]}],
        polygons=[{"points": [[55, 40], [75, 40], [75, 60], [55, 60]]}],
        clearance=1.0,
    )
    walls = obstacles.compile()
    planner = Planner(walls, lambda x, y: (x >= 0) & (x <= 100) & (y >= 0) & (y <= 100))
    for start, goal in (((5, 10), (95, 50)), ((5, 90), (60, 20)), ((30, 50), (90, 55))):
        path = planner.path(start, goal)
        assert path is not None and path[-1] == goal
        legs = [start, *path]
        xs, ys = np.array(legs).T
        assert walls.clear(xs[:-1], ys[:-1], xs[1:], ys[1:]).all(), "a leg of the plan crosses a wall"
        length = float(np.hypot(np.diff(xs), np.diff(ys)).sum())
        # the visibility graph's path is within the clearance detours of the true shortest path,
        # which a 2-unit grid over-estimates
        assert length <= grid_shortest(walls, start, goal, 0, 100, 2.0) + 1e-6
        assert length >= math.dist(start, goal)
    enclosed = ObstaclesSection(polygons=[{"points": [[40, 40], [60, 40], [60, 60], [40, 60]]}]).compile()
    walled_in = ObstaclesSection(
        walls=[
            {"start": [30, 30], "end": [70, 30]},
            {"start": [70, 30], "end": [70, 70]},
            {"start": [70, 70], "end": [30, 70]},
            {"start": [30, 70], "end": [30, 30]},
        ]
    ).compile()
    assert Planner(enclosed, lambda x, y: x == x).path((10, 10), (90, 90)) is not None
    assert Planner(walled_in, lambda x, y: x == x).path((10, 10), (50, 50)) is None, "a closed room has no way in"


def crossed_walls(walls, track_x, track_y):
    """Moves (between consecutive recorded positions of each robot) that cross a wall."""
    x0, y0, x1, y1 = track_x[:-1].ravel(), track_y[:-1].ravel(), track_x[1:].ravel(), track_y[1:].ravel()
    moved = (x0 != x1) | (y0 != y1)
    return int((~walls.clear(x0[moved], y0[moved], x1[moved], y1[moved])).sum())


def drive_world(exp, ticks, policy):
    world = resolve_experiment(exp).scenario().make_world(np.random.default_rng(exp.run.seed))
    xs, ys = [world.ax.copy()], [world.ay.copy()]
    for _ in range(ticks):
        obs = world.observations()
        world.apply({i: policy(world, i, o) for i, o in obs.items()})
        xs.append(world.ax.copy())
        ys.append(world.ay.copy())
    return world, np.array(xs), np.array(ys)


def nearest_task(world, i, o):
    if len(o.tasks):
        d = np.hypot(o.tasks["x"] - o.x, o.tasks["y"] - o.y)
        return ["goto_task", int(o.tasks["id"][int(np.argmin(d))])]
    # nothing in view: walk to a far corner of the floor (through the doors)
    return ["goto", float((i * 397) % 1400), float(1000 - (i * 211) % 1000)]


def test_office_robots_never_cross_a_wall_see_no_task_behind_one_and_get_work_done():
    exp = experiment("agents.count=12", "scenario.initial_tasks=60", "scenario.generations.count=0", base=OFFICE)
    world, xs, ys = drive_world(exp, 2500, nearest_task)
    walls = world.walls
    assert walls.free(xs[0], ys[0]).all() and walls.free(world.tx, world.ty).all(), "something spawned in a wall"
    assert crossed_walls(walls, xs, ys) == 0
    assert world.tasks_completed >= 15, "robots must get through the doors to tasks"
    assert world.navigator.plans_made > 0
    # sight: no observation holds a task a wall hides
    for o in world.observations().values():
        if len(o.tasks):
            assert walls.clear(np.full(len(o.tasks), o.x), np.full(len(o.tasks), o.y), o.tasks["x"], o.tasks["y"]).all()
    # and the same world without walls sees more
    open_world = (
        resolve_experiment(exp.model_copy(update={"obstacles": None}))
        .scenario()
        .make_world(np.random.default_rng(exp.run.seed))
    )
    walled = resolve_experiment(exp).scenario().make_world(np.random.default_rng(exp.run.seed))
    seen_open = sum(len(o.tasks) for o in open_world.observations().values())
    seen_walled = sum(len(o.tasks) for o in walled.observations().values())
    assert seen_walled < seen_open


def test_rubble_robots_go_round_the_slabs_and_see_no_victim_behind_one():
    exp = experiment("run.duration=300", base=RUBBLE)

    def inspect_nearest(world, i, o):
        if len(o.tasks):
            v = int(o.tasks["id"][int(np.argmin(np.hypot(o.tasks["x"] - o.x, o.tasks["y"] - o.y)))])
            return (
                ["inspect", v]
                if math.hypot(*(np.array([o.tasks["x"][0], o.tasks["y"][0]]) - (o.x, o.y))) < 5
                else ["goto_task", v]
            )
        return ["goto", -o.x, -o.y]  # cross the field

    world, xs, ys = drive_world(exp, 1200, inspect_nearest)
    walls = world.walls
    assert crossed_walls(walls, xs, ys) == 0
    assert not walls.inside(world.vx[: world.nv - world.base], world.vy[: world.nv - world.base]).any()
    assert world.counts["inspections"] > 0
    for o in world.observations().values():
        if len(o.tasks):
            assert walls.clear(np.full(len(o.tasks), o.x), np.full(len(o.tasks), o.y), o.tasks["x"], o.tasks["y"]).all()
        for _, rx, ry in o.robots:
            assert walls.clear([o.x], [o.y], [rx], [ry])[0]


@pytest.mark.slow
@pytest.mark.parametrize("path", [OFFICE, RUBBLE])
def test_the_shipped_walls_experiments_run_in_process_and_are_deterministic(tmp_path, path):
    exp = experiment("run.duration=120", base=path)
    a, b = tmp_path / "a", tmp_path / "b"
    run_in_process(exp, a)
    run_in_process(exp, b)
    for name in ("summary.json", "network_ledger.csv", "timeseries.csv", "config.yaml"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    if path == RUBBLE:
        assert "blocked_by_wall" in (a / "summary.json").read_text()


@pytest.mark.slow
def test_views_draw_a_runs_walls_and_refuse_crafted_ones_in_one_line(tmp_path):
    """The report, the replay and the MCAP recording draw the walls of the run's config.yaml; a
    config.yaml whose obstacles were tampered with (a self-crossing polygon) is refused by each in
    one line naming the file, never drawn half."""
    import yaml

    from swarmbed.results.recording import RecordingError, write_mcap
    from swarmbed.results.replay import ReplayError, replay
    from swarmbed.results.report import ReportError, report

    exp = experiment("run.duration=20", "run.record_trajectories=true", "network.ledger=per_receiver", base=RUBBLE)
    run = tmp_path / "run"
    run_in_process(exp, run)
    page = report(run).read_text()
    assert "Walls and paths" in page
    movie, frames = replay(run, tmp_path / "m.gif", every=10)
    assert frames > 0 and movie.stat().st_size > 0
    made = write_mcap(run, tmp_path / "r.mcap")
    assert made["messages"]["/walls"] == 1
    config = yaml.safe_load((run / "config.yaml").read_text())
    config["obstacles"]["polygons"][0]["points"] = [[0, 0], [6, 6], [6, 0], [0, 5]]
    (run / "config.yaml").write_text(yaml.safe_dump(config))
    for view, error in ((lambda: report(run), ReportError), (lambda: replay(run, tmp_path / "n.gif"), ReplayError)):
        with pytest.raises(error) as exc:
            view()
        assert "config.yaml: obstacles" in str(exc.value) and len(str(exc.value).splitlines()) == 1
    with pytest.raises(RecordingError) as exc:
        write_mcap(run, tmp_path / "s.mcap")
    assert "config.yaml: obstacles" in str(exc.value) and len(str(exc.value).splitlines()) == 1


# -- issue 74 item 4: the planner's graph, bounded before it is built ----------------------------


def test_the_graph_built_a_slice_at_a_time_joins_the_same_pairs_as_all_at_once(monkeypatch):
    from swarmbed.scenarios import paths
    from swarmbed.schema.obstacles import ObstaclesSection

    rng = np.random.default_rng(3)
    walls = [
        {"start": [float(x), float(y)], "end": [float(x) + 5, float(y) + 2]} for x, y in rng.uniform(0, 300, (60, 2))
    ]
    w = ObstaclesSection.model_validate({"walls": walls}).compile()
    nodes = paths.corner_nodes(w)
    i, j = np.triu_indices(len(nodes), 1)
    seen = w.clear(nodes[i, 0], nodes[i, 1], nodes[j, 0], nodes[j, 1])
    monkeypatch.setattr(paths, "SIGHT_TESTS_PER_SLICE", 600)  # ten node pairs a slice
    a, b = paths._visible_pairs(w, nodes)
    assert np.array_equal(a, i[seen]) and np.array_equal(b, j[seen]) and len(a) > 100
    assert paths.sight_tests(w) == len(i) * len(w.xy)


def test_a_map_whose_graph_is_too_large_is_refused_by_check_and_a_large_one_is_in_the_estimate(tmp_path, capsys):
    import math

    from swarmbed.cli import main as cli

    many = "".join(
        f"    - {{start: [{1 + (k % 190)}, {1 + (k // 190) * 10}], end: [{1.5 + (k % 190)}, {1 + (k // 190) * 10}]}}\n"
        for k in range(2000)
    )
    path = tmp_path / "many.yaml"
    path.write_text(QUICKSTART.read_text() + f"\nobstacles:\n  clearance: 0.1\n  walls:\n{many}")
    assert cli.main(["run", str(path), "--check"]) == 2
    err = capsys.readouterr().err
    assert "sight tests" in err and len(err.strip().splitlines()) == 1, err
    rings = "".join(
        "    - {points: ["
        + ", ".join(
            f"[{25 + 25 * k + 8 * math.cos(2 * math.pi * i / 256):.4f}, {75 + 8 * math.sin(2 * math.pi * i / 256):.4f}]"
            for i in range(256)
        )
        + "]}\n"
        for k in range(7)
    )
    path = tmp_path / "rings.yaml"
    path.write_text(QUICKSTART.read_text() + f"\nobstacles:\n  polygons:\n{rings}")
    assert cli.main(["run", str(path), "--check", "--engine", "inprocess"]) == 0
    out = capsys.readouterr().out
    seconds = int(out.split("estimated wall time: up to about ")[1].split(" s ")[0])
    assert 60 <= seconds < 120, out  # the graph's build (about 73 s measured), with the run's few seconds
