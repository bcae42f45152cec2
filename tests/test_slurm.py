"""``swarmbed run --slurm`` under a real Slurm: slurmctld here, one slurmd per stand-in host (network
namespaces), the run launched inside ``salloc`` as a user would. The agents spread over the
allocation's nodes give the results of the same experiment on one machine."""

import json
import os
import subprocess
import sys
import time

import psutil
import pytest

from swarmbed.hosts.netns import LabError
from swarmbed.hosts.slurm_lab import make_slurm_lab
from swarmbed.launch.slurm_allocation import spread
from tests.conftest import QUICKSTART, experiment, reference_run, same_results
from tests.test_radio_split import proxy_reads


@pytest.fixture
def cluster(lab, tmp_path):
    """Three Slurm nodes n1..n3 on ``lab``; skips, with the reason, where Slurm cannot start."""
    try:
        the_cluster = make_slurm_lab(lab, tmp_path / "slurm", nodes=3)
    except LabError as exc:
        pytest.skip(str(exc))
    try:
        yield the_cluster
    finally:
        the_cluster.close()


def test_spread_gives_contiguous_blocks_over_the_nodes_and_leaves_none_out():
    assert spread(["a", "b", "c"], 20) == {"a": "0-6", "b": "7-13", "c": "14-19"}
    assert spread(["a", "b", "c"], 2) == {"a": "0-0", "b": "1-1"}


