"""Admission and access control: the hub (a real Zenoh router) refuses sessions without the run's
credentials, and holds every identity to its own keys; refused messages never reach our code."""

import csv
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
import zenoh

from swarmbed.launch.access import RunAccess, access_rules
from swarmbed.launch.hub import HubOptions
from swarmbed.launch.runner import run_experiment
from swarmbed.wire.codec import decode_traffic, encode_agent_out, pack
from swarmbed.wire.credentials import CredentialsError, Identity, check_admitted, read_credentials, write_credentials
from swarmbed.wire.keys import Keys
from swarmbed.wire.membership import hand_over
from swarmbed.wire.zenoh_session import zenoh_config
from tests.conftest import SwapAsked, experiment, reference_run, same_results

BLOCK = zenoh.CongestionControl.BLOCK


def stolen(keys: Keys, user: str) -> Path:
    """The credentials file the launcher wrote for one of its processes: another process of the
    same user can read it (the model trusts the user's own account, nobody else's)."""
    [path] = Path(tempfile.gettempdir()).glob(f"swarmbed-{keys.run_id}-*/{user}.json")
    return path


def agent_cmd(keys: Keys, endpoint: str, agent: int, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "swarmbed",
        "agent",
        "--connect",
        endpoint,
        "--run-id",
        keys.run_id,
        "--id",
        str(agent),
        *extra,
    ]


def test_credentials_files_are_private_and_checked(tmp_path):
    path = write_credentials(tmp_path / "c.json", Identity.new("someone", "operator"))
    assert (path.stat().st_mode & 0o777) == 0o600 and read_credentials(path).user == "someone"
    path.chmod(0o644)
    with pytest.raises(CredentialsError, match="readable by others"):
        read_credentials(path)
    (tmp_path / "junk.json").write_text("[1, 2]")
    (tmp_path / "junk.json").chmod(0o600)
    with pytest.raises(CredentialsError, match="junk.json: not a JSON object"):
        read_credentials(tmp_path / "junk.json")
    with pytest.raises(CredentialsError, match="user name 'a:b'"):
        Identity.new("a:b", "host")


def _crafted(folder: Path, name: str, **fields) -> Path:
    path = folder / f"{name}.json"
    path.write_text(json.dumps(fields))
    path.chmod(0o600)
    return path


def test_a_credentials_file_carries_one_identity_and_only_its_own_host(tmp_path):
    """Every field is checked on read as on write: a password with a line break would add a second
    ``user:password`` line to the hub's dictionary; a host of ``*`` would be given every host's keys."""
    good = {"user": "op", "password": "p" * 24, "role": "operator"}
    cases = {
        "newline": ({**good, "password": "p" * 24 + "\nagent-4:stolenpass"}, "password"),
        "colon": ({**good, "password": "a:" + "p" * 24}, "password"),
        "star": ({**good, "role": "host", "host": "*"}, "host name '*'"),
        "host-of-operator": ({**good, "host": "labpc2"}, "only a host identity"),
        "number": ({**good, "user": 7}, "user: must be a string"),
        "list": ({**good, "password": ["x"]}, "password: must be a string"),
        "role": ({**good, "role": "coordinator"}, "role 'coordinator'"),
        "extra": ({**good, "admin": True}, "unknown field 'admin'"),
        "long": ({**good, "user": "u" * 65}, "user name"),
    }
    for name, (fields, why) in cases.items():
        path = _crafted(tmp_path, name, **fields)
        with pytest.raises(CredentialsError, match=re.escape(why)) as caught:
            read_credentials(path)
        assert str(path) in str(caught.value) and "\n" not in str(caught.value)
    # a device or a FIFO is refused before a byte is read (it would never end)
    with pytest.raises(CredentialsError, match="not a regular file"):
        read_credentials("/dev/zero")
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(CredentialsError, match="not a regular file"):
        read_credentials(tmp_path / "fifo")
    big = _crafted(tmp_path, "big", **good, pad="x" * 10_000)
    with pytest.raises(CredentialsError, match="more than a credentials file holds"):
        read_credentials(big)
    # two admitted files may not be one user, nor bound to one host name
    one = Identity.new("labpc2", "host")
    other = Identity.new("someone", "host", "labpc2")
    with pytest.raises(CredentialsError, match="both bound to host 'labpc2'"):
        check_admitted([one, other])
    with pytest.raises(CredentialsError, match="both user 'op'"):
        check_admitted([Identity.new("op", "operator"), Identity.new("op", "host")])
    with pytest.raises(CredentialsError, match="cannot be admitted"):
        check_admitted([Identity.new("agent-x", "agent")])
    with pytest.raises(ValueError, match="both bound"):  # the launcher refuses them too
        RunAccess(Keys("abc123"), range(2), [one, other])
    # what swarmbed run --admit says, before any process starts
    op = write_credentials(tmp_path / "op.json", Identity.new("op", "operator"))
    cli = subprocess.run(
        [sys.executable, "-m", "swarmbed", "run", "experiments/quickstart.yaml", "--out", str(tmp_path / "never")]
        + ["--admit", str(op), "--admit", str(_crafted(tmp_path, "bad", **cases["newline"][0]))],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=Path(__file__).resolve().parent.parent,
    )
    assert cli.returncode == 2 and len(cli.stderr.strip().splitlines()) == 1 and "bad.json" in cli.stderr
    assert not (tmp_path / "never").exists()


