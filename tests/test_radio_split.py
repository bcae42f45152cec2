"""A radio split over K netem proxies (``radio_split``, swarmbed.netem.radio_split): the per-copy
loss draws against their formula, K radios deciding what one radio decides, and K proxy
processes giving one proxy's result files byte for byte."""

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from swarmbed.netem.exchange import Exchange, SplitExchange
from swarmbed.netem.radio import per_copy_uniform
from swarmbed.netem.radio_split import merge_inbox, owners
from swarmbed.schema.experiment import RadioSplit, netem_spec
from swarmbed.wire.codec import (
    BROADCAST,
    AgentOut,
    RadioMessage,
    WireError,
    WorldSample,
    decode_inbox,
    encode_inbox,
)
from tests.conftest import experiment, reference_run, same_results

SPLIT = ["network.draws=per_copy", "radio_split.strip_width=30"]
#: CBBA over 8 agents, lossy and rate-capped (messages wait, so inboxes mix send ticks)
BUSY = ["agents.count=8", "allocator={name: cbba}", "run.duration=300", "network.loss=0.2", "network.rate=400"]


def test_per_copy_draws_are_uniform_and_each_copys_own():
    """Kolmogorov-Smirnov against U(0, 1) over 200,000 copies; a copy's draw does not depend on
    which other copies are drawn with it, nor in what order; neighbours' draws do not correlate."""
    rng = np.random.default_rng(5)
    n = 200_000
    senders, seqs, receivers = rng.integers(0, 1000, n), rng.integers(0, 4, n), rng.integers(0, 1000, n)
    u = per_copy_uniform(12345, 77, senders, seqs, receivers)
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 0.01
    perm = rng.permutation(n)[:1000]
    assert np.array_equal(per_copy_uniform(12345, 77, senders[perm], seqs[perm], receivers[perm]), u[perm])
    # each coordinate matters
    for other in (
        per_copy_uniform(12346, 77, senders, seqs, receivers),
        per_copy_uniform(12345, 78, senders, seqs, receivers),
        per_copy_uniform(12345, 77, senders, seqs + 1, receivers),
        per_copy_uniform(12345, 77, senders, seqs, receivers + 1),
    ):
        assert np.mean(other == u) < 1e-3


def test_per_copy_loss_drops_the_configured_share(tmp_path):
    """The loss stage with per-copy draws drops Binomial(copies, loss): its rate within 4 sigma."""
    exp = experiment("agents.count=40", "network.loss=0.3", "network.draws=per_copy", "run.duration=50")
    ex = Exchange(netem_spec(exp), tmp_path)
    ids = list(range(40))
    for tick in range(50):
        msgs = {a: AgentOut(tick, a, [], [RadioMessage(BROADCAST, "x", b"p")], {}) for a in ids}
        ex.confirm()
        ex.route(WorldSample(tick, ids, [0.0] * 40, [0.0] * 40, ids, {}), msgs)
    led = ex.ledger
    n = led.copies
    share = led.dropped["loss"] / n
    assert abs(share - 0.3) < 4 * np.sqrt(0.3 * 0.7 / n), share


def test_owners_are_strips_dealt_in_turn():
    split = RadioSplit(shards=3, regions="strips", strip_width=10.0)
    assert owners([0.0, 9.99, 10.0, 25.0, 30.0, 41.0, -0.5], split).tolist() == [0, 0, 1, 2, 0, 1, 2]


def test_owners_are_bands_of_equal_shares_of_the_agents_by_x():
    """Ranked by x, ties in the sample's order; K bands of N / K agents (where K does not divide N,
    some bands one more), however the agents crowd."""
    split = RadioSplit(shards=3)
    assert owners([5.0, 1.0, 9.0, 1.0, 100.0, 2.0, 3.0], split).tolist() == [1, 0, 2, 0, 2, 0, 1]
    crowd = np.concatenate([np.full(70, 10.0), np.linspace(0, 200, 30)])
    assert np.bincount(owners(crowd, RadioSplit(shards=4))).tolist() == [25, 25, 25, 25]
    assert owners([], split).tolist() == [] and owners([3.0], split).tolist() == [0]


