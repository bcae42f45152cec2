"""Bad experiment files are refused before any process starts, naming the dotted key and the file."""

import pytest

from swarmbed import config as cfg
from swarmbed.config import resolve_experiment
from tests.conftest import QUICKSTART, ROOT


def load_text(tmp_path, text, *overrides):
    p = tmp_path / "exp.yaml"
    p.write_text(text)
    return cfg.load(p, list(overrides))


@pytest.mark.parametrize(
    "text, needle",
    [
        ("agents:\n  cuont: 3\n", "agents.cuont: unknown key"),
        ("agents:\n  count: many\n", "agents.count:"),
        ("agents:\n  count: 0\n", "agents.count: Input should be greater than or equal to 1"),
        ("network:\n  loss: 1.5\n", "network.loss:"),
        ("run:\n  clock: warp\n", "run.clock:"),
        ("scenario:\n  workload: [60, 6]\n", "scenario: workload must be"),
        ("allocator:\n  name: fcg\n  mode: Fastest\n", "allocator.mode:"),
        ("allocator:\n  name: nosuch\n", "unknown allocator 'nosuch'"),
        ("agents:\n  behavior_tree: missing.xml\n", "agents.behavior_tree: file"),
        ("[1, 2]\n", "top level must be a mapping"),
        ("agents: {count: 3\n", "not valid YAML"),
    ],
)
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
    with pytest.raises(
        cfg.ConfigError, match=r"^--set agents.speed=3: unknown key \(did you mean 'agents.max_speed'\?\)$"
    ):
        cfg.load(QUICKSTART, ["agents.speed=3"])
    with pytest.raises(
        cfg.ConfigError,
        match=r'^--set scenario.generations=\{"interval": -1\}: '
        r"scenario.generations.interval: Input should be greater than 0$",
    ):
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


def test_an_empty_file_is_refused(tmp_path):
    (tmp_path / "empty.yaml").write_text("# nothing yet\n")
    with pytest.raises(cfg.ConfigError, match="empty.yaml: the file is empty"):
        cfg.load(tmp_path / "empty.yaml")


def test_a_bad_tree_given_with_set_is_refused_before_any_process_starts(tmp_path, monkeypatch):
    with pytest.raises(cfg.ConfigError, match=r"^--set agents.behavior_tree=.*missing.xml: file .* does not exist"):
        cfg.load(QUICKSTART, ["agents.behavior_tree=missing.xml"])
    (tmp_path / "bad.xml").write_text('<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Nope/>\n</BehaviorTree></root>')
    monkeypatch.chdir(tmp_path)  # a relative path on the command line is read from the current directory
    refused = r"^--set agents.behavior_tree=.*bad.xml: .*bad.xml:3 <Nope>: unknown node"
    with pytest.raises(cfg.ConfigError, match=refused):
        cfg.load(QUICKSTART, ["agents.behavior_tree=bad.xml"])
    (tmp_path / "good.xml").write_text((ROOT / "swarmbed" / "extension" / "trees" / "space_default.xml").read_text())
    exp = cfg.load(QUICKSTART, ["agents.behavior_tree=good.xml"])
    assert exp.agents.behavior_tree == str(tmp_path / "good.xml")


def test_a_tree_named_in_the_file_is_read_from_the_files_folder(tmp_path, monkeypatch):
    (tmp_path / "trees").mkdir()
    (tmp_path / "trees" / "mine.xml").write_text(
        (ROOT / "swarmbed" / "extension" / "trees" / "space_default.xml").read_text()
    )
    text = QUICKSTART.read_text().replace(
        "  exploration_duration: 60", "  exploration_duration: 60\n  behavior_tree: trees/mine.xml"
    )
    (tmp_path / "exp.yaml").write_text(text)
    monkeypatch.chdir(ROOT)  # not where the file is
    assert cfg.load(tmp_path / "exp.yaml").agents.behavior_tree == str(tmp_path / "trees" / "mine.xml")


def test_run_help_shows_no_python_internals(capsys):
    from swarmbed.cli.main import main

    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = capsys.readouterr().out
    assert "PydanticUndefined" not in out and "swarmbed params" in out
    assert main(["params"]) == 0
    out = capsys.readouterr().out
    assert "PydanticUndefined" not in out and "run.seed" in out and "network.loss" in out
    assert main(["params", "cbba-etc"]) == 0
    out = capsys.readouterr().out
    assert "allocator.theta_bid_change" in out and "float" in out
    assert main(["params", "nosuch"]) == 2
    # one key, and the sections beside run, agents and network
    assert main(["params", "network.loss"]) == 0
    out = capsys.readouterr().out
    assert "network.loss" in out and "network.range" not in out and "probability" in out
    assert main(["params"]) == 0
    out = capsys.readouterr().out
    assert all(key in out for key in ("ros2.command_timeout", "placement", "swaps[].to", "may_carry")), out
    assert main(["params", "network.los"]) == 2
    assert "did you mean 'network.loss'?" in capsys.readouterr().err


