"""The radio's models beyond the disk, checked against their formulas on long synthetic streams driven
through the real radio code (swarmbed.netem.Radio), with tolerances from the sample size; and
determinism and conservation with every model on at once."""

import math

import numpy as np
import pytest
from scipy import special, stats

from swarmbed.netem import Radio
from swarmbed.netem.delay import Delays
from swarmbed.netem.ledger import Ledger
from swarmbed.netem.normal import erfc
from swarmbed.netem.radio import drop_reasons
from swarmbed.schema.experiment import NetworkSection
from swarmbed.schema.obstacles import ObstaclesSection
from swarmbed.schema.radio_sections import BurstSection, DelaySection, WallsSection
from swarmbed.wire.codec import BROADCAST, RadioMessage

SIGMAS = 4.5  # an empirical figure may stray this many standard errors from its formula


def binomial_tolerance(p: float, n: int) -> float:
    return SIGMAS * math.sqrt(max(p * (1 - p), 1e-4) / n) + 1e-9


def drive(
    network: dict,
    xs,
    ys,
    ticks: int,
    payload: int = 50,
    senders=(0,),
    every: int = 1,
    seed: int = 7,
    dt: float = 1.0,
    obstacles: dict | None = None,
):
    """A stream of one broadcast per sender per ``every`` ticks among static agents (behind the
    ``obstacles`` section's walls, if any); returns the radio and, per tick, who received from whom."""
    params = NetworkSection(**network)
    n = len(xs)
    walls = ObstaclesSection(**obstacles).compile((params.walls or WallsSection()).loss_db) if obstacles else None
    radio = Radio(params, n, dt, np.random.default_rng(seed), Ledger(reasons=drop_reasons(params)), walls)
    ids = list(range(n))
    got = []
    msg = RadioMessage(BROADCAST, "x", b"p" * payload)
    for k in range(ticks):
        outs = {s: [msg] for s in senders} if k % every == 0 else {}
        radio.route(k, ids, xs, ys, outs)
        got.append(radio.deliver(k + 1, ids))
        radio.confirm()
    return radio, got


def test_erfc_agrees_with_scipy_to_seven_digits():
    x = np.linspace(-6, 9, 20001)
    assert np.max(np.abs(erfc(x) / special.erfc(x) - 1)) < 2e-7


LOG_DISTANCE = {"reference_loss_db": 46.6777, "exponent": 3.0, "tx_power_dbm": 16.0206, "noise_floor_dbm": -93.97}


def formula_delivery(
    d: np.ndarray, payload: int, modulation: str = "bpsk", walls_db: np.ndarray | float = 0.0
) -> np.ndarray:
    """(1 - BER)^bits at distance d behind walls costing ``walls_db``, from the textbook formulas
    (scipy's erfc; the walls' loss added to the path loss, COST 231's multi-wall sum)."""
    p = LOG_DISTANCE
    snr_db = (
        p["tx_power_dbm"]
        - (p["reference_loss_db"] + 10 * p["exponent"] * np.log10(np.maximum(d, 1.0)))
        - walls_db
        - (p["noise_floor_dbm"])
    )
    snr = 10 ** (snr_db / 10)
    ber = 0.5 * special.erfc(np.sqrt(snr if modulation == "bpsk" else snr / 2))
    below = snr_db + p["noise_floor_dbm"] < -101.0
    return np.where(below, 0.0, (1 - ber) ** (8 * payload))


@pytest.mark.parametrize("modulation", ["bpsk", "qpsk"])
def test_delivery_ratio_against_distance_follows_the_snr_and_bit_count(modulation):
    distances = np.linspace(40, 110, 29)
    xs, ys = [0.0, *distances], [0.0] * (len(distances) + 1)
    ticks, payload = 1500, 60
    radio, got = drive({"propagation": {**LOG_DISTANCE, "modulation": modulation}}, xs, ys, ticks, payload)
    received = np.zeros(len(distances))
    for inbox in got:
        for r in inbox:
            received[r - 1] += 1
    empirical = received / ticks
    expected = formula_delivery(distances, payload, modulation)
    assert expected.max() > 0.99 and expected.min() < 0.01, "the distances must cross the whole curve"
    for d, e, f in zip(distances, empirical, expected):
        assert abs(e - f) <= binomial_tolerance(f, ticks), f"at {d:.1f} m: delivered {e:.4f}, formula {f:.4f}"
    dropped = radio.ledger.dropped
    assert dropped["packet_error"] > 0 and radio.ledger.copies == radio.ledger.delivered + radio.ledger.dropped_total


