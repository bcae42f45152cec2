"""What a run's hub and proxy pay per tick as its agents spread over more hosts (needs root and
iproute2: the hosts are stand-ins, network namespaces on a bridge, one ``swarmbed host`` each).

    sudo python benchmarks/hub_load.py                    # 200 agents: all local, then over 1, 2 and 4 hosts
    sudo python benchmarks/hub_load.py --agents 100 --ticks 100 --hosts 0 2

For each layout, the same lock-step run (the no-op allocator, every agent messaging 5 peers a tick,
no range): ticks per second; the hub's CPU per tick (the launcher's process: the hub router, the
coordinator and this script's sampler thread) and its wake-ups per tick; the proxy's CPU per tick;
the TCP segments the hub's process sends and receives per tick, read from the kernel's counters of
its own sockets (``swarmbed.wire.tcp_counters``) four times a second while the ticks run; and the
host daemons' own CPU (their routers) per tick, start-up included. Each
layout's result files are compared with the all-local run's. Run it from a separate non-editable
install on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import tempfile
import threading
import time
from pathlib import Path

import psutil

from swarmbed import config as cfg
from swarmbed.hosts.netns import Lab, LabError, make_lab
from swarmbed.launch.runner import run_experiment
from swarmbed.wire.tcp_counters import tcp_counters

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ("summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv")


class Segments:
    """The hub process's TCP segments over time, sampled from the run's start to its end."""

    def __init__(self) -> None:
        self.readings: list[tuple[float, int]] = []
        self.stop = threading.Event()

    def start(self, *_: object) -> None:
        threading.Thread(target=self._sample, daemon=True).start()

    def _sample(self) -> None:
        while not self.stop.wait(0.25):
            counters = tcp_counters()
            if counters:
                self.readings.append((time.perf_counter(), counters["segments_in"] + counters["segments_out"]))

    def per_second(self) -> float:
        """Segments a second over the middle of the readings (the first and last quarter left out:
        start-up and links closing)."""
        middle = self.readings[len(self.readings) // 4 : 3 * len(self.readings) // 4]
        if len(middle) < 2:
            return float("nan")
        (t0, s0), (t1, s1) = middle[0], middle[-1]
        return (s1 - s0) / (t1 - t0)


def placement(n: int, hosts: int) -> list[str]:
    if hosts == 0:
        return []
    blocks, start = [], 0
    for k in range(hosts):
        count = n // hosts + (1 if k < n % hosts else 0)
        blocks.append(f"h{k}: '{start}-{start + count - 1}'")
        start += count
    return ["placement={" + ", ".join(blocks) + "}"]


def one(lab: Lab, out: Path, n: int, ticks: int, hosts: int) -> dict:
    sets = [
        f"agents.count={n}",
        "allocator={name: noop, peers: 5}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        f"run.duration={ticks}",
        "network.range=null",
        "run.record_every=1000000",
        "run.join_timeout=600",
        *placement(n, hosts),
    ]
    segments = Segments()
    daemons = [psutil.Process(lab.daemons[f"h{k}"].pid) for k in range(hosts)]
    before = sum(d.cpu_times().user + d.cpu_times().system for d in daemons)
    try:
        result = run_experiment(
            cfg.load(ROOT / "experiments" / "quickstart.yaml", sets),
            out,
            progress=False,
            hub=lab.hub_options(),
            on_ready=segments.start,
        )
    finally:
        segments.stop.set()
    daemon_cpu = sum(d.cpu_times().user + d.cpu_times().system for d in daemons) - before
    t = result.timings
    rate = t["ticks_per_s"]
    per_agent = t["per_agent_tick"]
    return {
        "ticks_per_s": rate,
        "hub_cpu_ms_per_tick": per_agent["cpu_us"]["hub"] * n / 1000,
        "hub_wakeups_per_tick": per_agent["wakeups"]["hub"] * n,
        "netem_cpu_ms_per_tick": per_agent["cpu_us"]["netem"] * n / 1000,
        "hub_segments_per_tick": segments.per_second() / rate,
        # the host daemons' own processes (their routers; the agents are their fork server's children),
        # over the whole run, start-up included: an upper bound on their per-tick cost
        "daemons_cpu_ms_per_tick": 1000 * daemon_cpu / ticks,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agents", type=int, default=200)
    ap.add_argument("--ticks", type=int, default=200)
    ap.add_argument("--hosts", type=int, nargs="+", default=[0, 1, 2, 4], help="0: every agent local")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        try:
            lab = make_lab(Path(tmp) / "hosts")
        except LabError as exc:
            raise SystemExit(f"cannot make stand-in hosts: {exc}") from None
        try:
            for k in range(max(args.hosts)):
                lab.add_host(f"h{k}")
            print(
                f"{args.agents} agents, {args.ticks} ticks, no-op + 5 messages each a tick\n"
                "hosts | ticks/s | hub CPU ms/tick | hub wake-ups/tick | hub TCP segments/tick | "
                "proxy CPU ms/tick | host daemons' CPU ms/tick | same files as all local",
                flush=True,
            )
            first: Path | None = None
            for hosts in args.hosts:
                out = Path(tmp) / f"hosts{hosts}"
                m = one(lab, out, args.agents, args.ticks, hosts)
                first = first or out
                same = all((first / f).read_bytes() == (out / f).read_bytes() for f in RESULTS)
                print(
                    f"{hosts or 'local':>5} | {m['ticks_per_s']:7.1f} | {m['hub_cpu_ms_per_tick']:15.2f} | "
                    f"{m['hub_wakeups_per_tick']:17.0f} | {m['hub_segments_per_tick']:21.0f} | "
                    f"{m['netem_cpu_ms_per_tick']:17.2f} | {m['daemons_cpu_ms_per_tick']:25.2f} | {same}",
                    flush=True,
                )
        finally:
            lab.close()


if __name__ == "__main__":
    main()
