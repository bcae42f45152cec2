"""The lock-step engine: the in-process transport writes the result files a real run writes.

Each case runs one shipped experiment (shortened) twice: once as a run of real processes over
Zenoh through the netem proxy, once on the in-process engine. The files that repeat byte for byte
between runs must be the same bytes: the same world, the same agents' decisions, the same radio
draws, the same ledger.
"""

import functools

import pytest

from swarmbed.launch.inprocess import run_in_process
from swarmbed.launch.runner import run_experiment
from swarmbed.records.run_folder import RECEIVER_LEDGER
from tests.conftest import ROOT, SAR_BASE, experiment, same_results

SAR = SAR_BASE
CASES = {
    "quickstart": (ROOT / "experiments" / "quickstart.yaml", []),
    # robots lost mid-run (the scenario retires them), failed actions, loss and a rate cap
    "sar c-cbba, losses and failures": (
        SAR,
        [
            "allocator.name=c-cbba",
            "run.duration=120",
            "scenario.agent_loss=0.01",
            "scenario.agent_loss_grace=20",
            "scenario.move_fail=0.25",
            "network.loss=0.1",
            "network.rate=2000",
            "network.limit=10",
        ],
    ),
    "sar cbba-etc, bursty loss": (
        SAR,
        ["allocator.name=cbba-etc", "run.duration=60", "network.burst={mean_loss: 0.3, mean_burst: 5.0}"],
    ),
    "mtsr grape, log-distance radio, per-receiver ledger": (
        ROOT / "experiments" / "space_mtsr.yaml",
        [
            "allocator.name=grape",
            "agents.count=12",
            "run.duration=300",
            "network.range=null",
            "network.propagation={shadowing_db: 6.0, tx_power_dbm: 19.6}",
            "network.ledger=per_receiver",
        ],
    ),
}


@pytest.mark.slow  # starts a real run per case
@pytest.mark.parametrize("case", list(CASES))
def test_the_in_process_engine_writes_a_real_runs_result_files_byte_for_byte(case, tmp_path):
    base, overrides = CASES[case]
    exp = experiment(*overrides, base=base)
    real = run_experiment(exp, tmp_path / "real", progress=False)
    alone = run_in_process(exp, tmp_path / "in_process")
    assert real.summary["ticks"] > 10 and real.summary["network"]["delivered"] > 0
    if exp.scenario.kind == "sar" and exp.scenario.params()["agent_loss"]:
        assert real.summary["agents_lost"], "no robot was lost: the case does not exercise retiring"
    same_results(real.out_dir, alone.out_dir)
    if exp.network.ledger == "per_receiver":
        assert (real.out_dir / RECEIVER_LEDGER).read_bytes() == (alone.out_dir / RECEIVER_LEDGER).read_bytes()


