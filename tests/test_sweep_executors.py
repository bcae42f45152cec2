"""Sweeps through every executor (the local pool, Slurm through submitit's local stand-in, a Dask
LocalCluster) give the same bytes; claim files keep concurrent sweep commands from running a run
twice; a run whose worker was killed is redone by the next command."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest

from swarmbed.campaigns import claims, executors
from swarmbed.campaigns.sweep import load_sweep, run_sweep, status
from swarmbed.results.campaign_folders import ATTEMPTS, read_table
from tests.conftest import QUICKSTART, cmdline, same_results, under_way

SWEEP = textwrap.dedent(f"""
    name: pair
    base: {QUICKSTART}
    seed: 11
    runs: 2
    set: {{agents.count: 3, run.duration: 120}}
    grid:
      network.range: [30, 60]
""")


@pytest.fixture(scope="module")
def sweep_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("executors") / "sweep.yaml"
    path.write_text(SWEEP)
    return path


@pytest.fixture(scope="module")
def local_sweep(sweep_file):
    out = sweep_file.parent / "local"
    table = run_sweep(load_sweep(sweep_file), out, jobs=2, progress=False)
    assert (table["status"] == "ok").all(), table
    return out


def _run_dirs(out: Path) -> list[Path]:
    return sorted(p.parent.relative_to(out) for p in out.glob("*/run_*/summary.json"))


def _same_sweep(a: Path, b: Path) -> None:
    assert _run_dirs(a) == _run_dirs(b) and len(_run_dirs(a)) == 4
    for rel in _run_dirs(a):
        same_results(a / rel, b / rel)
    # each run had its own hub port and run id (its own Zenoh namespace), wherever it ran
    deployments = [json.loads((b / rel / "deployment.json").read_text()) for rel in _run_dirs(b)]
    assert len({d["run_id"] for d in deployments}) == len({d["hub"][0] for d in deployments}) == 4


def test_local_sweep_writes_csv_and_parquet_with_the_same_rows(local_sweep):
    csv, parquet = pd.read_csv(local_sweep / "sweep.csv"), pd.read_parquet(local_sweep / "sweep.parquet")
    assert len(parquet) == 4 and list(parquet.columns) == list(csv.columns)
    assert parquet["mission_time"].tolist() == csv["mission_time"].tolist()
    assert read_table(local_sweep).equals(parquet)
    assert not list(local_sweep.rglob(claims.CLAIM))  # every claim was released
    table = status(local_sweep)  # per scenario, in the sweep's order
    assert table.index.tolist() == ["range-30", "range-60"] and table["ok"].tolist() == [2, 2]


def test_slurm_executor_through_submitit_gives_the_local_bytes(sweep_file, local_sweep):
    out = sweep_file.parent / "slurm"
    executor = executors.get("slurm", folder=out / ".submitit", cluster="local", time="10")
    table = run_sweep(load_sweep(sweep_file), out, progress=False, executor=executor)
    assert (table["status"] == "ok").all(), table
    _same_sweep(local_sweep, out)
    assert list((out / ".submitit").rglob("*_log.out"))  # each array task logged through submitit


def test_dask_executor_on_a_local_cluster_gives_the_local_bytes(sweep_file, local_sweep):
    distributed = pytest.importorskip("distributed")
    out = sweep_file.parent / "dask"
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, resources={"cores": 2, "mem_gb": 4}
    ) as cluster:
        executor = executors.get("dask", scheduler=cluster.scheduler_address)
        table = run_sweep(load_sweep(sweep_file), out, progress=False, executor=executor)
        assert "sized by cores, mem_gb" in executor.describe()
    assert (table["status"] == "ok").all(), table
    _same_sweep(local_sweep, out)


def test_a_missing_extra_or_scheduler_is_named(monkeypatch):
    monkeypatch.setitem(sys.modules, "submitit", None)  # as if not installed
    with pytest.raises(executors.ExecutorError, match=r"swarmbed\[slurm\]"):
        executors.get("slurm", folder=Path("x"))
    with pytest.raises(executors.ExecutorError, match="--scheduler"):
        executors.get("dask")
    with pytest.raises(executors.ExecutorError, match="cannot reach"):
        executors.get("dask", scheduler="tcp://127.0.0.1:9")


def test_resources_grow_with_the_agent_count():
    small, mid, big = (executors.resources_for(n) for n in (5, 200, 500))
    assert small == executors.Resources(2, 2) and mid.cpus == 5 and big.cpus == 11
    assert small.mem_gb < mid.mem_gb < big.mem_gb


def test_a_claim_is_exclusive_until_released_or_its_holder_dies(tmp_path):
    run = tmp_path / "run_000"
    mine = claims.take(run)
    assert isinstance(mine, claims.Claim)
    other = claims.take(run)
    assert isinstance(other, claims.Holder) and other.pid == os.getpid()
    mine.release()
    assert claims.holder(run) is None
    # a holder whose process is gone (same host) is stale at once; one on another host after stale_after
    dead = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    (run / claims.CLAIM).write_text(
        json.dumps(
            {
                "host": claims.socket.gethostname(),
                "pid": dead.pid,
                "started": psutil.Process(dead.pid).create_time(),
                "token": "t",
            }
        )
    )
    assert claims.holder(run).alive()
    dead.kill()
    dead.wait()
    assert not claims.holder(run).alive()
    (run / claims.CLAIM).write_text(json.dumps({"host": "elsewhere", "pid": 1, "started": 0, "token": "t"}))
    assert claims.holder(run).alive(stale_after=60)
    assert not claims.holder(run).alive(stale_after=60, now=time.time() + 61)
    taken = claims.take(run, stale_after=60)
    assert isinstance(taken, claims.Holder)  # still fresh: not taken over
    os.utime(run / claims.CLAIM, (time.time() - 120, time.time() - 120))
    taken = claims.take(run, stale_after=60)
    assert isinstance(taken, claims.Claim)
    assert json.loads((run / claims.CLAIM).read_text())["took_over"] == "pid 1 on elsewhere"
    taken.release()


def _sweep_cmd(sweep_file: Path, out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "swarmbed", "sweep", str(sweep_file), "--out", str(out), "--no-progress", *extra]


def _attempts(run_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (run_dir / ATTEMPTS).read_text().splitlines()]


def test_two_sweep_commands_on_one_directory_never_run_a_run_twice(sweep_file, tmp_path):
    """Both start at once on one directory with one worker each: every run is started exactly once
    (its attempts log says so and by whom), both commands did some of them, and a third command
    finds the sweep complete."""
    out = tmp_path / "shared"
    cmd = _sweep_cmd(sweep_file, out, "--jobs", "1", "--set", "run.duration=300")
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outputs = [p.communicate(timeout=280) for p in procs]
    runs = sorted(out.glob("*/run_*"))
    assert len(runs) == 4 and all((d / "summary.json").exists() for d in runs), outputs
    attempts = {d: _attempts(d) for d in runs}
    assert all([a["event"] for a in tries] == ["start", "end"] for tries in attempts.values()), attempts
    by = {tries[0]["ppid"] for tries in attempts.values()}  # the sweep command whose worker ran it
    assert by == {p.pid for p in procs}, (by, outputs)
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and "4 of 4 runs complete" in again.stdout, again.stderr
    assert all(len(_attempts(d)) == 2 for d in runs)  # nothing was run again


def test_a_run_whose_worker_was_killed_is_redone_by_the_next_command(sweep_file, tmp_path):
    """SIGKILL to the pool worker under a run (as the OOM killer would): that run is reported lost,
    the runs not yet started still run, --status shows it interrupted, and the same command again
    redoes it alone."""
    out = tmp_path / "killed"
    cmd = _sweep_cmd(sweep_file, out, "--jobs", "1", "--set", "run.duration=1500", "--set", "run.stop_when_done=false")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (victim := [d for d in out.glob("*/run_*") if under_way(d)]):
        assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    holder = claims.holder(victim[0])
    assert holder is not None and holder.pid != proc.pid
    os.kill(holder.pid, signal.SIGKILL)
    _, stderr = proc.communicate(timeout=240)
    assert proc.returncode == 1 and "lost: " in stderr, stderr
    table = status(out)
    assert table.loc[victim[0].parent.name, "interrupted"] == 1 and table["ok"].sum() == 3, table
    assert not (victim[0] / "summary.json").exists()
    listed = subprocess.run(
        [sys.executable, "-m", "swarmbed", "sweep", "--status", str(out)], capture_output=True, text=True, timeout=60
    )
    assert listed.returncode == 0 and "interrupted" in listed.stdout, listed
    done = {d: len(_attempts(d)) for d in out.glob("*/run_*") if d != victim[0]}
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=240)
    assert again.returncode == 0 and "4 of 4 runs complete" in again.stdout, again.stderr
    assert (victim[0] / "summary.json").exists() and not (victim[0] / claims.CLAIM).exists()
    assert [a["event"] for a in _attempts(victim[0])] == ["start", "start", "end"]
    assert all(len(_attempts(d)) == n for d, n in done.items())  # the others were kept


def test_a_detached_slurm_sweep_is_watched_with_status_and_collected_by_the_same_command(sweep_file, tmp_path):
    """--detach submits the array and returns; --status follows it; the same command again (once
    everything is done) runs nothing and writes the tables."""
    out = tmp_path / "detached"
    cmd = _sweep_cmd(sweep_file, out, "--executor", "slurm", "--slurm-cluster", "local", "--slurm-time", "0:10:00")
    first = subprocess.run([*cmd, "--detach"], capture_output=True, text=True, timeout=120)
    assert first.returncode == 0 and "submitted: slurm (array job" in first.stdout, first
    assert f"swarmbed sweep --status {out}" in first.stdout
    deadline = time.monotonic() + 240
    while (table := status(out)).get("ok", pd.Series(dtype=int)).sum() < 4:
        assert time.monotonic() < deadline, table
        time.sleep(1)
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and "4 of 4 runs complete" in again.stdout, again
    assert all(len(_attempts(d)) == 2 for d in out.glob("*/run_*"))  # nothing ran twice
    assert (out / "sweep.parquet").exists()


def test_a_killed_sweep_process_takes_its_workers_and_their_runs_with_it(sweep_file, tmp_path):
    """SIGKILL to the sweep itself (no chance to stop anything): its pool workers must not go on
    with the runs already queued, unseen, and no run's process may be left behind."""
    import psutil

    out = tmp_path / "orphans"
    cmd = _sweep_cmd(sweep_file, out, "--jobs", "2", "--set", "run.duration=1500", "--set", "run.stop_when_done=false")
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not [d for d in out.glob("*/run_*") if under_way(d)]:
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.1)
    family = psutil.Process(proc.pid).children(recursive=True)
    assert any("swarmbed.agent_runtime" in cmdline(p) for p in family)
    proc.kill()
    proc.wait()
    _, alive = psutil.wait_procs(family, timeout=15)
    assert not alive, [(p.pid, cmdline(p)[:200]) for p in alive]
