"""Every shipped file is an example, and every example is a test (as Mesa runs its examples): each
behavior tree loads with the node set the CLI and the runtime share, each experiment and sweep file
expands to valid experiments, and each runs a few ticks through real processes; each chaos file
(faults for swarmbed soak) loads."""

from pathlib import Path

import pytest
import yaml

from swarmbed.experiments.campaigns.chaos import load_chaos
from swarmbed.experiments.campaigns.sweep import experiment_for, load_sweep
from swarmbed.experiments.cli import main
from swarmbed.experiments.launch import config as cfg
from swarmbed.experiments.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent
TREES = sorted([*(ROOT / "agent_runtime" / "trees").glob("*.xml"), *(ROOT / "plugins").rglob("*.xml")])
YAML = sorted((ROOT / "experiments").rglob("*.yaml"))
CHAOS = [f for f in YAML if "events" in (yaml.safe_load(f.read_text()) or {})]  # faults for swarmbed soak
FILES = [f for f in YAML if f not in CHAOS]
SWEEPS = [f for f in FILES if "base" in (yaml.safe_load(f.read_text()) or {})]
EXPERIMENTS = [f for f in FILES if f not in SWEEPS]


def _id(path: Path) -> str:
    return str(path.relative_to(ROOT))


def test_there_are_examples():
    assert len(TREES) >= 6 and len(EXPERIMENTS) >= 3 and len(SWEEPS) >= 16 and CHAOS


@pytest.mark.parametrize("path", CHAOS, ids=_id)
def test_every_shipped_chaos_file_loads(path):
    assert load_chaos(path).events


def test_every_shipped_tree_loads(capsys):
    assert main(["bt", "check", *map(str, TREES)]) == 0
    assert capsys.readouterr().out.count(": ok") == len(TREES)


@pytest.mark.parametrize("path", SWEEPS, ids=_id)
def test_every_sweep_file_expands_to_valid_experiments(path):
    sweep = load_sweep(path)
    assert sweep.scenarios
    for variant in sweep.scenarios:
        experiment_for(sweep.base, variant, 0, [])


def _first_experiment(path: Path) -> cfg.Experiment:
    if path in SWEEPS:
        sweep = load_sweep(path)
        return experiment_for(sweep.base, sweep.scenarios[0], 0, [])
    return cfg.load(path)


@pytest.mark.parametrize("path", FILES, ids=_id)
def test_every_shipped_file_runs_a_few_ticks(path, tmp_path):
    exp = _first_experiment(path)
    exp = exp.model_copy(update={"run": exp.run.model_copy(update={"duration": 3 * exp.run.dt})})
    result = run_experiment(exp, tmp_path, progress=False)
    assert result.summary["ticks"] == 3
    net = result.summary["network"]
    assert net["copies"] == net["delivered"] + sum(net["dropped"].values())