#: two walls across the x axis, each spanning y in [-200, 200]: a heavy one at x = 10, a light one at x = 20
TWO_WALLS = {
    "walls": [
        {"start": [10.0, -200.0], "end": [10.0, 200.0], "material": "heavy"},
        {"start": [20.0, -200.0], "end": [20.0, 200.0], "material": "light"},
    ]
}


def test_delivery_behind_zero_one_and_two_walls_follows_the_multi_wall_formula():
    """A grid of receivers behind 0, 1 and 2 walls of a sender at the origin: each one's delivery
    ratio is (1 - BER)^bits with the SNR lowered by COST 231's wall losses (heavy 6.9 dB, light
    3.4 dB), counted here from the geometry, not from the radio."""
    gx, gy = np.meshgrid(np.linspace(4.5, 70.5, 23), [-30.0, 0.0, 30.0])
    rx, ry = gx.ravel(), gy.ravel()
    ticks, payload = 1500, 60
    radio, got = drive({"propagation": LOG_DISTANCE}, [0.0, *rx], [0.0, *ry], ticks, payload, obstacles=TWO_WALLS)
    received = np.zeros(len(rx))
    for inbox in got:
        for r in inbox:
            received[r - 1] += 1
    walls_db = 6.9 * (rx > 10) + 3.4 * (rx > 20)
    expected = formula_delivery(np.hypot(rx, ry), payload, walls_db=walls_db)
    for n_walls, behind in ((0, rx < 10), (1, (rx > 10) & (rx < 20)), (2, rx > 20)):
        assert behind.sum() >= 6, f"too few receivers behind {n_walls} walls"
    assert expected[rx > 20].max() > 0.95 and expected.min() < 0.01, "behind two walls the curve must be crossed"
    for x, y, e, f in zip(rx, ry, received / ticks, expected):
        assert abs(e - f) <= binomial_tolerance(f, ticks), f"at ({x:.1f}, {y:.0f}): delivered {e:.4f}, formula {f:.4f}"
    open_ground, _ = drive({"propagation": LOG_DISTANCE}, [0.0, *rx], [0.0, *ry], 200, payload)
    assert radio.ledger.delivered < open_ground.ledger.delivered * ticks / 200, "walls must cost deliveries"


def test_line_of_sight_drops_exactly_the_copies_that_cross_a_wall_and_draws_nothing():
    gx, gy = np.meshgrid(np.linspace(5, 71, 12), [-30.0, 0.0, 30.0])
    rx, ry = gx.ravel(), gy.ravel()
    network = {"loss": 0.3, "walls": {"line_of_sight": True}}
    radio, got = drive(network, [0.0, *rx], [0.0, *ry], 300, obstacles=TWO_WALLS)
    crossing = rx > 10
    heard = np.zeros(len(rx))
    for inbox in got:
        for r in inbox:
            heard[r - 1] += 1
    assert not heard[crossing].any(), "a copy through a wall was delivered"
    assert (heard[~crossing] > 0).all()
    assert radio.ledger.dropped["blocked_by_wall"] == 300 * int(crossing.sum())
    assert radio.ledger.copies == radio.ledger.delivered + radio.ledger.dropped_total
    # the loss draws are made for the copies in play only: those that see each other lose the same copies
    # as a radio where the blocked receivers are simply absent
    _, alone = drive({"loss": 0.3}, [0.0, *rx[~crossing]], [0.0, *ry[~crossing]], 300)
    mine = [sorted(r for r in inbox) for inbox in got]
    kept = np.flatnonzero(~crossing) + 1
    theirs = [sorted(int(kept[r - 1]) for r in inbox) for inbox in alone]
    assert mine == theirs


def test_walls_off_by_default_for_the_disc_and_without_obstacles_nothing_changes():
    xs, ys = [0.0, 15.0, 30.0], [0.0, 0.0, 0.0]
    with_walls, a = drive({"loss": 0.2}, xs, ys, 200, obstacles=TWO_WALLS)
    without, b = drive({"loss": 0.2}, xs, ys, 200)
    assert a == b and with_walls.ledger.dropped == without.ledger.dropped