def test_the_launcher_keeps_credentials_off_the_command_line_and_removes_them():
    access = RunAccess(Keys("abc123"), range(3))
    assert (access.folder.stat().st_mode & 0o777) == 0o700
    assert all((Path(access.credentials(u)).stat().st_mode & 0o777) == 0o600 for u in ("netem", "agent-2"))
    assert len(access.dictionary.read_text().splitlines()) == 4
    with pytest.raises(ValueError, match="a name a run gives its own processes"):  # refused as it is made
        RunAccess(Keys("abc123"), range(3), [Identity.new("agent-1", "operator")])
    access.close()
    assert not access.folder.exists()
    rules = access_rules(Keys("abc123"), [0], operators=["me"], hosts={})
    assert rules["default_permission"] == "deny" and {p["subjects"][0] for p in rules["policies"]} == {
        "netem",
        "agent-0",
        "operators",
    }


def test_only_processes_with_the_runs_credentials_join(tmp_path):
    tried = {}

    def intruders(keys: Keys, endpoint: str) -> None:
        with pytest.raises(zenoh.ZError):
            zenoh.open(zenoh_config("client", [endpoint]))
        wrong = write_credentials(tmp_path / "wrong.json", Identity("agent-1", "not-the-password", "agent"))
        with pytest.raises(zenoh.ZError):
            zenoh.open(zenoh_config("client", [endpoint], credentials=str(wrong)))
        # no credentials, wrong ones, and one of the run's own identities used by a second process
        # (our code refuses it): five intruders at once, each judged on its own
        own = ("--credentials", str(stolen(keys, "agent-1")))
        commands = {  # refused by the hub: a short --connect-timeout, not the 20 s a run's agent waits
            "none": agent_cmd(keys, endpoint, 1, "--connect-timeout", "2"),
            "wrong": agent_cmd(keys, endpoint, 1, "--credentials", str(wrong), "--connect-timeout", "2"),
            "twin": agent_cmd(keys, endpoint, 1, *own),
            "other": agent_cmd(keys, endpoint, 2, *own),
            "outside": agent_cmd(keys, endpoint, 99, *own),
        }
        procs = {
            name: subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            for name, cmd in commands.items()
        }
        for name, proc in procs.items():
            _, err = proc.communicate(timeout=60)
            tried[name] = (proc.returncode, err)

    result = run_experiment(
        experiment("run.duration=300", "run.stop_when_done=false"), tmp_path / "run", progress=False, on_ready=intruders
    )
    none_rc, none_err = tried["none"]
    assert none_rc == 2 and "cannot open a session" in none_err and "no credentials" in none_err
    assert tried["wrong"][0] == 2 and "wrong.json" in tried["wrong"][1]
    assert tried["twin"][0] == 2 and "already running" in tried["twin"][1]
    assert tried["other"][0] == 2 and "already running" in tried["other"][1]
    assert tried["outside"][0] == 2 and "outside 0..4" in tried["outside"][1]
    assert result.summary["ticks"] == 300 and not result.summary["agents_lost"]
    assert not list(Path(tempfile.gettempdir()).glob(f"swarmbed-{result.timings['run_id']}-*"))


