"""The radio model on crafted cases, checked against tc-netem's arithmetic written out here."""

import math

import numpy as np
import pytest

from swarmbed.netem import Radio
from swarmbed.schema.experiment import NetworkSection as NetemParams
from swarmbed.wire.codec import BROADCAST, RadioMessage


def radio(**kw) -> Radio:
    return Radio(NetemParams(**kw), n_agents=4, dt=1.0, rng=np.random.default_rng(0))


def msg(size: int, dest=BROADCAST, kind="k") -> RadioMessage:
    return RadioMessage(dest, kind, b"x" * size)


def run(r: Radio, ticks: int, per_tick, positions=((0, 0), (1, 0), (2, 0), (3, 0))):
    """Agent 0 sends ``per_tick(k)`` messages each tick; returns {tick: inbox of agent 1}."""
    ids = list(range(len(positions)))
    xs, ys = [p[0] for p in positions], [p[1] for p in positions]
    got = {}
    for k in range(ticks):
        r.confirm()
        r.route(k, ids, xs, ys, {0: per_tick(k)})
        got[k + 1] = r.deliver(k + 1, ids).get(1, [])
    r.finish(ticks - 1)
    return got


def test_no_limits_delivers_next_tick():
    r = radio()
    got = run(r, 3, lambda k: [msg(10, dest=1)])
    assert [len(got[t]) for t in (1, 2, 3)] == [1, 1, 1]
    r.ledger.check()


def test_rate_cap_queues_behind_earlier_messages_and_idle_earns_no_credit():
    # 100-byte messages at 50 B/s take 2 s each; one per tick for 3 ticks, then silence, then one more.
    r = radio(rate=50.0)
    sends = {0: 1, 1: 1, 2: 1, 9: 1}
    got = run(r, 14, lambda k: [msg(100, dest=1)] * sends.get(k, 0))
    delivered_at = [t for t, inbox in got.items() for _ in inbox]
    # tc rate: end_i = max(sent_i, end_{i-1}) + size/rate  ->  2, 4, 6; after idling, 9 + 2 = 11
    assert delivered_at == [2, 4, 6, 11]


def test_latency_adds_ticks():
    r = radio(latency=3)
    got = run(r, 6, lambda k: [msg(5, dest=1)] if k == 0 else [])
    assert [t for t, inbox in got.items() if inbox] == [4]


def test_queue_limit_tail_drops_whole_messages():
    r = radio(rate=10.0, limit=2)  # 10-byte messages take 1 s each
    run(r, 1, lambda k: [msg(10, dest=(1, 2))] * 5)
    led = r.ledger
    assert led.dropped["queue_full"] == 3 * 2  # messages 3..5 dropped, two copies each
    led.check()


def test_range_is_checked_per_receiver_at_the_send_tick():
    r = radio(range=1.5)
    run(r, 1, lambda k: [msg(8)])  # broadcast from x=0 to agents at x = 1, 2, 3
    assert r.ledger.dropped["out_of_range"] == 2
    assert r.ledger.delivered == 0  # the run ended before tick 1: in flight -> run_ended
    assert r.ledger.dropped["run_ended"] == 1
    r.ledger.check()


def test_loss_rate_within_binomial_bound():
    r = radio(loss=0.3)
    n = 10_000
    run(r, 1, lambda k: [msg(1, dest=1)] * n)
    lost = r.ledger.dropped["loss"]
    sd = math.sqrt(n * 0.3 * 0.7)
    assert abs(lost - 0.3 * n) < 5 * sd


def test_addressing_failures_are_booked():
    r = radio()
    ids = [0, 1]  # agents 2 and 3 are dead at this tick
    r.route(0, ids, [0, 1], [0, 0], {0: [msg(4, dest=(1, 2, 7, 0))]})
    led = r.ledger
    assert led.dropped["receiver_dead"] == 1
    assert led.dropped["no_such_receiver"] == 2  # id 7 is not an agent, 0 is the sender
    assert r.deliver(1, [0]) == {}  # receiver 1 died before delivery
    r.confirm()
    assert led.dropped["receiver_dead"] == 2
    led.check()