def test_a_receivers_inbox_parts_merge_in_the_order_one_radio_delivers():
    a = encode_inbox([[4, "k", b"a"], [1, "k", b"b"]])  # sent at ticks 3 and 5
    b = encode_inbox([[2, "k", b"c"], [7, "k", b"d"]])  # sent at ticks 3 and 4
    merged = decode_inbox(merge_inbox([(a, [3, 5]), (b, [3, 4])]))
    assert [(d.sender, d.payload) for d in merged] == [(2, b"c"), (4, b"a"), (7, b"d"), (1, b"b")]
    # a part that does not match its send ticks is a wire error, never a crash of the hub
    for bad in ([(a, [3]), (b, [3, 4])], [(encode_inbox([["x", "k", b""]]), [1]), (b, [3, 4])]):
        with pytest.raises(WireError):
            merge_inbox(bad)


@pytest.mark.parametrize("regions", ["strips", "bands"])
@pytest.mark.parametrize("capped", [True, False], ids=["rate-capped", "by-region"])
def test_k_exchanges_give_one_exchanges_steps_and_ledger_as_agents_wander_across_regions(tmp_path, regions, capped):
    """Thirty agents on a random walk over strips of 20 or bands (so owners change), broadcasting
    and unicasting with latency and per-copy loss, with a rate cap and a queue limit (each exchange
    reads every output) or without (each reads its own region's): the merged step of three
    exchanges equals one exchange's every tick (inboxes byte for byte), and so does the ledger."""
    sets = [
        "agents.count=30",
        "run.duration=80",
        *SPLIT,
        "radio_split.strip_width=20",
        f"radio_split.regions={regions}",
    ]
    net = ["network.loss=0.25", "network.latency=1", "network.range=60"]
    net += ["network.rate=120", "network.limit=3"] if capped else []
    (tmp_path / "one").mkdir()
    (tmp_path / "three").mkdir()
    one = Exchange(netem_spec(experiment(*sets, *net)), tmp_path / "one")
    split_exp = experiment(*sets, *net, "radio_split.shards=3")
    three = SplitExchange(netem_spec(split_exp), tmp_path / "three")
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 120, (30, 2))
    ids = list(range(30))
    changed = 0
    before = owners(xy[:, 0], split_exp.radio_split)
    for tick in range(80):
        xy += rng.normal(0, 4, xy.shape)
        now = owners(xy[:, 0], split_exp.radio_split)
        changed += int((now != before).sum())
        before = now
        outs = {}
        for a in ids:
            msgs = [RadioMessage(BROADCAST, "bid", bytes(int(rng.integers(20, 120))))]
            if rng.random() < 0.5:
                msgs.append(RadioMessage(int(rng.integers(0, 30)), "ask", b"q" * int(rng.integers(5, 50))))
            outs[a] = AgentOut(tick, a, [], msgs, {})
        w = WorldSample(tick, ids, xy[:, 0].tolist(), xy[:, 1].tolist(), ids, {})
        one.confirm()
        three.confirm()
        assert one.route(w, outs) == three.route(w, outs), tick
    one.finish(79, 0)
    three.finish(79, 0)
    assert changed > 50, changed
    ledger = "network_ledger.csv"
    assert (tmp_path / "one" / ledger).read_bytes() == (tmp_path / "three" / ledger).read_bytes()


@pytest.mark.slow
def test_k_radios_in_one_process_decide_what_one_decides_and_each_decides_some(tmp_path):
    """The in-process engine with the radio split over 3 (SplitExchange) gives the result files of
    one radio with the same per-copy draws, byte for byte; every part decided copies, and agents
    crossed from one part's region to another's during the run."""
    traced = [*BUSY, *SPLIT, "run.record_trajectories=true"]
    reference_run(experiment(*traced), tmp_path / "one")
    split = experiment(*traced, "radio_split.shards=3")
    seen = []
    real_finish = SplitExchange.finish

    def finish(self, last_tick, malformed):
        seen.extend(part.ledger.copies for part in self.parts)
        return real_finish(self, last_tick, malformed)

    SplitExchange.finish = finish
    try:
        reference_run(split, tmp_path / "three")
    finally:
        SplitExchange.finish = real_finish
    same_results(tmp_path / "one", tmp_path / "three")
    assert len(seen) == 3 and all(copies > 0 for copies in seen), seen
    assert not list((tmp_path / "three").glob("network_ledger.shard*")), "the parts are merged away"
    paths = pd.read_csv(tmp_path / "three" / "trajectories.csv")
    paths["owner"] = owners(paths["x"], split.radio_split)
    assert (paths.groupby("agent")["owner"].nunique() > 1).sum() >= 2, "no agent changed proxy"


