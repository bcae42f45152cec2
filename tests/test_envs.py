"""swarmbed.envs: PettingZoo's own checks on real runs (processes, Zenoh, the proxy), byte identity
with a run swarmbed itself drives, and bad actions refused while the run goes on."""

import json
from pathlib import Path

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

from swarmbed.envs import SwarmbedParallelEnv
from swarmbed.launch.runner import run_experiment
from tests.conftest import ROOT, experiment, same_results

RADIO = ("network.loss=0.2", "network.burst={mean_loss: 0.2, mean_burst: 4}")
SMALL = ("agents.count=3", "run.duration=40", *RADIO)


@pytest.mark.parametrize(
    "config, sets",
    [
        (ROOT / "experiments" / "quickstart.yaml", SMALL),
        (ROOT / "experiments" / "sar" / "_base.yaml", ("agents.count=3", "run.duration=40", *RADIO)),
    ],
    ids=["mtsr", "sar"],
)
@pytest.mark.parametrize("engine", ["processes", "inprocess"])
def test_pettingzoos_api_and_seed_tests_pass_on_real_runs(config, sets, engine):
    env = SwarmbedParallelEnv(config, sets, engine=engine)
    try:
        parallel_api_test(env, num_cycles=30)
    finally:
        env.close()
    parallel_seed_test(lambda: SwarmbedParallelEnv(config, sets, engine=engine), num_cycles=30)


def _drive(tmp_path, name, policy, seed=5, sets=SMALL):
    env = SwarmbedParallelEnv(sets=sets, out_dir=tmp_path / name)
    rng = np.random.default_rng(0)
    try:
        obs, _ = env.reset(seed=seed)
        total = 0.0
        while env.agents:
            obs, rewards, *_ = env.step({a: policy(obs[a], rng) for a in env.agents})
            total += sum(rewards.values())
        return env.results[-1], total
    finally:
        env.close()


def test_the_same_seed_and_actions_give_byte_identical_result_files(tmp_path):
    a, _ = _drive(tmp_path, "a", lambda o, rng: int(rng.integers(0, 9)))
    b, _ = _drive(tmp_path, "b", lambda o, rng: int(rng.integers(0, 9)))
    for name in ("summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv", "config.yaml"):
        assert (a.out_dir / name).read_bytes() == (b.out_dir / name).read_bytes(), name


def test_a_run_driven_through_the_env_is_the_run_swarmbed_drives(tmp_path):
    """Always the first row (the nearest task) is the built-in nearest allocator's policy: the
    learner's decisions travel the path a plugin's do, so the files are the same."""
    sets = ("agents.count=4", "run.duration=300")
    driven, total = _drive(tmp_path, "env", lambda o, rng: 1 if o["task_mask"][0] else 0, seed=3, sets=sets)
    builtin = run_experiment(
        experiment(*sets, "run.seed=3", "allocator.name=nearest"), tmp_path / "run", progress=False
    )
    for name in ("timeseries.csv", "agents.csv", "network_ledger.csv"):
        assert (driven.out_dir / name).read_bytes() == (builtin.out_dir / name).read_bytes(), name
    ours, theirs = (json.loads((r.out_dir / "summary.json").read_text()) for r in (driven, builtin))
    assert (ours.pop("allocator"), theirs.pop("allocator")) == ("external", "nearest")
    assert ours == theirs
    assert total == ours["tasks_completed"] * 4  # the team's progress, to each of the 4 agents


def test_bad_actions_are_refused_with_one_line_and_the_run_goes_on(tmp_path):
    env = SwarmbedParallelEnv(sets=SMALL, out_dir=tmp_path / "bad")
    try:
        env.reset(seed=1)
        good = dict.fromkeys(env.agents, 0)
        for bad, words in (
            ({**good, "agent_1": 99}, ["agent_1", "99"]),
            ({**good, "agent_2": float("nan")}, ["agent_2", "nan"]),
            ({**good, "agent_7": 0}, ["agent_7"]),
            ({**good, "agent_0": -1}, ["agent_0", "-1"]),
            ([0, 0, 0], ["mapping", "list"]),
            (None, ["mapping", "NoneType"]),
        ):
            with pytest.raises(ValueError) as err:
                env.step(bad)
            line = str(err.value)
            assert "\n" not in line and all(w in line for w in words), line
        obs, *_ = env.step(good)  # the tick was never sent: the run is where it was
        assert set(obs) == set(env.agents) == {"agent_0", "agent_1", "agent_2"}
    finally:
        env.close()