def test_an_agent_may_publish_only_on_its_own_keys(tmp_path):
    """Agent 3's identity, in a second process, tries everything that is not agent 3's: the router
    refuses it all, so our decoders never see it and the results are those of a clean run."""
    seen = {}

    def impostor(keys: Keys, endpoint: str) -> None:
        with zenoh.open(zenoh_config("client", [endpoint], credentials=str(stolen(keys, "agent-3")))) as s:
            heard = []  # agent 4's inputs, which the hub would forward had it accepted this subscription
            sub = s.declare_subscriber(keys.agent_in(4), lambda sample: heard.append(1))
            time.sleep(0.5)
            sub.undeclare()
            seen["heard"] = len(heard)
            for key in (
                keys.agent_out(4),
                keys.agent_in(4),
                keys.world,
                keys.netem_step,
                keys.netem_stop,
                keys.status,
                keys.agent_report(4),
                keys.root + "/anything",
            ):
                for junk in (b"\xc1", b"\x93\x01\x02", os.urandom(64)):
                    s.put(key, junk, congestion_control=BLOCK)
            seen["report taken"] = hand_over(s, keys.agent_report(4), b"\xc1", timeout=2)
            seen["stop taken"] = hand_over(s, keys.netem_report, b"\xc1", timeout=2)

    sets = [
        "allocator={name: noop, peers: 3}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        "run.duration=400",
    ]
    attacked = run_experiment(experiment(*sets), tmp_path / "attacked", progress=False, on_ready=impostor)
    reference_run(experiment(*sets), tmp_path / "clean")
    assert seen == {"report taken": False, "stop taken": False, "heard": 0}
    assert attacked.summary["network"]["malformed"] == {"coordinator": 0, "netem": 0, "agents": 0}
    same_results(tmp_path / "clean", tmp_path / "attacked")


def test_each_proxy_of_a_split_radio_reads_only_what_goes_to_it_and_holds_only_its_token(tmp_path):
    """A radio split by region over two proxies, each with its own identity: with proxy 1's
    credentials a second process hears the outputs sent to proxy 1 and none sent to proxy 0, and
    cannot hold a proxy token that is not proxy 1's; the run's files are those of a clean run."""
    seen: dict = {}
    threads: list[threading.Thread] = []

    def impostor(keys: Keys, endpoint: str) -> None:
        who = str(stolen(keys, "netem-1"))
        with (
            zenoh.open(zenoh_config("client", [endpoint], credentials=who)) as s,
            zenoh.open(zenoh_config("client", [endpoint], credentials=who)) as looker,
        ):  # a session of its own: it sees only the tokens the hub took
            heard = {"0": [], "1": []}
            subs = [
                s.declare_subscriber(f"{keys.agent_out_all}/{shard}", lambda _s, shard=shard: heard[shard].append(1))
                for shard in heard
            ]
            tokens = [s.liveliness().declare_token(key) for key in (keys.alive_netem, keys.alive_netem_shard(5))]
            time.sleep(1.5)
            seen["tokens"] = sorted(
                str(r.ok.key_expr).rsplit("/", 1)[1]
                for r in looker.liveliness().get(f"{keys.root}/alive/netem/**", timeout=2)
                if r.ok is not None
            )
            for entity in subs + tokens:
                entity.undeclare()
            seen["heard"] = {shard: len(n) > 0 for shard, n in heard.items()}

    def in_the_background(keys: Keys, endpoint: str) -> None:
        threads.append(threading.Thread(target=impostor, args=(keys, endpoint)))
        threads[-1].start()

    sets = ["agents.count=8", "allocator={name: noop, peers: 3}", "scenario.initial_tasks=0"]
    sets += ["run.stop_when_done=false", "run.duration=3000", "network.draws=per_copy", "radio_split.strip_width=30"]
    attacked = run_experiment(
        experiment(*sets, "radio_split.shards=2"), tmp_path / "attacked", progress=False, on_ready=in_the_background
    )
    threads[0].join(timeout=30)
    reference_run(experiment(*sets), tmp_path / "clean")
    assert seen == {"heard": {"0": False, "1": True}, "tokens": ["0", "1"]}
    assert attacked.summary["network"]["malformed"] == {"coordinator": 0, "netem": 0, "agents": 0}
    same_results(tmp_path / "clean", tmp_path / "attacked")