def test_rayleigh_fading_with_a_threshold_receiver_delivers_with_probability_exp_minus_x():
    distances = np.linspace(80, 200, 13)
    xs, ys = [0.0, *distances], [0.0] * (len(distances) + 1)
    ticks = 3000
    network = {"propagation": {**LOG_DISTANCE, "fading": "rayleigh", "reception": "threshold"}}
    _, got = drive(network, xs, ys, ticks)
    received = np.zeros(len(distances))
    for inbox in got:
        for r in inbox:
            received[r - 1] += 1
    mean_power = LOG_DISTANCE["tx_power_dbm"] - (46.6777 + 30 * np.log10(distances))
    expected = np.exp(-(10 ** ((-101.0 - mean_power) / 10)))  # P(gain >= threshold / mean power)
    for d, e, f in zip(distances, received / ticks, expected):
        assert abs(e - f) <= binomial_tolerance(f, ticks), f"at {d:.0f} m: {e:.4f} vs {f:.4f}"


def test_nakagami_fading_follows_the_gamma_survival_function():
    distances = np.linspace(100, 200, 6)
    xs, ys = [0.0, *distances], [0.0] * (len(distances) + 1)
    ticks, m = 3000, 2.5
    network = {"propagation": {**LOG_DISTANCE, "fading": "nakagami", "nakagami_m": m, "reception": "threshold"}}
    _, got = drive(network, xs, ys, ticks)
    received = np.zeros(len(distances))
    for inbox in got:
        for r in inbox:
            received[r - 1] += 1
    mean_power = LOG_DISTANCE["tx_power_dbm"] - (46.6777 + 30 * np.log10(distances))
    expected = stats.gamma.sf(10 ** ((-101.0 - mean_power) / 10), a=m, scale=1 / m)
    for d, e, f in zip(distances, received / ticks, expected):
        assert abs(e - f) <= binomial_tolerance(f, ticks), f"at {d:.0f} m: {e:.4f} vs {f:.4f}"


def test_shadowing_is_normal_with_its_sigma_and_decorrelates_over_the_distance_the_pair_moves():
    n, sigma, dcorr, step = 60, 6.0, 20.0, 2.5
    params = NetworkSection(propagation={"shadowing_db": sigma, "decorrelation_distance": dcorr})
    radio = Radio(params, n, 1.0, np.random.default_rng(3))
    prop = radio.propagation
    i, j = np.triu_indices(n, 1)
    first = prop.shadow[i, j].copy()
    assert np.allclose(prop.shadow, prop.shadow.T)
    assert stats.kstest(first / sigma, "norm").pvalue > 1e-3
    ids = list(range(n))
    xs = np.zeros(n)
    radio.route(0, ids, xs, np.zeros(n), {})
    before = prop.shadow[i, j].copy()
    radio.route(1, ids, xs, np.zeros(n), {})  # nobody moved: nothing changes
    assert np.array_equal(prop.shadow[i, j], before)
    radio.route(2, ids, xs + step, np.zeros(n), {})  # everyone moved 2.5: each pair moved 5 in sum
    after = prop.shadow[i, j]
    rho = math.exp(-2 * step / dcorr)
    r = np.corrcoef(before, after)[0, 1]
    se = (1 - rho**2) / math.sqrt(len(i))
    assert abs(r - rho) < SIGMAS * se, (r, rho)
    assert abs(after.std() - sigma) < SIGMAS * sigma / math.sqrt(2 * len(i))


def _runs(lost: np.ndarray) -> np.ndarray:
    """Lengths of the runs of consecutive True."""
    edges = np.diff(np.r_[0, lost.astype(np.int8), 0])
    return np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)


LINKS = 30  # one sender, this many receivers: as many independent chains (bursts per link)


def _lost_per_link(got: list[dict], ticks: range) -> list[np.ndarray]:
    return [np.array([r not in got[k] for k in ticks]) for r in range(1, LINKS + 1)]