def test_an_agent_lost_to_a_failure_is_terminated_and_leaves(tmp_path):
    sets = ("agents.count=4", "run.duration=30", "scenario.agent_loss=0.02", "scenario.agent_loss_grace=0")
    env = SwarmbedParallelEnv(ROOT / "experiments" / "sar" / "_base.yaml", sets, out_dir=tmp_path / "loss")
    try:
        env.reset(seed=2)
        terminated_at, steps = {}, 0
        while env.agents:
            acting = list(env.agents)
            obs, rewards, terminations, truncations, infos = env.step(dict.fromkeys(acting, 0))
            steps += 1
            assert set(terminations) == set(acting)  # every agent that acted hears its outcome
            ended = {a for a, t in terminations.items() if t}
            assert ended.isdisjoint(env.agents) and set(env.agents) == set(acting) - ended  # the others go on
            terminated_at.update(dict.fromkeys(ended, steps))
        summary = env.results[-1].summary
    finally:
        env.close()
    # step k returns tick k: each robot's episode ended at the tick the world lost it, and only those
    lost = {f"agent_{i}": tick for i, tick in summary["agents_lost"].items()}
    assert terminated_at == lost and len(lost) == 4


def test_a_built_in_allocator_plays_as_a_policy_through_the_env(tmp_path):
    """fallback="fcg" runs FCG in every agent beside the learner; deferring at every tick gives
    FCG's own run, messages and all: a learned policy and FCG compared on the same seeds."""
    sets = ("agents.count=4", "run.duration=200", "network.loss=0.1")
    env = SwarmbedParallelEnv(sets=sets, out_dir=tmp_path / "env", fallback="fcg")
    assert env.defer == 9 and env.action_space("agent_0").n == 10
    try:
        env.reset(seed=6)
        while env.agents:
            env.step(dict.fromkeys(env.agents, env.defer))
        driven = env.results[-1]
    finally:
        env.close()
    builtin = run_experiment(experiment(*sets, "run.seed=6"), tmp_path / "run", progress=False)
    for name in ("timeseries.csv", "agents.csv", "network_ledger.csv"):
        assert (driven.out_dir / name).read_bytes() == (builtin.out_dir / name).read_bytes(), name
    ours, theirs = (json.loads((r.out_dir / "summary.json").read_text()) for r in (driven, builtin))
    assert (ours.pop("allocator"), theirs.pop("allocator")) == ("external", "fcg")
    assert ours == theirs and ours["network"]["messages_sent"] > 0


TINY = ("agents.count=2", "run.duration=4")


def _to_the_end(env: SwarmbedParallelEnv) -> None:
    while env.agents:
        env.step(dict.fromkeys(env.agents, 0))


def test_runs_are_numbered_after_what_the_folder_holds_and_unseeded_episodes_differ(tmp_path):
    first = SwarmbedParallelEnv(sets=TINY, out_dir=tmp_path / "shared")
    try:
        first.reset(seed=1)
        _to_the_end(first)
        first.reset()  # no seed: drawn from the last one given, so another world
        _to_the_end(first)
    finally:
        first.close()
    kept = (tmp_path / "shared" / "run_0" / "summary.json").read_bytes()
    second = SwarmbedParallelEnv(sets=TINY, out_dir=tmp_path / "shared")
    try:
        second.reset(seed=2)
        _to_the_end(second)
    finally:
        second.close()
    assert sorted(p.name for p in (tmp_path / "shared").iterdir()) == ["run_0", "run_1", "run_2"]
    assert (tmp_path / "shared" / "run_0" / "summary.json").read_bytes() == kept
    seeds = [json.loads((tmp_path / "shared" / f"run_{k}" / "summary.json").read_text())["seed"] for k in range(3)]
    assert seeds[0] == 1 and seeds[2] == 2 and seeds[1] not in (1, 2), seeds


def test_arguments_no_world_has_are_refused_in_one_line(tmp_path):
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="max_tasks"):
            SwarmbedParallelEnv(sets=TINY, max_tasks=bad, out_dir=tmp_path / "never")
    env = SwarmbedParallelEnv(sets=TINY, reward_key="nope", out_dir=tmp_path / "nope")
    assert env.render_mode is None  # SuperSuit's vector wrappers read it
    try:
        with pytest.raises(ValueError, match="reward_key 'nope'.*tasks_completed"):
            env.reset(seed=1)
    finally:
        env.close()


