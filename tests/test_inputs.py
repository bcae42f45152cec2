"""What a user types and writes, refused before any process starts with one line that names what and
where (issue 42: a new user's ~60 bad inputs). Nothing here starts a process: each command is
refused, checked or planned in this interpreter."""

import json

import pandas as pd
import pytest

from swarmbed import config as cfg
from swarmbed.bt import BTError, load_tree
from swarmbed.cli import main as cli
from swarmbed.extension.space_nodes import space_registry
from swarmbed.launch.hub import HubOptions
from swarmbed.launch.runner import RunError, plan_run
from swarmbed.plugins.registry import PluginError, resolve
from swarmbed.results.analyze import scenario_summary
from swarmbed.results.groot import agent_command
from tests.conftest import QUICKSTART, experiment


def _file(path, text):
    path.write_text(text)
    return path


def _main(capsys, *argv):
    rc = cli.main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return rc, out, err


def test_a_key_given_twice_is_refused_with_file_line_and_key(tmp_path):
    twice = _file(tmp_path / "twice.yaml", "run:\n  seed: 5\n  duration: 100\nrun:\n  seed: 6\n")
    with pytest.raises(cfg.ConfigError, match=r"twice.yaml, line 4: key 'run' is given twice .*first on line 1"):
        cfg.load(twice)
    inner = _file(tmp_path / "inner.yaml", "run:\n  seed: 5\n  seed: 6\n")
    with pytest.raises(cfg.ConfigError, match=r"inner.yaml, line 3: key 'seed' is given twice"):
        cfg.load(inner)


def test_numbers_are_read_as_yaml_1_2_reads_them(tmp_path):
    base = QUICKSTART.read_text()
    octal = _file(tmp_path / "octal.yaml", base.replace("count: 5", "count: 010"))
    assert "count: 010" in octal.read_text() and cfg.load(octal).agents.count == 10  # not 8
    text = QUICKSTART.read_text()
    clock = _file(tmp_path / "clock.yaml", text.replace("duration: 2000", "duration: 1:00"))
    with pytest.raises(cfg.ConfigError, match=r"run.duration"):  # text, not 60 seconds
        cfg.load(clock)
    assert cfg.load(QUICKSTART, ["network.loss=1e-1"]).network.loss == 0.1  # refused before
    yes = _file(tmp_path / "yes.yaml", text.replace("run:\n", "run:\n  stop_when_done: yes\n", 1))
    with pytest.raises(cfg.ConfigError, match="stop_when_done"):  # "yes" is text in YAML 1.2
        cfg.load(yes)


def test_a_plan_of_zero_ticks_is_refused():
    with pytest.raises(cfg.ConfigError, match="makes 0 ticks"):
        experiment("run.dt=10", "run.duration=5")
    assert experiment("run.dt=10", "run.duration=10").ticks == 1


def test_a_port_value_of_the_wrong_type_is_refused_when_the_tree_loads(tmp_path):
    tree = _file(
        tmp_path / "t.xml",
        '<root BTCPP_format="4"><BehaviorTree ID="M"><Repeat num_cycles="abc">'
        "<AlwaysSuccess/></Repeat></BehaviorTree></root>",
    )
    with pytest.raises(BTError, match=r"t.xml:1 .*port 'num_cycles': 'abc' is not a int"):
        load_tree(tree, space_registry())
    with pytest.raises(cfg.ConfigError, match="num_cycles"):  # before any process starts
        experiment(f"agents.behavior_tree={tree}")
    tree.write_text(tree.read_text().replace("abc", "3"))
    load_tree(tree, space_registry())


def test_a_plugin_that_raises_at_import_or_lacks_its_class_is_one_line(tmp_path):
    bad = _file(tmp_path / "bad.py", "import json\n\nraise RuntimeError('no licence server')\n")
    with pytest.raises(PluginError) as caught:
        resolve(f"{bad}:Picker")
    assert "RuntimeError: no licence server" in str(caught.value) and "bad.py, line 3" in str(caught.value)
    assert "\n" not in str(caught.value)
    empty = _file(tmp_path / "empty.py", "X = 1\n")
    with pytest.raises(PluginError, match="has no class 'Picker'"):
        resolve(f"{empty}:Picker")


