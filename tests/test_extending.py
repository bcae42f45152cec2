"""docs/EXTENDING.md's worked example runs as written: its allocator passes the conformance kit,
and an experiment naming it checks, both in this process."""

import re

import pytest

from swarmbed.cli import main as cli
from tests.conftest import ROOT

GUIDE = ROOT / "docs" / "EXTENDING.md"


def _files() -> dict[str, str]:
    """Every fenced block the guide names a file for (```python file=NAME)."""
    return dict(re.findall(r"```\w+ file=(\S+)\n(.*?)```", GUIDE.read_text(), flags=re.S))


def test_the_guides_allocator_passes_the_kit_and_its_experiment_checks(tmp_path, monkeypatch, capsys):
    files = _files()
    assert "claim_nearest.py" in files
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["check-allocator", "claim_nearest.py:ClaimNearest"]) == 0, capsys.readouterr().out
    assert "FAIL" not in capsys.readouterr().out
    command = re.search(
        r"`swarmbed (run \S+ --set allocator.name=claim_nearest.py:ClaimNearest --check)`", GUIDE.read_text()
    )
    argv = command.group(1).split()
    argv[1] = str(ROOT / argv[1])
    assert cli.main(argv) == 0, capsys.readouterr()
    assert "claim_nearest.py:ClaimNearest" in capsys.readouterr().out
    # the kit is not a rubber stamp: an allocator that returns a task it does not see fails it
    broken = files["claim_nearest.py"].replace("return task.id", "return task.id + 10_000")
    (tmp_path / "broken.py").write_text(broken)
    assert cli.main(["check-allocator", "broken.py:ClaimNearest"]) == 1


def test_the_kit_checks_an_allocator_on_a_scenario_whose_observation_fields_have_no_defaults(capsys):
    """Issue 74 item 17: the example scenario's observation declares ``carrying`` and ``depot``
    without defaults; the kit fills them as the scenario's own world does (carrying -1, the depot),
    so every check runs, and assigns, instead of failing on fields it could not fill."""
    example = ROOT / "tests" / "example_scenario.py"
    rc = cli.main(["check-allocator", f"{example}:NearestItem", "--scenario", f"{example}:PickupDelivery"])
    out = capsys.readouterr().out
    assert rc == 0 and "FAIL" not in out and "cannot fill" not in out, out
    assert "'assigned_clean': 0" not in out, out  # the allocator was shown items it could take


@pytest.mark.slow  # a run, in-process, still starts a helper process
def test_the_guides_scenario_passes_the_checker_and_runs_with_the_guides_allocator(tmp_path, monkeypatch, capsys):
    """Issue 74 item 18: the scenario written out in the guide is whole: the scenario checker
    passes it, the guide's experiment runs it to the end, and every point is visited."""
    import json

    files = _files()
    assert {"visit_points.py", "visit.yaml", "claim_nearest.py"} <= set(files)
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["check-scenario", "visit_points.py:VisitPoints"]) == 0, capsys.readouterr().out
    assert "FAIL" not in capsys.readouterr().out
    rc = cli.main(["run", "visit.yaml", "--engine", "inprocess", "--out", str(tmp_path / "run"), "--no-progress"])
    assert rc == 0, capsys.readouterr()
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["visited"] == summary["points"] == 12, summary
