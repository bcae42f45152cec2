"""``swarmbed replay RUN --mcap``: a recorded run as MCAP, read back with the mcap library and
protobuf (not with the SDK that wrote it) and compared with the run's own files."""

import json
import subprocess
import sys

import pandas as pd
import pytest

from swarmbed.launch.runner import run_experiment
from swarmbed.wire.btlog import EPOCH_US, read_btlog
from tests.conftest import QUICKSTART, experiment

pytest.importorskip("foxglove", reason="recordings need Foxglove's SDK (swarmbed[viewers])")
reader = pytest.importorskip("mcap.reader", reason="reading recordings back needs mcap")
protobuf_decoder = pytest.importorskip("mcap_protobuf.decoder", reason="decoding Foxglove's schemas needs protobuf")

RECORDED = [
    "run.duration=40",
    "run.stop_when_done=false",
    "run.record_trajectories=true",
    "run.record_bt=true",
    "network.ledger=per_receiver",
    "network.loss=0.2",
]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    run = tmp_path_factory.mktemp("recorded") / "run"
    run_experiment(experiment(*RECORDED), run, progress=False)
    return run


def replay_mcap(run, out):
    return subprocess.run(
        [sys.executable, "-m", "swarmbed", "replay", str(run), "--mcap", str(out)], capture_output=True, text=True
    )


class JsonDecoder:
    def decoder_for(self, message_encoding, schema):
        return json.loads if message_encoding == "json" else None


def read_back(path):
    """{topic: [(log_time, schema name, decoded message)]}"""
    out: dict[str, list] = {}
    decoders = [protobuf_decoder.DecoderFactory(), JsonDecoder()]
    with open(path, "rb") as f:
        for schema, channel, message, decoded in reader.make_reader(
            f, decoder_factories=decoders
        ).iter_decoded_messages():
            out.setdefault(channel.topic, []).append((message.log_time, schema.name, decoded))
    return out


def test_the_recording_holds_the_runs_poses_counters_copies_markers_and_trees(recorded, tmp_path):
    done = replay_mcap(recorded, tmp_path / "run.mcap")
    assert done.returncode == 0, done.stderr
    again = replay_mcap(recorded, tmp_path / "again.mcap")
    assert again.returncode == 0 and (tmp_path / "run.mcap").read_bytes() == (tmp_path / "again.mcap").read_bytes()
    topics = read_back(tmp_path / "run.mcap")
    dt = 1.0  # quickstart's tick
    stamp = {tick: EPOCH_US * 1000 + round(tick * dt * 1e9) for tick in range(100)}

    traj = pd.read_csv(recorded / "trajectories.csv", keep_default_na=False)
    poses = topics["/agents/poses"]
    assert {name for _, name, _ in poses} == {"foxglove.PosesInFrame"} and len(poses) == traj["tick"].nunique()
    for (time, _, msg), (tick, rows) in zip(poses, traj.groupby("tick")):
        assert time == stamp[tick] and msg.frame_id == "world"
        assert [(p.position.x, p.position.y) for p in msg.poses] == list(zip(rows["x"], rows["y"]))
    assert {name for _, name, _ in topics["/agents"]} == {"foxglove.SceneUpdate"}

    counters = pd.read_csv(recorded / "timeseries.csv")
    assert [m for _, _, m in topics["/counters"]] == counters.to_dict("records")

    copies = pd.read_parquet(recorded / "network_ledger_receivers.parquet")
    for time, _, update in topics["/radio"]:
        tick = round((time - stamp[0]) / 1e9 / dt)
        drawn = {}
        for line in update.entities[0].lines:
            drawn[len(drawn)] = len(line.points) // 2
        assert sum(drawn.values()) == (copies["tick"] == tick).sum()
    assert len({line.color.r for _, _, u in topics["/radio"] for line in u.entities[0].lines}) >= 2  # outcomes

    markers = pd.read_csv(recorded / "markers.csv", keep_default_na=False)
    appeared = sum(len(u.entities) for _, _, u in topics["/markers"])
    vanished = sum(len(u.deletions) for _, _, u in topics["/markers"])
    assert (appeared, vanished) == ((markers["event"] == "appear").sum(), (markers["event"] != "appear").sum())

    statuses = ("IDLE", "RUNNING", "SUCCESS", "FAILURE")
    for agent in range(5):
        _, _, records = read_btlog((recorded / "bt" / f"agent_{agent}.btlog").read_bytes())
        logged = [
            (round((time - stamp[0]) / 1000), c["uid"], statuses.index(c["status"]))
            for time, _, m in topics["/agents/tree"]
            if m["agent"] == agent
            for c in m["changes"]
        ]
        assert logged == records


def test_a_run_without_trajectories_is_refused_with_the_flag_to_set(tmp_path):
    run_experiment(experiment("run.duration=5"), tmp_path / "run", progress=False)
    done = replay_mcap(tmp_path / "run", tmp_path / "run.mcap")
    assert done.returncode == 2 and "--set run.record_trajectories=true" in done.stderr
    assert not (tmp_path / "run.mcap").exists()


