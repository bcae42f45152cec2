"""Lock-step throughput: swarmbed (no-op allocator, each agent messages 5 peers per tick) next to two
raw Zenoh baselines measured in the same run: the relay (a hub ticks N client processes; each sends
one message through a relay process to 5 others, waits for the 5 it is owed, then replies) and the
bare barrier floor (one sample in and one out per client per tick, nothing else).

    python benchmarks/lockstep.py            # N = 10, 50, 100
    python benchmarks/lockstep.py --n 10 20  # other sizes

Prints ticks per second of all three, swarmbed's ratio to each, its start-up time and the memory
each agent process holds of its own (USS); then, from the run's timings.json, what one agent-tick
cost over the tick loop in wake-ups (voluntary context switches of every thread of every run
process) and CPU microseconds, by process kind: figures that do not move with the machine's day.
``ZENOH_RUNTIME`` in the environment reaches every run process (issue 32's single-worker layout).
"""

from __future__ import annotations

import argparse
import queue
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import zenoh

from swarmbed.experiments.launch import config as cfg
from swarmbed.experiments.launch.hub import HubOptions, open_hub
from swarmbed.experiments.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parent.parent

BLOCK = zenoh.CongestionControl.BLOCK


def raw_baseline(n: int, ticks: int, fanout: int = 5) -> float:
    """Ticks per second of ``n`` raw Zenoh clients; ``fanout`` 0: the bare barrier (no relay)."""
    session, endpoint = open_hub()
    ns = f"bench/{time.monotonic_ns()}"
    alive: queue.SimpleQueue = queue.SimpleQueue()
    done: queue.SimpleQueue = queue.SimpleQueue()
    live = session.liveliness().declare_subscriber(f"{ns}/alive/*", lambda s: alive.put(1), history=True)
    sub = session.declare_subscriber(f"{ns}/done", lambda s: done.put(1))
    tick_pubs = [session.declare_publisher(f"{ns}/c/{i}/tick", congestion_control=BLOCK) for i in range(n)]
    relay_pub = session.declare_publisher(f"{ns}/relay", congestion_control=BLOCK)
    script = str(ROOT / "benchmarks" / "raw_zenoh.py")
    env_cmd = [sys.executable, script]
    procs = (
        [subprocess.Popen([*env_cmd, "relay", "--ns", ns, "--connect", endpoint, "--n", str(n)], cwd=ROOT)]
        if fanout
        else []
    )
    procs += [
        subprocess.Popen(
            [*env_cmd, "client", "--ns", ns, "--connect", endpoint, "--id", str(i), "--fanout", str(fanout)], cwd=ROOT
        )
        for i in range(n)
    ]
    try:
        for _ in range(len(procs)):
            alive.get(timeout=120)
        t0 = time.perf_counter()
        for k in range(ticks):
            payload = struct.pack("<q", k)
            for p in tick_pubs:
                p.put(payload)
            for _ in range(n):
                done.get(timeout=60)
        rate = ticks / (time.perf_counter() - t0)
        for p in tick_pubs:
            p.put(struct.pack("<q", -1))
        relay_pub.put(struct.pack("<qq", -1, 0))
        for p in procs:
            p.wait(timeout=30)
        return rate
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
        live.undeclare()
        sub.undeclare()
        session.close()


def swarmbed_run(n: int, ticks: int, auth: bool = True) -> dict:
    exp = cfg.load(
        ROOT / "experiments" / "quickstart.yaml",
        [
            f"agents.count={n}",
            "allocator={name: noop, peers: 5}",
            "scenario.initial_tasks=0",
            "run.stop_when_done=false",
            f"run.duration={ticks}",
            "network.range=null",
            "run.record_every=1000000",
        ],
    )
    with tempfile.TemporaryDirectory() as out:
        result = run_experiment(exp, Path(out), progress=False, hub=HubOptions(auth=auth))
    t = result.timings
    return {
        "ticks_per_s": t["ticks_per_s"],
        "startup_s": t["startup_s"],
        "uss_mb": t["agent_uss_mb_mean"],
        "copies": result.summary["network"]["copies"],
        "wakeups": t["per_agent_tick"]["wakeups"],
        "cpu_us": t["per_agent_tick"]["cpu_us"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[10, 50, 100])
    ap.add_argument("--seconds", type=float, default=6.0, help="rough measuring time per case")
    args = ap.parse_args()
    print(
        f"{'N':>4} {'barrier ticks/s':>15} {'relay ticks/s':>13} {'swarmbed ticks/s':>17} {'/barrier':>8} "
        f"{'/relay':>6} {'startup s':>10} {'USS/agent MB':>13}"
    )
    for n in args.n:
        guess = {10: 800, 50: 120, 100: 40}.get(n, max(20, 4000 // n))
        ticks = max(50, int(guess * args.seconds))
        floor = raw_baseline(n, 2 * ticks, fanout=0)
        raw = raw_baseline(n, ticks)
        ours = swarmbed_run(n, ticks)
        print(
            f"{n:>4} {floor:>15.1f} {raw:>13.1f} {ours['ticks_per_s']:>17.1f} {ours['ticks_per_s'] / floor:>8.2f} "
            f"{ours['ticks_per_s'] / raw:>6.2f} {ours['startup_s']:>10.1f} {ours['uss_mb']:>13.1f}",
            flush=True,
        )
        woke, cpu = ours["wakeups"], ours["cpu_us"]
        print(
            "      per agent-tick (counts, not times): wake-ups "
            + ", ".join(f"{k} {woke[k]:.2f}" for k in ("agents", "hub", "netem", "total"))
            + "; CPU us "
            + ", ".join(f"{k} {cpu[k]:.0f}" for k in ("agents", "hub", "netem", "total")),
            flush=True,
        )


if __name__ == "__main__":
    main()
