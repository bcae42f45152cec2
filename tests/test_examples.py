"""Every shipped file is an example, and every example is a test (as Mesa runs its examples): each
behavior tree loads with the node set the CLI and the runtime share, each experiment and sweep file
expands to valid experiments and builds its world, and each kind of experiment runs a few ticks
through real processes; each chaos file (faults for swarmbed soak) loads.

Files of one kind (the same scenario, allocator, radio and tree, every text and switch alike: they
differ in numbers only, as the 14 search-and-rescue series files do) run the same code; one of each
kind runs, the others are loaded and their worlds built."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from swarmbed import config as cfg
from swarmbed.campaigns.chaos import load_chaos
from swarmbed.campaigns.sweep import experiment_for, load_sweep
from swarmbed.cli.main import main
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent
TREES = sorted([*(ROOT / "swarmbed" / "extension" / "trees").glob("*.xml"), *(ROOT / "plugins").rglob("*.xml")])
YAML = sorted((ROOT / "experiments").rglob("*.yaml"))
CHAOS = [f for f in YAML if "events" in (yaml.safe_load(f.read_text()) or {})]  # faults for swarmbed soak
MAPS = [f for f in YAML if set(yaml.safe_load(f.read_text()) or {}) == {"obstacles"}]  # obstacles: a map file
FILES = [f for f in YAML if f not in CHAOS and f not in MAPS]
SWEEPS = [f for f in FILES if "base" in (yaml.safe_load(f.read_text()) or {})]
EXPERIMENTS = [f for f in FILES if f not in SWEEPS]


def _id(path: Path) -> str:
    return str(path.relative_to(ROOT))


def test_there_are_examples():
    assert len(TREES) >= 6 and len(EXPERIMENTS) >= 3 and len(SWEEPS) >= 16 and CHAOS and len(MAPS) >= 2


@pytest.mark.parametrize("path", CHAOS, ids=_id)
def test_every_shipped_chaos_file_loads(path):
    assert load_chaos(path).events


@pytest.mark.parametrize("path", MAPS, ids=_id)
def test_every_shipped_map_file_is_an_obstacles_section(path):
    from swarmbed.schema.obstacles import ObstaclesSection

    section = ObstaclesSection.model_validate(yaml.safe_load(path.read_text())["obstacles"])
    assert len(section.compile()) > 0


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


def _leaves(tree: object, prefix: str = "") -> dict[str, object]:
    if isinstance(tree, dict):
        return {k: v for key, sub in tree.items() for k, v in _leaves(sub, f"{prefix}.{key}").items()}
    return {prefix: tree}


def _kind(path: Path) -> tuple:
    """What picks code in a file's first experiment: its texts, switches and unset keys (not its name)."""
    leaves = _leaves(_first_experiment(path).model_dump(mode="json"))
    return tuple(
        sorted((k, v) for k, v in leaves.items() if k != ".name" and (v is None or isinstance(v, (str, bool))))
    )


KINDS = list({_kind(f): f for f in reversed(FILES)}.values())  # the first file of each kind


def test_files_of_one_kind_differ_in_numbers_only():
    assert 5 <= len(KINDS) < len(FILES)
    for f in FILES:
        run = next(k for k in KINDS if _kind(k) == _kind(f))
        a, b = (
            _leaves(_first_experiment(f).model_dump(mode="json")),
            _leaves(_first_experiment(run).model_dump(mode="json")),
        )
        assert set(a) == set(b)
        assert all(isinstance(a[k], (int, float)) for k in a if k != ".name" and a[k] != b[k]), f


@pytest.mark.parametrize("path", FILES, ids=_id)
def test_every_shipped_file_builds_its_world(path):
    exp = _first_experiment(path)
    world = cfg.resolve_experiment(exp).scenario().make_world(np.random.default_rng(exp.run.seed))
    assert len(world.observations()) == exp.agents.count


@pytest.mark.parametrize("path", KINDS, ids=_id)
def test_every_kind_of_shipped_file_runs_a_few_ticks(path, tmp_path):
    exp = _first_experiment(path)
    exp = exp.model_copy(update={"run": exp.run.model_copy(update={"duration": 3 * exp.run.dt})})
    result = run_experiment(exp, tmp_path, progress=False)
    assert result.summary["ticks"] == 3
    net = result.summary["network"]
    assert net["copies"] == net["delivered"] + sum(net["dropped"].values())
