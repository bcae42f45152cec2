"""Runs spread over stand-in hosts (network namespaces, one ``swarmbed host`` each): placement never
changes results, a host that dies is agent loss, a missing host is named with the command to start it."""

import csv
import json
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import psutil
import pytest

from swarmbed.engine.run_errors import RunError
from swarmbed.launch.runner import run_experiment
from swarmbed.wire.credentials import Identity
from tests.conftest import SAR_BASE, experiment, reference_run, same_results

SAR = SAR_BASE


def test_agents_split_over_three_hosts_give_the_all_local_results(lab, tmp_path, operator):
    for name in ("h1", "h2", "h3"):
        lab.add_host(name)
    sets = ["agents.count=20", "allocator={name: cbba}", "run.duration=150", "run.stop_when_done=false"]
    local = reference_run(experiment(*sets), tmp_path / "local")
    placed = experiment(*sets, "placement={h1: '0-5', h2: '6-12,19', h3: [13, 14, 15, 16, 17, 18]}")
    seen = {}

    def look(keys, endpoint):
        seen["hosts"] = subprocess.run(
            [sys.executable, "-m", "swarmbed", "hosts", "--connect", endpoint, *operator.args],
            capture_output=True,
            text=True,
            timeout=30,
        ).stdout

    spread = run_experiment(
        placed, tmp_path / "spread", progress=False, on_ready=look, hub=lab.hub_options(operator.identity)
    )
    same_results(tmp_path / "local", tmp_path / "spread")
    assert spread.summary["network"]["messages_sent"] == local.summary["network"]["messages_sent"] > 0
    deployment = (tmp_path / "spread" / "deployment.json").read_text()
    assert '"19": "h2"' in deployment and '"13": "h3"' in deployment
    for name in ("h1", "h2", "h3"):
        assert name in seen["hosts"]
    assert list((lab.logs / "h2").glob("*/agent_19.log")), "agent 19 did not run on host h2"


def test_search_and_rescue_over_two_hosts_gives_the_all_local_results(lab, tmp_path):
    lab.add_host("a")
    lab.add_host("b")
    sets = ["allocator.name=cbba-etc", "run.duration=40"]
    reference_run(experiment(*sets, base=SAR), tmp_path / "local")
    run_experiment(
        experiment(*sets, "placement={a: '0-9', b: '10-19'}", base=SAR),
        tmp_path / "spread",
        progress=False,
        hub=lab.hub_options(),
    )
    same_results(tmp_path / "local", tmp_path / "spread")


def _kill_when_running(lab, name, delay):
    def later(keys, endpoint):
        threading.Timer(delay, lab.kill_host, [name]).start()

    return later


def test_a_host_that_dies_takes_its_agents_and_the_run_accounts_for_them(lab, tmp_path):
    lab.add_host("doomed")
    lab.add_host("fine")
    long = [
        "allocator={name: noop, peers: 2}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        "agents.count=6",
        "placement={doomed: '0-1', fine: '2-3'}",
    ]
    result = run_experiment(
        experiment(*long, "run.duration=3000", "run.allow_agent_failures=true"),
        tmp_path / "allowed",
        progress=False,
        on_ready=_kill_when_running(lab, "doomed", 1.0),
        hub=lab.hub_options(),
    )
    assert set(result.summary["agents_lost"]) == {"0", "1"}
    net = result.summary["network"]
    assert net["copies"] == net["delivered"] + net["dropped_total"] and net["dropped"]["receiver_dead"] > 0
    assert lab.pids("doomed") == []  # nothing of that host is left running

    lab.start_daemon("doomed", lab.namespaces[0])  # the machine comes back for the next run
    with pytest.raises(RunError, match=r"agent [01] stopped at tick \d+ .* logs of host doomed"):
        run_experiment(
            experiment(*long, "run.duration=1000000"),
            tmp_path / "strict",
            progress=False,
            on_ready=_kill_when_running(lab, "doomed", 1.0),
            hub=lab.hub_options(),
        )


def test_a_missing_host_is_named_with_the_command_that_starts_it(lab, tmp_path):
    lab.add_host("here")
    exp = experiment("placement={here: 0, gone: '1-2'}", "run.join_timeout=3")
    # a host the run does not admit could be up and would still never get in: said before anything starts
    with pytest.raises(RunError, match=r"placement names host\(s\) gone, which this run does not admit"):
        run_experiment(exp, tmp_path, progress=False, hub=lab.hub_options())
    assert not (tmp_path / "logs").exists()
    t0 = time.monotonic()
    with pytest.raises(RunError) as info:  # admitted but not up: not reachable, and how to start it
        run_experiment(exp, tmp_path, progress=False, hub=lab.hub_options(Identity.new("gone", "host")))
    msg = str(info.value)
    assert "hosts not reachable after 3 s: gone" in msg and f"swarmbed host --name gone --connect {lab.hub}" in msg
    assert time.monotonic() - t0 < 20
    assert not (tmp_path / "summary.json").exists()