RAISING_PLUGIN = """
from swarmbed.extension import Allocator, NoParams

class Raising(Allocator):
    Params = NoParams

    def decide(self, view):
        raise KeyError("oops")
"""


def test_check_allocator_reports_every_check_of_a_plugin_that_raises(tmp_path, capsys):
    plugin = _file(tmp_path / "raising.py", RAISING_PLUGIN)
    rc, out, _ = _main(capsys, "check-allocator", f"{plugin}:Raising")
    fails = [line for line in out.splitlines() if line.startswith("FAIL")]
    assert rc == 1 and len(fails) >= 4, out  # every check ran and said why
    assert all("raised KeyError: 'oops' (" in line and "raising.py:8" in line for line in fails), fails


def test_out_that_holds_a_run_is_refused_and_kept_unless_forced(tmp_path, capsys):
    out = tmp_path / "done"
    out.mkdir()
    (out / "summary.json").write_text("{}")
    (out / "logs").mkdir()
    (out / "logs" / "agent_7.log").write_text("old")
    rc, _, err = _main(capsys, "run", QUICKSTART, "--out", out)
    assert rc == 2 and "holds a finished run already" in err and "--force" in err
    assert (out / "summary.json").read_text() == "{}" and (out / "logs" / "agent_7.log").exists()
    (tmp_path / "file").write_text("x")
    rc, _, err = _main(capsys, "run", QUICKSTART, "--out", tmp_path / "file")
    assert rc == 2 and "not a folder" in err


def test_errors_blame_the_flag_that_gave_the_value(tmp_path, capsys):
    rc, _, err = _main(capsys, "run", QUICKSTART, "--seed", "-1", "--check")
    assert rc == 2 and err.startswith("error: --seed -1:"), err
    rc, _, err = _main(capsys, "run", QUICKSTART, "--set", "run=null", "--check")
    assert rc == 2 and err.startswith("error: --set run=null: must be a section"), err
    # a check over several keys blames the flag that gave the first, in the validator's own words
    rc, _, err = _main(capsys, "run", QUICKSTART, "--set", "run.duration=0.5", "--check")
    assert rc == 2 and err.startswith("error: --set run.duration=0.5: run.duration 0.5 s"), err
    assert "Value error" not in err and ": :" not in err, err
    rc, _, err = _main(capsys, "run", QUICKSTART, "--set", "agents.cout=3", "--check")
    assert rc == 2 and "unknown key (did you mean 'agents.count'?)" in err, err
    rc, _, err = _main(capsys, "run", QUICKSTART, "--set", "allocator.name=ros2", "--check")
    assert rc == 2 and "needs a ros2: section" in err, err
    rc, _, err = _main(capsys, "run", QUICKSTART, "--set", "allocator.name=missing.py:X", "--check")
    assert rc == 2 and "missing.py does not exist" in err and "targets.py" not in err, err
    rc, _, err = _main(capsys, "sweep", QUICKSTART, "--grid", "allocator.name=,,", "--check")
    assert rc == 2 and "none of them empty" in err and "share a name" not in err, err
    rc, _, err = _main(capsys, "sweep", QUICKSTART, "--grid", "allocator.name=fcg,fcg", "--check")
    assert rc == 2 and "given twice" in err, err
    sweep = tmp_path / "two_cbbas.yaml"  # two values of one name: the clash and the way out are named
    sweep.write_text(
        f"name: two\nbase: {QUICKSTART}\ngrid:\n  allocator: [{{name: cbba}}, {{name: cbba, execute: first}}]\n"
    )
    rc, _, err = _main(capsys, "sweep", sweep, "--check")
    assert rc == 2 and "share the name 'allocator-cbba'" in err and "allocator.execute" in err, err