def test_an_operator_watches_and_asks_but_cannot_publish(tmp_path, operator):
    seen: dict = {}

    def look(keys: Keys, endpoint: str) -> None:
        s = zenoh.open(zenoh_config("client", [endpoint], credentials=str(operator.path)))
        seen["session"] = s
        seen["outs"], seen["ins"], seen["traffic"], seen["status"] = [], [], [], []
        seen["subs"] = [
            s.declare_subscriber(keys.agent_out_all, lambda x: seen["outs"].append(1)),  # refused: BLOCK keys
            s.declare_subscriber(keys.agent_in(0), lambda x: seen["ins"].append(1)),
            s.declare_subscriber(keys.view_traffic, lambda x: seen["traffic"].append(x.payload.to_bytes())),
            s.declare_subscriber(keys.status, lambda x: seen["status"].append(1)),
        ]
        for _ in range(5):  # refused at the hub (its own subscriber above is local: it would hear these)
            s.put(keys.world, b"\xc1", congestion_control=BLOCK)

    try:
        result = run_experiment(
            experiment("run.duration=600", "run.stop_when_done=false", "allocator.name=cbba"),
            tmp_path / "run",
            progress=False,
            on_ready=look,
            hub=HubOptions(admit=[operator.identity]),
        )
    finally:
        for sub in seen.get("subs", []):
            sub.undeclare()
        if "session" in seen:
            seen["session"].close()
    assert seen["outs"] == [] and seen["ins"] == []  # never a key the run blocks on
    assert seen["status"] and seen["traffic"]  # it reads the run's progress and every agent's traffic
    last = decode_traffic(seen["traffic"][-1])
    assert set(last) == set(range(5)) and all(m > 0 and b > 0 for m, b in last.values())
    assert sum(m for m, _ in last.values()) <= result.summary["network"]["messages_sent"]
    assert result.summary["network"]["malformed"] == {"coordinator": 0, "netem": 0, "agents": 0}


#: an operator's client that subscribes and then never reads (stopped with SIGSTOP by the test)
STOPPED_CLIENT = """
import sys, time, zenoh
from swarmbed.wire.zenoh_session import zenoh_config
s = zenoh.open(zenoh_config("client", [sys.argv[1]], credentials=sys.argv[2]))
subs = [s.declare_subscriber(k, zenoh.handlers.FifoChannel(4)) for k in sys.argv[3:]]
print("ready", flush=True)
time.sleep(600)
"""


def test_an_operator_that_stops_reading_holds_nothing_up(tmp_path, operator):
    """A suspended ``swarmbed watch`` (or any admitted client that stops reading) subscribed to all
    it may: the run goes on at its pace and computes what it computes alone. Before operators were
    kept to DROP keys, this run lost agent 2 at tick ~480 ("let go of its token") within 26 s."""
    clients: list[subprocess.Popen] = []

    def look(keys: Keys, endpoint: str) -> None:
        asked = [f"{keys.root}/**", keys.status, keys.view, keys.agent_out_all, keys.agent_in(2)]
        client = subprocess.Popen(
            [sys.executable, "-c", STOPPED_CLIENT, endpoint, str(operator.path), *asked],
            stdout=subprocess.PIPE,
            text=True,
        )
        clients.append(client)
        assert client.stdout.readline().startswith("ready")
        client.send_signal(signal.SIGSTOP)

    sets = ("agents.count=10", "allocator.name=cbba", "run.duration=1000", "run.stop_when_done=false")
    try:
        run_experiment(
            experiment(*sets),
            tmp_path / "held",
            progress=False,
            on_ready=look,
            hub=HubOptions(admit=[operator.identity]),
        )
    finally:
        for client in clients:
            client.kill()
            client.wait(timeout=10)
    assert clients
    reference_run(experiment(*sets), tmp_path / "alone")
    same_results(tmp_path / "held", tmp_path / "alone")


