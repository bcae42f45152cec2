"""Lock-step throughput: swarmbed (no-op allocator, each agent messages 5 peers per tick) against
floors measured in the same run, interleaved (B0 B1 B2, swarmbed, B0 B1 B2: a floor whose two
figures differ by more than 10 % is flagged with ``!``):

- B0, the bare barrier with Zenoh's defaults: a hub ticks N client processes, each replies with one
  sample, nothing else;
- B1, the same barrier tuned: every client on one Zenoh worker thread (``ZENOH_RUNTIME``, as
  ``run.zenoh_threads: single``) answering inside a direct callback (no Python thread hop);
- B2, swarmbed's skeleton with no Python work, tuned like B1: hub -> N agents -> one output each
  -> a separate proxy process that counts them -> one step sample back to the hub.

    python benchmarks/lockstep.py                 # N = 50, 100, 200
    python benchmarks/lockstep.py --n 10 20       # other sizes
    python benchmarks/lockstep.py --relay         # also the retired relay baseline

For each N it prints ticks per second of every case and swarmbed's ratio to each floor (with
each ``run.zenoh_threads``: ``zenoh``, Zenoh's own threads; ``default``; ``single``); then, per case,
what one agent-tick cost over the tick loop in wake-ups (voluntary context switches of every thread of
every process of the case, hub included) and, for swarmbed, CPU microseconds by process kind:
counts that do not move with the machine's day. The hub (this process) keeps Zenoh's default
layout in every case.
"""

from __future__ import annotations

import argparse
import os
import queue
import struct
import subprocess
import sys
import tempfile
import time
from importlib.metadata import version
from pathlib import Path

import psutil
import zenoh

import swarmbed
from swarmbed import config as cfg
from swarmbed.launch.hub import HubOptions, open_hub
from swarmbed.launch.launcher import wakeups
from swarmbed.launch.runner import run_experiment
from swarmbed.wire.zenoh_session import SINGLE_WORKER

ROOT = Path(__file__).resolve().parent.parent

BLOCK = zenoh.CongestionControl.BLOCK
FLOORS = ("B0", "B1", "B2")
DRIFT = 0.10


def _cpu(pids: list[int]) -> list[float]:
    """User and system CPU seconds so far of each process (every thread)."""
    out = []
    for pid in pids:
        t = psutil.Process(pid).cpu_times()
        out.append(t.user + t.system)
    return out


def floor(kind: str, n: int, ticks: int) -> dict:
    """Ticks per second and wake-ups per client-tick of one raw Zenoh case: ``B0``, ``B1``, ``B2``
    or ``relay`` (each client relays one message to 5 others through a relay process)."""
    session, endpoint = open_hub()
    ns = f"bench/{time.monotonic_ns()}"
    alive: queue.SimpleQueue = queue.SimpleQueue()
    done: queue.SimpleQueue = queue.SimpleQueue()
    live = session.liveliness().declare_subscriber(f"{ns}/alive/*", lambda s: alive.put(1), history=True)
    sub = session.declare_subscriber(f"{ns}/step" if kind == "B2" else f"{ns}/done", lambda s: done.put(1))
    tick_pubs = [session.declare_publisher(f"{ns}/c/{i}/tick", congestion_control=BLOCK) for i in range(n)]
    script = str(ROOT / "benchmarks" / "raw_zenoh.py")
    common = ["--ns", ns, "--connect", endpoint]
    env = {**os.environ, "ZENOH_RUNTIME": SINGLE_WORKER} if kind in ("B1", "B2") else dict(os.environ)
    if kind == "B2":
        argv = [["proxy", *common, "--n", str(n)]] + [["agent", *common, "--id", str(i)] for i in range(n)]
    elif kind == "relay":
        argv = [["relay", *common, "--n", str(n)]] + [["client", *common, "--id", str(i)] for i in range(n)]
    else:
        extra = ["--direct"] if kind == "B1" else []
        argv = [["client", *common, "--id", str(i), "--fanout", "0", *extra] for i in range(n)]
    procs = [subprocess.Popen([sys.executable, script, *a], cwd=ROOT, env=env) for a in argv]
    pids = [os.getpid()] + [p.pid for p in procs]
    replies = 1 if kind == "B2" else n
    try:
        for _ in range(len(procs)):
            alive.get(timeout=120)
        woke0 = sum(wakeups(pid) for pid in pids)
        cpu0 = _cpu(pids)
        t0 = time.perf_counter()
        for k in range(ticks):
            payload = struct.pack("<q", k)
            for p in tick_pubs:
                p.put(payload)
            for _ in range(replies):
                done.get(timeout=60)
        rate = ticks / (time.perf_counter() - t0)
        woke = (sum(wakeups(pid) for pid in pids) - woke0) / (n * ticks)
        cpu = [(b - a) * 1e6 / (n * ticks) for a, b in zip(cpu0, _cpu(pids))]
        for p in tick_pubs:
            p.put(struct.pack("<q", -1))
        session.put(f"{ns}/relay", struct.pack("<qq", -1, 0))
        session.put(f"{ns}/stop", b"")
        for p in procs:
            p.wait(timeout=30)
        # CPU per client-tick: the clients (B2: its agents), the proxy (B2 only), this process (the hub)
        clients = cpu[2:] if kind in ("B2", "relay") else cpu[1:]
        helper = cpu[1] if kind in ("B2", "relay") else 0.0
        return {"ticks_per_s": rate, "wakeups": woke, "cpu_us": (sum(clients), helper, cpu[0])}
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
        live.undeclare()
        sub.undeclare()
        session.close()