def test_ten_swaps_between_hosts_give_the_all_local_results(lab, tmp_path):
    lab.add_host("h1")
    lab.add_host("h2")
    sets = ["agents.count=8", "allocator={name: cbba}", "run.duration=120", "run.stop_when_done=false"]
    reference_run(experiment(*sets), tmp_path / "local")
    rng = np.random.default_rng(3)
    ticks = sorted(int(t) for t in rng.choice(np.arange(1, 110), 10, replace=False))
    swaps = ", ".join(
        f"{{agent: {int(rng.integers(8))}, tick: {t}, to: {['h1', 'h2', 'local'][int(rng.integers(3))]}}}"
        for t in ticks
    )
    run_experiment(
        experiment(*sets, "placement={h1: '0-2', h2: '3-5'}", f"swaps=[{swaps}]"),
        tmp_path / "moved",
        progress=False,
        hub=lab.hub_options(),
    )
    same_results(tmp_path / "local", tmp_path / "moved")
    with open(tmp_path / "moved" / "swaps.csv") as f:
        records = list(csv.DictReader(f))
    assert len(records) == 10 and all(r["outcome"] == "ok" for r in records), records
    assert {r["to"] for r in records} >= {"h1", "h2"}
    import json

    deployment = json.loads((tmp_path / "moved" / "deployment.json").read_text())
    last = {}  # where each agent is after the last swap that moved it
    for r in records:
        last[r["agent"]] = r["to"]
    for agent, host in last.items():
        assert deployment["placement_at_end"][agent] == host
        if host != "local":
            assert int(agent) in deployment["hosts"][host]["agents"][deployment["run_id"]]


def test_a_swap_to_a_dead_host_fails_and_the_agent_goes_on_where_it_was(lab, tmp_path):
    lab.add_host("alive")
    lab.add_host("dead")
    lab.kill_host("dead")
    sets = ["allocator={name: cbba}", "run.duration=60", "run.stop_when_done=false"]
    reference_run(experiment(*sets), tmp_path / "local")
    run_experiment(
        experiment(*sets, "placement={alive: '0-1'}", "swaps=[{agent: 1, tick: 10, to: dead}]"),
        tmp_path / "tried",
        progress=False,
        hub=lab.hub_options(),
    )
    same_results(tmp_path / "local", tmp_path / "tried")
    with open(tmp_path / "tried" / "swaps.csv") as f:
        (record,) = list(csv.DictReader(f))
    assert record["outcome"] == "failed" and "cannot start it on dead" in record["reason"]


def test_sigterm_on_a_host_daemon_stops_its_agents_and_leaves_nothing(lab, tmp_path):
    lab.add_host("h")

    def stop_the_daemon_soon(keys, endpoint):
        threading.Timer(1.0, lab.daemons["h"].send_signal, [signal.SIGTERM]).start()

    exp = experiment(
        "allocator={name: noop, peers: 2}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        "run.duration=3000",
        "run.allow_agent_failures=true",
        "placement={h: '0-1'}",
    )
    result = run_experiment(exp, tmp_path, progress=False, on_ready=stop_the_daemon_soon, hub=lab.hub_options())
    assert set(result.summary["agents_lost"]) == {"0", "1"}
    assert lab.daemons["h"].wait(timeout=20) == 0
    assert lab.pids("h") == []