def test_junk_at_every_key_is_refused_or_counted_and_changes_nothing(tmp_path, operator):
    """10,000 junk samples during a run (random bytes, msgpack of the wrong shape, outputs naming
    another agent or a tick that never comes, a 10 MB payload) at every key the run listens on,
    from two authenticated processes: agent 3's identity and an operator. What the router lets
    through (agent 3's own output and report keys) our code drops and counts, one by one; the
    results are those of a clean run."""
    rng = np.random.default_rng(5)
    sent = {"out": 0, "report": 0}
    done = threading.Event()

    def junk_kinds():
        yield os.urandom(int(rng.integers(1, 200)))
        yield pack({"tick": 1})
        yield pack([1, 2, 3])
        yield encode_agent_out(0, 4, ["none"], [])  # another agent's output
        yield encode_agent_out(10**6, 3, ["none"], [])  # a tick that never comes

    def attack(keys: Keys, endpoint: str) -> None:
        every = [
            *(keys.agent_in(i) for i in range(5)),
            *(keys.agent_out(i) for i in range(5)),
            keys.world,
            keys.netem_step,
            keys.netem_stop,
            keys.status,
            keys.swap,
            keys.root + "/anything",
        ]
        for who in (str(stolen(keys, "agent-3")), str(operator.path)):
            with zenoh.open(zenoh_config("client", [endpoint], credentials=who)) as s:
                for n in range(490):
                    for key in every:
                        for junk in junk_kinds() if n % 49 == 0 else [os.urandom(16)]:
                            s.put(key, junk, congestion_control=BLOCK)
                            if key == keys.agent_out(3) and who != str(operator.path):
                                sent["out"] += 1
                huge = os.urandom(10 * 2**20)
                s.put(keys.agent_out(3), huge, congestion_control=BLOCK)
                s.put(keys.world, huge, congestion_control=BLOCK)
                if who != str(operator.path):
                    sent["out"] += 1
                for junk in (b"\xc1", pack({"kind": "fatal", "agent": 4}), pack({"kind": "final"})):
                    if who == str(operator.path):  # refused by the router: nothing would answer
                        s.get(keys.agent_report(3), payload=junk, timeout=0.5)
                    elif hand_over(s, keys.agent_report(3), junk, timeout=5):
                        sent["report"] += 1
                s.get(keys.agent_snapshot(4), payload=b"\xc1", timeout=0.5)
        done.set()

    def in_the_background(keys: Keys, endpoint: str) -> None:
        threading.Thread(target=attack, args=(keys, endpoint), daemon=True).start()

    sets = [
        "agents.count=5",
        "allocator={name: noop, peers: 3}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        "run.duration=3000",
    ]
    attacked = run_experiment(
        experiment(*sets),
        tmp_path / "attacked",
        progress=False,
        on_ready=in_the_background,
        hub=HubOptions(admit=[operator.identity]),
    )
    assert done.is_set(), "the run ended before all junk was sent"
    reference_run(experiment(*sets), tmp_path / "clean")
    assert sent == {"out": 531, "report": 3}  # of 16,972 junk samples in all
    assert attacked.summary["network"]["malformed"] == {"coordinator": 3, "netem": 531, "agents": 0}
    summaries = [json.loads((tmp_path / run / "summary.json").read_text()) for run in ("clean", "attacked")]
    for s in summaries:
        s["network"].pop("malformed")
    assert summaries[0] == summaries[1]
    for name in ("timeseries.csv", "agents.csv", "network_ledger.csv"):
        assert (tmp_path / "clean" / name).read_bytes() == (tmp_path / "attacked" / name).read_bytes(), name