def test_same_seed_same_fate():
    outcomes = []
    for _ in range(2):
        r = Radio(NetemParams(loss=0.5), 4, 1.0, np.random.default_rng(42))
        run(r, 5, lambda k: [msg(3)] * 4)
        outcomes.append(r.ledger.totals())
    assert outcomes[0] == outcomes[1]


def test_params_reject_out_of_range_values():
    for bad in ({"loss": 1.5}, {"rate": 0}, {"limit": 0}, {"latency": -1}, {"range": -2}):
        with pytest.raises(ValueError):
            NetemParams(**bad)


def test_receiver_ledger_books_each_copy_once_and_sums_to_the_sender_ledger(tmp_path):
    """Random traffic through every drop path (addressing, queue, range, loss, death, run end):
    the per-copy Parquet rows add up, per (tick, sender, kind, outcome), to the sender ledger."""
    import pandas as pd

    from swarmbed.netem.ledger import Ledger, ReceiverLog
    from swarmbed.records.rowfile import RowFile
    from swarmbed.records.run_folder import LEDGER_COLUMNS

    rng = np.random.default_rng(7)
    sink = RowFile(tmp_path / "ledger.csv", LEDGER_COLUMNS, chunk_rows=7)  # small chunks: several writes
    path = tmp_path / "receivers.parquet"
    ledger = Ledger(sink, ReceiverLog(path, group=50))  # small row groups: several flushes
    n = 6
    r = Radio(
        NetemParams(range=3.0, loss=0.3, rate=40.0, limit=3),
        n_agents=n,
        dt=1.0,
        rng=np.random.default_rng(1),
        ledger=ledger,
    )
    for k in range(40):
        alive = [a for a in range(n) if not (a == 5 and k >= 20)]  # agent 5 dies at tick 20
        xs, ys = rng.uniform(0, 6, n), rng.uniform(0, 2, n)
        outs = {}
        for a in alive:
            dests = [BROADCAST, int(rng.integers(0, n + 1)), (0, 5, 9)]
            outs[a] = [
                msg(int(rng.integers(1, 30)), dest=dests[int(rng.integers(0, 3))], kind=f"k{a % 2}")
                for _ in range(int(rng.integers(0, 3)))
            ]
        r.confirm()
        r.route(k, alive, [xs[a] for a in alive], [ys[a] for a in alive], outs)
        r.deliver(k + 1, [a for a in alive if not (a == 5 and k + 1 >= 20)])
        ledger.close_tick(k)
    r.finish(39)
    ledger.close_tick(1 << 62)
    ledger.check()
    ledger.receivers.close()
    per_copy = pd.read_parquet(path).astype({"sender": "int64", "bytes": "int64"})
    assert len(per_copy) == ledger.copies
    assert set(per_copy["outcome"]) >= {"delivered", "loss", "out_of_range", "receiver_dead", "no_such_receiver"}
    to_self = per_copy[per_copy["sender"] == per_copy["receiver"]]
    assert set(to_self["outcome"]) <= {"no_such_receiver"}  # addressed to itself: refused, never delivered
    rows = pd.read_csv(sink.finish())
    copies = rows[rows["outcome"] != "sent"].set_index(["tick", "sender", "kind", "outcome"]).sort_index()
    summed = per_copy.groupby(["tick", "sender", "kind", "outcome"]).agg(
        messages=("bytes", "size"), bytes=("bytes", "sum")
    )
    pd.testing.assert_frame_equal(copies[["messages", "bytes"]], summed, check_dtype=False)


def test_a_receiver_ledger_refuses_a_booking_without_its_receivers(tmp_path):
    from swarmbed.netem.ledger import Ledger, ReceiverLog

    ledger = Ledger(receivers=ReceiverLog(tmp_path / "r.parquet"))
    with pytest.raises(ValueError, match="without its receivers"):
        ledger.book(0, 1, "k", 10, "loss", 2)
    with pytest.raises(ValueError, match="2 'loss' copies booked with 1 receivers"):
        ledger.book(0, 1, "k", 10, "loss", 2, to=[3])


