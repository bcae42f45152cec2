"""``swarmbed watch`` as a person uses it: in a terminal (a pseudo-terminal here), against a real run."""

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
import threading
import time

from swarmbed.launch.hub import HubOptions
from swarmbed.launch.runner import run_experiment
from swarmbed.wire.zenoh_session import free_loopback_endpoint
from tests.conftest import experiment

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07|\r")


def _shown(screen: bytes) -> str:
    """What a terminal shows of ``screen``'s bytes, escape sequences left out."""
    return ANSI.sub("", screen.decode("utf-8", "replace"))


def _run_in_background(tmp_path, endpoint, results, operator, watching: threading.Event | None = None):
    """The quick start's world for 2,500 ticks, with an operator's hub. ``watching``: the first tick
    waits (at most a minute) until it is set, so that a watcher sees the run from its start: the
    run lasts about a wall second, and the proxy counts each agent's traffic only once watched."""
    exp = experiment("agents.count=6", "run.stop_when_done=false", "run.duration=2500", "run.seed=9")

    def hold(_keys, _endpoint) -> None:
        if watching is not None:
            watching.wait(timeout=60)

    hub = HubOptions(listen=[endpoint], admit=[operator.identity])
    results["run"] = run_experiment(exp, tmp_path / "run", progress=False, on_ready=hold, hub=hub)


def test_watch_shows_a_running_experiment_in_a_terminal_and_leaves_when_it_ends(tmp_path, operator):
    endpoint = free_loopback_endpoint()
    results: dict = {}
    watching = threading.Event()
    runner = threading.Thread(target=_run_in_background, args=(tmp_path, endpoint, results, operator, watching))
    runner.start()
    main_fd, child_fd = pty.openpty()
    fcntl.ioctl(child_fd, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 140, 0, 0))
    watcher = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "swarmbed",
            "watch",
            "--connect",
            endpoint,
            "--wait",
            "30",
            *operator.args,
            "--map",
            str(tmp_path / "map.html"),
        ],
        stdin=child_fd,
        stdout=child_fd,
        stderr=child_fd,
        close_fds=True,
        env={**os.environ, "TERM": "xterm-256color", "COLUMNS": "140", "LINES": "40"},
    )
    os.close(child_fd)
    screen = b""
    release: threading.Timer | None = None
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([main_fd], [], [], 0.5)
            if ready:
                try:
                    chunk = os.read(main_fd, 65536)
                except OSError:  # the watcher closed its end
                    break
                if not chunk:
                    break
                screen += chunk
                if release is None and "waiting for its first progress" in _shown(screen):
                    # its subscriptions are declared: a second for them to reach the proxy, then tick
                    release = threading.Timer(1.0, watching.set)
                    release.start()
            elif watcher.poll() is not None:
                break
        code = watcher.wait(timeout=30)
    finally:
        if watcher.poll() is None:
            watcher.kill()
            watcher.wait()
        os.close(main_fd)
        watching.set()
        runner.join(timeout=120)
    text = _shown(screen)
    assert code == 0, text[-2000:]
    summary = results["run"].summary
    assert "quickstart" in text and "ticks/s" in text and "tasks_completed" in text
    assert "coordinator up" in text and "netem up" in text and "agents 6 up of 6 in the world" in text
    seen = [int(t.replace(",", "")) for t in re.findall(r"tick ([\d,]+) of 2,500", text)]
    assert len(seen) >= 3 and seen == sorted(seen)  # it followed the run as it went
    # the last view shows the final tick and the run's totals
    assert seen[-1] == summary["ticks"] == 2500
    assert f"{summary['network']['messages_sent']:,} messages" in text
    assert text.rstrip().endswith("is over (its coordinator left)")
    for agent in range(6):  # one table row per agent
        assert re.search(rf"│\s+{agent} │\s+(up|-) │", text), agent
    # every agent's traffic, from the proxy's view/traffic (an operator may not read agent outputs)
    assert summary["network"]["messages_sent"] > 0
    assert re.search(r"│\s+\d+ │\s+(?:up|-) │\s+[\d,.]+ │\s+[\d,]+ │\s+[1-9][\d,]* │", text), text[-3000:]
    page = (tmp_path / "map.html").read_text()  # the live map's last state: every agent and every task
    assert "http-equiv='refresh'" in page and "tick 2,500 of 2,500" in page
    assert page.count("<circle") == 6 and page.count("<title>agent") == 6
    assert page.count("<rect") == summary["tasks_total"] - summary["tasks_completed"]


def test_watch_serves_a_running_run_to_foxglove(tmp_path, operator):
    """``swarmbed watch --foxglove 0``, an operator's watcher started while the run goes, serves the
    run to a WebSocket client speaking Foxglove's protocol: the advertised channels, and poses of
    every agent decoded with the advertised schema, at positions inside the quick start's floor."""
    import base64
    import json

    import websocket
    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory

    endpoint = free_loopback_endpoint()
    results: dict = {}
    subscribed = threading.Event()
    runner = threading.Thread(target=_run_in_background, args=(tmp_path, endpoint, results, operator, subscribed))
    runner.start()
    watcher = subprocess.Popen(
        [sys.executable, "-m", "swarmbed", "watch", "--connect", endpoint, "--wait", "30", *operator.args]
        + ["--foxglove", "0"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = watcher.stderr.readline()
        url = re.search(r"ws://127\.0\.0\.1:\d+/\S+", line).group(0)  # with the run's token
        ws = websocket.create_connection(url, subprotocols=["foxglove.sdk.v1"], timeout=30)
        channels: dict[str, dict] = {}
        while not {"/agents", "/agents/poses", "/markers"} <= set(channels):
            message = json.loads(ws.recv())
            if message["op"] == "advertise":
                channels.update({c["topic"]: c for c in message["channels"]})
        poses = channels["/agents/poses"]
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 3, "channelId": poses["id"]}]}))
        subscribed.set()
        frame = ws.recv()
        while not isinstance(frame, bytes):
            frame = ws.recv()
        schema = Schema(id=1, name=poses["schemaName"], encoding="protobuf", data=base64.b64decode(poses["schema"]))
        decoded = DecoderFactory().decoder_for("protobuf", schema)(frame[13:])
        assert len(decoded.poses) == 6
        assert all(0 <= p.position.x <= 200 and 0 <= p.position.y <= 150 for p in decoded.poses)
        ws.close()
        assert watcher.wait(timeout=180) == 0
    finally:
        if watcher.poll() is None:
            watcher.kill()
            watcher.wait()
        subscribed.set()
        runner.join(timeout=180)
    assert results["run"].summary["ticks"] == 2500
