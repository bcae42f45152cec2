"""Scenarios: the checker on every registered one and on a third written outside swarmbed, a run
of that third one through real processes, and a package adding one through an entry point."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from swarmbed import config as cfg
from swarmbed.checks.scenario_check import ScenarioCheckError, check_scenario
from swarmbed.extension.scenario import Scenario
from swarmbed.launch.runner import run_experiment
from swarmbed.plugins.registry import resolve_scenario, scenario_names
from swarmbed.wire.codec import WireError
from swarmbed.wire.targets import load_target
from tests.conftest import ledger_outcomes, read_ledger, sweep_in_process

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = Path(__file__).resolve().parent / "example_scenario.py"
PICKUP = f"{EXAMPLE}:PickupDelivery"


#: agents fast enough that tasks get done, victims inspected and items carried within the check
CHECK_AGENTS = {
    "mtsr": {"max_speed": 20.0, "max_accel": 5.0, "max_turn_rate": 3.0, "awareness_range": 2000.0},
    "sar": {"max_speed": 11.1},
    PICKUP: {"max_speed": 5.0},
}


@pytest.mark.parametrize("kind", [*scenario_names(), PICKUP])
def test_every_scenario_passes_the_checker(kind):
    result = check_scenario(resolve_scenario(kind), agents=CHECK_AGENTS.get(kind))
    assert result["samples_checked"] > 0


def _example_module():
    return sys.modules[load_target(PICKUP, Scenario).__module__]


def test_the_checker_catches_a_world_that_is_not_seeded():
    ex = _example_module()

    class Unseeded(ex.PickupDelivery):
        def make_world(self, rng, allocator=None):
            return ex.PickupWorld(self, np.random.default_rng())  # fresh entropy: not reproducible

    with pytest.raises(ScenarioCheckError, match="two runs with seed 0 differ"):
        check_scenario(Unseeded, agents=CHECK_AGENTS[PICKUP])


def test_the_checker_catches_lost_items_and_a_crash_on_bad_actions():
    ex = _example_module()

    class LeakyWorld(ex.PickupWorld):
        def apply(self, actions):
            super().apply(actions)
            self.carrying[:] = -1  # robots drop what they carry into nowhere

    class Leaky(ex.PickupDelivery):
        def make_world(self, rng, allocator=None):
            return LeakyWorld(self, rng)

    check_scenario(ex.PickupDelivery, agents=CHECK_AGENTS[PICKUP])
    with pytest.raises(ScenarioCheckError, match="conservation broken"):
        check_scenario(Leaky, agents=CHECK_AGENTS[PICKUP])

    class FragileWorld(ex.PickupWorld):
        def apply(self, actions):
            for a in actions.values():
                if a[0] == "goto_task":
                    self.ix[a[1]]  # IndexError on a well-shaped action naming an item that does not exist
            super().apply(actions)

    class Fragile(ex.PickupDelivery):
        def make_world(self, rng, allocator=None):
            return FragileWorld(self, rng)

    with pytest.raises(ScenarioCheckError, match="raised IndexError"):
        check_scenario(Fragile, ticks=1)


@pytest.mark.slow  # starts processes
def test_an_action_the_scenario_does_not_declare_never_reaches_the_world(tmp_path):
    """Agents whose exploration waypoints are NaN send ``["goto", nan, nan]``: the coordinator hands
    the world ``["invalid"]`` instead (counted), and no position becomes NaN."""
    hostile = Path(__file__).resolve().parent / "hostile_scenario.py"
    path = tmp_path / "nan.yaml"
    path.write_text(f"""name: nan-waypoints
run: {{seed: 1, dt: 1.0, duration: 20}}
scenario: {{kind: "{hostile}:NaNWaypoints", initial_tasks: 5}}
agents: {{count: 3}}
allocator: {{name: noop}}
""")
    result = run_experiment(cfg.load(path, []), tmp_path / "run", progress=False)
    assert result.summary["invalid_actions"] == 3 * 20, result.summary["invalid_actions"]
    assert np.isfinite(result.summary["distance_total"]) and result.summary["distance_total"] == 0.0


def test_a_malformed_observation_is_a_wire_error_naming_the_field():
    ex = _example_module()
    scenario = cfg.resolve_experiment(_pickup_experiment(Path("/tmp"))).scenario()
    obs = scenario.make_world(np.random.default_rng(0)).observations()[0].to_wire()
    assert ex.PickupObservation.from_wire(obs).depot == (0.0, 0.0)
    for field, bad in (("carrying", "one"), ("depot", [1.0]), ("me", [1, 2]), ("tasks", b"xyz")):
        with pytest.raises(WireError, match=field):
            ex.PickupObservation.from_wire({**obs, field: bad})
    with pytest.raises(WireError, match="carrying: missing"):
        ex.PickupObservation.from_wire({k: v for k, v in obs.items() if k != "carrying"})


def _pickup_experiment(tmp: Path, *overrides: str) -> cfg.Experiment:
    path = tmp / "pickup.yaml"
    path.write_text(f"""name: pickup