def _one_copy_at_a_time(params: NetemParams, n: int, dt: float, rng, ticks):
    """The radio's rules written out per message and per copy, in the order the module docstring
    states them: the oracle for the radio's batched arrays. Returns {(tick, sender, receiver,
    outcome): copies} and {delivery tick: {receiver: [(sender, kind, size)]}}."""
    booked: dict = {}
    inboxes: dict = {}
    busy: dict = {}
    queues: dict = {}

    def book(tick, sender, receiver, outcome):
        booked[(tick, sender, receiver, outcome)] = booked.get((tick, sender, receiver, outcome), 0) + 1

    for tick, ids, pos, outs in ticks:
        alive = set(ids)
        for sender in sorted(outs):
            for m in outs[sender]:
                if m.dest == BROADCAST:
                    wanted = [a for a in sorted(alive) if a != sender]
                else:
                    wanted = list(m.dest) if isinstance(m.dest, tuple) else [m.dest]
                candidates = []
                for r in wanted:
                    if r == sender or not 0 <= r < n:
                        book(tick, sender, r, "no_such_receiver")
                    elif r not in alive:
                        book(tick, sender, r, "receiver_dead")
                    else:
                        candidates.append(r)
                end = tick * dt
                if params.rate is not None:
                    queue = [e for e in queues.get(sender, []) if e > tick * dt + 1e-9]
                    if params.limit is not None and len(queue) >= params.limit:
                        for r in candidates:
                            book(tick, sender, r, "queue_full")
                        queues[sender] = queue
                        continue
                    end = max(tick * dt, busy.get(sender, 0.0)) + len(m.payload) / params.rate
                    busy[sender] = end
                    queues[sender] = queue + [end]
                near = []
                for r in candidates:
                    far = (
                        params.range is not None
                        and math.hypot(pos[sender][0] - pos[r][0], pos[sender][1] - pos[r][1]) > params.range + 1e-9
                    )
                    if far:
                        book(tick, sender, r, "out_of_range")
                    else:
                        near.append(r)
                draws = rng.random(len(near)) if params.loss > 0 and near else [1.0] * len(near)
                due = max(tick + 1, math.ceil(end / dt - 1e-9)) + params.latency
                for r, draw in zip(near, draws):
                    if draw < params.loss:
                        book(tick, sender, r, "loss")
                    else:
                        inboxes.setdefault(due, {}).setdefault(r, []).append((sender, m.kind, len(m.payload)))
    return booked, inboxes


@pytest.mark.parametrize(
    "params",
    [
        {"range": 300.0, "loss": 0.2},
        {"loss": 0.0},
        {"range": 200.0, "loss": 0.3, "rate": 2000.0, "limit": 3, "latency": 1},
    ],
)
def test_batched_routing_books_and_delivers_what_one_copy_at_a_time_would(params, tmp_path):
    """Broadcast, unicast and multicast (repeated and unknown receivers too) among agents that come
    and go: every copy's outcome and every inbox equal the per-copy rules of the module docstring,
    loss draws included."""
    from swarmbed.netem.ledger import Ledger, ReceiverLog

    n, dt, g = 30, 0.5, np.random.default_rng(3)
    script = []
    for tick in range(25):
        ids = [a for a in range(n) if g.random() > 0.1]
        pos = {a: (float(g.uniform(0, 1000)), float(g.uniform(0, 800))) for a in ids}
        outs = {}
        for a in ids:
            kinds = g.random(int(g.integers(0, 3)))
            dests = [
                BROADCAST
                if c < 0.5
                else int(g.integers(-1, n + 2))
                if c < 0.8
                else tuple(int(x) for x in g.integers(0, n, 3))
                for c in kinds
            ]
            if dests:
                outs[a] = [RadioMessage(d, f"k{i}", bytes(int(g.integers(1, 400)))) for i, d in enumerate(dests)]
        script.append((tick, ids, pos, outs))
    expected, expected_inboxes = _one_copy_at_a_time(NetemParams(**params), n, dt, np.random.default_rng(7), script)

    log = ReceiverLog(tmp_path / "copies.parquet")
    r = Radio(NetemParams(**params), n, dt, np.random.default_rng(7), Ledger(receivers=log))
    inboxes = {}
    for tick, ids, pos, outs in script:
        r.route(tick, ids, [pos[a][0] for a in ids], [pos[a][1] for a in ids], outs)
        got = r.deliver(tick + 1, range(n))
        if got:
            inboxes[tick + 1] = {a: [(s, k, len(p)) for s, k, p in v] for a, v in got.items()}
        r.confirm()
    r.finish(len(script))
    log.close()
    import pyarrow.parquet as pq

    booked: dict = {}
    for row in pq.read_table(tmp_path / "copies.parquet").to_pylist():
        if row["outcome"] not in ("delivered", "run_ended"):
            key = (row["tick"], row["sender"], row["receiver"], row["outcome"])
            booked[key] = booked.get(key, 0) + 1
    assert booked == expected
    assert inboxes == {t: v for t, v in expected_inboxes.items() if t <= len(script)}
    r.ledger.check()


