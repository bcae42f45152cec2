"""``swarmbed soak``: an experiment left running for a wall-clock duration, every process watched,
faults injected (:mod:`.chaos`), and a verdict at the end.

The run is an ordinary run (lock-step or real-time, as the experiment says) whose simulated
duration is unbounded and which stops when the wall duration is up. A :class:`Monitor` samples
every process of the run on this machine (host daemons of stand-in hosts and their agents too)
with psutil every ``interval`` seconds and appends rows as it goes:

- ``soak_processes.csv``: wall_s, tick, process, kind, pid, rss_mb, cpu_pct, fds, threads, tcp
  (TCP connections: a process's Zenoh session is one link to the hub; the hub holds one per process)
- ``soak_run.csv``: wall_s, tick, sim_s, ticks_per_s, slowest_tick_ms (lock-step: the longest a
  tick took in the interval), start_lag_ms (real time: the largest in the interval), messages and
  bytes per second, copies, delivered, dropped, in_flight (copies not yet delivered or dropped),
  agents alive / down / lost, restarts

The verdict (``soak_verdict.json``, printed, exit code 1 on a breach) fits each process's RSS and
open file descriptors over the second half of the run (where start-up growth is over): the RSS
slope in % per hour (Theil-Sen, robust to the steps an allocator's arenas make) and the fd growth
per hour (a restarted agent's process over the second half of its own life; a process that lived
less than a quarter of the soak is listed without a slope), reported per process kind as the worst
process of that kind; the longest stall; the ledger's conservation; every fault and how it ended;
ticks/s at the start and at the end. Each is held to a threshold the user can set. RSS growth is a
breach only where it is there: the slope over its limit, the slope's 95 % confidence interval
above zero and at least ``min_rss_growth_mb`` of growth over the judged window. A window so short
that growth at the limit would stay under that floor is reported "too short to judge" instead of
extrapolating a wiggle of a few tenths of a MB to tens of % per hour.

Speed is judged as memory is: over the second half, the CPU milliseconds per tick of each kind of
process (all its processes together) and the run's ticks per second, each a Theil-Sen slope in %
of its mean per hour; a breach where the cost per tick grows (or the rate falls) beyond its limit,
with the slope's 95 % interval on that side of zero and at least ``min_speed_change_pct`` of change
over the window. The verdict counts the faults of each action that ran and says which of the
plan's actions the soak was too short to show (fewer than three expected at their mean gap).
"""

from __future__ import annotations

import math
import os
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import psutil

from swarmbed.campaigns.chaos import Chaos, ChaosPlan
from swarmbed.engine import results
from swarmbed.launch.hub import LOOPBACK_ONLY, HubOptions
from swarmbed.launch.runner import LiveRun, RunObserver, run_experiment
from swarmbed.records.rowfile import RowFile
from swarmbed.results.campaign_folders import SOAK_PROCESSES as PROCESSES
from swarmbed.results.campaign_folders import SOAK_RUN as RUN
from swarmbed.results.campaign_folders import SOAK_VERDICT as VERDICT
from swarmbed.results.progress import Progress
from swarmbed.schema.experiment import Experiment
from swarmbed.wire.child_process import process_name
from swarmbed.wire.keys import Keys

PROCESS_COLUMNS = ["wall_s", "tick", "process", "kind", "pid", "rss_mb", "cpu_pct", "fds", "threads", "tcp"]
RUN_COLUMNS = [
    "wall_s",
    "tick",
    "sim_s",
    "ticks_per_s",
    "slowest_tick_ms",
    "start_lag_ms",
    "messages_per_s",
    "bytes_per_s",
    "copies",
    "delivered",
    "dropped",
    "in_flight",
    "agents_alive",
    "agents_down",
    "agents_lost",
    "restarts",
]
UNBOUNDED_S = 1e9  # the simulated duration of a soak: it ends on the wall clock
MIN_SAMPLES = 10  # a process sampled fewer times (or alive for less than a quarter of the soak) gets no slope