def test_an_environment_never_closed_leaves_no_temporary_folder(tmp_path):
    import subprocess
    import sys

    make = "from swarmbed.envs import SwarmbedParallelEnv; env = SwarmbedParallelEnv(sets={sets!r}); print(env.out_dir)"
    killed = subprocess.run(
        [sys.executable, "-c", make.format(sets=TINY) + "; import os, signal; os.kill(os.getpid(), signal.SIGKILL)"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    left = Path(killed.stdout.strip())
    assert killed.returncode == -9 and left.is_dir()
    returned = subprocess.run(
        [sys.executable, "-c", make.format(sets=TINY)], capture_output=True, text=True, timeout=120
    )
    assert returned.returncode == 0, returned.stderr
    assert not Path(returned.stdout.strip()).exists()  # removed at exit
    assert not left.exists()  # a killed process's folder: removed by the next environment


@pytest.mark.parametrize(
    "config", [ROOT / "experiments" / "quickstart.yaml", ROOT / "experiments" / "sar" / "_base.yaml"]
)
def test_both_engines_give_the_same_observations_and_result_files(tmp_path, config):
    """The learner that owns the loop (in-process) and the one that steps a run of processes see the
    same world tick by tick, and leave the same result files."""
    seen = {}
    for engine in ("processes", "inprocess"):
        env = SwarmbedParallelEnv(config, SMALL, out_dir=tmp_path / engine, engine=engine)
        rng = np.random.default_rng(3)
        trace = []
        try:
            obs, _ = env.reset(seed=11)
            while env.agents:
                trace.append({a: {k: v.tolist() for k, v in o.items()} for a, o in sorted(obs.items())})
                actions = {a: int(rng.integers(env.action_space(a).n)) for a in env.agents}
                obs, rewards, term, trunc, _ = env.step(actions)
                trace.append((sorted(rewards.items()), sorted(term.items()), sorted(trunc.items())))
        finally:
            env.close()
        seen[engine] = trace
    assert len(seen["processes"]) > 20 and seen["processes"] == seen["inprocess"]
    for step in seen["inprocess"][::2]:  # every action the mask allows picks a row that holds a task
        for view in step.values():
            assert view["action_mask"] == [1, *view["task_mask"]]
    same_results(tmp_path / "processes" / "run_0", tmp_path / "inprocess" / "run_0")


def test_a_claim_broadcast_through_the_env_reaches_the_others_over_the_radio(tmp_path):
    """With ``broadcast=True`` the learner's K extra actions choose a row and broadcast a claim of its
    task: the claims are real radio messages (booked as ``claim`` in the ledger, ranged and lost like
    any other), and the agents that hear one see it against their own row of that task. Both engines
    give the same observations and files; PettingZoo's checks pass."""
    sets = ("agents.count=3", "run.duration=40", "network.range=null", "agents.awareness_range=400")
    env = SwarmbedParallelEnv(sets=sets, engine="inprocess", broadcast=True)
    try:
        parallel_api_test(env, num_cycles=20)
    finally:
        env.close()
    seen = {}
    for engine in ("processes", "inprocess"):
        env = SwarmbedParallelEnv(sets=sets, out_dir=tmp_path / engine, engine=engine, broadcast=True)
        k = env.max_tasks
        heard, trace = 0, []
        try:
            obs, _ = env.reset(seed=4)
            assert env.action_space("agent_0").n == 2 * k + 1 and len(obs["agent_0"]["action_mask"]) == 2 * k + 1
            while env.agents:
                # everyone claims its nearest task, out loud
                last = dict(obs)
                obs, *_ = env.step({a: k + 1 if o["task_mask"][0] else 0 for a, o in obs.items()})
                trace.append({a: o["claimed"].tolist() for a, o in sorted(obs.items())})
                # a claim heard is counted against the hearer's own row of that task
                for a, o in obs.items():
                    heard += int(o["claimed"].sum())
                    assert o["claimed"].sum() <= sum(1 for b in last if b != a)
        finally:
            env.close()
        seen[engine] = trace
        ledger = (tmp_path / engine / "run_0" / "network_ledger.csv").read_text()
        assert ",claim," in ledger
        assert heard > 0, "no claim was heard: every robot sees every task, and all of them claim the nearest"
    assert seen["processes"] == seen["inprocess"]
    same_results(tmp_path / "processes" / "run_0", tmp_path / "inprocess" / "run_0")


def test_several_inprocess_environments_step_side_by_side_in_one_process(tmp_path):
    """What a vector wrapper (SuperSuit's, TorchRL's) does: several in-process environments in one
    process, stepped in turn, each leaving the files it leaves alone."""
    envs = [SwarmbedParallelEnv(sets=SMALL, out_dir=tmp_path / f"side_{i}", engine="inprocess") for i in range(3)]
    try:
        obs = [env.reset(seed=20 + i)[0] for i, env in enumerate(envs)]
        while any(env.agents for env in envs):
            for i, env in enumerate(envs):
                if env.agents:
                    obs[i] = env.step(dict.fromkeys(env.agents, 1))[0]
    finally:
        for env in envs:
            env.close()
    for i in range(3):
        alone = SwarmbedParallelEnv(sets=SMALL, out_dir=tmp_path / f"alone_{i}", engine="inprocess")
        try:
            alone.reset(seed=20 + i)
            while alone.agents:
                alone.step(dict.fromkeys(alone.agents, 1))
        finally:
            alone.close()
        same_results(tmp_path / f"side_{i}" / "run_0", tmp_path / f"alone_{i}" / "run_0")