@pytest.mark.parametrize("every", [1, 4])
def test_gilbert_elliott_in_time_keeps_its_stationary_loss_and_burst_length_in_seconds(every):
    """Advanced once per tick for every link: a sender that speaks every 4th tick sees the same loss
    and the same bursts in seconds as one that speaks every tick."""
    dt, mean_loss, mean_burst = 0.5, 0.2, 3.0  # seconds
    ticks = 4000
    network = {"burst": {"mean_loss": mean_loss, "mean_burst": mean_burst}}
    xs = [0.0] + [1.0] * LINKS
    radio, got = drive(network, xs, [0.0] * (LINKS + 1), ticks, every=every, dt=dt)
    links = _lost_per_link(got, range(0, ticks, every))
    lost = np.concatenate(links)
    n = len(lost)
    assert abs(lost.mean() - mean_loss) <= SIGMAS * math.sqrt(mean_loss * (1 - mean_loss) / n) * 4  # correlated draws
    r_tick = 1 - math.exp(-dt / mean_burst)  # P(bad -> good) per tick
    p_tick = 1 - math.exp(-dt / (mean_burst * (1 - mean_loss) / mean_loss))
    # seen every `every` ticks, a loss follows a loss with P(bad after `every` ticks | bad now)
    stay = mean_loss + (1 - mean_loss) * (1 - p_tick - r_tick) ** every
    runs = np.concatenate([_runs(link) for link in links])
    expected = 1 / (1 - stay)
    se = math.sqrt(stay / (1 - stay) ** 2 / len(runs))
    assert abs(runs.mean() - expected) <= SIGMAS * se, (runs.mean(), expected)
    if every == 1:
        assert abs(runs.mean() * dt - mean_burst) < 0.2 * mean_burst
    assert radio.ledger.dropped["burst"] == int(lost.sum())


def test_gilbert_elliott_per_packet_matches_tc_netem_gemodel():
    p, r, ticks = 0.05, 0.25, 3000
    xs = [0.0] + [1.0] * LINKS
    radio, got = drive({"burst": {"advance": "packet", "p": p, "r": r}}, xs, [0.0] * (LINKS + 1), ticks)
    links = _lost_per_link(got, range(ticks))
    lost = np.concatenate(links)
    pi_bad = p / (p + r)
    assert abs(lost.mean() - pi_bad) <= SIGMAS * 3 * math.sqrt(pi_bad * (1 - pi_bad) / len(lost))
    runs = np.concatenate([_runs(link) for link in links])
    assert abs(runs.mean() - 1 / r) <= SIGMAS * math.sqrt((1 - r) / r**2 / len(runs))


@pytest.mark.parametrize(
    ("distribution", "mean", "sd"),
    [
        ("normal", 0.5, 0.05),
        ("uniform", 0.5, 0.05 / math.sqrt(3)),
        ("pareto", 0.5, 0.05),
        ("paretonormal", 0.5, 0.05),
    ],
)
def test_delay_draws_have_the_distribution_moments(distribution, mean, sd):
    n = 200000
    delays = Delays(DelaySection(mean=0.5, jitter=0.05, distribution=distribution), 2, np.random.default_rng(1))
    x = delays.draw(np.zeros(n, dtype=np.int64), np.ones(n, dtype=np.int64))
    assert abs(x.mean() - mean) < SIGMAS * sd / math.sqrt(n) * (3 if "pareto" in distribution else 1)
    assert abs(x.std() - sd) < 0.03 * sd * (3 if "pareto" in distribution else 1)
    if distribution == "uniform":
        assert x.min() >= 0.45 - 1e-12 and x.max() <= 0.55 + 1e-12


