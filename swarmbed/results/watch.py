"""``swarmbed watch``: a live terminal view of a running experiment, from any machine that reaches it.

With ``--map FILE.html`` it also keeps an HTML page of the run's map (agents, tasks or victims)
that reloads itself every second.

Read-only by construction: the watcher's session only subscribes (the coordinator's progress
samples, the proxy's per-agent traffic totals, the run's liveliness tokens) and never puts, queries
a run's queryables or declares a token. Both samples come at most four times a wall second with
congestion control ``DROP``, so a slow or stopped watcher loses samples rather than slowing the run
(operators may read nothing else: see ``swarmbed.launch.access``).
"""

from __future__ import annotations

import collections
import html
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh
from rich.columns import Columns
from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from swarmbed.files import safefiles
from swarmbed.results.colours import LABEL_COLORS
from swarmbed.wire.codec import WireError, decode_traffic
from swarmbed.wire.keys import PREFIX, Keys, agent_id_of
from swarmbed.wire.run_status import RunStatus, decode_status

RATE_WINDOW = 2.0  # wall seconds over which per-agent rates are measured


class WatchError(RuntimeError):
    pass


def running_runs(session: zenoh.Session, timeout: float = 2.0) -> list[str]:
    """Ids of the runs whose coordinator is alive as seen from this session."""
    replies = session.liveliness().get(f"{PREFIX}/*/alive/coordinator", timeout=timeout)
    runs = {str(r.ok.key_expr).split("/")[1] for r in replies if r.ok is not None}
    return sorted(runs)