def parse_duration(text: str) -> float:
    """``90``, ``90s``, ``30m``, ``2h``, ``1h30m`` -> seconds."""
    parts = re.fullmatch(r"\s*(?:(\d+(?:\.\d+)?)h)?\s*(?:(\d+(?:\.\d+)?)m)?\s*(?:(\d+(?:\.\d+)?)s?)?\s*", text)
    if not text.strip() or parts is None or not any(parts.groups()):
        raise ValueError(f"not a duration: {text!r} (e.g. 90s, 30m, 2h, 1h30m)")
    h, m, s = (float(g) if g else 0.0 for g in parts.groups())
    if h * 3600 + m * 60 + s < 10:
        raise ValueError(f"soak duration {text!r}: at least 10 s (a soak samples its processes every few seconds)")
    return h * 3600 + m * 60 + s


@dataclass
class Thresholds:
    max_rss_slope_pct_h: float = 10.0
    max_fd_growth_h: float = 10.0
    max_stall_s: float = 10.0
    #: RSS growth over the judged window below which no slope is a breach: allocators' arenas and
    #: Python's free lists move a process's RSS by a few tenths of a MB at random
    min_rss_growth_mb: float = 5.0
    #: how fast a kind of process's CPU per tick may grow, and the run's ticks per second may fall,
    #: in % of its mean per hour over the judged window (the second half), before it is a breach
    max_cpu_tick_slope_pct_h: float = 20.0
    max_rate_fall_pct_h: float = 20.0
    #: the least change over the judged window that is a breach: a few % moves with the machine's day
    min_speed_change_pct: float = 10.0
    #: the shortest judged window (the soak's second half) whose speed trend is judged: over a few
    #: minutes a restart's or a fault's extra work reads as tens of % per hour
    min_speed_window_s: float = 300.0


def kind_of(name: str) -> str:
    if name.startswith("agent_"):
        return "agent"
    return "host" if name.startswith("host_") else name