def _agent_process(keys: Keys, agent: int) -> psutil.Process:
    """The local process of ``agent`` in run ``keys`` (the fork server titles each with its arguments)."""
    for proc in psutil.process_iter(["cmdline"]):
        cmd = proc.info["cmdline"] or []
        if (
            keys.run_id in " ".join(cmd)
            and "swarmbed.agent_runtime" in " ".join(cmd)
            and "--id" in cmd
            and cmd[cmd.index("--id") + 1] == str(agent)
        ):
            return proc
    raise AssertionError(f"no process of agent {agent}")


def test_a_host_identity_may_carry_only_its_own_agents_and_act_only_as_its_own_host(tmp_path, operator):
    """A host admitted as h1 that may carry agent 2 (and nothing placed on it): with its
    credentials, processes try, while the run goes, everything an admitted host must not do. The
    hub refuses all of it; what it may do (read agent 2's inputs, announce and serve h1) goes through."""
    host = Identity.new("host-h1", "host", host="h1")
    host_file = write_credentials(tmp_path / "h1.json", host)
    seen: dict = {}
    threads: list[threading.Thread] = []

    def attack(keys: Keys, endpoint: str) -> None:
        def session(path: Path) -> zenoh.Session:
            return zenoh.open(zenoh_config("client", [endpoint], credentials=str(path)))

        with session(host_file) as listener, session(host_file) as s, session(operator.path) as op:
            heard: dict[int, list] = {0: [], 2: []}  # a session of its own: never its own puts
            subs = [
                listener.declare_subscriber(keys.agent_in(i), lambda sample, i=i: heard[i].append(1)) for i in heard
            ]
            for key in (keys.agent_out(0), keys.agent_in(2), keys.agent_in(0), keys.world, keys.netem_step):
                for junk in (b"\xc1", pack([0, 1, {}, b""]), os.urandom(32)):
                    s.put(key, junk, congestion_control=BLOCK)
            seen["report of agent 0 taken"] = hand_over(s, keys.agent_report(0), b"\xc1", timeout=2)
            tokens = [
                s.liveliness().declare_token(k)
                for k in ("swarmbed/hosts/h1", "swarmbed/hosts/fake", keys.alive_agent(0, 7), keys.alive_agent(2, 7))
            ]
            serve = [
                s.declare_queryable(f"swarmbed/hosts/{h}/info", lambda q, h=h: q.reply(f"swarmbed/hosts/{h}/info", h))
                for h in ("h1", "fake")
            ]
            time.sleep(1.5)
            seen["tokens"] = sorted(
                str(r.ok.key_expr) for r in op.liveliness().get("swarmbed/hosts/**", timeout=2) if r.ok is not None
            )
            seen["agent tokens"] = sorted(
                str(r.ok.key_expr).split("/alive/agent/")[1]
                for r in op.liveliness().get(keys.alive_agents, timeout=2)
                if r.ok is not None and str(r.ok.key_expr).endswith("/7")
            )
            seen["answers"] = sorted(
                r.ok.payload.to_string() for r in op.get("swarmbed/hosts/*/info", timeout=2) if r.ok is not None
            )
            for entity in subs + tokens + serve:
                entity.undeclare()
            seen["heard"] = {i: len(v) > 0 for i, v in heard.items()}

    def in_the_background(keys: Keys, endpoint: str) -> None:
        threads.append(threading.Thread(target=attack, args=(keys, endpoint)))
        threads[-1].start()

    sets = [
        "allocator={name: noop, peers: 3}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        "run.duration=6000",
    ]
    attacked = run_experiment(
        experiment(*sets, "may_carry={h1: 2}"),
        tmp_path / "attacked",
        progress=False,
        on_ready=in_the_background,
        hub=HubOptions(admit=[host, operator.identity]),
    )
    threads[0].join(timeout=30)
    reference_run(experiment(*sets), tmp_path / "clean")
    assert seen == {
        "report of agent 0 taken": False,
        "heard": {0: False, 2: True},
        "tokens": ["swarmbed/hosts/h1"],
        "agent tokens": ["2/7"],
        "answers": ["h1"],
    }
    assert attacked.summary["network"]["malformed"] == {"coordinator": 0, "netem": 0, "agents": 0}
    same_results(tmp_path / "clean", tmp_path / "attacked")


