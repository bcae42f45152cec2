"""Bad experiment files are refused before any process starts, naming the dotted key and the file."""

import pytest

from swarmbed.experiments import config as cfg
from swarmbed.experiments.config import resolve_experiment
from tests.conftest import QUICKSTART


def load_text(tmp_path, text, *overrides):
    p = tmp_path / "exp.yaml"
    p.write_text(text)
    return cfg.load(p, list(overrides))


@pytest.mark.parametrize("text, needle", [
    ("agents:\n  cuont: 3\n", "agents.cuont: unknown key"),
    ("agents:\n  count: many\n", "agents.count:"),
    ("agents:\n  count: 0\n", "agents.count: Input should be greater than or equal to 1"),
    ("network:\n  loss: 1.5\n", "network.loss:"),
    ("run:\n  clock: warp\n", "run.clock:"),
    ("scenario:\n  workload: [60, 6]\n", "scenario: Value error, workload"),
    ("allocator:\n  name: fcg\n  mode: Fastest\n", "allocator.mode:"),
    ("allocator:\n  name: nosuch\n", "unknown allocator 'nosuch'"),
    ("agents:\n  behavior_tree: missing.xml\n", "agents.behavior_tree: file"),
    ("[1, 2]\n", "top level must be a mapping"),
    ("agents: {count: 3\n", "not valid YAML"),
])
def test_bad_files_are_refused_with_key_and_file(tmp_path, text, needle):
    with pytest.raises(cfg.ConfigError) as info:
        load_text(tmp_path, text)
    assert needle in str(info.value)
    assert str(tmp_path / "exp.yaml") in str(info.value)


def test_overrides_apply_to_any_dotted_key():
    exp = cfg.load(QUICKSTART, ["agents.count=7", "network.range=null", "allocator.mode=Random", "run.dt=0.5"])
    assert (exp.agents.count, exp.network.range, exp.allocator.params()["mode"], exp.run.dt) == (7, None, "Random", 0.5)
    assert exp.ticks == int(exp.run.duration / 0.5)


def test_bad_overrides_are_refused():
    with pytest.raises(cfg.ConfigError, match="^--set agents.speed=3: unknown key$"):
        cfg.load(QUICKSTART, ["agents.speed=3"])
    with pytest.raises(cfg.ConfigError, match=r"^--set scenario.generations=\{'interval': -1\}: "
                                              r"scenario.generations.interval: Input should be greater than 0$"):
        cfg.load(QUICKSTART, ["scenario.generations={interval: -1}"])
    with pytest.raises(cfg.ConfigError, match="^--set allocator.mode=Fastest: Input should be"):
        cfg.load(QUICKSTART, ["allocator.mode=Fastest"])
    with pytest.raises(cfg.ConfigError, match="expected dotted.key=value"):
        cfg.load(QUICKSTART, ["agents.count"])


def test_resolved_config_round_trips():
    exp = cfg.load(QUICKSTART)
    assert cfg.from_yaml(cfg.to_yaml(exp)) == exp


def test_every_key_is_described():
    rows = [row for model in cfg.SECTIONS.values() for row in cfg.describe(model)]
    rows += cfg.describe(resolve_experiment(cfg.load(QUICKSTART)).scenario_cls.Params)
    for key, typ, default, meaning in rows:
        assert typ and default and meaning and "Undefined" not in default, (key, typ, default, meaning)
    keys = {r[0] for r in rows}
    assert {"seed", "duration", "count", "loss", "rate", "width", "generations.interval"} <= keys


def test_naming_another_allocator_drops_the_old_ones_parameters():
    exp = cfg.load(QUICKSTART, ["allocator.name=cbba"])  # quickstart sets fcg's mode
    assert exp.allocator.name == "cbba" and "mode" not in exp.allocator.params()
    assert exp.allocator.params()["max_tasks"] == 5  # resolved: every parameter, defaults included
    exp = cfg.load(QUICKSTART, ["allocator.name=cbba", "allocator.max_tasks=3"])
    assert exp.allocator.params()["max_tasks"] == 3


def test_a_sweep_file_given_to_run_says_so():
    with pytest.raises(cfg.ConfigError, match="swarmbed sweep"):
        cfg.load(QUICKSTART.parent / "space_fig3.yaml")
