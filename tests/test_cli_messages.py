"""What a new user reads when a command goes wrong: one line, with the closest name where a name
was mistyped, and ``swarmbed --version`` (issue 82, item 27)."""

import pytest

import swarmbed
from swarmbed.bt import BTError, NodeRegistry, load_tree
from swarmbed.cli.main import main
from swarmbed.extension.node_sets import node_registry
from tests.conftest import QUICKSTART


def _err(capsys, *argv: str) -> str:
    with pytest.raises(SystemExit) as stop:
        main(list(argv))
    assert stop.value.code in (0, 2)
    captured = capsys.readouterr()
    return (captured.err or captured.out).strip()


def test_version(capsys):
    assert _err(capsys, "--version") == f"swarmbed {swarmbed.__version__}"


@pytest.mark.parametrize(
    "argv, expected",
    [
        (("run", str(QUICKSTART), "--sed", "x=1"), "did you mean '--seed'?"),
        (("sweep", "s.yaml", "--runs", "0"), "--runs"),
        (("bogus",), "invalid choice"),
    ],
)
def test_a_usage_error_is_one_line_naming_the_fix(capsys, argv, expected):
    err = _err(capsys, *argv)
    assert len(err.splitlines()) == 1 and expected in err and "--help" in err and "usage:" not in err, err


def test_a_mistyped_allocator_or_scenario_names_the_closest(capsys):
    assert main(["run", str(QUICKSTART), "--set", "allocator.name=cbbba", "--check"]) == 2
    assert "did you mean 'cbba'?" in capsys.readouterr().err
    assert main(["run", str(QUICKSTART), "--set", "scenario.kind=mtrs", "--check"]) == 2
    assert "did you mean 'mtsr'?" in capsys.readouterr().err


def test_a_mistyped_node_names_the_closest(tmp_path):
    tree = tmp_path / "t.xml"
    tree.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequense><AlwaysSuccess/></Sequense></BehaviorTree></root>'
    )
    registry: NodeRegistry = node_registry(())
    with pytest.raises(BTError, match="did you mean 'Sequence'"):
        load_tree(tree, registry)


def test_a_grid_axis_over_a_key_a_scenario_sets_is_refused_and_one_scenario_can_be_picked(capsys):
    from tests.conftest import ROOT

    sweep = str(ROOT / "experiments" / "space_fcg_same_tick.yaml")  # its scenario a30 sets agents.count
    assert main(["sweep", sweep, "--grid", "agents.count=10", "--check"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "agents.count" in err and "a30" in err, err
    assert main(["sweep", sweep, "--scenario", "a3", "--check"]) == 2
    assert "did you mean 'a30'?" in capsys.readouterr().err
    assert main(["sweep", sweep, "--scenario", "a30", "--runs", "1", "--check"]) == 0
    assert "a30_range-100_same_tick_claims-unseen" in capsys.readouterr().out


def test_a_sweep_into_a_run_folder_is_refused(capsys, tmp_path):
    (tmp_path / "config.yaml").write_text("name: a run\n")
    assert main(["sweep", str(QUICKSTART), "--out", str(tmp_path), "--check"]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds a run" in err and len(err.splitlines()) == 1, err


@pytest.mark.slow  # starts a run
def test_run_says_its_run_id_and_endpoint_for_watch_and_swap(tmp_path):
    import json
    import subprocess
    import sys

    out = tmp_path / "run"
    done = subprocess.run(
        [sys.executable, "-m", "swarmbed", "run", str(QUICKSTART), "--out", str(out), "--no-progress",
         "--set", "run.duration=50"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    run_id = json.loads((out / "deployment.json").read_text())["run_id"]
    assert f"run {run_id} at tcp/" in done.stderr and f"--run {run_id}" in done.stderr, done.stderr


def test_long_work_says_it_is_alive_a_line_a_minute_where_no_terminal_shows_a_bar():
    """Issue 82 item 19: a soak, a replay, an analysis went silent for minutes or hours."""
    import io

    from swarmbed.results.progress import Progress

    out = io.StringIO()
    with Progress(200, "replay", "frames", every_s=0.0, stream=out) as bar:
        bar.update(50)
        bar.update(100, "tick 1,000")
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("replay: 50 of 200 frames (25 %) after 00:00:0")
    assert lines[1].endswith("; tick 1,000")
    quiet = io.StringIO()
    with Progress(200, "replay", every_s=60.0, stream=quiet) as bar:
        bar.update(199)
    assert quiet.getvalue() == ""  # within its first minute
    off = io.StringIO()
    Progress(10, "x", enabled=False, every_s=0.0, stream=off).update(5)
    assert off.getvalue() == ""


def test_watch_breaks_between_figures_on_an_80_column_terminal():
    """Issue 82 item 27: ``watch`` wrapped its cells inside figures at 80 columns."""
    from rich.console import Console

    from swarmbed.results.watch import RunView
    from swarmbed.wire.run_status import NetworkCounters, RunStatus

    row = {"tick": 10, "time": 10.0, **{f"metric_{i}": 1000.5 * i for i in range(8)}}
    status = RunStatus(
        name="quickstart", scenario="mtsr", allocator="fcg", tick=10, time=10.0, ticks=2000, wall_s=1.0, row=row,
        network=NetworkCounters(messages_sent=10, bytes_sent=100, copies=40, delivered=30, dropped=10),
        drops={"out_of_range": 8, "loss": 1, "queue_full": 1, "late": 0}, alive=list(range(5)),
    )  # fmt: skip
    console = Console(width=80, record=True, color_system=None)
    console.print(RunView("abc", status=status).render())
    text = console.export_text()
    for i in range(8):
        pair = f"metric_{i} {1000.5 * i:,.1f}"
        assert any(pair in line for line in text.splitlines()), (pair, text)
    assert max(len(line) for line in text.splitlines()) <= 80


def test_run_check_and_sweep_check_give_one_cell_the_same_estimate(capsys):
    """Issue 82 item 22: the same cell was 33 s by ``run --check`` and 61 s by ``sweep --check``."""
    import re

    assert main(["run", str(QUICKSTART), "--check"]) == 0
    alone = re.search(r"estimated wall time: .*?about (\S+ \w+)", capsys.readouterr().out).group(1)
    assert main(["sweep", str(QUICKSTART), "--runs", "4", "--check", "--jobs", "2"]) == 0
    out = capsys.readouterr().out
    assert f"about {alone} a run alone" in out, (alone, out)
    assert "estimated wall time" in out.splitlines()[-1]
