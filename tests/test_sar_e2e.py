"""Search and rescue with real processes over Zenoh: every strategy on a small case."""

import csv
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from swarmbed.launch.runner import run_experiment
from swarmbed.plugins.sar.ccbba import CLUSTER_STREAM, kmeans_pp
from tests.conftest import experiment, ledger_outcomes, read_ledger

SAR = Path(__file__).resolve().parent.parent / "experiments" / "sar" / "_base.yaml"
# 10-s inspections: in 60 s a robot makes several, whatever its strategy (33 s, the default, allows one)
SMALL = ["agents.count=6", "scenario.victims=30", "run.duration=60", "run.record_every=4", "scenario.inspect_time=10"]
STRATEGIES = ["tree", "comm", "cbba", "cbba-tree", "cbba-etc", "c-cbba"]


def sar_run(tmp_path, strategy, *extra):
    exp = experiment(*SMALL, f"allocator.name={strategy}", *extra, base=SAR)
    return run_experiment(exp, tmp_path, progress=False)


@pytest.mark.parametrize("strategy", STRATEGIES)
def test_each_strategy_rescues_victims_and_accounts_for_every_one(tmp_path, strategy):
    s = sar_run(tmp_path, strategy, "run.record_trajectories=true").summary
    assert s["rescued"] > 0
    assert s["rescued"] + s["expired"] + s["victims_alive"] == s["spawned"]
    assert s["invalid_actions"] == 0
    net = s["network"]
    assert net["copies"] == net["delivered"] + sum(net["dropped"].values())
    with open(tmp_path / "timeseries.csv") as f:
        last = list(csv.DictReader(f))[-1]
    assert int(last["rescued"]) == s["rescued"] and int(last["expired"]) == s["expired"]
    if strategy == "tree":
        assert net["messages_sent"] == 0 and net["bytes_sent"] == 0
    else:
        assert net["messages_sent"] > 0
    if strategy.startswith("cbba") or strategy == "c-cbba":
        assert s["negotiations"] > 0 and int(last["negotiations"]) == s["negotiations"]
    if strategy == "c-cbba":
        _check_members_talk_to_their_leader_only(tmp_path, s)


def _check_members_talk_to_their_leader_only(run_dir: Path, summary: dict):
    with open(run_dir / "trajectories.csv") as f:
        start = [(int(r["agent"]), float(r["x"]), float(r["y"])) for r in csv.DictReader(f) if r["tick"] == "0"]
    labels = kmeans_pp(
        np.array([[x, y] for _, x, y in start]),
        2,
        np.random.default_rng(np.random.SeedSequence([summary["seed"], CLUSTER_STREAM])),
    )
    leaders = {min(a for (a, _, _), lab in zip(start, labels) if lab == c) for c in set(labels)}
    sent = defaultdict(lambda: defaultdict(int))
    copies = defaultdict(int)
    for row in read_ledger(run_dir):
        if row["outcome"] == "sent":
            sent[row["sender"]][row["kind"]] += row["messages"]
        elif row["sender"] not in leaders:
            copies[row["sender"]] += row["messages"]
    members = [a for a, _, _ in start if a not in leaders]
    assert members and any(sent[m] for m in members)
    for m in members:
        assert set(sent[m]) <= {"bids"}, f"member {m} sent {dict(sent[m])}"
        assert copies[m] == sent[m].get("bids", 0)  # unicast: one copy per message
    assert {k for a in leaders for k in sent[a]} <= {"leaders", "result"}


def test_same_seed_same_rescue(tmp_path):
    a = sar_run(tmp_path / "a", "cbba-etc").out_dir
    b = sar_run(tmp_path / "b", "cbba-etc").out_dir
    for name in ("summary.json", "timeseries.csv", "network_ledger.csv", "agents.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_agent_loss_stops_the_process_and_the_run_goes_on(tmp_path):
    result = sar_run(tmp_path, "cbba-etc", "scenario.agent_loss=0.01", "scenario.agent_loss_grace=5", "run.duration=40")
    s = result.summary
    assert s["agents_lost"], "with 1% per step over 140 steps some robot should be lost"
    lost = {int(a): t for a, t in s["agents_lost"].items()}
    assert all(code == 0 for code in result.timings["exit_codes"].values())  # stopped cleanly
    with open(tmp_path / "agents.csv") as f:
        rows = {int(r["agent"]): r for r in csv.DictReader(f)}
    for a, tick in lost.items():
        assert rows[a]["alive"] == "0" and int(rows[a]["lost_at_tick"]) == tick
    assert s["ticks"] == 160  # the run went on without them
    dead = ledger_outcomes(read_ledger(tmp_path)).get("receiver_dead", 0)
    assert dead >= 0 and s["network"]["dropped"]["receiver_dead"] == dead
