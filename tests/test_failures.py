"""Processes that die, plugins that raise, and garbage on the wire."""

import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import psutil
import pytest
import zenoh

from swarmbed.engine.run_errors import RunError
from swarmbed.launch.hub import HubOptions
from swarmbed.launch.runner import run_experiment
from swarmbed.wire.codec import EMPTY_INBOX, MAX_AGENT_SAMPLE_BYTES, encode_tick, pack
from swarmbed.wire.keys import Keys
from swarmbed.wire.membership import hand_over
from swarmbed.wire.zenoh_session import zenoh_config
from tests.conftest import QUICKSTART, ROOT, cmdline, experiment, under_way

LONG_NOOP = [
    "--set",
    "allocator={name: noop, peers: 2}",
    "--set",
    "scenario.initial_tasks=0",
    "--set",
    "run.stop_when_done=false",
    "--set",
    "run.duration=1000000",
]


def _agents_of(runner: psutil.Process) -> list[psutil.Process]:
    return [p for p in runner.children(recursive=True) if "agent_runtime" in cmdline(p)]


@pytest.mark.parametrize("allow", [False, True])
def test_sigkilled_agent_is_noticed_and_leaves_no_orphans(tmp_path, allow):
    cmd = [
        sys.executable,
        "-m",
        "swarmbed",
        "run",
        str(QUICKSTART),
        "--out",
        str(tmp_path),
        "--no-progress",
        *LONG_NOOP,
        "--set",
        f"run.allow_agent_failures={str(allow).lower()}",
    ]
    if allow:
        cmd[cmd.index("run.duration=1000000")] = "run.duration=3000"
    runner = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc = psutil.Process(runner.pid)
    deadline = time.monotonic() + 60
    while len(_agents_of(proc)) < 5 or not under_way(tmp_path):
        assert runner.poll() is None and time.monotonic() < deadline, runner.communicate()
        time.sleep(0.1)
    time.sleep(0.5)  # well into the run
    children = proc.children(recursive=True)
    victim = next(p for p in _agents_of(proc) if "--id 2" in cmdline(p))
    killed_at = time.monotonic()
    victim.send_signal(signal.SIGKILL)
    out, err = runner.communicate(timeout=120)
    if allow:
        assert runner.returncode == 0, err
        import json

        summary = json.loads((tmp_path / "summary.json").read_text())
        assert "2" in summary["agents_lost"]
        assert summary["network"]["copies"] == summary["network"]["delivered"] + summary["network"]["dropped_total"]
    else:
        noticed = time.monotonic() - killed_at
        assert runner.returncode == 1
        assert "agent 2 stopped at tick" in err and "logs/agent_2.log" in err
        assert "its process was killed by signal SIGKILL" in err, err
        assert noticed < 10, f"took {noticed:.1f} s"
        assert not (tmp_path / "summary.json").exists()
    gone, alive = psutil.wait_procs(children, timeout=5)
    assert not alive, f"orphans: {[p.pid for p in alive]}"


def _start_long_run(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "swarmbed",
        "run",
        str(QUICKSTART),
        "--out",
        str(tmp_path),
        "--no-progress",
        *LONG_NOOP,
    ]
    runner = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc = psutil.Process(runner.pid)
    deadline = time.monotonic() + 60
    while len(_agents_of(proc)) < 5 or not under_way(tmp_path):
        assert runner.poll() is None and time.monotonic() < deadline, runner.communicate()
        time.sleep(0.1)
    time.sleep(0.5)
    return runner, proc, proc.children(recursive=True)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_or_sigterm_stops_every_process_with_a_clear_message(tmp_path, sig):
    """SIGTERM (``kill``, or the only way to stop a run started in the background, where the shell
    ignores SIGINT for it) cleans up as Ctrl-C does; the exit code says which signal it was."""
    runner, _, children = _start_long_run(tmp_path)
    runner.send_signal(sig)
    _, err = runner.communicate(timeout=60)
    assert runner.returncode == 128 + sig
    assert "interrupted" in err and "no summary.json" in err
    assert not list(tmp_path.glob("*.part"))  # no half-written file left looking like a result
    assert not (tmp_path / "summary.json").exists()
    _, alive = psutil.wait_procs(children, timeout=5)
    assert not alive


def test_crashed_proxy_stops_the_run_with_a_clear_message(tmp_path):
    runner, proc, children = _start_long_run(tmp_path)
    proxy = next(p for p in proc.children() if "-m swarmbed.netem" in cmdline(p))
    proxy.send_signal(signal.SIGKILL)
    _, err = runner.communicate(timeout=60)
    assert runner.returncode == 1
    assert "netem proxy exited unexpectedly" in err and "logs/netem.log" in err
    assert "netem was killed by signal SIGKILL" in err, err
    _, alive = psutil.wait_procs(children, timeout=5)
    assert not alive


