"""The proxy's routing alone: milliseconds per tick for the radio model to decide every copy of a
tick (addressing, range, loss, the ledger's bookings) and hand out the next tick's inboxes, with
every agent broadcasting one 200-byte message per tick, agents spread over SPACE's 1400 x 1000
arena, 10 % loss. No process and no network: this is the Python work inside the proxy.

    python benchmarks/radio.py                 # N = 50, 100, 200, 500
    python benchmarks/radio.py --n 1000 --ticks 10
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from swarmbed.netem.ledger import Ledger
from swarmbed.netem.radio import Radio
from swarmbed.wire.codec import BROADCAST, RadioMessage
from swarmbed.wire.schema import NetworkSection


def ms_per_tick(n: int, comm_range: float | None, ticks: int) -> tuple[float, int]:
    place = np.random.default_rng(1)
    radio = Radio(
        NetworkSection.model_validate({"range": comm_range, "loss": 0.1}), n, 1.0, np.random.default_rng(2), Ledger()
    )
    ids = list(range(n))
    xs, ys = place.uniform(0, 1400, n).tolist(), place.uniform(0, 1000, n).tolist()
    outs = {a: [RadioMessage(BROADCAST, "bench", bytes(200))] for a in ids}
    start = time.perf_counter()
    for k in range(ticks):
        radio.route(k, ids, xs, ys, outs)
        radio.deliver(k + 1, ids)
        radio.confirm()
        radio.ledger.close_tick(k)
    return (time.perf_counter() - start) / ticks * 1e3, radio.ledger.delivered // ticks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[50, 100, 200, 500])
    ap.add_argument("--ticks", type=int, default=40)
    args = ap.parse_args()
    print(f"{'N':>5} {'range':>6} {'copies/tick':>12} {'delivered/tick':>15} {'ms/tick':>8}")
    for n in args.n:
        for comm_range in (100.0, 300.0, None):
            ms, delivered = ms_per_tick(n, comm_range, args.ticks)
            label = "-" if comm_range is None else f"{comm_range:.0f}"
            print(f"{n:>5} {label:>6} {n * (n - 1):>12} {delivered:>15} {ms:>8.2f}")


if __name__ == "__main__":
    main()