def test_a_split_radio_refuses_what_it_cannot_split_in_one_line():
    refused = r"quickstart.yaml: a radio split over 2 proxies cannot go with network.draws: sequential \(one"
    with pytest.raises(ValueError, match=refused):
        experiment("radio_split.shards=2")
    with pytest.raises(ValueError, match=r"cannot go with network.channel \(a receiver's airtime"):
        experiment("radio_split.shards=2", "network.draws=per_copy", "network.channel={capacity: 1000}")
    assert experiment("radio_split.shards=2", "network.draws=per_copy").radio_split.shards == 2


def test_per_copy_draws_change_the_config_but_a_split_does_not(tmp_path):
    """``network.draws`` is a result's setting (config.yaml names it when per_copy); where the
    copies were decided is deployment, like placement."""
    dumped = experiment(*SPLIT, "radio_split.shards=3").model_dump(mode="json")
    assert "radio_split" not in dumped and dumped["network"]["draws"] == "per_copy"
    assert "draws" not in experiment().model_dump(mode="json")["network"]


@pytest.mark.slow
def test_three_proxy_processes_give_one_proxys_result_files(tmp_path):
    """Three proxy processes (logs/netem.log, netem-1.log, netem-2.log), the hub merging their
    steps and ledgers: the files of the same run with one proxy, byte for byte."""
    from swarmbed.launch.runner import run_experiment

    run_experiment(experiment(*BUSY, *SPLIT), tmp_path / "one", progress=False)
    run_experiment(experiment(*BUSY, *SPLIT, "radio_split.shards=3"), tmp_path / "three", progress=False)
    same_results(tmp_path / "one", tmp_path / "three")
    logs = sorted(p.name for p in (tmp_path / "three" / "logs").glob("netem*.log"))
    assert logs == ["netem-1.log", "netem-2.log", "netem.log"]
    assert not list((tmp_path / "three").glob("network_ledger.shard*"))
    # with a rate cap every proxy reads every output (each keeps every sender's transmit queue)
    one, ticks = proxy_reads(tmp_path / "one")[0]
    assert one == 8 * ticks and proxy_reads(tmp_path / "three") == [(one, ticks)] * 3


def proxy_reads(run_dir: Path) -> list[tuple[int, int]]:
    """(outputs read, ticks) of each proxy of a run, from its log: netem.log, netem-1.log, ..."""
    found = []
    for shard in range(64):
        log = run_dir / "logs" / ("netem.log" if shard == 0 else f"netem-{shard}.log")
        if not log.exists():
            break
        match = re.search(r"netem: read (\d+) agent outputs over (\d+) ticks", log.read_text())
        assert match, f"{log.name} says nothing of what it read"
        found.append((int(match[1]), int(match[2])))
    return found


@pytest.mark.slow
def test_without_a_rate_cap_each_proxy_reads_only_its_regions_outputs_and_the_files_are_one_proxys(tmp_path):
    """No rate cap, so no transmit queue spans ticks: the hub tells each agent its owner at every
    tick, the agent answers on that proxy's key, and each of three proxies reads only the outputs
    of the agents in its strips (they wander across strips over the run), carrying their actions
    and events; the merged files are still one proxy's, byte for byte."""
    from swarmbed.launch.runner import run_experiment

    sets = ["agents.count=12", "allocator={name: cbba}", "run.duration=400", "run.stop_when_done=false"]
    sets += ["network.loss=0.2", "network.range=80", *SPLIT]
    reference_run(experiment(*sets), tmp_path / "reference")
    run_experiment(experiment(*sets, "radio_split.shards=3"), tmp_path / "three", progress=False)
    same_results(tmp_path / "reference", tmp_path / "three")
    reads = proxy_reads(tmp_path / "three")
    ticks = reads[0][1]
    assert len(reads) == 3 and all(t == ticks for _, t in reads), reads
    assert sum(n for n, _ in reads) == 12 * ticks, reads  # each output read once, by one proxy
    assert all(0 < n < 12 * ticks for n, _ in reads), reads