@pytest.mark.slow  # a run of real processes
def test_a_run_is_served_live_to_a_foxglove_client_over_its_websocket_protocol(tmp_path):
    """Issue 62: ``swarmbed run --foxglove``'s hook serves the recording's channels while the run
    goes. A WebSocket client speaking the SDK's protocol (as Foxglove does) reads the server's
    advertisement (the channels, their well-known schemas), subscribes to ``/agents/poses`` and
    decodes a message with the advertised schema: every agent's pose, at positions of the run. The
    server is gone once the run ended."""
    import base64
    import struct
    import threading
    import time

    import websocket
    from mcap.records import Schema
    from mcap_protobuf.decoder import DecoderFactory

    from swarmbed.results.foxglove_live import TOPICS, FoxgloveLive

    PROTOCOL = "foxglove.sdk.v1"  # Foxglove's WebSocket protocol, as the SDK's server names it

    exp = experiment(
        "agents.count=3", "run.clock=realtime", "run.speed=10", "run.duration=60", "run.stop_when_done=false"
    )
    made: list[FoxgloveLive] = []

    def view(session):
        made.append(FoxgloveLive(session.world, exp.run.dt, port=0))
        return made[-1]

    result: list = []
    runner = threading.Thread(target=lambda: result.append(run_experiment(exp, tmp_path / "run", False, views=[view])))
    runner.start()
    deadline = time.monotonic() + 30
    while not made and time.monotonic() < deadline:
        time.sleep(0.05)
    url = made[0].url  # ws://127.0.0.1:PORT/TOKEN
    with pytest.raises(websocket.WebSocketBadStatusException):  # without the run's token: refused
        websocket.create_connection(f"ws://127.0.0.1:{made[0].port}", subprotocols=[PROTOCOL], timeout=10)
    ws = websocket.create_connection(url, subprotocols=[PROTOCOL], timeout=10)
    channels: dict[str, dict] = {}
    while not set(TOPICS) <= set(channels):
        message = json.loads(ws.recv())
        if message["op"] == "advertise":
            channels.update({c["topic"]: c for c in message["channels"]})
    assert channels["/agents/poses"]["schemaName"] == "foxglove.PosesInFrame"
    assert {channels[t]["schemaName"] for t in ("/agents", "/markers", "/radio")} == {"foxglove.SceneUpdate"}
    poses = channels["/agents/poses"]
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": poses["id"]}]}))
    frame = ws.recv()
    while not isinstance(frame, bytes):
        frame = ws.recv()
    opcode, subscription, _stamp = struct.unpack_from("<BIQ", frame)
    assert (opcode, subscription) == (1, 7)  # message data, of our subscription
    schema = Schema(id=1, name=poses["schemaName"], encoding="protobuf", data=base64.b64decode(poses["schema"]))
    decoded = DecoderFactory().decoder_for("protobuf", schema)(frame[13:])
    assert decoded.frame_id == "world" and len(decoded.poses) == 3
    ws.close()
    runner.join(timeout=60)
    assert result and result[0].summary["ticks"] == 60
    with pytest.raises(OSError):
        websocket.create_connection(url, subprotocols=[PROTOCOL], timeout=2)


def test_clients_that_never_read_and_idle_connections_never_stall_a_run_or_its_results(tmp_path):
    """Issue 74 item 6: one Foxglove client that subscribed to every channel and then never reads
    (a 4 kB receive buffer), and 50 idle TCP connections beside it: the run ends, writes its results
    and exits in bounded time (it stalled for good: the SDK's stop() waits for every client's close)."""
    import socket
    import subprocess
    import sys

    import websocket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "run"
    sets = ["run.stop_when_done=false", "run.duration=1500", "agents.count=20"]
    cmd = [sys.executable, "-m", "swarmbed", "run", str(QUICKSTART), "--out", str(out), "--foxglove", str(port)]
    cmd += ["--no-progress", "--engine", "inprocess", *[a for k in sets for a in ("--set", k)]]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    held: list = []
    try:
        ws = websocket.WebSocket(sockopt=((socket.SOL_SOCKET, socket.SO_RCVBUF, 4096),))
        line = proc.stderr.readline()
        while "open connection" not in line:
            assert line, proc.stderr.read()
            line = proc.stderr.readline()
        ws.connect(line.split()[-1], subprotocols=["foxglove.sdk.v1"], timeout=10)
        channels: dict = {}
        while len(channels) < 4:
            message = ws.recv()
            if isinstance(message, str) and json.loads(message)["op"] == "advertise":
                channels.update({c["topic"]: c for c in json.loads(message)["channels"]})
        subscribe = [{"id": i, "channelId": c["id"]} for i, c in enumerate(channels.values())]
        ws.send(json.dumps({"op": "subscribe", "subscriptions": subscribe}))
        held = [ws, *(socket.create_connection(("127.0.0.1", port), timeout=5) for _ in range(50))]
        assert proc.wait(timeout=90) == 0, proc.stderr.read()
    finally:
        proc.kill()
        proc.wait()
        for h in held:
            h.close()
    assert json.loads((out / "summary.json").read_text())["ticks"] == 1500