@dataclass
class RunView:
    """What the watcher knows of one run, fed from Zenoh callbacks, read by the renderer."""

    run_id: str
    status: RunStatus | None = None
    first_status: tuple[float, int] | None = None  # (wall, tick) when watching began
    last_status_at: float = 0.0
    ticks_per_s: float = 0.0
    alive: set[str] = field(default_factory=set)  # liveliness keys below alive/
    coordinator_seen: bool = False
    coordinator_gone: bool = False
    traffic: dict[int, collections.deque] = field(default_factory=dict)  # agent -> (wall, msgs, bytes)
    totals: dict[int, list[int]] = field(default_factory=dict)  # agent -> [messages, bytes] seen
    malformed: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on_status(self, data: bytes) -> None:
        try:
            status = decode_status(data)
        except WireError:
            self.malformed += 1
            return
        now = time.monotonic()
        with self.lock:
            if self.status is not None and status.tick > self.status.tick and now > self.last_status_at:
                rate = (status.tick - self.status.tick) / (now - self.last_status_at)
                self.ticks_per_s = rate if self.ticks_per_s == 0 else 0.5 * self.ticks_per_s + 0.5 * rate
            self.status, self.last_status_at = status, now

    def on_traffic(self, data: bytes) -> None:
        try:
            totals = decode_traffic(data)
        except WireError:
            self.malformed += 1
            return
        now = time.monotonic()
        with self.lock:
            for agent, (messages, size) in totals.items():
                self.totals[agent] = [messages, size]
                window = self.traffic.setdefault(agent, collections.deque())
                window.append((now, messages, size))
                while window and window[0][0] < now - RATE_WINDOW:
                    window.popleft()

    def on_alive(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr).split("/alive/", 1)[1]
        with self.lock:
            if sample.kind == zenoh.SampleKind.DELETE:
                self.alive.discard(key)
                if key == "coordinator":
                    self.coordinator_gone = True
            else:
                self.alive.add(key)
                self.coordinator_seen |= key == "coordinator"

    def rates(self) -> dict[int, tuple[float, float]]:
        """Messages and payload bytes per wall second of each agent, over the last window."""
        now = time.monotonic()
        out = {}
        for agent, window in self.traffic.items():
            recent = [w for w in window if w[0] >= now - RATE_WINDOW]
            if len(recent) >= 2 and recent[-1][0] > recent[0][0]:
                span = recent[-1][0] - recent[0][0]
                out[agent] = ((recent[-1][1] - recent[0][1]) / span, (recent[-1][2] - recent[0][2]) / span)
            else:
                out[agent] = (0.0, 0.0)
        return out

    def render(self) -> Group:
        with self.lock:
            s = self.status
            rates = self.rates()
            alive = set(self.alive)
            totals = {a: list(t) for a, t in self.totals.items()}
        if s is None:
            return Group(Text(f"run {self.run_id}: waiting for its first progress sample ..."))
        dt = s.time / max(s.tick, 1) if s.tick else 0.0
        head = Table.grid(padding=(0, 2))  # two columns: a label, and figures that never break inside
        head.add_row(Text(s.name, style="bold"), _lines([f"run {self.run_id}", f"{s.scenario} / {s.allocator}"]))
        head.add_row(
            "progress",
            _lines(
                [
                    f"tick {s.tick + 1:,} of {s.ticks:,}",
                    f"t = {s.time:,.1f} s",
                    f"{self.ticks_per_s:,.1f} ticks/s",
                    f"({self.ticks_per_s * dt:,.1f} sim s per wall s)",
                ]
            ),
        )
        figures = [
            f"{k} {v:,}" if isinstance(v, int) else f"{k} {v:,.1f}"
            for k, v in s.row.items()
            if k not in ("tick", "time")
        ]
        head.add_row("outcome", _lines(figures))
        net = s.network
        radio = [f"{net.messages_sent:,} messages", f"{net.bytes_sent:,} B"]
        head.add_row("radio", _lines([*radio, f"copies {net.delivered:,} delivered / {net.copies:,}"]))
        drops = [f"{r} {n:,}" for r, n in sorted(s.drops.items())] or ["none"]
        head.add_row("dropped", _lines([*drops, f"late ticks {s.late_ticks:,}"]))
        agents_alive = sorted({i for k in alive if k.startswith("agent/") and (i := _agent_or_none(k)) is not None})
        procs = [
            f"{n} {'up' if ok else 'DOWN'}"
            for n, ok in (("coordinator", "coordinator" in alive), ("netem", "netem" in alive))
        ]
        head.add_row("processes", _lines([*procs, f"agents {len(agents_alive)} up of {len(s.alive)} in the world"]))
        table = Table(
            title="payload each agent sent since the first watcher attached\n(rates: per wall second, last 2 s)",
            title_justify="left",
        )
        for col in ("agent", "process", "msgs/s", "B/s", "messages", "bytes"):
            table.add_column(col, justify="right")
        for a in sorted(set(s.alive) | set(totals)):
            m, b = rates.get(a, (0.0, 0.0))
            t = totals.get(a, [0, 0])
            table.add_row(
                str(a), "up" if a in agents_alive else "-", f"{m:,.1f}", f"{b:,.0f}", f"{t[0]:,}", f"{t[1]:,}"
            )
        return Group(head, table)

    def line(self) -> str:
        """One plain line, for output that is not a terminal."""
        s = self.status
        if s is None:
            return f"run {self.run_id}: waiting"
        return (
            f"tick {s.tick + 1} t={s.time:.1f}s {self.ticks_per_s:.1f} ticks/s "
            + " ".join(f"{k}={v:.6g}" for k, v in s.row.items() if k not in ("tick", "time"))
            + f" messages={s.network.messages_sent} dropped={s.network.dropped}"
        )


def _lines(items: list[str]) -> Columns:
    """``items`` side by side, as many to a line as the terminal holds, each held together: a narrow
    terminal breaks between two figures, never inside one."""
    return Columns([Text(item, no_wrap=True) for item in items], padding=(0, 2))