def test_a_swap_to_a_host_that_may_not_carry_the_agent_is_refused_before_anything_moves(tmp_path, operator):
    """An operator asks to move agent 1 to h9, an admitted host that may carry only agent 4: the
    coordinator refuses it (the hub would refuse that host agent 1's keys) and nothing moves."""
    host = Identity.new("host-h9", "host", host="h9")
    swap = SwapAsked(operator, 1, "h9")

    sets = ["allocator.name=cbba", "run.duration=1000", "run.stop_when_done=false", "may_carry={h9: 4}"]
    run_experiment(
        experiment(*sets),
        tmp_path / "run",
        progress=False,
        on_ready=swap.on_ready,
        hub=HubOptions(admit=[host, operator.identity]),
    )
    rc, out, err = swap.wait()
    assert rc == 2 and "host 'h9' may not carry agent 1" in err and "queued" not in out, (rc, out, err)


def test_state_nobody_asked_for_is_refused_even_from_the_agent_itself(tmp_path):
    """Agent 3's own identity hands the coordinator a snapshot and a checkpoint it never asked for,
    then its process is killed: the snapshot is refused, and the restart starts agent 3 fresh
    instead of restoring the planted checkpoint."""
    from swarmbed.wire.codec import encode_handover, pack

    seen = {}

    def plant(keys: Keys, endpoint: str) -> None:
        with zenoh.open(zenoh_config("client", [endpoint], credentials=str(stolen(keys, "agent-3")))) as s:
            for ticket in (b"", b"\x00" * 16, os.urandom(16)):
                seen.setdefault("snapshots taken", []).append(
                    hand_over(s, keys.agent_snapshot(3), encode_handover(ticket, b"\xc1"), timeout=2)
                )
            for ticket in (b"", b"\x00" * 16, None):
                hand_over(
                    s,
                    keys.agent_report(3),
                    pack(
                        {
                            "kind": "checkpoint",
                            "agent": 3,
                            "incarnation": 0,
                            "ticks": 1,
                            "state": b"\xc1",
                            **({"ticket": ticket} if ticket is not None else {}),
                        }
                    ),
                )
        time.sleep(0.5)
        _agent_process(keys, 3).kill()

    sets = [
        "agents.count=5",
        "allocator={name: noop, peers: 3}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        "run.duration=3000",
        "run.on_agent_loss=restart",
    ]
    result = run_experiment(experiment(*sets), tmp_path / "run", progress=False, on_ready=plant)
    assert seen["snapshots taken"] == [False, False, False]
    with open(tmp_path / "run" / "restarts.csv") as f:
        first = next(csv.DictReader(f))
    assert first["agent"] == "3" and first["outcome"] == "ok" and first["checkpoint_tick"] == "", first
    assert result.summary["agents_lost"] == {}


def test_on_an_open_hub_malformed_keys_and_control_samples_are_counted_not_fatal(tmp_path):
    """With --no-auth nothing stops a sample at the router: well-formed outputs on agent keys that
    name no agent (not a number, negative, out of range), junk on the proxy's stop and control
    keys, and liveliness tokens with such keys that come and go. Each is counted as malformed by
    whoever parses it; the run completes with the results of a clean run."""
    done = threading.Event()

    def attack(keys: Keys, endpoint: str) -> None:
        with zenoh.open(zenoh_config("client", [endpoint])) as s:
            for chunk in ("abc", "-1", "+1", "1_0", "99999", "007", "٣"):
                s.put(f"{keys.root}/agent/{chunk}/out", encode_agent_out(0, 1, ["stop"], []), congestion_control=BLOCK)
            for key in (keys.netem_stop, keys.netem_control):
                for junk in (b"\xc1", pack({"tick": "x"}), pack([]), os.urandom(64)):
                    s.put(key, junk, congestion_control=BLOCK)
            tokens = [
                s.liveliness().declare_token(f"{keys.root}/alive/agent/{chunk}")
                for chunk in ("abc/0", "1/x", "99999/0", "3/0/extra", "-2/0")
            ]
            time.sleep(0.5)
            for token in tokens:
                token.undeclare()
            time.sleep(0.5)
        done.set()

    def in_the_background(keys: Keys, endpoint: str) -> None:
        threading.Thread(target=attack, args=(keys, endpoint), daemon=True).start()

    sets = [
        "agents.count=5",
        "allocator={name: noop, peers: 3}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        "run.duration=3000",
    ]
    attacked = run_experiment(
        experiment(*sets), tmp_path / "attacked", progress=False, on_ready=in_the_background, hub=HubOptions(auth=False)
    )
    assert done.is_set(), "the run ended before all junk was sent"
    reference_run(experiment(*sets), tmp_path / "clean")
    malformed = attacked.summary["network"]["malformed"]
    assert malformed["netem"] >= 7 + 8 and malformed["coordinator"] >= 5, malformed
    for name in ("timeseries.csv", "agents.csv", "network_ledger.csv"):
        assert (tmp_path / "clean" / name).read_bytes() == (tmp_path / "attacked" / name).read_bytes(), name