def test_a_host_daemon_answers_crafted_start_and_stop_requests_with_why_and_starts_nothing(tmp_path):
    """The start and stop requests decode into their declared types only (wire.reports): a request
    with an unknown key, a run id that is not alphanumeric, a number as text, or no JSON at all is
    answered with one line naming the field, and no process starts."""
    import zenoh

    from swarmbed.wire.zenoh_session import free_loopback_endpoint, zenoh_config

    endpoint = free_loopback_endpoint()
    daemon = subprocess.Popen(
        [sys.executable, "-m", "swarmbed", "host", "--name", "h", "--insecure", "--listen", endpoint],
        stdout=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    try:
        assert "host h up" in daemon.stdout.readline()
        crafted = {
            b'{"run_id": "abc", "agents": [1], "args": ["--config", "/tmp/x.py"]}': "args: Extra inputs",
            b'{"run_id": "a;rm -rf", "agents": [1]}': "run_id: String should match pattern",
            b'{"run_id": "abc", "agents": [1], "log_max_mb": "20; sh"}': "log_max_mb: Input should be a valid int",
            b'{"run_id": "abc", "agents": []}': "agents: List should have at least 1 item",
            b'{"run_id": "abc", "agents": [1], "incarnation": -1}': "incarnation: Input should be greater",
            b"[1, 2]": "start request: Input should be a valid dictionary",
            b"\xc1 not json": "start request: not JSON",
            b'{"run_id": "abc", "agents": [1]}': "run abc has no coordinator reachable from host h",
        }
        with zenoh.open(zenoh_config("client", [endpoint])) as s:
            answers = {}
            for request in crafted:
                replies = [r.ok for r in s.get("swarmbed/hosts/h/start", payload=request, timeout=5) if r.ok]
                answers[request] = json.loads(replies[0].payload.to_bytes())["error"]
            stop = [r.ok for r in s.get("swarmbed/hosts/h/stop", payload=b'{"run_id": "../etc"}', timeout=5) if r.ok]
            info = [r.ok for r in s.get("swarmbed/hosts/h/info", timeout=5) if r.ok]
        for request, why in crafted.items():
            assert why in answers[request] and "\n" not in answers[request], (request, answers[request])
        assert "stop request: run_id: String should match pattern" in json.loads(stop[0].payload.to_bytes())["error"]
        assert json.loads(info[0].payload.to_bytes())["agents"] == {}
        assert not psutil.Process(daemon.pid).children(recursive=True)
    finally:
        daemon.terminate()
        daemon.wait(timeout=10)


def _host_says(hub_admits: bool, tmp_path) -> str:
    """What a host daemon prints within 20 s when it connects to a hub that does or does not admit it."""
    from swarmbed.launch.access import RunAccess
    from swarmbed.launch.hub import open_hub
    from swarmbed.wire.credentials import write_credentials
    from swarmbed.wire.keys import Keys

    me = Identity.new("lab1", "host")
    tmp_path.mkdir()
    creds = write_credentials(tmp_path / "lab1.json", me)
    access = RunAccess(Keys("hubcheck"), range(1), [me] if hub_admits else [])
    hub, endpoint = open_hub(settings=access.hub_settings())
    daemon = subprocess.Popen(
        [sys.executable, "-m", "swarmbed", "host", "--name", "lab1", "--connect", endpoint]
        + ["--credentials", str(creds), "--logs", str(tmp_path / "logs")],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    said: list[str] = []
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not any("connected to" in line for line in said):
            said.append(daemon.stdout.readline())
    finally:
        daemon.send_signal(signal.SIGINT)
        daemon.wait(timeout=20)
        hub.close()
        access.close()
    return "".join(said)


def test_a_host_the_hub_does_not_admit_says_so_and_one_it_admits_says_connected(tmp_path):
    refused = _host_says(False, tmp_path / "refused")
    assert "not connected to" in refused and "does not admit this host's credentials" in refused, refused
    admitted = _host_says(True, tmp_path / "admitted")
    assert "host lab1: connected to" in admitted and "not connected" not in admitted, admitted


def test_on_the_real_time_clock_a_hosts_relay_misses_exactly_the_ticks_its_slow_agent_missed(lab, tmp_path):
    """The real-time case of tests/test_realtime.py with its sleeper (agent 1) and agent 0 on a
    host: the relay sends agent 0's answers on without waiting for the sleeper's late ones, so the
    same four ticks, and only those, are missed, each late message booked dropped ``late``."""
    from tests.test_realtime import SLEEPY, SLOW_TICKS

    lab.add_host("h1")
    (tmp_path / "sleepy.py").write_text(SLEEPY)
    allocator = f"allocator={{name: '{tmp_path / 'sleepy.py'}:Sleepy', peers: 2, ticks: {SLOW_TICKS}, sleep: 0.35}}"
    sets = [allocator, "agents.count=4", "run.duration=20", "run.stop_when_done=false", "placement={h1: '0-1'}"]
    sets += ["run.clock=realtime", "run.speed=2", "run.deadline=0.5"]
    run = run_experiment(experiment(*sets), tmp_path / "rt", progress=False, hub=lab.hub_options())
    clock, net = run.summary["realtime"], run.summary["network"]
    assert clock["late_ticks"] == {"1": len(SLOW_TICKS)}, clock
    assert net["dropped"]["late"] == 2 * len(SLOW_TICKS) and net["copies"] == net["delivered"] + sum(
        net["dropped"].values()
    )
    assert list((lab.logs / "h1").glob("*/agent_1.log")), "agent 1 did not run on host h1"
