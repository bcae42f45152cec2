"""The lock-step engine: the in-process transport writes the result files a real run writes.

Each case runs one shipped experiment (shortened) twice: once as a run of real processes over
Zenoh through the netem proxy, once on the in-process engine. The files that repeat byte for byte
between runs must be the same bytes: the same world, the same agents' decisions, the same radio
draws, the same ledger.
"""

import pytest

from swarmbed.experiments.launch.inprocess import run_in_process
from swarmbed.experiments.launch.runner import run_experiment
from swarmbed.wire.rundir import RECEIVER_LEDGER
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
    with pytest.raises(ValueError, match="no one to ask"):
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