def _cli(*args, cwd: Path | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "swarmbed", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd or Path(__file__).resolve().parent.parent,
    )


def _one_line(done: subprocess.CompletedProcess, *words: str) -> None:
    err = done.stderr.strip()
    assert done.returncode == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert all(word in err for word in words), err


def test_credentials_never_replace_a_file_without_force_and_name_what_is_wrong(tmp_path):
    experiment = tmp_path / "exp.yaml"
    experiment.write_text("name: mine\n")
    experiment.chmod(0o644)
    _one_line(_cli("credentials", experiment, "--user", "op"), "exists", "--force")
    assert experiment.read_text() == "name: mine\n" and (experiment.stat().st_mode & 0o777) == 0o644
    host = tmp_path / "host.json"
    assert _cli("credentials", host, "--user", "lab1", "--role", "host").returncode == 0
    before = host.read_text()
    _one_line(_cli("credentials", host, "--user", "op"), "exists")
    assert host.read_text() == before
    assert _cli("credentials", host, "--user", "op", "--force").returncode == 0
    assert read_credentials(host).role == "operator"
    _one_line(_cli("credentials", tmp_path / "missing" / "c.json", "--user", "op"), "missing", "No such file")
    # a run's own process names and names that are no names are refused, at once and in a file
    for user in ("agent-0", "netem", "lab1-agents", "..", ".", "-rf"):
        _one_line(_cli("credentials", tmp_path / f"u{len(user)}{user.strip('.-')}.json", f"--user={user}"), "user name")
    crafted = _crafted(tmp_path, "agent0", user="agent-0", password="p" * 24, role="operator")
    _one_line(_cli("run", "experiments/quickstart.yaml", "--admit", crafted, "--check"), "agent0.json", "agent-<i>")


def test_a_credentials_file_of_nested_brackets_is_one_line(tmp_path):
    nested = tmp_path / "nested.json"
    nested.write_text("[" * 4000)
    nested.chmod(0o600)
    with pytest.raises(CredentialsError, match="not JSON"):
        read_credentials(nested)
    _one_line(_cli("run", "experiments/quickstart.yaml", "--admit", nested, "--check"), "nested.json")
    _one_line(_cli("host", "--name", "h", "--connect", "tcp/127.0.0.1:9", "--credentials", nested), "nested.json")


def test_a_host_daemon_refuses_a_long_name_and_a_busy_port_in_one_line(tmp_path):
    import socket

    _one_line(_cli("host", "--name", "h" * 58, "--connect", "tcp/127.0.0.1:9", "--insecure"), "host name", "57")
    _one_line(_cli("host", "--name=-rf", "--connect", "tcp/127.0.0.1:9", "--insecure"), "host name")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        done = _cli(
            "host", "--name", "h1", "--insecure", "--connect", "tcp/127.0.0.1:9", "--listen", f"tcp/127.0.0.1:{port}"
        )
    _one_line(done, f"127.0.0.1:{port}", "--listen")