def write_map(status: RunStatus, path: Path, bounds: list[float]) -> None:
    """An HTML page with the run's map as SVG that reloads itself every second (written atomically)."""
    points = [(x, y) for _, x, y in status.positions] + [(x, y) for x, y, _ in status.markers]
    for x, y in points:  # the view only grows, so that the map does not jump about
        bounds[:] = [min(bounds[0], x), min(bounds[1], y), max(bounds[2], x), max(bounds[3], y)]
    x0, y0, x1, y1 = bounds if bounds[0] <= bounds[2] else (0.0, 0.0, 1.0, 1.0)
    pad = 0.05 * max(x1 - x0, y1 - y0, 1.0)
    w, h = x1 - x0 + 2 * pad, y1 - y0 + 2 * pad
    r = max(w, h) / 120

    def sy(y: float) -> float:  # SVG's y grows downwards
        return y0 + y1 - y

    shapes = [
        f"<rect x='{x - r:.2f}' y='{sy(y) - r:.2f}' width='{2 * r:.2f}' height='{2 * r:.2f}' "
        f"fill='{LABEL_COLORS.get(lab, '#999')}'/>"
        for x, y, lab in status.markers
    ]
    labels = status.labels
    shapes += [
        f"<circle cx='{x:.2f}' cy='{sy(y):.2f}' r='{1.4 * r:.2f}' "
        f"fill='{LABEL_COLORS.get(labels.get(a, ''), '#222')}' "
        f"stroke='black' stroke-width='{r / 3:.2f}'><title>agent {a}</title></circle>"
        for a, x, y in status.positions
    ]
    page = (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><meta http-equiv='refresh' content='1'>"
        f"<title>{html.escape(status.name)}: tick {status.tick + 1}</title></head>"
        f"<body style='font-family:sans-serif'><p>{html.escape(status.name)}: tick {status.tick + 1:,} of "
        f"{status.ticks:,}, t = {status.time:,.1f} s</p>"
        f"<svg viewBox='{x0 - pad:.2f} {y0 - pad:.2f} {w:.2f} {h:.2f}' style='width:90vmin;height:90vmin;"
        f"border:1px solid #ccc'>{''.join(shapes)}</svg></body></html>"
    )
    safefiles.write_text(path, page)


def watch(
    session: zenoh.Session,
    run_id: str | None,
    console: Console | None = None,
    refresh: float = 4.0,
    wait: float = 10.0,
    map_file: Path | None = None,
    foxglove: Any = None,
) -> int:
    """Show one run until it ends (0) or Ctrl-C (130); 1 when no such run answers within ``wait`` s.
    ``foxglove``: a :class:`~swarmbed.results.foxglove_live.StatusFoxglove` each sample is shown on."""
    console = console or Console()
    if run_id is None:
        deadline = time.monotonic() + wait
        runs = running_runs(session)
        while not runs and time.monotonic() < deadline:  # the run may still be starting
            time.sleep(0.5)
            runs = running_runs(session, timeout=1.0)
        if not runs:
            raise WatchError("no running experiment is visible from here (is --connect the run's hub or a host?)")
        if len(runs) > 1:
            raise WatchError(f"several runs are visible: {', '.join(runs)}; choose one with --run")
        run_id = runs[0]
    keys = Keys(run_id)
    view = RunView(run_id)
    subs = [
        session.declare_subscriber(keys.status, lambda s: view.on_status(s.payload.to_bytes())),
        session.declare_subscriber(keys.view_traffic, lambda s: view.on_traffic(s.payload.to_bytes())),
        session.liveliness().declare_subscriber(keys.alive_all, view.on_alive, history=True),
    ]
    started = time.monotonic()
    bounds = [float("inf"), float("inf"), float("-inf"), float("-inf")]

    def draw_map() -> None:
        if map_file is not None and view.status is not None:
            write_map(view.status, map_file, bounds)
        if foxglove is not None and view.status is not None:
            foxglove.show(view.status)

    try:
        if console.is_terminal:
            with Live(view.render(), console=console, refresh_per_second=refresh, transient=False) as live:
                while not view.coordinator_gone:
                    if _gave_up(view, started, wait):
                        break
                    time.sleep(1 / refresh)
                    live.update(view.render())
                    draw_map()
                live.update(view.render())
        else:
            while not view.coordinator_gone and not _gave_up(view, started, wait):
                time.sleep(1.0)
                print(view.line(), flush=True)
                draw_map()
        draw_map()
    except KeyboardInterrupt:
        return 130
    finally:
        for sub in subs:
            sub.undeclare()
    if not view.coordinator_seen:
        console.print(f"run {run_id}: no coordinator answered within {wait:.0f} s")
        return 1
    console.print(f"run {run_id} is over (its coordinator left)")
    return 0


def _gave_up(view: RunView, started: float, wait: float) -> bool:
    return not view.coordinator_seen and time.monotonic() - started > wait


def _agent_or_none(key: str) -> int | None:
    """The agent a token names, or None for a token no agent of a run would hold."""
    try:
        return agent_id_of(key)
    except WireError:
        return None
