"""netem through real processes: range, loss, rate and queue limit, read back from the ledger."""

import csv
import math
from collections import defaultdict

import msgpack

from swarmbed.launch.runner import run_experiment
from tests.conftest import experiment, read_ledger


def noop_run(tmp_path, *overrides):
    exp = experiment(
        "allocator={name: noop, peers: 1, payload_bytes: 100}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        "network.range=null",
        *overrides,
    )
    return run_experiment(exp, tmp_path, progress=False)


def test_agents_moving_apart_stop_hearing_each_other_at_the_range(tmp_path):
    exp = experiment(
        "agents.count=2",
        "agents.awareness_range=300",
        "scenario.initial_tasks=2",
        "scenario.workload=[6, 6]",
        "scenario.agent_positions=[[95, 75], [105, 75]]",
        "scenario.task_positions=[[0, 75], [200, 75]]",
        "network.range=60",
        "run.record_trajectories=true",
    )
    run = run_experiment(exp, tmp_path, progress=False)
    pos = defaultdict(dict)
    with open(tmp_path / "trajectories.csv") as f:
        for r in csv.DictReader(f):
            pos[int(r["tick"])][int(r["agent"])] = (float(r["x"]), float(r["y"]))
    far = {k for k, p in pos.items() if math.dist(p[0], p[1]) > 60}
    assert far and len(far) < len(pos)  # they started in range and ended out of it
    dropped = {r["tick"] for r in read_ledger(tmp_path) if r["sender"] == 0 and r["outcome"] == "out_of_range"}
    sent = {r["tick"] for r in read_ledger(tmp_path) if r["sender"] == 0 and r["outcome"] == "sent"}
    assert dropped == far & sent
    assert run.summary["network"]["dropped"]["out_of_range"] > 0


def test_loss_over_ten_thousand_copies_is_binomial(tmp_path):
    run = noop_run(tmp_path, "agents.count=10", "allocator.peers=5", "run.duration=200", "network.loss=0.3")
    net = run.summary["network"]
    n = net["copies"]
    assert n == 10 * 5 * 200
    sd = math.sqrt(n * 0.3 * 0.7)
    assert abs(net["dropped"]["loss"] - 0.3 * n) < 5 * sd
    assert net["copies"] == net["delivered"] + sum(net["dropped"].values())


def _tc_rate(sizes_by_tick, rate, limit, ticks):
    """tc-netem rate + limit, written out: (delivery ticks, tail-dropped count)."""
    busy, queue, delivered, dropped = 0.0, [], [], 0
    for k in range(ticks):
        for size in sizes_by_tick(k):
            queue = [e for e in queue if e > k]
            if limit is not None and len(queue) >= limit:
                dropped += 1
                continue
            busy = max(k, busy) + size / rate
            queue.append(busy)
            delivered.append(max(k + 1, math.ceil(busy - 1e-9)))
    return delivered, dropped


def test_rate_cap_delays_messages_as_tc_netem_computes(tmp_path):
    size = len(msgpack.packb(b"\0" * 100))
    run = noop_run(tmp_path, "agents.count=2", "run.duration=20", f"network.rate={size / 2}")
    expected, _ = _tc_rate(lambda k: [size], size / 2, None, 20)
    got = sorted(
        r["tick"]
        for r in read_ledger(tmp_path)
        if r["sender"] == 0 and r["outcome"] == "delivered"
        for _ in range(r["messages"])
    )
    assert got == [t for t in expected if t <= 19]
    assert run.summary["network"]["dropped"]["run_ended"] > 0


def test_full_queue_drops_and_books_it(tmp_path):
    size = len(msgpack.packb(b"\0" * 100))
    run = noop_run(tmp_path, "agents.count=2", "run.duration=30", f"network.rate={size / 3}", "network.limit=2")
    _, dropped = _tc_rate(lambda k: [size], size / 3, 2, 30)
    assert dropped > 0
    assert run.summary["network"]["dropped"]["queue_full"] == 2 * dropped  # both senders
    rows = [r for r in read_ledger(tmp_path) if r["outcome"] == "queue_full"]
    assert sum(r["messages"] for r in rows) == 2 * dropped


def test_every_radio_model_in_a_real_run_books_every_copy_and_repeats_byte_for_byte(tmp_path):
    """Propagation with shadowing and fading, bursts and delay at once, through the real proxy: every
    copy is delivered or dropped with one of the reasons the summary declares, the ledger file
    agrees, and the same seed gives the same files."""
    models = (
        "agents.count=8",
        "allocator.peers=7",
        "run.duration=150",
        "run.dt=0.5",
        "network.propagation={shadowing_db: 4.0, fading: rayleigh, coherence_time: 2.0}",
        "network.burst={mean_loss: 0.1, mean_burst: 3.0}",
        "network.delay={mean: 0.8, jitter: 0.4, distribution: pareto, correlation: 0.2}",
        "network.ledger=per_receiver",
        "scenario.agent_positions=[[10, 10], [40, 20], [70, 40], [100, 60], [130, 80], [160, 99], [190, 9], [5, 99]]",
    )
    a = noop_run(tmp_path / "a", *models)
    noop_run(tmp_path / "b", *models)
    net = a.summary["network"]
    dropped = net["dropped"]
    assert {"below_sensitivity", "packet_error", "burst"} <= set(dropped)
    assert dropped["burst"] > 0 and dropped["below_sensitivity"] + dropped["packet_error"] > 0
    assert net["delivered"] > 0 and net["copies"] == net["delivered"] + sum(dropped.values())
    booked = defaultdict(int)
    for r in read_ledger(tmp_path / "a"):
        booked[r["outcome"]] += int(r["messages"])
    assert {k: v for k, v in booked.items() if k != "sent"} == {
        k: v for k, v in {**dropped, "delivered": net["delivered"]}.items() if v
    }
    for name in ("summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv", "config.yaml"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    assert "propagation:" in (tmp_path / "a" / "config.yaml").read_text()