@pytest.mark.parametrize(
    "text, needle",
    [
        ("run:\n  dt: .inf\n", "run.dt: infinite and NaN numbers are not accepted"),
        ("network:\n  range: .nan\n", "network.range: infinite and NaN numbers are not accepted"),
        ("allocator:\n  name: cbba\n  epsilon: -.inf\n", "allocator.epsilon: infinite and NaN"),
        ("run:\n  seed: true\n", "run.seed: Input should be a valid integer"),
        ("network:\n  loss: '0.1'\n", "network.loss: Input should be a valid number"),
        ("run:\n  duration: 1.0e+12\n  dt: 0.001\n", "more than the 100,000,000 a run may have"),
        ("agents:\n  count: 5\nplacement:\n  h1: 0-1000000000\n", "placement.h1: agent 1000000000 is outside 0..4"),
        ("agents:\n  count: 5\nmay_carry:\n  h1: '3-99'\n", "may_carry.h1: agent 99 is outside 0..4"),
        ("name: ../../etc\n", "name: String should match pattern"),
        ("name: /tmp/elsewhere\n", "name: String should match pattern"),
        ("base: &b {count: 3}\nagents: *b\n", "anchors and aliases"),
        ("a: " + "[" * 40 + "]" * 40 + "\n", "nested more than 32 levels deep"),
    ],
)
def test_input_that_must_never_reach_a_process_is_refused_in_one_line(tmp_path, text, needle):
    with pytest.raises(cfg.ConfigError) as info:
        load_text(tmp_path, text)
    assert needle in str(info.value), str(info.value)
    assert str(tmp_path / "exp.yaml") in str(info.value)


def test_binary_huge_and_non_utf8_files_are_refused_before_they_are_parsed(tmp_path):
    cases = {
        "binary.yaml": b"\x7fELF\x02\x01\x01\0\0\0",
        "latin1.yaml": "name: caf\xe9\n".encode("latin-1"),
        "huge.yaml": b"# padding\n" * 200_000,
    }
    needles = {"binary.yaml": "a binary file", "latin1.yaml": "not UTF-8 text", "huge.yaml": "larger than the"}
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(cfg.ConfigError) as info:
            cfg.load(tmp_path / name)
        assert needles[name] in str(info.value) and len(str(info.value).splitlines()) == 1, str(info.value)


def test_a_billion_laughs_sweep_file_is_refused_at_once(tmp_path):
    """A few hundred bytes of nested aliases expand tenfold per level: refused, not expanded."""
    import time

    from swarmbed.campaigns.sweep import load_sweep

    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, 9)]
    (tmp_path / "laughs.yaml").write_text("\n".join(lines) + "\nbase: quickstart.yaml\nset: {x: *a8}\n")
    t0 = time.perf_counter()
    with pytest.raises(cfg.ConfigError, match="anchors and aliases"):
        load_sweep(tmp_path / "laughs.yaml")
    assert time.perf_counter() - t0 < 1.0
    (tmp_path / "escape.yaml").write_text("name: ../../outside\nbase: quickstart.yaml\n")
    with pytest.raises(cfg.ConfigError, match="name: String should match pattern"):
        load_sweep(tmp_path / "escape.yaml")


def test_a_section_set_as_a_mapping_keeps_its_other_keys(tmp_path):
    exp = load_text(tmp_path, "agents:\n  count: 5\n  max_speed: 3.0\n", "agents={count: 3}")
    assert (exp.agents.count, exp.agents.max_speed) == (3, 3.0)
    swapped = load_text(tmp_path, "allocator:\n  name: fcg\n  mode: Random\n", "allocator={name: cbba}")
    assert swapped.allocator.name == "cbba" and "mode" not in swapped.allocator.params()