# -- issue 75 item 2: out-of-range copies counted, not made ---------------------------------------


class _Rows(list):
    """A ledger sink that keeps the rows it is given."""

    def write(self, row):
        self.append(tuple(row))

    def tick(self):
        pass


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_broadcasts_out_of_range_copies_are_counted_without_being_made_and_nothing_else_changes(seed, monkeypatch):
    """The radio finds each broadcaster's neighbours through a KD-tree and books the rest as
    out_of_range by count: the ledger rows, the inboxes and every later random draw (loss, the
    rate queue) are those of the radio that makes every copy, on positions that put receivers at
    exactly the range (the range stage's own tolerance decides them) and directed messages beside."""
    from swarmbed.netem.ledger import Ledger
    from swarmbed.netem.radio import drop_reasons

    params = NetemParams.model_validate({"range": 100.0, "loss": 0.3, "rate": 4000.0, "limit": 3})
    n, place = 60, np.random.default_rng(seed)
    made: list[int] = []

    def radio(prefilter: bool) -> tuple[Radio, _Rows]:
        rows = _Rows()
        r = Radio(params, n, 1.0, np.random.default_rng(seed), Ledger(rows, reasons=drop_reasons(params)))
        if not prefilter:
            monkeypatch.setattr(r, "_near", lambda *a: None)
        return r, rows

    fast, fast_rows = radio(True)
    full, full_rows = radio(False)
    for k in range(12):
        xs = place.uniform(0, 400, n)
        ys = place.uniform(0, 300, n)
        xs[:4], ys[:4] = [0.0, 100.0, 0.0, 60.0], [0.0, 0.0, 100.0 + 1e-10, 80.0]  # at the range, on its edge
        ids = [a for a in range(n) if a % 17 != k % 17]  # one agent dead each tick
        outs = {
            a: [RadioMessage(BROADCAST, "b", bytes(int(place.integers(10, 400))))]
            + ([RadioMessage((a + 1) % n, "d", bytes(30))] if a % 5 == 0 else [])
            for a in ids
            if place.random() < 0.7
        }
        inboxes = []
        for r in (fast, full):
            r.route(k, ids, xs.tolist(), ys.tolist(), outs)
            inboxes.append(r.deliver(k + 1, ids))
            r.confirm()
            r.ledger.close_tick(k)
        assert inboxes[0] == inboxes[1], k
        made.append(sum(len(v) for v in inboxes[0].values()))
    for r in (fast, full):
        r.finish(11)
        r.ledger.close_tick(11)
    assert fast_rows == full_rows and fast.ledger.totals() == full.ledger.totals()
    assert fast.ledger.dropped["out_of_range"] > 3 * sum(made) > 0  # most copies were never made
    assert fast.rng.random() == full.rng.random()  # the same draws were taken
