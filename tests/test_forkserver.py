"""Agents forked from the fork server: the same results as fresh interpreters, visible in ps under
their own command line, and gone with whatever dies above them."""

import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

from swarmbed.launch.launcher import own_cpu_s
from swarmbed.launch.runner import run_experiment
from tests.conftest import QUICKSTART, ROOT, cmdline, experiment, same_results, under_way


def test_forked_agents_give_the_results_of_fresh_interpreters(tmp_path):
    sets = ["allocator={name: cbba}", "run.duration=300", "run.stop_when_done=false"]
    forked = run_experiment(experiment(*sets), tmp_path / "forked", progress=False, fork_agents=True)
    cpu_before = own_cpu_s()
    fresh = run_experiment(experiment(*sets), tmp_path / "fresh", progress=False, fork_agents=False)
    # a second run in one process, as in a sweep's pool worker: the hub's CPU is this run's alone
    assert 0 < fresh.timings["cpu_s"]["coordinator"] <= own_cpu_s() - cpu_before + 0.01
    same_results(tmp_path / "fresh", tmp_path / "forked")
    assert forked.timings["startup"]["fork_server_s"] is not None and fresh.timings["startup"]["fork_server_s"] is None
    # forked agents share what the server imported: each holds less of its own
    assert forked.timings["agent_uss_mb_mean"] < fresh.timings["agent_uss_mb_mean"]


def _run_until_under_way(tmp_path) -> tuple[subprocess.Popen, psutil.Process]:
    cmd = [
        sys.executable,
        "-m",
        "swarmbed",
        "run",
        str(QUICKSTART),
        "--out",
        str(tmp_path),
        "--no-progress",
        "--set",
        "allocator={name: noop, peers: 2}",
        "--set",
        "run.stop_when_done=false",
        "--set",
        "run.duration=1000000",
    ]
    runner = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not under_way(tmp_path):
        assert runner.poll() is None and time.monotonic() < deadline, runner.communicate()
        time.sleep(0.1)
    return runner, psutil.Process(runner.pid)


def test_forked_agents_show_their_command_line_and_die_with_the_launcher(tmp_path):
    runner, proc = _run_until_under_way(tmp_path)
    everyone = proc.children(recursive=True)
    agents = [p for p in everyone if "-m swarmbed.agent_runtime" in cmdline(p)]
    assert sorted(int(cmdline(p).split("--id ")[1].split()[0]) for p in agents) == [0, 1, 2, 3, 4]
    server = next(p for p in everyone if "swarmbed.launch.forkserver" in cmdline(p))
    assert all(a.ppid() == server.pid for a in agents)
    runner.send_signal(signal.SIGKILL)  # no clean-up code runs: the kernel's death signals must do it
    runner.communicate(timeout=30)
    _, alive = psutil.wait_procs(everyone, timeout=15)
    assert not alive, f"orphans: {[(p.pid, cmdline(p)[:200]) for p in alive]}"
    run_id = json.loads((tmp_path / "deployment.json").read_text())["run_id"]
    for private in Path(tempfile.gettempdir()).glob(f"swarmbed-{run_id}-*"):  # the killed launcher's identities
        shutil.rmtree(private)


def test_a_dead_fork_server_takes_its_agents_and_the_run_says_so(tmp_path):
    runner, proc = _run_until_under_way(tmp_path)
    everyone = proc.children(recursive=True)
    server = next(p for p in everyone if "swarmbed.launch.forkserver" in cmdline(p))
    server.send_signal(signal.SIGKILL)
    _, err = runner.communicate(timeout=60)
    assert runner.returncode == 1 and "stopped at tick" in err and "agent" in err
    _, alive = psutil.wait_procs(everyone, timeout=15)
    assert not alive


def test_a_run_started_beside_another_swarmbed_runs_every_process_on_the_launchers_own(tmp_path):
    """``python -m`` puts the current directory first on a child's path: a run started in a folder
    holding another ``swarmbed`` (a second checkout, say) must not start its fork server, agents
    and proxy on that code. The launcher here has no current directory on its path (``-P``, as an
    installed ``swarmbed`` command has not)."""
    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "swarmbed").mkdir(parents=True)
    (elsewhere / "swarmbed" / "__init__.py").write_text('raise ImportError("the other swarmbed was imported")\n')
    cmd = [
        sys.executable,
        "-P",
        "-m",
        "swarmbed",
        "run",
        str(QUICKSTART),
        "--out",
        str(tmp_path / "run"),
        "--no-progress",
        "--set",
        "run.duration=20",
        "--set",
        "agents.count=2",
    ]
    done = subprocess.run(cmd, cwd=elsewhere, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["ticks"] == 20