def test_errors_name_what_the_user_wrote_not_our_classes(tmp_path, capsys):
    from swarmbed.cli.main import main

    with pytest.raises(cfg.ConfigError, match=r"^--set run=5: must be a section \(a mapping of keys\), not 5$"):
        cfg.load(QUICKSTART, ["run=5"])
    with pytest.raises(cfg.ConfigError) as info:
        load_text(tmp_path, "scenario:\n  workload: [60, 6]\n")
    assert "scenario.kind" not in str(info.value) and "workload must be" in str(info.value)
    (tmp_path / "broken.py").write_text("from swarmbed.extension import Allocator\nclass A(Allocator)\n")
    assert main(["run", str(QUICKSTART), "--set", f"allocator.name={tmp_path / 'broken.py'}:A"]) == 2
    err = capsys.readouterr().err.strip()
    assert "SyntaxError" in err and "broken.py, line 2" in err and len(err.splitlines()) == 1, err
    (tmp_path / "other.py").write_text("class A:\n    pass\n")
    with pytest.raises(cfg.ConfigError, match="is not a subclass of Allocator"):
        cfg.load(QUICKSTART, [f"allocator.name={tmp_path / 'other.py'}:A"])


def test_a_sweep_names_the_scenario_whose_value_is_bad(tmp_path):
    from swarmbed.campaigns.sweep import experiment_for, load_sweep

    sweep = load_sweep(QUICKSTART, grid=["network.loss=0.1,7"])
    bad = sweep.scenarios[1]
    with pytest.raises(cfg.ConfigError, match=r"sweep scenario loss-7: network.loss=7: Input should be less"):
        experiment_for(QUICKSTART, bad, 0, [])


def test_params_describe_every_strategy_parameter_in_whole_sentences(capsys):
    from swarmbed.cli.main import main

    assert main(["params", "cbba-etc"]) == 0
    out = capsys.readouterr().out
    head, *rows = out.splitlines()
    assert "``" not in out and head.endswith("(cbba-etc: consensus only on events (Algorithm 4).)"), head
    for name in ("rho_base", "theta_high", "theta_low", "kappa", "gamma", "phi_min", "phi_max"):
        row = next(r for r in rows if f"allocator.{name} " in r)
        assert len(row.split(None, 3)) == 4, row  # key, type, default and a meaning


def test_check_allocator_finds_the_scenario_an_allocator_is_for(capsys):
    from swarmbed.cli.main import main

    assert main(["check-allocator", "comm"]) == 0
    assert "PASS check_snapshot" in capsys.readouterr().out


@pytest.mark.parametrize(
    "allocator, needle",
    [
        ("{name: external, fallback: cbba, fallback_params: {max_tasks: 0}}", "allocator.fallback_params.max_tasks: "),
        (
            "{name: external, fallback: cbba, fallback_params: {bogus: 1}}",
            "allocator.fallback_params.bogus: unknown key",
        ),
        ("{name: external, fallback: cbbx}", "allocator.fallback: unknown allocator 'cbbx'"),
        ("{name: external, fallback: ros2}", "allocator.fallback: 'ros2' takes its decisions from outside too"),
        ("{name: external, fallback_params: {max_tasks: 2}}", "allocator.fallback_params: given without a fallback"),
    ],
)
def test_an_external_allocators_fallback_is_checked_where_the_experiment_is_loaded(allocator, needle):
    """Issue 57: the fallback is resolved and its keys validated by config.load (so by ``--check``
    and the environment), before any agent process would first build it."""
    with pytest.raises(cfg.ConfigError) as info:
        cfg.load(QUICKSTART, [f"allocator={allocator}"])
    assert needle in str(info.value) and len(str(info.value).splitlines()) == 1, str(info.value)
    assert cfg.load(QUICKSTART, ["allocator={name: external, fallback: cbba, fallback_params: {max_tasks: 2}}"])


def test_what_no_run_can_do_is_refused_by_check_too(capsys):
    """One list of refusals (engine.refusals) for the launcher, config.validate and --check: an
    allocator whose decisions come from a learner cannot be run by ``swarmbed run`` on either engine,
    and one that takes them from ROS 2 needs a ros2: section."""
    from swarmbed.cli.main import main

    for engine in ("processes", "inprocess"):
        assert main(["run", str(QUICKSTART), "--check", "--engine", engine, "--set", "allocator.name=external"]) == 2
        err = capsys.readouterr().err.strip()
        assert "swarmbed run cannot drive it" in err and len(err.splitlines()) == 1, err
    with pytest.raises(cfg.ConfigError, match="needs a ros2: section"):
        cfg.load(QUICKSTART, ["allocator.name=ros2"])


def test_a_centralized_allocators_leader_is_one_of_the_runs_agents():
    """Allocator.check, as Scenario.check: a fixed leader outside the run's agents is refused where
    the experiment is loaded (its followers would wait for it forever)."""
    with pytest.raises(cfg.ConfigError, match=r"allocator.leader: agent 9 is not one of this run's agents 0..4"):
        cfg.load(QUICKSTART, ["agents.count=5", "allocator={name: sga, leader: 9}"])
    assert (
        cfg.load(QUICKSTART, ["agents.count=5", "allocator={name: sga, leader: 4}"]).allocator.params()["leader"] == 4
    )