def test_slurm_outside_an_allocation_is_one_line(capsys, monkeypatch):
    from swarmbed.cli.main import main

    for name in ("SLURM_JOB_ID", "SLURM_JOB_NODELIST"):
        monkeypatch.delenv(name, raising=False)
    assert main(["run", str(QUICKSTART), "--slurm", "--check"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "error: --slurm: not inside a Slurm allocation (SLURM_JOB_ID unset): run it under salloc or sbatch"
    assert main(["run", str(QUICKSTART), "--slurm", "--set", "placement={h: 0}", "--check"]) == 2
    assert "places the agents itself" in capsys.readouterr().err


def _queue_empties(env: dict, within_s: float) -> str:
    """What squeue still lists after at most ``within_s`` seconds ('' once the queue is empty)."""
    deadline = time.monotonic() + within_s
    while True:
        left = subprocess.run(["squeue", "-h"], env=env, capture_output=True, text=True).stdout.strip()
        if left == "" or time.monotonic() > deadline:
            return left
        time.sleep(0.5)


@pytest.mark.slow
@pytest.mark.parametrize(("launcher", "shards"), [("salloc", 1), ("sbatch", 1), ("salloc", 3)])
def test_a_run_in_an_allocation_spreads_its_agents_over_the_nodes_and_gives_the_one_machine_results(
    cluster, tmp_path, launcher, shards
):
    """``salloc``: the run's hub, coordinator and proxy stay on the submitting machine; ``sbatch``:
    they run on the allocation's first node (a namespace), beside that node's own daemon. With
    ``shards`` 3 the radio is split over three proxies (per-copy loss draws, strips of 30), each a
    job step on its own node, and the files are still those of one machine with one radio."""
    sets = ["agents.count=9", "allocator={name: cbba}", "run.duration=60", "run.stop_when_done=false"]
    if shards > 1:
        sets += ["network.loss=0.1", "network.draws=per_copy", "radio_split.strip_width=30"]
    reference_run(experiment(*sets), tmp_path / "local")
    sets += [f"radio_split.shards={shards}"]
    run = [sys.executable, "-m", "swarmbed", "run", str(QUICKSTART), "--slurm", "--no-progress"]
    run += ["--out", str(tmp_path / "slurm_run"), *[arg for s in sets for arg in ("--set", s)]]
    if launcher == "salloc":
        cmd = ["salloc", "--nodes=3", "--immediate=60", "--job-name=swarmbed-test", *run]
    else:
        script = tmp_path / "job.sh"
        script.write_text("#!/bin/sh\nexec " + " ".join(f"'{a}'" for a in run) + "\n")
        cmd = ["sbatch", "--wait", "--nodes=3", "--job-name=swarmbed-test", f"--output={tmp_path}/job.out", str(script)]
    done = subprocess.run(cmd, cwd=tmp_path, env=cluster.env, capture_output=True, text=True, timeout=300)
    output = done.stdout + done.stderr + ((tmp_path / "job.out").read_text() if launcher == "sbatch" else "")
    assert done.returncode == 0, output
    same_results(tmp_path / "local", tmp_path / "slurm_run")
    deployment = json.loads((tmp_path / "slurm_run" / "deployment.json").read_text())
    where = {int(agent): host for agent, host in deployment["placement"].items()}
    assert where == {
        **dict.fromkeys(range(3), "n1"),
        **dict.fromkeys(range(3, 6), "n2"),
        **dict.fromkeys(range(6, 9), "n3"),
    }
    assert len(list((tmp_path / "slurm_run" / "logs").glob("netem*.log"))) == shards
    if shards > 1:  # each proxy ran as a job step on its own node (proxy i on node i mod 3)
        for shard, node in enumerate(("n1", "n2", "n3")):
            name = "netem" if shard == 0 else f"netem-{shard}"
            text = (tmp_path / "slurm_run" / "logs" / f"{name}.log").read_text()
            assert f"proxy {shard} of 3 on Slurm node {node}" in text, text[-2000:]
        # the nodes' relays sent each output to the one proxy that owns its agent at the tick
        reads = proxy_reads(tmp_path / "slurm_run")
        ticks = reads[0][1]
        assert sum(n for n, _ in reads) == 9 * ticks and all(0 < n < 9 * ticks for n, _ in reads), reads
    # each node's daemon ran in its own namespace and logged its agents there
    for node, agent in (("n1", 0), ("n2", 4), ("n3", 8)):
        assert list((tmp_path / "runs" / "hosts").glob(f"slurm-*/{node}/*/agent_{agent}.log")), (node, agent)
    # the job steps ended with the run: nothing of the job is left running. Slurm lists a job as
    # completing (CG) for a while after its last step left, longer on a busy machine: wait, bounded
    assert _queue_empties(cluster.env, within_s=60) == ""
    assert not [p for p in os.listdir(tmp_path / "runs" / "hosts") if p.startswith("swarmbed-slurm-")]


@pytest.mark.slow
def test_a_sweep_through_the_slurm_executor_runs_its_runs_as_array_tasks_on_the_nodes(cluster, tmp_path, monkeypatch):
    """``sweep --executor slurm`` against a real slurmctld: one array job, its tasks on the nodes
    (network namespaces), every run's files those of the same sweep run here."""
    from swarmbed.campaigns import executors
    from swarmbed.campaigns.sweep import load_sweep, run_sweep

    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(
        f"name: pair\nbase: {QUICKSTART}\nseed: 11\nruns: 2\nset: {{agents.count: 3, run.duration: 60}}\n"
        "grid:\n  network.range: [30, 60]\n"
    )
    local = run_sweep(load_sweep(sweep), tmp_path / "local", jobs=2, progress=False, in_process=True)
    assert (local["status"] == "ok").all(), local
    for name, value in cluster.env.items():
        monkeypatch.setenv(name, value)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "slurm"
    executor = executors.get("slurm", folder=out / ".submitit", time="10")
    table = run_sweep(load_sweep(sweep), out, progress=False, executor=executor)
    assert (table["status"] == "ok").all(), table
    runs = sorted(p.parent.relative_to(out) for p in out.glob("*/run_*/summary.json"))
    assert len(runs) == 4
    for rel in runs:
        same_results(tmp_path / "local" / rel, out / rel)
    nodes = {json.loads((out / rel / "deployment.json").read_text())["hub"][0] for rel in runs}
    assert len(nodes) == 4  # each run its own hub
    array = executor.jobs[0].job_id.split("_")[0]
    shown = subprocess.run(["scontrol", "show", "job", "-o", array], env=cluster.env, capture_output=True, text=True)
    tasks = [dict(f.split("=", 1) for f in line.split() if "=" in f) for line in shown.stdout.splitlines()]
    assert len(tasks) == 4 and {t["JobState"] for t in tasks} == {"COMPLETED"}, shown.stdout
    assert {t["NodeList"] for t in tasks} <= set(cluster.nodes), shown.stdout


@pytest.mark.slow
def test_the_slurm_lab_command_starts_a_cluster_a_user_can_reach_and_stops_it_whole(tmp_path):
    """Issue 82 item 18: a documented way to try ``run --slurm`` on one machine."""
    import signal

    from swarmbed.hosts.netns import why_not as no_namespaces
    from swarmbed.hosts.slurm_lab import why_not as no_slurm

    reason = no_namespaces() or no_slurm()
    if reason:
        pytest.skip(reason)
    folder = tmp_path / "lab"
    proc = subprocess.Popen(
        [sys.executable, "-m", "swarmbed", "slurm-lab", "--nodes", "2", "--folder", str(folder)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        lines = [proc.stdout.readline() for _ in range(4)]
        assert lines[1].strip() == f"export SLURM_CONF={folder / 'slurm.conf'}", lines
        env = dict(os.environ, SLURM_CONF=str(folder / "slurm.conf"))
        sinfo = subprocess.run(["sinfo", "-h", "-o", "%D %t"], env=env, capture_output=True, text=True).stdout
        assert sinfo.split() == ["2", "idle"], sinfo
        conf = str(folder / "slurm.conf")
        nodes = {  # the network namespaces this lab's slurmd run in
            os.stat(f"/proc/{p.pid}/ns/net").st_ino
            for p in psutil.process_iter(["cmdline"])
            if conf in (p.info["cmdline"] or []) and "slurmd" in (p.info["cmdline"] or [""])[0]
        }
        ours = [n for n in os.listdir("/var/run/netns") if os.stat(f"/var/run/netns/{n}").st_ino in nodes]
        assert len(ours) == 2, ours
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and "slurm-lab: stopped" in out, (out, err)
    assert "slurmctld" not in err  # its start-up lines went to its log, not the user's terminal
    left = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout.split()
    assert not set(ours) & set(left), left