BOOM = textwrap.dedent("""
    from swarmbed.extension import Allocator

    class Boom(Allocator):
        def decide(self, view):
            if view.tick == 5 and self.agent_id == 1:
                raise RuntimeError("boom at five")
            return None
""")


@pytest.mark.parametrize("threads", ["default", "single", "zenoh"])
def test_plugin_that_raises_stops_the_run_with_its_traceback(tmp_path, threads):
    plugin = tmp_path / "boom.py"
    plugin.write_text(BOOM)
    exp = experiment(f"allocator={{name: '{plugin}:Boom'}}", f"run.zenoh_threads={threads}")
    with pytest.raises(RunError) as info:
        run_experiment(exp, tmp_path / "run", progress=False)
    msg = str(info.value)
    assert "agent 1 stopped at tick 5" in msg and "boom at five" in msg and "Traceback" in msg
    assert "boom at five" in (tmp_path / "run" / "logs" / "agent_1.log").read_text()
    assert not (tmp_path / "run" / "summary.json").exists()


GARBAGE = textwrap.dedent("""
    from swarmbed.extension import Allocator

    class Garbage(Allocator):
        def decide(self, view):
            return "task-3" if view.tick == 2 and self.agent_id == 3 else None
""")


def test_a_decision_that_is_no_task_id_names_the_agent_the_tick_and_the_value(tmp_path):
    plugin = tmp_path / "garbage.py"
    plugin.write_text(GARBAGE)
    with pytest.raises(RunError) as info:
        run_experiment(experiment(f"allocator={{name: '{plugin}:Garbage'}}"), tmp_path / "run", progress=False)
    msg = str(info.value)
    assert (
        "agent 3 stopped at tick 2" in msg and "DecisionError: agent 3, tick 2: Garbage.decide returned 'task-3'" in msg
    )
    assert "restart" not in msg.splitlines()[0]  # a plugin that raised is not offered a restart


STUCK = textwrap.dedent("""
    import time
    from swarmbed.extension import Allocator

    class Stuck(Allocator):
        def decide(self, view):
            if view.tick == 3 and self.agent_id == 2:
                time.sleep(30)
            return None
""")


def test_a_stuck_tick_names_the_agents_that_did_not_answer(tmp_path):
    plugin = tmp_path / "stuck_agent.py"
    plugin.write_text(STUCK)
    exp = experiment(f"allocator={{name: '{plugin}:Stuck'}}", "run.tick_timeout=4")
    with pytest.raises(RunError) as info:
        run_experiment(exp, tmp_path / "run", progress=False)
    assert "the proxy still waits for agent(s) 2 at tick 3; see logs/agent_2.log" in str(info.value), info.value


LONG_TICK = textwrap.dedent("""
    import time
    from swarmbed.extension import Allocator

    class LongTick(Allocator):
        def decide(self, view):
            if view.tick == 3 and self.agent_id == 1:
                time.sleep(14)  # longer than Zenoh's 10 s lease
            return None
""")


@pytest.mark.parametrize("threads", ["default", "single"])
def test_a_tick_longer_than_zenohs_lease_keeps_the_agent(tmp_path, threads):
    """An agent answers ticks in the receiving worker's callback. On the single worker that is
    Zenoh's only thread, which sends no keep-alive meanwhile: the agent's lease is a minute. On the
    default layout a worker of its own transmits, so keep-alives flow under Zenoh's 10 s lease.
    Either way a 14 s tick does not cost the agent its session."""
    # its own file name: plugin files load as modules named by their stem (test_realtime has a sleepy.py)
    plugin = tmp_path / "long_tick.py"
    plugin.write_text(LONG_TICK)
    sets = [f"allocator={{name: '{plugin}:LongTick'}}", "agents.count=4", "run.duration=10", "run.stop_when_done=false"]
    result = run_experiment(experiment(*sets, f"run.zenoh_threads={threads}"), tmp_path / "run", progress=False)
    assert result.summary["ticks"] == 10


def test_run_goes_on_without_a_failed_agent_when_allowed(tmp_path):
    plugin = tmp_path / "boom.py"
    plugin.write_text(BOOM)
    exp = experiment(
        f"allocator={{name: '{plugin}:Boom'}}",
        "run.allow_agent_failures=true",
        "run.stop_when_done=false",
        "run.duration=40",
    )
    result = run_experiment(exp, tmp_path / "run", progress=False)
    assert result.summary["agents_lost"] == {"1": 5}
    assert result.summary["ticks"] == 40