def test_check_validates_and_plans_without_starting_anything(tmp_path, capsys):
    out = tmp_path / "never"
    rc, text, _ = _main(capsys, "run", QUICKSTART, "--check", "--out", out)
    assert rc == 0 and "nothing was started" in text and "estimated wall time: up to about" in text, text
    assert "5 agents" in text and "fcg" in text and not out.exists()
    sweep = _file(tmp_path / "big.yaml", f"name: big\nbase: {QUICKSTART}\nruns: 400\n")
    rc, _, err = _main(capsys, "sweep", sweep, "--grid", "allocator.name=fcg,cbba,grape", "--out", tmp_path / "s")
    assert rc == 2 and "1,200 runs" in err and "--yes" in err and not (tmp_path / "s").exists()
    rc, text, _ = _main(capsys, "sweep", sweep, "--grid", "allocator.name=fcg,cbba", "--check", "--out", tmp_path / "s")
    assert rc == 0 and "800 runs planned, 800 still to run" in text and not (tmp_path / "s").exists(), text
    # without --jobs the local pool runs one a core, and the estimate says so
    import os

    assert f"with --jobs {os.cpu_count()}" in text, text


def test_a_host_that_is_not_admitted_is_named_as_such():
    exp = experiment("agents.count=4", "placement={labpc2: '2-3'}")
    with pytest.raises(RunError, match="host\\(s\\) labpc2, which this run does not admit"):
        plan_run(exp, cfg.Path("/nonexistent"), HubOptions())
    plan_run(exp, cfg.Path("/nonexistent"), HubOptions(auth=False))  # an open hub admits anyone


def test_the_gateway_takes_only_plain_agent_ids():
    assert agent_command(" 4 ") == 4 and agent_command("²") is None and agent_command("7" * 5000) is None
    assert agent_command("-1") is None and agent_command("x") is None


def test_interrupting_a_view_says_nothing_of_a_summary(capsys, monkeypatch):
    def interrupted(_args):
        raise KeyboardInterrupt

    from swarmbed.cli import campaigns, run

    monkeypatch.setattr(campaigns, "cmd_replay", interrupted)
    monkeypatch.setattr(run, "cmd_run", interrupted)
    rc, _, err = _main(capsys, "replay", "somewhere")
    assert rc == 130 and err.strip() == "interrupted"
    rc, _, err = _main(capsys, "run", QUICKSTART)
    assert rc == 130 and "no summary.json was written" in err


def test_capped_runs_are_counted_and_marked_per_cell():
    runs = pd.DataFrame(
        {
            "scenario": ["a"] * 4,
            "mission_time": [100.0, 120.0, 3000.0, 3000.0],
            "all_tasks_completed": [True, True, False, False],
        }
    )
    table = scenario_summary(runs, {"mission_time": "mission time"}, {"mission_time": "all_tasks_completed"})
    row = table.iloc[0]
    assert row["capped"] == 2 and "2 of 4 runs stopped at run.duration: a lower bound" in row["note"]
    plain = scenario_summary(
        runs.assign(all_tasks_completed=True), {"mission_time": "m"}, {"mission_time": "all_tasks_completed"}
    )
    assert plain.iloc[0]["capped"] == 0 and plain.iloc[0]["note"] == ""
    assert json.loads(json.dumps(list(table.columns)))[-2:] == ["capped", "note"]


def test_swap_requests_are_bounded_before_they_are_queued():
    from swarmbed.wire.control import SwapRequest, decode_swap
    from swarmbed.wire.errors import WireError

    assert decode_swap(b'{"agent": 3, "to": "labpc2"}') == SwapRequest(agent=3, to="labpc2")
    for crafted, why in (
        (json.dumps({"agent": 3, "to": "h" * (2 << 20)}).encode(), r"bytes \(at most 1024\)"),
        (b"[" * 100_000, r"bytes \(at most 1024\)"),
        (b"[" * 900, "nested too deep|not JSON"),
        (b'{"agent": 3, "to": "a\\nb"}', "a swap request is"),
        (b'{"agent": 3, "to": "*"}', "a swap request is"),
    ):
        with pytest.raises(WireError, match=why):
            decode_swap(crafted)


# -- issue 74: files that are not files, maps, task counts, loose types ---------------------------


def _map_experiment(tmp_path, obstacles: str) -> object:
    return _file(tmp_path / "e.yaml", QUICKSTART.read_text() + f"\nobstacles: {obstacles}\n")