def test_the_in_process_engine_refuses_the_real_time_clock(tmp_path):
    with pytest.raises(ValueError, match="lock-step runs only"):
        run_in_process(experiment("run.clock=realtime"), tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_the_in_process_engine_refuses_an_allocator_that_takes_decisions_from_outside(tmp_path):
    with pytest.raises(ValueError, match="swarmbed run cannot drive it"):
        run_in_process(experiment("allocator={name: external}"), tmp_path / "run")
    assert not (tmp_path / "run").exists()  # refused before the folder was made


def _swarmbed(*args, cwd=ROOT):
    import subprocess
    import sys

    return subprocess.run(
        [sys.executable, "-m", "swarmbed", *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=300
    )


@pytest.mark.slow  # starts a real run
def test_users_reach_the_in_process_engine_and_get_a_runs_files(tmp_path):
    quick = ROOT / "experiments" / "quickstart.yaml"
    done = _swarmbed("run", quick, "--engine", "inprocess", "--out", tmp_path / "ip", "--no-progress")
    assert done.returncode == 0, done.stderr
    assert _swarmbed("run", quick, "--out", tmp_path / "pr", "--no-progress").returncode == 0
    same_results(tmp_path / "pr", tmp_path / "ip")
    assert '"engine": "inprocess"' in (tmp_path / "ip" / "timings.json").read_text()
    check = _swarmbed("run", quick, "--engine", "inprocess", "--check")
    assert check.returncode == 0 and "engine: in-process" in check.stdout and "on one core" in check.stdout


@pytest.mark.slow  # the command line in a subprocess
def test_what_needs_processes_is_refused_in_one_line_before_anything_starts(tmp_path):
    quick = ROOT / "experiments" / "quickstart.yaml"
    for sets, words in (
        (["--set", "run.clock=realtime"], "lock-step"),
        (["--set", "placement={lab1: '0-1'}"], "other hosts"),
        (["--set", "allocator.name=ros2", "--set", "ros2={domain: 3}"], "decisions from outside"),
        (["--set", "ros2={domain: 3}"], "ROS 2 topics"),
        (["--set", "run.record_bt=true"], "behavior-tree logs"),
        (["--listen", "tcp/127.0.0.1:7447"], "--listen"),
    ):
        for check in ([], ["--check"]):
            done = _swarmbed("run", quick, "--engine", "inprocess", "--out", tmp_path / "never", *sets, *check)
            err = done.stderr.strip()
            assert done.returncode == 2 and len(err.splitlines()) == 1 and words in err, (sets, err)
            assert not (tmp_path / "never").exists()


@pytest.mark.slow  # a sweep, then runs of processes
def test_a_sweep_in_process_is_verified_against_processes_and_a_difference_is_named(tmp_path):
    sweep = tmp_path / "s.yaml"
    sweep.write_text(f"name: s\nbase: {ROOT / 'experiments' / 'quickstart.yaml'}\nruns: 2\n")
    args = ("sweep", sweep, "--engine", "inprocess", "--out", tmp_path / "out", "--no-progress")
    done = _swarmbed(*args, "--set", "run.duration=60", "--verify", "1")
    assert done.returncode == 0, done.stderr
    assert "1 runs again in processes; all the same" in done.stdout, done.stdout
    ours = tmp_path / "out" / "base" / "run_000" / "timeseries.csv"
    seeds = sorted(tmp_path.glob("out/base/run_*"))
    assert len(seeds) == 2
    # a file that the engine got wrong is named, and the command fails
    for run in seeds:
        series = run / "timeseries.csv"
        series.write_text(series.read_text().replace("\n1,", "\n1,9", 1))
    again = _swarmbed(*args, "--set", "run.duration=60", "--verify", "1")
    assert again.returncode == 1 and "DIFFERS" in again.stdout and "timeseries.csv" in again.stdout, again.stdout
    assert ours.exists()


class _Calls:
    """What a fake transport, membership and hooks were asked, in order."""

    def __init__(self):
        self.log: list[tuple] = []


def _tick_loop_with_fakes(tmp_path, calls: _Calls, lose_at: int | None = None, stop_after: int | None = None):
    from swarmbed.config import resolve_experiment
    from swarmbed.engine import OneProcess, Session, TickHook
    from swarmbed.wire.codec import NetemStep

    exp = experiment("run.duration=3", "run.dt=1", "agents.count=2")  # three ticks
    resolved = resolve_experiment(exp)

    class Transport:
        def exchange(self, k, sample, observed, inboxes, decisions):
            calls.log.append(("exchange", k, sorted(observed), dict(decisions)))
            lost = [1] if k == lose_at else []
            return NetemStep(k, {}, {0: b"inbox"}, [0, 0, 0, 0, 0], lost, {}, {}, [])

    class Members(OneProcess):
        def incarnations(self):
            calls.log.append(("incarnations",))
            return {}

        def gone(self, agent, k):
            calls.log.append(("gone", agent, k))

    class Every(TickHook):  # every point
        def run_starts(self):
            calls.log.append(("run_starts",))

        def tick_starts(self, k):
            calls.log.append(("tick_starts", k))

        def before_world(self, k):
            calls.log.append(("before_world", k))

        def world_ready(self, sample):
            calls.log.append(("world_ready", sample.tick))

        def exchange_starts(self, k, sample, observed, inboxes):
            calls.log.append(("exchange_starts", k, dict(inboxes)))

        def row_columns(self):
            calls.log.append(("row_columns",))
            return ()

        def tick_done(self, k, admitted):
            calls.log.append(("tick_done", k))

        def should_stop(self):
            calls.log.append(("should_stop",))
            return stop_after is not None and any(c == ("tick_done", stop_after) for c in calls.log)

        def run_ends(self):
            calls.log.append(("run_ends",))

    class Second(TickHook):  # one point only: called after the first hook's, never at another point
        def tick_done(self, k, admitted):
            calls.log.append(("second tick_done", k))

    session = Session(exp, resolved.scenario(), resolved.allocator_cls, tmp_path)
    session.connect(Transport(), Members(session.world), [Every(), Second()])
    return session


def test_the_tick_loop_calls_its_transport_membership_and_hooks_in_order(tmp_path):
    """TickLoop's order of calls, with a fake transport (fast lane): per tick the hooks' points in
    the documented order, the transport once, the second hook after the first at the one point
    it overrides, ``run_ends`` once after the last tick; the inboxes a step returns are the next
    tick's; a process the step reports gone goes to the membership."""
    calls = _Calls()
    session = _tick_loop_with_fakes(tmp_path, calls, lose_at=1)
    assert session.run() == 2
    expected = [("run_starts",)]
    for k in range(3):
        inboxes = {0: b"inbox"} if k else {}
        expected += [("should_stop",), ("tick_starts", k)]
        expected += [("before_world", k)] if k else []
        expected += [("incarnations",), ("world_ready", k), ("exchange_starts", k, inboxes)]
        expected += [("exchange", k, [0, 1], {})]
        expected += [("gone", 1, 1)] if k == 1 else []
        expected += [("row_columns",), ("tick_done", k), ("second tick_done", k)]
    expected += [("run_ends",)]  # the duration is over: no hook is asked whether to stop
    assert calls.log == expected


def test_a_caller_that_owns_the_loop_hands_its_decisions_to_the_transport_and_a_hook_can_stop_the_run(tmp_path):
    calls = _Calls()
    session = _tick_loop_with_fakes(tmp_path, calls, stop_after=0)
    session.start()
    hand = session.observe()
    assert session.observe() is hand and sorted(hand.observed) == [0, 1]  # the first half is made once
    session.step({0: 7})
    assert ("exchange", 0, [0, 1], {0: 7}) in calls.log
    assert calls.log[-1] == ("run_ends",) and session.over  # a hook asked to stop after tick 0


# numpy picks its SIMD code per CPU at import; with AVX-512 its exp and arctan2 differ from the
# standard library's (and from its own AVX2 and baseline paths) in the last bit for some inputs.
# Results must not depend on which CPU the coordinator or an agent ran on.
_PLAIN_SIMD = (
    "X86_V4 AVX512_ICL AVX512_SPR AVX512F AVX512CD AVX512VL AVX512BW AVX512DQ AVX512_SKX AVX512_CLX AVX512_CNL"
)
_PROBE = (
    "import hashlib, numpy as np; x = np.random.default_rng(0).uniform(-5, 5, (2, 4096)); "
    "print(hashlib.sha256(np.exp(x[0]).tobytes() + np.arctan2(*x).tobytes()).hexdigest())"
)
SIMD_CASES = {
    "sar c-cbba, cones and bids": (SAR, ["allocator.name=c-cbba", "run.duration=300", "run.record_trajectories=true"]),
    "mtsr cbba, log-distance radio": (
        ROOT / "experiments" / "space_mtsr.yaml",
        [
            "allocator.name=cbba",
            "agents.count=12",
            "run.duration=300",
            "run.record_trajectories=true",
            "network.range=null",
            "network.propagation={shadowing_db: 6.0, tx_power_dbm: 19.6}",
        ],
    ),
}


def _plain_simd_env() -> dict[str, str]:
    import os

    return {**os.environ, "NPY_DISABLE_CPU_FEATURES": _PLAIN_SIMD}


@functools.cache  # the same answer for every case: probe once
def _simd_changes_numpy() -> bool:
    """Whether switching AVX-512 off changes numpy's exp or arctan2 on this CPU (else nothing to test)."""
    import subprocess
    import sys

    ours, plain = (
        subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env, check=True).stdout
        for env in (None, _plain_simd_env())
    )
    return ours != plain


@pytest.mark.slow  # two runs per case, one in a subprocess
@pytest.mark.parametrize("case", list(SIMD_CASES))
def test_results_do_not_depend_on_the_cpus_simd_level(case, tmp_path):
    import subprocess
    import sys

    if not _simd_changes_numpy():
        pytest.skip("numpy's exp and arctan2 give the same bits with and without AVX-512 on this CPU")
    base, overrides = SIMD_CASES[case]
    alone = run_in_process(experiment(*overrides, base=base), tmp_path / "here")
    sets = [arg for value in overrides for arg in ("--set", value)]
    cmd = [sys.executable, "-m", "swarmbed", "run", str(base), "--engine", "inprocess", "--no-progress", *sets]
    done = subprocess.run(
        [*cmd, "--out", str(tmp_path / "plain")], capture_output=True, text=True, env=_plain_simd_env()
    )
    assert done.returncode == 0, done.stderr
    same_results(alone.out_dir, tmp_path / "plain")
    assert (alone.out_dir / "trajectories.csv").read_bytes() == (tmp_path / "plain" / "trajectories.csv").read_bytes()


def test_each_agents_seeds_are_its_child_of_the_agents_sequence_made_alone():
    """Issue 75: an agent's seed sequences are made without spawning every other agent's (O(n) per
    agent, not O(n^2) for the in-process engine's n agents), and are numpy's own spawn's children."""
    import numpy as np

    from swarmbed.wire.seeds import AGENTS, agent_seeds

    for seed, n, i in ((0, 1, 0), (7, 5, 3), (2**40, 1000, 999), (123, 50, 17)):
        agents = np.random.SeedSequence(seed).spawn(3)[AGENTS]
        reference = agents.spawn(n)[i].spawn(3)
        made = agent_seeds(seed, i, n, 3)
        assert [r.generate_state(4).tolist() for r in reference] == [m.generate_state(4).tolist() for m in made]