def test_malformed_samples_are_dropped_counted_and_survived(tmp_path):
    def inject(keys: Keys, endpoint: str) -> None:
        with zenoh.open(zenoh_config("client", connect=[endpoint])) as s:
            for key in (keys.agent_in(0), keys.agent_out(0), keys.world, keys.netem_step):
                for junk in (b"\xc1", b"\x93\x01\x02", b"not msgpack at all"):
                    s.put(key, junk, congestion_control=zenoh.CongestionControl.BLOCK)
            huge = pack([0, 0, ["none"], [], {"x": 0}]) + bytes(MAX_AGENT_SAMPLE_BYTES)
            for key in (keys.agent_in(0), keys.agent_out(0)):
                s.put(key, huge, congestion_control=zenoh.CongestionControl.BLOCK)
            for junk in (b"\xc1", b"\x93\x01\x02", b"not msgpack at all"):  # reports are handed over as queries
                assert hand_over(s, keys.agent_report(1), junk, timeout=5)
            far = 10**6  # observations for ticks that never come: the answers the agent gives are never used
            for k, obs in enumerate(
                (
                    {"t": "noon", "me": [0, 0, 0, 0], "tasks": b""},
                    {"t": 0, "me": [0, 0], "tasks": b""},
                    {"t": 0, "me": [0, 0, 0, 0], "tasks": b"\x01\x02"},
                    {"t": 0, "me": [0, 0, 0, 0], "tasks": b"", "weather": "rain"},
                )
            ):
                s.put(
                    keys.agent_in(0),
                    encode_tick(far + k, obs, EMPTY_INBOX),
                    congestion_control=zenoh.CongestionControl.BLOCK,
                )
            time.sleep(0.3)

    exp = experiment(
        "allocator={name: noop, peers: 2}", "scenario.initial_tasks=0", "run.stop_when_done=false", "run.duration=400"
    )
    # an open hub: these samples test our own decoding, behind the hub's access control (which
    # refuses most of them before they reach us; see test_access.py)
    result = run_experiment(exp, tmp_path, progress=False, on_ready=inject, hub=HubOptions(auth=False))
    bad = result.summary["network"]["malformed"]
    assert bad["coordinator"] >= 6 and bad["netem"] >= 6 + 1 and bad["agents"] >= 3 + 4 + 1
    assert "oversized: 16,777,2" in (tmp_path / "logs" / "netem.log").read_text()
    assert result.summary["ticks"] == 400
    log = (tmp_path / "logs" / "agent_0.log").read_text()
    for field in ("field t", "field me", "field tasks", "unknown fields: weather"):
        assert "malformed observation of tick" in log and field in log, field


def test_a_second_agent_with_a_taken_id_is_refused(tmp_path):
    refused = {}

    def second(keys: Keys, endpoint: str) -> None:
        proc = subprocess.run(
            [sys.executable, "-m", "swarmbed", "agent", "--connect", endpoint, "--run-id", keys.run_id, "--id", "1"],
            capture_output=True,
            text=True,
            timeout=60,
        )
        refused["rc"], refused["err"] = proc.returncode, proc.stderr

    exp = experiment("run.duration=50")
    open_hub = HubOptions(auth=False)  # with auth: test_access.py
    result = run_experiment(exp, tmp_path, progress=False, on_ready=second, hub=open_hub)
    assert refused["rc"] == 2 and "agent 1 of run" in refused["err"] and "already running" in refused["err"]
    assert result.summary["ticks"] > 0 and not result.summary["agents_lost"]


def test_a_coordinator_that_fails_while_being_built_leaves_no_process_or_credentials(tmp_path, monkeypatch):
    """A run whose coordinator raises in its constructor (a scenario's world that cannot be built,
    say) stops the fork server it had started and removes the run's private credentials folder."""
    import tempfile

    from swarmbed.launch import runner

    class Broken(runner.ZenohTransport):
        def __init__(self, *args, **kwargs):
            raise RuntimeError("the world cannot be built")

    monkeypatch.setattr(runner, "ZenohTransport", Broken)
    made: list[Path] = []  # this run's private folders (a test beside this one may make its own)
    mkdtemp = tempfile.mkdtemp

    def recorded_mkdtemp(*args, **kwargs):
        made.append(Path(mkdtemp(*args, **kwargs)))
        return str(made[-1])

    monkeypatch.setattr(tempfile, "mkdtemp", recorded_mkdtemp)
    with pytest.raises(RuntimeError, match="cannot be built"):
        run_experiment(experiment(), tmp_path / "run", progress=False)
    private = [f for f in made if f.name.startswith("swarmbed-")]
    assert private and not any(f.exists() for f in private)
    # the standard library's tracker for spawned pools, which an earlier test may have started, stays
    ours = [p for p in psutil.Process().children(recursive=True) if "resource_tracker" not in cmdline(p)]
    _, alive = psutil.wait_procs(ours, timeout=5)
    assert not alive, [cmdline(p) for p in alive]