class Monitor:
    """Samples the run's processes and counters every ``interval`` wall seconds; stops the run
    when ``duration_s`` is up (a :class:`~swarmbed.launch.runner.RunObserver`)."""

    def __init__(self, duration_s: float, interval: float = 5.0, progress: Progress | None = None) -> None:
        self.duration_s = duration_s
        self.interval = interval
        self.progress = progress
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._procs: dict[int, psutil.Process] = {}
        self.started = 0.0

    def start(self, run: LiveRun) -> None:
        self.run = run
        self.processes = RowFile(run.out_dir / PROCESSES, PROCESS_COLUMNS)
        self.counters = RowFile(run.out_dir / RUN, RUN_COLUMNS)
        self.started = time.monotonic()
        self._last: tuple[float, int, tuple[int, ...]] = (self.started, -1, (0,) * 5)  # (time, tick, network counters)
        self._sample()  # before the first tick: the processes as they joined
        self._thread = threading.Thread(target=self._loop, name="soak-monitor", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
        self._sample()  # the state at the end
        self.processes.finish()
        self.counters.finish()

    def _loop(self) -> None:
        coord = self.run.coordinator
        while not self._stop.wait(self.interval - (time.monotonic() - self.started) % self.interval):
            self._sample()
            if self.progress is not None:
                status = coord.live()
                self.progress.update(min(time.monotonic() - self.started, self.duration_s), f"tick {status.tick:,}")
            if time.monotonic() - self.started >= self.duration_s:
                coord.stop.ask()

    def _watched(self) -> dict[str, int]:
        """Name -> pid of every local process of the run still there."""
        children = self.run.children
        pids = {"coordinator": os.getpid()}
        if children.server is not None:
            pids["forkserver"] = children.server.proc.pid
        for name, proc in children.procs.items():
            if proc.poll() is None:
                pids[name] = proc.pid
        for host, info in self.run.hosts.items():
            pids.update(_host_processes(host, info.pid if info is not None else None))
        return pids

    def _sample(self) -> None:
        now = time.monotonic()
        coord = self.run.coordinator
        status = coord.live()
        tick = status.tick
        wall = round(now - self.started, 3)
        for name, pid in self._watched().items():
            try:
                proc = self._procs.get(pid)
                if proc is None:
                    proc = self._procs[pid] = psutil.Process(pid)
                    proc.cpu_percent(None)  # the first reading is a baseline
                with proc.oneshot():
                    row = [
                        wall,
                        tick,
                        name,
                        kind_of(name.split(".")[0]),
                        pid,
                        round(proc.memory_info().rss / 2**20, 3),
                        proc.cpu_percent(None),
                        proc.num_fds(),
                        proc.num_threads(),
                        len(proc.net_connections("tcp")),
                    ]
            except (psutil.Error, OSError):
                continue  # it exited between the listing and the reading
            self.processes.write(row)
        last_time, last_tick, last_net = self._last
        span = max(now - last_time, 1e-9)
        net = status.network
        interval = coord.take_interval()
        self.counters.write(
            [
                wall,
                tick,
                round(status.time, 6),
                round((tick - last_tick) / span, 3),
                round(1000 * interval.slowest_tick_s, 3),
                round(1000 * interval.latest_start_s, 3) if interval.latest_start_s is not None else "",
                round((net[0] - last_net[0]) / span, 3),
                round((net[1] - last_net[1]) / span, 3),
                net[2],
                net[3],
                net[4],
                net[2] - net[3] - net[4],
                len(status.alive),
                len(status.down),
                len(status.lost),
                status.restarts_ok,
            ]
        )
        self._last = (now, tick, net)
        self.processes.flush()  # one sample, one chunk: a kill loses at most the sample under way
        self.counters.flush()


def _host_processes(host: str, pid: int | None) -> dict[str, int]:
    """A host daemon that runs on this machine (a stand-in host in a network namespace, or a second
    daemon here) and its agents, as ``host_<name>`` and ``agent_<i>[.<n>]@<name>``; nothing for a
    host on another machine (its daemon's pid is not a process here)."""
    try:
        daemon = psutil.Process(pid) if pid else None
        if daemon is None or f"--name {host}" not in " ".join(daemon.cmdline()):
            return {}
        found = {f"host_{host}": daemon.pid}
        for child in daemon.children(recursive=True):
            args = child.cmdline()
            if "swarmbed.agent_runtime" in args and "--id" in args:
                agent = int(args[args.index("--id") + 1])
                incarnation = int(args[args.index("--incarnation") + 1]) if "--incarnation" in args else 0
                found[f"{process_name(agent, incarnation)}@{host}"] = child.pid
        return found
    except (psutil.Error, ValueError, IndexError):
        return {}


def _theil_sen(t: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """The Theil-Sen slope of ``y`` over ``t`` with its 95 % confidence interval (low, high)."""
    from scipy.stats import theilslopes

    if len(t) < 3 or np.ptp(t) <= 0:
        return 0.0, 0.0, 0.0
    slope, _, low, high = theilslopes(y, t, alpha=0.95)
    return float(slope), float(low), float(high)


def rss_growth(t: np.ndarray, rss: np.ndarray, limits: Thresholds) -> dict[str, Any]:
    """How a process's RSS moves over its judged window, and whether that is growth that is there:
    a breach needs the slope over the limit, its 95 % confidence interval above zero, and growth
    over the window of at least ``min_rss_growth_mb``. A window so short that even growth at the
    limit would stay under that floor is "too short to judge" (a 0.3 MB wiggle over 30 s would
    otherwise extrapolate to 80 %/h)."""
    mean = float(rss.mean()) if len(rss) else 0.0
    slope, low, _high = _theil_sen(t, rss)
    window_h = float(np.ptp(t)) / 3600 if len(t) else 0.0
    pct = slope * 3600 / mean * 100 if mean else 0.0
    growth_mb = slope * window_h * 3600
    at_limit_mb = limits.max_rss_slope_pct_h / 100 * mean * window_h
    if pct > limits.max_rss_slope_pct_h and low > 0 and growth_mb >= limits.min_rss_growth_mb:
        judged = "grows"
    elif at_limit_mb < limits.min_rss_growth_mb:
        judged = "too short to judge"
    else:
        judged = "steady"
    return {
        "rss_mb_mean": round(mean, 2),
        "rss_slope_pct_h": round(pct, 2),
        "rss_slope_low_pct_h": round(low * 3600 / mean * 100 if mean else 0.0, 2),
        "rss_growth_mb": round(growth_mb, 2),
        "rss": judged,
    }


def speed_trend(
    t: np.ndarray, y: np.ndarray, limit_pct_h: float, min_change_pct: float, falling: bool, min_window_s: float = 0.0
) -> dict:
    """The trend of a speed figure ``y`` over ``t`` (the judged window): its Theil-Sen slope in %
    of its mean per hour, and whether it is a breach: beyond ``limit_pct_h`` in the bad direction
    (up for CPU per tick, down for ticks per second), the slope's 95 % interval on that side of
    zero, and a change of at least ``min_change_pct`` % over the window. A window shorter than
    ``min_window_s`` is reported, not judged."""
    keep = np.isfinite(y)
    t, y = t[keep], y[keep]
    if len(t) < MIN_SAMPLES or np.ptp(t) <= 0 or not y.mean():
        mean = round(float(y.mean()), 3) if len(y) else None
        return {"mean": mean, "slope_pct_h": None, "trend": "too short to judge"}
    mean = float(y.mean())
    slope, low, high = _theil_sen(t, y)
    pct = slope * 3600 / mean * 100
    change = abs(slope * np.ptp(t)) / mean * 100
    sign = -1 if falling else 1
    bad = sign * pct > limit_pct_h and (high < 0 if falling else low > 0) and change >= min_change_pct
    trend = ("falls" if falling else "grows") if bad else "steady"
    if np.ptp(t) < min_window_s:
        trend = "too short to judge"
    return {"mean": round(mean, 3), "slope_pct_h": round(pct, 2), "change_pct": round(change, 1), "trend": trend}


def speed_trends(procs: Any, counters: Any, limits: Thresholds) -> dict[str, Any]:
    """CPU milliseconds per tick of each kind of process (all its processes together) and the run's
    ticks per second, each over the second half of the soak, with their trends."""
    half = float(counters["wall_s"].max()) / 2 if len(counters) else 0.0
    judged = counters[counters["wall_s"] >= half].sort_values("wall_s")
    wall = judged["wall_s"].to_numpy(float)
    spans = np.diff(wall, prepend=wall[0] if len(wall) else 0.0)
    ticks = np.diff(judged["tick"].to_numpy(float), prepend=np.nan)
    rate_limit, cpu_limit = limits.max_rate_fall_pct_h, limits.max_cpu_tick_slope_pct_h
    floor, window = limits.min_speed_change_pct, limits.min_speed_window_s
    rates = judged["ticks_per_s"].to_numpy(float)
    out: dict[str, Any] = {"ticks_per_s": speed_trend(wall, rates, rate_limit, floor, True, window)}
    out["cpu_ms_per_tick"] = {}
    for kind, rows in procs[procs["wall_s"] >= half].groupby("kind"):
        cpu = rows.groupby("wall_s")["cpu_pct"].sum().reindex(wall).to_numpy(float) / 100  # cores busy
        per_tick = np.where(ticks > 0, 1000 * cpu * spans / np.where(ticks > 0, ticks, 1), np.nan)
        out["cpu_ms_per_tick"][kind] = speed_trend(wall, per_tick, cpu_limit, floor, False, window)
    return out


def fault_counts(faults: list[dict[str, Any]]) -> dict[str, int]:
    """How many faults of each action ran."""
    counts: dict[str, int] = {}
    for f in faults:
        counts[f["action"]] = counts.get(f["action"], 0) + 1
    return counts


def plan_coverage(plan: ChaosPlan | None, duration_s: float) -> list[str]:
    """What the chaos plan asked for that the soak was too short to show, one line each: an action
    at a mean gap longer than a third of the soak (fewer than three expected), or listed times
    after its end."""
    notes = []
    for event in plan.events if plan else []:
        if event.every is not None and duration_s / event.every < 3:
            notes.append(
                f"{event.action} every {event.every:g} s on average: about {duration_s / event.every:.1f} in "
                f"{duration_s:.0f} s, too few to judge it (a soak of {3 * event.every:.0f} s or more, or "
                "experiments/soak/chaos_short.yaml)"
            )
        late = [t for t in event.at if t + event.duration >= duration_s]
        if late:
            notes.append(f"{event.action} at {', '.join(f'{t:g}' for t in late)} s: after the soak's end, never run")
    return notes


def fault_breaches(faults: list[dict[str, Any]]) -> list[str]:
    """The faults that were not survived: unresolved, a restart that failed, or never injected."""
    bad = ("unresolved", "restart failed", "not injected")
    return [f"{f['action']} at {f['wall_s']} s: {f['outcome']}" for f in faults if str(f["outcome"]).startswith(bad)]


def _process_trends(procs: Any, limits: Thresholds, end: float) -> list[dict[str, Any]]:
    """Per process: its RSS and open-file trends over the second half of its life (a process that
    lived too short a time is marked so, with its last RSS)."""
    per_process = []
    for name, life in procs.groupby("process"):
        first, last = float(life["wall_s"].min()), float(life["wall_s"].max())
        if len(life) < MIN_SAMPLES or last - first < end / 4:  # e.g. an agent killed early: no trend to read
            per_process.append(
                {
                    "process": name,
                    "kind": life["kind"].iloc[0],
                    "samples": len(life),
                    "short_lived": True,
                    "rss_mb_last": float(life["rss_mb"].iloc[-1]),
                }
            )
            continue
        rows = life[life["wall_s"] >= (first + last) / 2]  # the second half of this process's life
        t, rss, fds = rows["wall_s"].to_numpy(float), rows["rss_mb"].to_numpy(float), rows["fds"].to_numpy(float)
        fd_slope = float(np.polyfit(t, fds, 1)[0]) * 3600 if len(t) >= 3 and np.ptp(t) > 0 else 0.0
        per_process.append(
            {
                "process": name,
                "kind": rows["kind"].iloc[0],
                "samples": len(rows),
                **rss_growth(t, rss, limits),
                "fd_growth_h": round(fd_slope, 2),
                "fds_last": int(fds[-1]) if len(fds) else 0,
            }
        )
    return per_process


def _worst_by_kind(per_process: list[dict[str, Any]], procs: Any) -> dict[str, dict[str, Any]]:
    """Per process kind: how many, its worst RSS trend and open-file growth and which process had them."""
    by_kind: dict[str, dict[str, Any]] = {}
    for p in per_process:
        if p.get("short_lived"):
            continue
        worst = by_kind.setdefault(
            p["kind"],
            {
                "processes": 0,
                "rss_slope_pct_h": -math.inf,
                "fd_growth_h": -math.inf,
                "rss_mb_peak": 0.0,
                "rss": "steady",
            },
        )
        worst["processes"] += 1
        rank = ("steady", "too short to judge", "grows")
        if (rank.index(p["rss"]), p["rss_slope_pct_h"]) > (rank.index(worst["rss"]), worst["rss_slope_pct_h"]):
            worst.update(
                rss_slope_pct_h=p["rss_slope_pct_h"],
                worst_rss=p["process"],
                rss=p["rss"],
                rss_growth_mb=p["rss_growth_mb"],
            )
        if p["fd_growth_h"] > worst["fd_growth_h"]:
            worst.update(fd_growth_h=p["fd_growth_h"], worst_fds=p["process"])
    for kind, rows in procs.groupby("kind"):
        if kind in by_kind:
            by_kind[kind]["rss_mb_peak"] = round(float(rows["rss_mb"].max()), 2)
    return by_kind


def _breaches(
    by_kind: dict[str, dict[str, Any]],
    limits: Thresholds,
    slowest_tick: tuple[float, int],
    failure: str | None,
    conserved: bool,
    faults: list[dict[str, Any]],
    speed: dict[str, Any] | None = None,
) -> list[str]:
    """Every breach of the thresholds, one line each, in the order the soak's page lists them."""
    breaches = []
    for kind, trend in sorted((speed or {}).get("cpu_ms_per_tick", {}).items()):
        if trend["trend"] == "grows":
            breaches.append(
                f"CPU per tick of the {kind} processes grows {trend['slope_pct_h']:.1f} %/h "
                f"({trend['change_pct']:.0f} % over the judged window; limit {limits.max_cpu_tick_slope_pct_h:g} %/h)"
            )
    rate = (speed or {}).get("ticks_per_s", {})
    if rate.get("trend") == "falls":
        breaches.append(
            f"ticks per second fall {-rate['slope_pct_h']:.1f} %/h ({rate['change_pct']:.0f} % over the judged "
            f"window; limit {limits.max_rate_fall_pct_h:g} %/h)"
        )
    for _kind, worst in sorted(by_kind.items()):
        if worst["rss"] == "grows":
            breaches.append(
                f"RSS of {worst['worst_rss']} grows {worst['rss_slope_pct_h']:.1f} %/h, "
                f"{worst['rss_growth_mb']:.1f} MB over the judged window "
                f"(limit {limits.max_rss_slope_pct_h:g} %/h)"
            )
        if worst["fd_growth_h"] > limits.max_fd_growth_h:
            breaches.append(
                f"open files of {worst['worst_fds']} grow {worst['fd_growth_h']:.1f}/h "
                f"(limit {limits.max_fd_growth_h:g})"
            )
    if slowest_tick[0] > limits.max_stall_s:
        breaches.append(f"tick {slowest_tick[1]} took {slowest_tick[0]:.1f} s (limit {limits.max_stall_s:g})")
    if failure:
        breaches.append(f"the run stopped: {failure}")
    elif not conserved:
        breaches.append("the ledger does not balance (copies != delivered + dropped)")
    breaches += fault_breaches(faults)
    return breaches


def tick_rates(wall_s: np.ndarray, ticks_per_s: np.ndarray) -> tuple[float, float]:
    """Ticks per second over the first and the last tenth of the soak's full sampling windows. A
    window cut short (the sample taken as the soak stops, a few tenths of a second after the one
    before) is left out: its few ticks over a short span say nothing of the rate."""
    spans = np.diff(wall_s, prepend=0.0)
    keep = wall_s > 0
    if keep.sum() > 2:
        keep &= spans >= 0.9 * np.median(spans[keep])
    rates = ticks_per_s[keep]
    if not len(rates):
        return 0.0, 0.0
    tenth = max(1, len(rates) // 10)
    return float(rates[:tenth].mean()), float(rates[-tenth:].mean())


def verdict(
    out_dir: Path,
    limits: Thresholds,
    chaos_rows: list[list[Any]],
    summary: dict | None,
    failure: str | None,
    slowest_tick: tuple[float, int],
    plan: ChaosPlan | None = None,
) -> dict[str, Any]:
    """The soak's verdict from its files (see the module docstring)."""
    import pandas as pd

    procs = pd.read_csv(out_dir / PROCESSES)
    counters = pd.read_csv(out_dir / RUN)
    end = float(procs["wall_s"].max()) if len(procs) else 0.0
    per_process = _process_trends(procs, limits, end)
    by_kind = _worst_by_kind(per_process, procs)
    rate_start, rate_end = tick_rates(counters["wall_s"].to_numpy(float), counters["ticks_per_s"].to_numpy(float))
    net = (summary or {}).get("network", {})
    conserved = bool(net) and net["copies"] == net["delivered"] + net["dropped_total"]
    faults = [dict(zip(["wall_s", "tick", "action", "target", "detail", "outcome"], row)) for row in chaos_rows]
    faults.sort(key=lambda f: float(f["wall_s"]))  # logged as each ended: shown in the order they began
    speed = speed_trends(procs, counters, limits)
    breaches = _breaches(by_kind, limits, slowest_tick, failure, conserved, faults, speed)
    return {
        "passed": not breaches,
        "breaches": breaches,
        "wall_s": end,
        "ticks": int(counters["tick"].max()) + 1 if len(counters) else 0,
        "ticks_per_s": {"start": round(rate_start, 3), "end": round(rate_end, 3)},
        "longest_stall_s": round(slowest_tick[0], 3),
        "longest_stall_tick": slowest_tick[1],
        "conserved": conserved,
        "network": {k: net.get(k) for k in ("messages_sent", "copies", "delivered", "dropped_total")},
        "agents_lost": (summary or {}).get("agents_lost"),
        "restarts": (summary or {}).get("agent_restarts", 0),
        "faults": faults,
        "faults_by_action": fault_counts(faults),
        "plan_not_shown": plan_coverage(plan, end),
        "speed": speed,
        "by_kind": by_kind,
        "processes": per_process,
        "thresholds": vars(limits),
    }


def soak(
    exp: Experiment,
    out_dir: Path,
    duration_s: float,
    chaos: ChaosPlan | None = None,
    interval: float = 5.0,
    limits: Thresholds | None = None,
    progress: bool = True,
    hub: HubOptions = LOOPBACK_ONLY,
    on_ready: Callable[[Keys, str], None] | None = None,
) -> dict[str, Any]:
    """Run ``exp`` for ``duration_s`` wall seconds under ``chaos``; write and return the verdict.
    ``hub``: where the run's hub listens and whom it admits (a soak across hosts, an operator)."""
    from swarmbed.engine.run_errors import RunError

    exp = exp.model_copy(update={"run": exp.run.model_copy(update={"duration": UNBOUNDED_S, "stop_when_done": False})})
    bar = Progress(duration_s, "soak", "s", enabled=progress)
    monitor = Monitor(duration_s, interval, bar)
    injector = Chaos(chaos, duration_s, exp.run.seed) if chaos and chaos.events else None
    observers: list[RunObserver] = [monitor, *([injector] if injector else [])]
    summary, failure = None, None
    try:
        summary = run_experiment(exp, out_dir, False, on_ready, hub, observers=observers).summary
    except RunError as exc:
        failure = str(exc)
    finally:
        bar.close()
    if not (out_dir / PROCESSES).exists():
        raise RunError(failure or "the soak never got under way")
    live = getattr(monitor, "run", None)  # set once the run got under way
    slowest = live.coordinator.live().slowest_tick if live else (0.0, -1)
    rows = injector.rows if injector else []
    result = verdict(out_dir, limits or Thresholds(), rows, summary, failure, slowest, chaos)
    results.write_json(out_dir / VERDICT, result)
    return result


def format_verdict(v: dict[str, Any]) -> str:
    lines = [
        f"soak verdict: {'PASSED' if v['passed'] else 'FAILED'} after {v['wall_s']:.0f} s, {v['ticks']} ticks "
        f"({v['ticks_per_s']['start']:.1f} ticks/s at the start, {v['ticks_per_s']['end']:.1f} at the end)"
    ]
    for kind, worst in sorted(v["by_kind"].items()):
        judged = " (too short to judge)" if worst.get("rss") == "too short to judge" else ""
        lines.append(
            f"  {kind:<12} x{worst['processes']:<4} RSS slope {worst['rss_slope_pct_h']:+8.1f} %/h{judged}   "
            f"fds {worst['fd_growth_h']:+7.1f}/h   peak RSS {worst['rss_mb_peak']:.0f} MB"
        )
    lines.append(
        f"  longest stall {v['longest_stall_s']:.2f} s (tick {v['longest_stall_tick']}); ledger "
        f"{'balanced' if v['conserved'] else 'NOT balanced'}; restarts {v['restarts']}; "
        f"agents lost {len(v['agents_lost'] or {})}"
    )
    speed = v.get("speed", {})
    for kind, trend in sorted(speed.get("cpu_ms_per_tick", {}).items()):
        if trend.get("slope_pct_h") is not None:
            lines.append(
                f"  {kind:<12} CPU {trend['mean']:.2f} ms a tick, {trend['slope_pct_h']:+.1f} %/h ({trend['trend']})"
            )
    rate = speed.get("ticks_per_s", {})
    if rate.get("slope_pct_h") is not None:
        lines.append(f"  ticks/s {rate['mean']:.1f}, {rate['slope_pct_h']:+.1f} %/h ({rate['trend']})")
    if v.get("faults_by_action"):
        counts = ", ".join(f"{n} {action}" for action, n in sorted(v["faults_by_action"].items()))
        lines.append(f"  faults that ran: {counts}")
    for f in v["faults"]:
        lines.append(f"  fault {f['wall_s']:>8.1f} s tick {f['tick']}: {f['action']} {f['target']}: {f['outcome']}")
    lines += [f"  NOTE: {note}" for note in v.get("plan_not_shown", [])]
    lines += [f"  BREACH: {b}" for b in v["breaches"]]
    return "\n".join(lines)