def test_delay_correlation_is_the_lag_one_correlation_of_a_links_delays():
    n, c = 100000, 0.6
    delays = Delays(DelaySection(mean=1.0, jitter=0.1, correlation=c), 2, np.random.default_rng(2))
    x = np.concatenate([delays.draw(np.zeros(1, dtype=np.int64), np.ones(1, dtype=np.int64)) for _ in range(n // 10)])
    r = np.corrcoef(x[:-1], x[1:])[0, 1]
    assert abs(r - c) < SIGMAS * (1 - c**2) / math.sqrt(len(x))


def test_delay_through_the_radio_delivers_at_the_tick_its_arrival_falls_in():
    """Normal delay of mean 0.25 s and jitter 0.05 s, ticks of 0.1 s: the copy sent at tick k is
    delivered at k + max(1, ceil(D / 0.1)); the share delivered m ticks later follows the normal CDF."""
    dt, ticks = 0.1, 20000
    radio = Radio(NetworkSection(delay={"mean": 0.25, "jitter": 0.05}), 2, dt, np.random.default_rng(5))
    lags: list[int] = []
    for k in range(ticks + 10):
        outs = {0: [RadioMessage(BROADCAST, "x", k.to_bytes(4, "big"))]} if k < ticks else {}
        radio.route(k, [0, 1], [0.0, 1.0], [0.0, 0.0], outs)
        for _sender, _kind, payload in radio.deliver(k + 1, [0, 1]).get(1, []):
            lags.append(k + 1 - int.from_bytes(payload, "big"))
        radio.confirm()
    assert len(lags) == ticks == radio.ledger.delivered
    cdf = stats.norm(0.25, 0.05).cdf
    counts = np.bincount(lags, minlength=8)
    for m in range(1, 6):
        expected = cdf(m * dt) - (cdf((m - 1) * dt) if m > 1 else 0.0)
        got = counts[m] / ticks
        assert abs(got - expected) <= binomial_tolerance(expected, ticks), (m, got, expected)
    assert sorted(lags) != lags  # copies overtake one another


def _inboxes_of(network: dict, seed: int):
    rng = np.random.default_rng(99)
    n = 12
    xs, ys = rng.uniform(0, 150, n), rng.uniform(0, 150, n)
    radio = Radio(
        NetworkSection(**network),
        n,
        0.5,
        np.random.default_rng(seed),
        Ledger(reasons=drop_reasons(NetworkSection(**network))),
    )
    seen = []
    for k in range(400):
        xs, ys = xs + rng.normal(0, 1, n), ys + rng.normal(0, 1, n)
        outs = {s: [RadioMessage(BROADCAST, "b", bytes([s, k % 256]) * (1 + s))] for s in range(n) if (s + k) % 3 == 0}
        outs.setdefault(0, []).append(RadioMessage((3, 4, 40), "u", b"u" * 9))
        radio.route(k, list(range(n)), xs.tolist(), ys.tolist(), outs)
        inbox = radio.deliver(k + 1, list(range(n)))
        radio.confirm()
        seen.append({r: [(m[0], m[1], bytes(m[2])) for m in v] for r, v in sorted(inbox.items())})
    radio.finish(400)
    return radio, seen


EVERYTHING = {
    "range": 140.0,
    "loss": 0.05,
    "rate": 2000.0,
    "propagation": {"shadowing_db": 4.0, "fading": "nakagami", "nakagami_m": 1.5, "coherence_time": 1.0},
    "burst": {"mean_loss": 0.1, "mean_burst": 2.0},
    "delay": {"mean": 0.3, "jitter": 0.2, "distribution": "paretonormal", "correlation": 0.3},
    "channel": {"capacity": 60.0},
}


def test_every_model_at_once_is_deterministic_under_its_seed_and_accounts_for_every_copy():
    a, seen_a = _inboxes_of(EVERYTHING, seed=11)
    b, seen_b = _inboxes_of(EVERYTHING, seed=11)
    c, seen_c = _inboxes_of(EVERYTHING, seed=12)
    assert seen_a == seen_b and seen_a != seen_c
    assert a.ledger.totals() == b.ledger.totals()
    for radio in (a, b, c):
        led = radio.ledger
        led.check()  # copies = delivered + dropped, exactly
        for reason in (
            "below_sensitivity",
            "channel_busy",
            "packet_error",
            "burst",
            "loss",
            "out_of_range",
            "no_such_receiver",
        ):
            assert led.dropped[reason] > 0, reason


def test_turning_one_model_on_leaves_the_independent_loss_draws_as_they_were():
    """Each model draws from its own stream: a delay that draws a normal for every copy but never
    moves one out of the next 0.5 s tick (10 ms +- 1 ms) leaves every loss draw, and so every
    inbox, as it was. Were the delay drawn from the radio's own generator, the next tick's loss
    draws would shift."""
    base = {"range": 140.0, "loss": 0.2}
    _, plain = _inboxes_of(base, seed=4)
    _, delayed = _inboxes_of({**base, "delay": {"mean": 0.01, "jitter": 0.001}}, seed=4)
    assert plain == delayed


def test_a_burst_section_with_two_parametrisations_is_one_line_naming_it():
    with pytest.raises(ValueError, match="give mean_loss and mean_burst, or good_s and bad_s"):
        BurstSection(mean_loss=0.1, mean_burst=2.0, good_s=3.0, bad_s=1.0)
    with pytest.raises(ValueError, match="p and r belong to advance: packet"):
        BurstSection(p=0.1, r=0.5)


def test_params_network_lists_every_key_of_every_model_and_a_bad_one_is_named(capsys, tmp_path):
    from swarmbed.cli.main import main as cli
    from tests.conftest import QUICKSTART

    assert cli(["params", "network"]) == 0
    out = capsys.readouterr().out
    for key in ("network.propagation.shadowing_db", "network.burst.mean_burst", "network.delay.correlation"):
        assert key in out, key
    assert cli(["run", str(QUICKSTART), "--out", str(tmp_path), "--set", "network.burst={mean_loss: 0.1}"]) == 2
    assert "network.burst" in capsys.readouterr().err


@pytest.mark.parametrize("senders", [2, 6])
def test_a_shared_channel_gives_each_receiver_its_capacity_at_saturation_first_come_first_served(senders):
    """Every robot broadcasts one 100-byte message per 0.5 s tick; a receiver hears 500 B/s, so 250
    bytes a tick: two messages. Below saturation everything arrives; at saturation each receiver
    gets exactly two a tick, from the lowest sender ids (copy order), the rest are channel_busy."""
    n, ticks, size = senders + 1, 200, 100
    params = NetworkSection(channel={"capacity": 500.0})
    radio = Radio(params, n, 0.5, np.random.default_rng(1), Ledger(reasons=drop_reasons(params)))
    heard: dict[int, list[int]] = {r: [] for r in range(n)}
    msg = RadioMessage(BROADCAST, "x", bytes(size))
    for k in range(ticks):
        radio.route(k, list(range(n)), [0.0] * n, [0.0] * n, {s: [msg] for s in range(n)})
        for r, inbox in radio.deliver(k + 1, list(range(n))).items():
            heard[r].append(len(inbox))
            if k == 0:
                assert [m[0] for m in inbox] == [s for s in range(n) if s != r][:2], inbox
        radio.confirm()
    offered = n - 1
    per_tick = min(offered, int(500.0 * 0.5 // size))
    for r in range(n):
        assert heard[r] == [per_tick] * (ticks - 1) or heard[r] == [per_tick] * ticks, (r, heard[r][:5])
    led = radio.ledger
    assert led.dropped["channel_busy"] == ticks * n * (offered - per_tick)
    led.check()


def test_the_receiver_ledger_records_each_copys_distance_power_snr_and_delay(tmp_path):
    import pandas as pd

    from swarmbed.netem.ledger import ReceiverLog

    params = NetworkSection(propagation=LOG_DISTANCE, delay={"mean": 0.4, "jitter": 0.1})
    log = ReceiverLog(tmp_path / "copies.parquet", measured=True)
    radio = Radio(params, 6, 0.5, np.random.default_rng(2), Ledger(receivers=log, reasons=drop_reasons(params)))
    xs = [0.0, 30.0, 60.0, 75.0, 90.0, 250.0]
    for k in range(200):
        radio.route(k, list(range(6)), xs, [0.0] * 6, {0: [RadioMessage(BROADCAST, "x", bytes(60))]})
        radio.deliver(k + 1, list(range(6)))
        radio.confirm()
    radio.finish(200)
    log.close()
    rows = pd.read_parquet(tmp_path / "copies.parquet")
    copies = rows[rows["outcome"] != "sent"]
    assert len(copies) == 200 * 5
    expected_power = 16.0206 - (46.6777 + 30 * np.log10(copies["distance"]))
    assert np.allclose(copies["power_dbm"], expected_power)
    assert np.allclose(copies["snr_db"], copies["power_dbm"] + 93.97)
    assert np.allclose(copies["distance"], np.array(xs)[copies["receiver"]])
    delivered = copies[copies["outcome"] == "delivered"]
    assert delivered["delay_s"].notna().all() and abs(delivered["delay_s"].mean() - 0.4) < 0.02
    lost = copies[~copies["outcome"].isin(["delivered", "run_ended"])]  # in flight at the end: delayed too
    assert lost["delay_s"].isna().all() and copies[copies["outcome"] == "run_ended"]["delay_s"].notna().all()
    assert set(copies["outcome"]) >= {"delivered", "below_sensitivity", "packet_error"}


@pytest.mark.parametrize(
    "extra",
    [{}, {"fading": "rayleigh"}, {"shadowing_db": 6.0}, {"fading": "nakagami", "nakagami_m": 2.5, "shadowing_db": 4.0}],
    ids=["plain", "rayleigh", "shadowing", "nakagami+shadowing"],
)
def test_the_model_curve_is_the_delivery_ratio_the_radio_draws(extra):
    """netem.propagation.delivery_probability (the report's curve) against copies drawn through the
    radio: static pairs, shadowing redrawn by moving the pair far between ticks is not needed, as
    many independent receivers at each distance average the shadowing instead."""
    from swarmbed.netem.propagation import delivery_probability

    distances = np.repeat(np.linspace(60, 140, 9), 40)  # 40 receivers per distance: 40 shadowing draws
    angles = np.linspace(0, 2 * np.pi, len(distances), endpoint=False)
    xs, ys = [0.0, *(distances * np.cos(angles))], [0.0, *(distances * np.sin(angles))]
    ticks, payload = 300, 60
    network = {"propagation": {**LOG_DISTANCE, **extra}}
    _, got = drive(network, xs, ys, ticks, payload)
    received = np.zeros(len(distances))
    for inbox in got:
        for r in inbox:
            received[r - 1] += 1
    params = NetworkSection(**network).propagation
    expected = delivery_probability(params, distances, payload)
    for d in np.unique(distances):
        at = distances == d
        e, f = received[at].sum() / (ticks * at.sum()), expected[at][0]
        # shadowing draws are shared per pair across ticks: the spread is of 40 pairs, not of all copies
        n = at.sum() if params.shadowing_db > 0 else ticks * at.sum()
        assert abs(e - f) <= binomial_tolerance(f, n) + 0.01, f"at {d:.0f} m: {e:.4f} vs {f:.4f}"


def test_every_reason_a_radio_may_drop_for_has_its_colour_in_every_view():
    """The stages name their reasons and colours; a model whose reason had no colour was left out
    of the replay's legend and drawn in the report's default colour (channel_busy was)."""
    from swarmbed.netem.radio import STAGES
    from swarmbed.results.colours import DROP_COLORS

    every = NetworkSection(
        range=100,
        loss=0.1,
        propagation={},
        burst={"mean_loss": 0.2, "mean_burst": 5.0},
        channel={"capacity": 1000},
        walls={"line_of_sight": True},
        delay={"mean": 0.1},
    )
    reasons = drop_reasons(every)
    assert [s.reason for s in STAGES if s.on(every)] == [s.reason for s in STAGES]  # each stage on
    assert set(reasons) == set(DROP_COLORS)
    assert len(set(DROP_COLORS.values())) == len(DROP_COLORS)  # no two reasons look alike
    assert drop_reasons(NetworkSection()) == reasons[: reasons.index("late") + 1]  # the disk's alone


def test_parameters_replaced_mid_run_turn_their_stages_on_and_off():
    """A soak's loss burst replaces the radio's parameters (loss 0 -> 0.6 -> 0) between ticks: the
    loss stage must follow them, as a radio built with those parameters would."""
    params = NetworkSection()
    radio = Radio(params, 3, 1.0, np.random.default_rng(1), Ledger(reasons=drop_reasons(params)))
    msg = RadioMessage(BROADCAST, "x", b"p" * 10)

    def lost_at(tick: int) -> int:
        before = radio.ledger.dropped["loss"]
        radio.route(tick, [0, 1, 2], [0.0, 1.0, 2.0], [0.0, 0.0, 0.0], {0: [msg] * 20})
        radio.deliver(tick + 1, [0, 1, 2])
        radio.confirm()
        return radio.ledger.dropped["loss"] - before

    assert lost_at(0) == 0
    radio.params = params.model_copy(update={"loss": 1.0})
    assert lost_at(1) == 40  # every copy of 20 broadcasts to 2 receivers
    radio.params = params
    assert lost_at(2) == 0