@pytest.mark.timeout(30)
def test_a_map_that_is_a_device_a_fifo_or_a_link_loop_is_one_line_without_blocking(tmp_path, capsys):
    import os

    os.mkfifo(tmp_path / "fifo.yaml")
    (tmp_path / "zero.yaml").symlink_to("/dev/zero")
    (tmp_path / "a.yaml").symlink_to(tmp_path / "b.yaml")
    (tmp_path / "b.yaml").symlink_to(tmp_path / "a.yaml")
    for name, why in (("fifo.yaml", "not a regular file"), ("zero.yaml", "not a regular file"), ("a.yaml", "loop")):
        rc, _, err = _main(capsys, "run", _map_experiment(tmp_path, name), "--check")
        assert rc == 2 and len(err.strip().splitlines()) == 1, err
        typed = ("--set", f"obstacles={tmp_path / name}")  # typed, it may be anywhere: read, bounded
        rc, _, err = _main(capsys, "run", _map_experiment(tmp_path, "none.yaml"), "--check", *typed)
        assert rc == 2 and len(err.strip().splitlines()) == 1 and name in err and why in err, err
    rc, _, err = _main(capsys, "run", _file(tmp_path / "fifo_exp.yaml", "x: 1\n").with_name("fifo.yaml"), "--check")
    assert rc == 2 and "not a regular file" in err, err
    with pytest.raises(BTError, match="not a regular file"):
        load_tree(tmp_path / "fifo.yaml", space_registry())


def test_every_problem_of_a_map_is_listed_at_once_with_the_right_reasons(tmp_path):
    walls = (
        "\n  walls:\n    - {start: [0, 0], end: [0, 0]}\n    - {start: [1, 1], end: [1000, 1]}\n"
        "    - {start: [1, 1], end: [5, 1], material: glass}\n"
        "  polygons:\n    - {points: [[0, 0], [10, 10], [10, 0], [0, 10]]}\n"
        "    - {points: [[0, 0], [500, 10], [10, 0]]}\n"
    )
    with pytest.raises(cfg.ConfigError) as caught:
        cfg.load(_map_experiment(tmp_path, walls))
    lines = str(caught.value).splitlines()
    assert any("walls.0" in line and "must differ" in line for line in lines), lines
    assert any("polygons.0" in line and "edges 0 and 2 cross" in line for line in lines), lines
    assert any("material 'glass'" in line for line in lines), lines
    assert any("walls[1].end: [1000, 1] lies outside" in line for line in lines), lines
    assert any("polygons[1].points[1]: [500, 10] lies outside" in line for line in lines), lines
    assert len(lines) == 5, lines


def test_a_map_that_leaves_no_room_to_spawn_is_refused_by_check(tmp_path, capsys):
    full = "\n  polygons:\n    - {points: [[0, 0], [200, 0], [200, 150], [0, 150]]}\n"
    far = "\n  walls:\n    - {start: [0, 0], end: [10, 10]}\n  clearance: 1000000\n"
    for name, text in (("full", full), ("far", far)):
        rc, _, err = _main(
            capsys, "run", _file(tmp_path / f"{name}.yaml", QUICKSTART.read_text() + f"\nobstacles:{text}"), "--check"
        )
        assert rc == 2 and "free for spawns" in err and len(err.strip().splitlines()) == 1, err
    rc, out, err = _main(capsys, "run", QUICKSTART.parent / "walls" / "office.yaml", "--check")
    assert rc == 0, err


def test_a_map_named_in_an_experiment_stays_in_its_folder_and_its_content_is_not_quoted(tmp_path, capsys):
    secret = tmp_path / "secret.txt"
    secret.write_text("hunter2-password-line\n")
    inner = tmp_path / "exp"
    inner.mkdir()
    rc, _, err = _main(capsys, "run", _map_experiment(inner, str(secret)), "--check")
    assert rc == 2 and "outside the experiment's folder" in err and "hunter2" not in err, err
    rc, _, err = _main(capsys, "run", _map_experiment(inner, "x.yaml"), "--check", "--set", f"obstacles={secret}")
    assert rc == 2 and "must hold a mapping" in err and "hunter2" not in err, err
    _file(inner / "text.yaml", "walls: hunter2-password-line\n")
    rc, _, err = _main(capsys, "run", _map_experiment(inner, "text.yaml"), "--check")
    assert rc == 2 and "hunter2" not in err, err