run: {{seed: 3, dt: 1.0, duration: 120}}
scenario: {{kind: "{PICKUP}", items: 8, width: 60, height: 40}}
agents: {{count: 3, max_speed: 2.0, exploration_duration: 20}}
allocator: {{name: "{EXAMPLE}:NearestItem"}}
network: {{range: 40}}
""")
    return cfg.load(path, list(overrides))


@pytest.mark.slow  # starts processes
def test_a_third_scenario_runs_end_to_end_with_no_change_to_swarmbed(tmp_path):
    exp = _pickup_experiment(tmp_path)
    result = run_experiment(exp, tmp_path / "run", progress=False)
    s = result.summary
    assert s["scenario_kind"] == PICKUP and s["items"] == 8 and 0 < s["delivered"] <= 8
    assert s["network"]["per_kind"]["claim"]["messages"] > 0 and s["network"]["bytes_agree"]
    outcomes = ledger_outcomes(read_ledger(tmp_path / "run"))
    assert outcomes["delivered"] + outcomes.get("out_of_range", 0) == s["network"]["copies"]
    again = run_experiment(_pickup_experiment(tmp_path), tmp_path / "again", progress=False)
    for name in ("summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv"):
        assert (tmp_path / "run" / name).read_bytes() == (tmp_path / "again" / name).read_bytes(), name
    assert again.summary["delivered"] == s["delivered"]


@pytest.mark.slow  # a sweep's pool workers (its runs on the in-process engine)
def test_analyze_draws_the_figures_a_third_scenario_names(tmp_path):
    """``Scenario.figures`` and ``metric_labels``: the analysis tabulates and draws a scenario it
    has never heard of, with no edit of its own."""
    from swarmbed.results.analyze import analyze

    _pickup_experiment(tmp_path)
    (tmp_path / "sweep.yaml").write_text("name: pickups\nbase: pickup.yaml\nruns: 2\n")
    sweep_in_process(tmp_path / "sweep.yaml", tmp_path / "out", "run.duration=40")
    # a results folder is data: the class it names is imported only where the user vouches for it
    assert {p.name for p in analyze(tmp_path / "out")} == {"scenario_summary.csv", "scenario_summary.md"}
    names = {p.name for p in analyze(tmp_path / "out", trusted=True)}
    assert {"fig_delivered.png", "fig_boxplots.png", "scenario_summary.csv"} <= names, names
    summary = (tmp_path / "out" / "scenario_summary.csv").read_text()
    assert ",delivered,2," in summary and ",distance_total,2," in summary, summary


@pytest.mark.slow  # starts processes
def test_an_installed_package_adds_a_scenario_and_an_allocator_through_entry_points(tmp_path):
    dist = tmp_path / "pickup_plugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: pickup-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(
        "[swarmbed.scenarios]\npickup = tests.example_scenario:PickupDelivery\n\n"
        "[swarmbed.allocators]\nnearest@pickup = tests.example_scenario:NearestItem\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    listing = subprocess.run(
        [sys.executable, "-m", "swarmbed", "params"], env=env, capture_output=True, text=True, check=True
    ).stdout
    assert "pickup" in listing and "nearest (pickup)" in listing
    exp = tmp_path / "exp.yaml"
    exp.write_text(
        "run: {seed: 1, duration: 40}\nscenario: {kind: pickup, items: 4}\n"
        "agents: {count: 2, max_speed: 3.0}\nallocator: {name: nearest}\n"
    )
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "swarmbed", "run", str(exp), "--out", str(out), "--no-progress"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scenario_kind"] == "pickup" and summary["items"] == 4
    assert "delivered" in proc.stdout  # the printed summary uses the scenario's own outcome metrics
