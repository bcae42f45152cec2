"""The proxy's routing alone: milliseconds per tick for the radio model to decide every copy of a
tick (addressing, range, loss, the ledger's bookings) and hand out the next tick's inboxes, with
every agent broadcasting one 200-byte message per tick, agents spread over SPACE's 1400 x 1000
arena, 10 % loss. No process and no network: this is the Python work inside the proxy.

    python benchmarks/radio.py                 # N = 50, 100, 200, 500
    python benchmarks/radio.py --n 1000 --ticks 10

A second table sets the disk against the full model chain of ``network:`` (log-distance path loss
with shadowing and Rayleigh fading, Gilbert-Elliott bursts, delay with jitter and correlation, a
shared channel) at
200 and 500 agents, moving at random, one 120-byte broadcast each per tick: milliseconds per tick
(median) and the chain's cost as a multiple of the disk's measured in the same run. They run
interleaved (disk, chain, disk); the disk's two figures are printed, and if they differ by more
than 10 % the machine was not idle and the ratio is flagged. Target (issue 33): the chain at most
twice the disk at 200 agents.

A third table puts walls in (issue 61): 50 agents, a range of 300, 0 / 50 / 200 random wall
segments (20-80 units long) with line of sight (each crossing copy dropped), and 200 with
propagation (each crossing costs 6.9 dB): milliseconds per tick and the walls' cost as a multiple
of the same radio without them, measured in the same run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from swarmbed.netem.ledger import Ledger
from swarmbed.netem.radio import Radio, drop_reasons
from swarmbed.schema.experiment import NetworkSection
from swarmbed.schema.obstacles import ObstaclesSection, Walls
from swarmbed.wire.codec import BROADCAST, RadioMessage


def ms_per_tick(n: int, comm_range: float | None, ticks: int) -> tuple[float, int]:
    place = np.random.default_rng(1)
    radio = Radio(
        NetworkSection.model_validate({"range": comm_range, "loss": 0.1}), n, 1.0, np.random.default_rng(2), Ledger()
    )
    ids = list(range(n))
    xs, ys = place.uniform(0, 1400, n).tolist(), place.uniform(0, 1000, n).tolist()
    outs = {a: [RadioMessage(BROADCAST, "bench", bytes(200))] for a in ids}
    warm = Radio(radio.params, n, 1.0, np.random.default_rng(2), Ledger())  # imports (the range's KD-tree) once
    warm.route(0, ids, xs, ys, outs)
    start = time.perf_counter()
    for k in range(ticks):
        radio.route(k, ids, xs, ys, outs)
        radio.deliver(k + 1, ids)
        radio.confirm()
        radio.ledger.close_tick(k)
    return (time.perf_counter() - start) / ticks * 1e3, radio.ledger.delivered // ticks


DISK = {"range": 300.0, "loss": 0.1}
CHAIN = {
    "range": 300.0,
    "loss": 0.01,
    "propagation": {"shadowing_db": 4.0, "fading": "rayleigh", "coherence_time": 1.0},
    "burst": {"mean_loss": 0.05, "mean_burst": 2.0},
    "delay": {"mean": 0.05, "jitter": 0.02, "distribution": "normal", "correlation": 0.25},
    "channel": {"capacity": 50000.0},
}


def random_walls(count: int, seed: int = 5) -> Walls | None:
    """``count`` wall segments 20-80 units long at random in the arena (heavy: 6.9 dB each)."""
    if not count:
        return None
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(50, 1350, count), rng.uniform(50, 950, count)
    angle, length = rng.uniform(0, np.pi, count), rng.uniform(20, 80, count)
    walls = [
        {"start": [float(a), float(b)], "end": [float(a + L * np.cos(t)), float(b + L * np.sin(t))]}
        for a, b, t, L in zip(x, y, angle, length)
    ]
    return ObstaclesSection(walls=walls).compile({"heavy": 6.9})


def chain_ms(network: dict, agents: int, ticks: int, seed: int = 1, walls: Walls | None = None) -> tuple[float, float]:
    """Median ms per tick and copies per tick, agents moving at random."""
    rng = np.random.default_rng(seed)
    params = NetworkSection.model_validate(network)
    radio = Radio(params, agents, 0.25, np.random.default_rng(seed), Ledger(reasons=drop_reasons(params)), walls)
    ids = list(range(agents))
    x, y = rng.uniform(0, 1400, agents), rng.uniform(0, 1000, agents)
    outs = {i: [RadioMessage(BROADCAST, "bid", bytes(120))] for i in ids}
    times = []
    for k in range(ticks):
        x = np.clip(x + rng.normal(0, 1, agents), 0, 1400)
        y = np.clip(y + rng.normal(0, 1, agents), 0, 1000)
        xs, ys = x.tolist(), y.tolist()
        t0 = time.perf_counter()
        radio.route(k, ids, xs, ys, outs)
        radio.deliver(k + 1, ids)
        radio.confirm()
        radio.ledger.close_tick(k)
        times.append(time.perf_counter() - t0)
    return 1000 * float(np.median(times)), radio.ledger.copies / ticks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[50, 100, 200, 500])
    ap.add_argument("--ticks", type=int, default=40)
    ap.add_argument("--chain-n", type=int, nargs="*", default=[200, 500], help="agents for the disk/chain table")
    args = ap.parse_args()
    print(f"{'N':>5} {'range':>6} {'copies/tick':>12} {'delivered/tick':>15} {'ms/tick':>8}")
    for n in args.n:
        for comm_range in (100.0, 300.0, None):
            ms, delivered = ms_per_tick(n, comm_range, args.ticks)
            label = "-" if comm_range is None else f"{comm_range:.0f}"
            print(f"{n:>5} {label:>6} {n * (n - 1):>12} {delivered:>15} {ms:>8.2f}")
    print(f"\n{'N':>5} {'model':>6} {'copies/tick':>12} {'ms/tick':>8} {'x disk':>7}")
    for n in args.chain_n:
        chain_ms(CHAIN, n, 10)  # warm-up: allocator and caches, not measured
        disk_a, copies = chain_ms(DISK, n, args.ticks)
        chain, chain_copies = chain_ms(CHAIN, n, args.ticks)
        disk_b, _ = chain_ms(DISK, n, args.ticks)
        disk = (disk_a + disk_b) / 2
        busy = "" if abs(disk_a - disk_b) <= 0.1 * disk else "  disk figures differ by > 10 %: machine busy?"
        print(f"{n:>5} {'disk':>6} {copies:>12.0f} {disk:>8.2f} {1.0:>7.2f}  ({disk_a:.2f}, {disk_b:.2f}){busy}")
        print(f"{n:>5} {'chain':>6} {chain_copies:>12.0f} {chain:>8.2f} {chain / disk:>7.2f}", flush=True)
    print(f"\n{'N':>5} {'walls':>6} {'model':>13} {'copies/tick':>12} {'ms/tick':>8} {'x none':>7}")
    sight = {"range": 300.0, "loss": 0.1, "walls": {"line_of_sight": True}}
    power = {"loss": 0.0, "propagation": {}}
    for network, label, counts in ((sight, "line of sight", (0, 50, 200)), (power, "propagation", (0, 200))):
        base = None
        for count in counts:
            ms, copies = chain_ms(network, 50, args.ticks, walls=random_walls(count))
            base = ms if base is None else base
            print(f"{50:>5} {count:>6} {label:>13} {copies:>12.0f} {ms:>8.2f} {ms / base:>7.2f}", flush=True)


if __name__ == "__main__":
    main()