@pytest.mark.parametrize(
    "setting",
    [
        "scenario.initial_tasks=1e9",
        "scenario.generations={count: 1000000000, tasks: 1000000000}",
        "scenario.generations={count: 1000, tasks: 1000}",
    ],
)
def test_task_counts_are_bounded_before_anything_is_built(setting, capsys):
    rc, _, err = _main(capsys, "run", QUICKSTART, "--check", "--set", setting)
    assert rc == 2 and ("100,000" in err or "100000" in err), err


@pytest.mark.parametrize("value", ["true", "'3'"])
def test_plugin_parameters_of_the_wrong_kind_are_refused_not_converted(value):
    with pytest.raises(cfg.ConfigError, match="robots_needed"):
        experiment(f"scenario.robots_needed={value}")
    with pytest.raises(cfg.ConfigError, match="allocator"):
        experiment("allocator.name=cbba", f"allocator.max_tasks={value}")


def test_the_environment_refuses_a_broadcast_flag_that_is_not_a_boolean():
    from swarmbed.envs import parallel_env

    with pytest.raises(ValueError, match="broadcast"):
        parallel_env(broadcast="false")


def test_a_foxglove_port_out_of_range_or_in_use_is_one_line_and_leaves_no_folder(tmp_path, capsys):
    import socket

    for port in ("70000", "-1", "http"):
        with pytest.raises(SystemExit) as code:
            cli.main(["run", str(QUICKSTART), "--check", "--foxglove", port])
        assert code.value.code == 2 and "--foxglove" in capsys.readouterr().err
    pytest.importorskip("foxglove")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        rc, _, err = _main(capsys, "run", QUICKSTART, "--out", tmp_path / "out", "--foxglove", port)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and f"--foxglove {port}" in err, err
    assert not (tmp_path / "out").exists()


def test_an_interrupted_run_and_a_missing_report_folder_are_named_as_such(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "config.yaml").write_text("name: x\n")
    (out / "partial_timeseries.csv").write_text("tick\n")
    rc, _, err = _main(capsys, "run", QUICKSTART, "--out", out)
    assert rc == 2 and "an interrupted run" in err, err
    from swarmbed.results.report import ReportError, report

    with pytest.raises(ReportError, match=r"the folder .*missing.* does not exist") as caught:
        report(tmp_path, tmp_path / "missing" / "x.html")
    assert ".part" not in str(caught.value)


def test_a_grid_key_the_file_already_varies_replaces_that_axis_with_a_line(tmp_path, capsys):
    from swarmbed.campaigns.sweep import load_sweep

    spec = _file(
        tmp_path / "s.yaml",
        f"name: s\nbase: {QUICKSTART}\nruns: 1\ngrid:\n  network.range: [100, 200, 300]\n"
        "  allocator: [{name: cbba}, {name: grape}, {name: fcg}]\n",
    )
    sweep = load_sweep(spec, grid=["allocator.name=sga,cbba"])
    names = sorted(s.name for s in sweep.scenarios)
    assert len(names) == 6 and all(n.count("allocator") == 1 for n in names), names
    assert "--grid allocator.name replaces the grid's allocator axis" in capsys.readouterr().err
    assert len(load_sweep(spec, grid=["network.range=50"]).scenarios) == 3


def test_the_sweep_estimate_is_never_below_one_run_and_says_it_is_a_ceiling(capsys):
    rc, out, _ = _main(capsys, "sweep", QUICKSTART, "--runs", "1", "--jobs", "2", "--check")
    one = next(line for line in out.splitlines() if "a run" in line).split("about ")[1].split(" a run")[0]
    total = next(line for line in out.splitlines() if "estimated wall time" in line)
    assert rc == 0 and f"up to about {one} with --jobs 2" in total and "1 at a time" in total, out