def swarmbed_run(n: int, ticks: int, threads: str = "default", auth: bool = True) -> dict:
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
            f"run.zenoh_threads={threads}",
        ],
    )
    with tempfile.TemporaryDirectory() as out:
        result = run_experiment(exp, Path(out), progress=False, hub=HubOptions(auth=auth))
    t = result.timings
    return {
        "ticks_per_s": t["ticks_per_s"],
        "startup_s": t["startup_s"],
        "uss_mb": t["agent_uss_mb_mean"],
        "wakeups": t["per_agent_tick"]["wakeups"],
        "cpu_us": t["per_agent_tick"]["cpu_us"],
    }


def _pair(first: dict, second: dict) -> tuple[float, float, bool, list[float]]:
    """A floor's mean rate, wake-ups and CPU over its two interleaved runs, and whether they drifted."""
    a, b = first["ticks_per_s"], second["ticks_per_s"]
    cpu = [(x + y) / 2 for x, y in zip(first["cpu_us"], second["cpu_us"])]
    return (a + b) / 2, (first["wakeups"] + second["wakeups"]) / 2, abs(a - b) > DRIFT * max(a, b), cpu


#: the thread layouts of ``run.zenoh_threads`` measured
LAYOUTS = ("zenoh", "default", "single")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[50, 100, 200])
    ap.add_argument("--seconds", type=float, default=6.0, help="rough measuring time per case")
    ap.add_argument("--relay", action="store_true", help="also the retired relay baseline")
    args = ap.parse_args()
    print(f"eclipse-zenoh {version('eclipse-zenoh')}, swarmbed {swarmbed.__version__}")
    print(f"single worker: ZENOH_RUNTIME={SINGLE_WORKER}")
    for n in args.n:
        ticks = max(50, int(max(10, 6000 // n) * args.seconds))
        runs: dict[str, list[dict]] = {k: [] for k in FLOORS}
        for kind in FLOORS:
            runs[kind].append(floor(kind, n, ticks))
        ours = {t: swarmbed_run(n, ticks, t) for t in LAYOUTS}
        for kind in FLOORS:
            runs[kind].append(floor(kind, n, ticks))
        relay = floor("relay", n, ticks) if args.relay else None
        print(f"N = {n}, {ticks} ticks per case")
        print(f"  {'case':<18} {'ticks/s':>8} {'wake-ups/agent-tick':>20}   swarmbed {' / '.join(LAYOUTS)}")
        rates = {}
        for kind in FLOORS:
            rate, woke, drift, cpu = _pair(*runs[kind])
            rates[kind] = rate
            ratios = " / ".join(f"{ours[t]['ticks_per_s'] / rate:.2f}" for t in LAYOUTS)
            print(f"  {kind + (' !' if drift else ''):<18} {rate:>8.1f} {woke:>20.2f}   {ratios}", flush=True)
            proxy = f", proxy {cpu[1]:.0f}" if kind == "B2" else ""
            print(f"      per agent-tick: CPU us clients {cpu[0]:.0f}{proxy}, hub {cpu[2]:.0f}", flush=True)
        if relay:
            print(f"  {'relay':<18} {relay['ticks_per_s']:>8.1f} {relay['wakeups']:>20.2f}")
        for t, r in ours.items():
            woke, cpu = r["wakeups"], r["cpu_us"]
            print(
                f"  {'swarmbed ' + t:<18} {r['ticks_per_s']:>8.1f} {woke['total']:>20.2f}   "
                f"(startup {r['startup_s']:.1f} s, USS/agent {r['uss_mb']:.1f} MB)"
            )
            print(
                "      per agent-tick: wake-ups "
                + ", ".join(f"{k} {woke[k]:.2f}" for k in ("agents", "hub", "netem"))
                + "; CPU us "
                + ", ".join(f"{k} {cpu[k]:.0f}" for k in ("agents", "hub", "netem", "total")),
                flush=True,
            )


if __name__ == "__main__":
    main()