def test_names_are_resolved_once_where_the_experiment_is_checked_and_again_only_for_an_edited_file(
    tmp_path, monkeypatch
):
    """config.load resolves the scenario and allocator names and the experiment carries what they
    resolved to: the plan, the CLI's summary and refusals ask resolve_experiment, which resolves
    nothing again, unless a plugin file named by path was edited since (its digest) or the names
    changed (a copy with another allocator)."""
    from swarmbed.plugins import registry

    calls: list[str] = []
    real = registry.resolve

    def counting(name, *args, **kwargs):
        calls.append(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(cfg, "resolve", counting)
    exp = cfg.load(QUICKSTART)
    loaded = len(calls)
    for _ in range(3):
        assert resolve_experiment(exp).allocator_cls.__name__ == "FirstClaimedGreedy"
    assert len(calls) == loaded, "resolve_experiment resolved the names again"
    other = exp.model_copy(update={"allocator": cfg.AllocatorSection(name="nearest")})
    assert resolve_experiment(other).allocator_cls is not resolve_experiment(exp).allocator_cls
    assert len(calls) == loaded + 1
    # a plugin given by path: edited after the check, it is resolved (and checked) anew
    plugin = tmp_path / "mine.py"
    plugin.write_text("from swarmbed.plugins.nearest import NearestTask\n\n\nclass Mine(NearestTask):\n    pass\n")
    mine = cfg.load(QUICKSTART, [f"allocator.name={plugin}:Mine"])
    first = resolve_experiment(mine).targets.digests
    plugin.write_text(plugin.read_text() + "# edited\n")
    assert resolve_experiment(mine).targets.digests != first


def test_a_preset_fills_its_keys_below_the_experiments_own_and_the_config_holds_the_values(tmp_path):
    """``preset: NAME`` in a scenario or allocator section fills the keys the plugin's preset sets; a key
    the experiment sets wins; the resolved experiment (what config.yaml records) is the one with every
    key written out, and names no preset."""
    code = ROOT / "experiments" / "space_mtsr_code.yaml"
    exp = cfg.load(code, ["allocator={name: fcg, preset: space_code, heard_claims: tick}"])
    assert exp.allocator.params()["on_earlier_claim"] == "keep"
    assert exp.allocator.params()["same_tick_claims"] == "id_order"  # from the preset
    assert exp.allocator.params()["heard_claims"] == "tick"  # the experiment's own key wins
    scenario = exp.scenario.params()
    assert (scenario["work_radius_per_workload"], scenario["approach_radius"]) == (1 / 3, 50.0)
    assert scenario.get("work_motion", "brake") == "brake"  # the file's own key over the preset's close_in
    assert "preset" not in scenario and "preset" not in exp.allocator.params()
    spelled = cfg.load(
        code,
        [
            "scenario.preset=null",
            "scenario.work_radius_per_workload=0.3333333333333333",
            "scenario.approach_radius=50",
            "allocator={name: fcg, on_earlier_claim: keep, same_tick_claims: id_order, heard_claims: tick}",
        ],
    )
    assert cfg.to_yaml(spelled) == cfg.to_yaml(exp)


def test_an_unknown_preset_is_one_line_naming_the_plugins_presets():
    with pytest.raises(cfg.ConfigError) as err:
        cfg.load(QUICKSTART, ["allocator.preset=space_txt"])
    assert str(err.value).count("\n") == 0
    assert "allocator.preset" in str(err.value) and "space_code, space_text" in str(err.value)
    with pytest.raises(cfg.ConfigError, match=r"allocator.preset: 'x' is not one of this plugin's presets \(none\)"):
        cfg.load(QUICKSTART, ["allocator={name: nearest, preset: x}"])


def test_every_shipped_preset_sets_keys_its_plugin_has_to_values_it_takes():
    """A preset with a misspelt key or a value out of range would fail only where someone names it."""
    from swarmbed.extension.presets import presets_of
    from swarmbed.plugins import registry

    models = [registry.resolve_scenario(kind).Params for kind in registry.scenario_names()]
    models += [registry.resolve(name).Params for name, _ in registry.entries()]
    checked = 0
    for model in {id(m): m for m in models}.values():
        for name, preset in presets_of(model).items():
            assert set(preset.values) <= set(model.model_fields), (model.__name__, name)
            model.model_validate(preset.values)
            checked += 1
    assert checked >= 8  # fcg 2, cbba 2, grape 2, mtsr 1, sar 1
