"""The report page of a soak (``swarmbed report SOAK_DIR``): the verdict on top, then each process's
RSS, open files and CPU, the tick rate and lag, and the traffic over wall time, with every chaos
event marked on the same time axis. A soak that was killed is reported from its ``.part`` files."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import plotly.graph_objects as go

import swarmbed
from swarmbed.records.run_folder import read_json_member, read_table_member
from swarmbed.results.campaign_folders import CHAOS as CHAOS_FILE
from swarmbed.results.campaign_folders import SOAK_PROCESSES as PROCESSES
from swarmbed.results.campaign_folders import SOAK_RUN as RUN
from swarmbed.results.campaign_folders import SOAK_VERDICT as VERDICT
from swarmbed.results.colours import DROP_COLORS
from swarmbed.results.page import Page

CHAOS_COLORS = {"kill_agent": "#D55E00", "stop_agent": "#E69F00", "loss_burst": "#0072B2", "rate_cap": "#009E73"}


def _read(folder: Path, name: str) -> tuple[pd.DataFrame | None, str]:
    """A soak table and the file it came from (the ``.part`` of a soak that did not finish)."""
    for candidate in (name, name + ".part"):
        if (folder / candidate).exists():
            return read_table_member(folder, candidate), candidate
    return None, name


def soak_report(folder: Path) -> tuple[str, int]:
    procs, procs_file = _read(folder, PROCESSES)
    run, run_file = _read(folder, RUN)
    chaos, chaos_file = _read(folder, CHAOS_FILE)
    assert procs is not None, f"{folder}: no {PROCESSES}"
    page = Page(f"{folder.name}: soak")
    verdict = read_json_member(folder, VERDICT) if (folder / VERDICT).exists() else None
    _verdict(page, verdict)
    if chaos is not None and len(chaos):
        _faults(page, chaos, chaos_file)
    mark = _marker(chaos)
    _processes(page, procs, procs_file, mark)
    if run is not None:
        _the_run(page, run, run_file, mark)
    subtitle = f"soak {folder} · swarmbed {swarmbed.__version__} · report made {time.strftime('%Y-%m-%d %H:%M')}"
    return page.render(subtitle), page.figures


def _verdict(page: Page, verdict: dict | None) -> None:
    """The verdict and its figures, or a note that the soak did not finish."""
    if verdict is None:
        page.heading(
            "No verdict", f"The soak did not finish (no {VERDICT}); what follows is read from the files it was writing."
        )
    else:
        page.heading(
            f"Verdict: {'passed' if verdict['passed'] else 'FAILED'}",
            "Slopes are fitted over the second half of each process's life and given for the worst "
            "process of each kind.",
        )
        rows = [("breach", b, VERDICT) for b in verdict["breaches"]]
        rows += [
            ("wall time, ticks", f"{verdict['wall_s']:.0f} s, {verdict['ticks']}", VERDICT),
            (
                "ticks/s at the start, at the end",
                f"{verdict['ticks_per_s']['start']:.1f}, {verdict['ticks_per_s']['end']:.1f}",
                VERDICT,
            ),
            ("longest stall", f"{verdict['longest_stall_s']:.2f} s (tick {verdict['longest_stall_tick']})", VERDICT),
            ("ledger balanced", verdict["conserved"], VERDICT),
            ("restarts", verdict["restarts"], VERDICT),
        ]
        for kind, worst in sorted(verdict["by_kind"].items()):
            rows.append(
                (
                    f"{kind} (x{worst['processes']}): RSS slope, fd growth, peak RSS",
                    f"{worst['rss_slope_pct_h']:+.1f} %/h, {worst['fd_growth_h']:+.1f}/h, "
                    f"{worst['rss_mb_peak']:.0f} MB",
                    VERDICT,
                )
            )
        page.table(rows)


def _faults(page: Page, chaos: pd.DataFrame, chaos_file: str) -> None:
    page.heading("Faults", "Each injected fault and how it ended.")
    page.table(
        [
            (f"{r.wall_s:.1f} s, tick {r.tick}: {r.action} {r.target}", r.outcome, chaos_file)
            for r in chaos.itertuples()
        ],
        ("fault", "outcome", "from"),
    )


def _marker(chaos: pd.DataFrame | None) -> Callable[[go.Figure], go.Figure]:
    """A function that marks each injected fault on a figure over wall time."""

    def mark(fig: go.Figure) -> go.Figure:
        if chaos is not None:
            for r in chaos.itertuples():
                fig.add_vline(
                    x=r.wall_s,
                    line_dash="dot",
                    line_color=CHAOS_COLORS.get(r.action, "#999"),
                    annotation_text=r.action,
                    annotation_textangle=-90,
                    annotation_font_size=9,
                )
        fig.update_layout(xaxis_title="wall time (s)")
        return fig

    return mark


def _processes(page: Page, procs: pd.DataFrame, procs_file: str, mark: Callable[[go.Figure], go.Figure]) -> None:
    page.heading(
        "Processes",
        "Every local process of the run, sampled with psutil (agents thin and grey; a "
        "restarted agent's new process is its own line).",
    )
    for column, title in (
        ("rss_mb", "Resident memory (MB)"),
        ("fds", "Open file descriptors"),
        ("cpu_pct", "CPU (% of one core)"),
        ("threads", "Threads"),
    ):
        fig = go.Figure()
        for name, rows in procs.groupby("process", sort=False):
            agent = rows["kind"].iloc[0] == "agent"
            fig.add_trace(
                go.Scatter(
                    x=rows["wall_s"],
                    y=rows[column],
                    name=str(name),
                    mode="lines",
                    line={"width": 1 if agent else 2.5, **({"color": "#bbbbbb"} if agent else {})},
                    showlegend=not agent,
                    legendgroup="agents" if agent else str(name),
                )
            )
        page.figure(mark(fig.update_layout(title=title, yaxis_title=title)), procs_file)


def _the_run(page: Page, run: pd.DataFrame, run_file: str, mark: Callable[[go.Figure], go.Figure]) -> None:
    page.heading("The run", "Tick rate, how long ticks took, traffic and the ledger over wall time.")
    lag = "start_lag_ms" if run["start_lag_ms"].notna().any() else "slowest_tick_ms"
    fig = go.Figure(
        [
            go.Scatter(x=run["wall_s"], y=run["ticks_per_s"], name="ticks/s"),
            go.Scatter(x=run["wall_s"], y=run[lag], name=lag.replace("_", " "), yaxis="y2"),
        ]
    )
    fig.update_layout(
        title="Ticks per second and " + lag.replace("_", " "),
        yaxis_title="ticks/s",
        yaxis2={"title": "ms", "overlaying": "y", "side": "right"},
    )
    page.figure(mark(fig), run_file)
    fig = go.Figure(
        [
            go.Scatter(x=run["wall_s"], y=run["messages_per_s"], name="messages/s"),
            go.Scatter(x=run["wall_s"], y=run["bytes_per_s"] / 1000, name="kB/s", yaxis="y2"),
        ]
    )
    fig.update_layout(
        title="Radio traffic",
        yaxis_title="messages/s",
        yaxis2={"title": "kB/s", "overlaying": "y", "side": "right"},
    )
    page.figure(mark(fig), run_file)
    fig = go.Figure(
        [
            go.Scatter(x=run["wall_s"], y=run["in_flight"], name="copies in flight"),
            go.Scatter(
                x=run["wall_s"],
                y=run["dropped"].diff().fillna(0),
                name="dropped per sample",
                line={"color": DROP_COLORS.get("loss", "#0072B2")},
            ),
            go.Scatter(
                x=run["wall_s"], y=run["agents_down"] + run["agents_lost"], name="agents down or lost", yaxis="y2"
            ),
        ]
    )
    fig.update_layout(
        title="Ledger and agents",
        yaxis_title="copies",
        yaxis2={"title": "agents", "overlaying": "y", "side": "right"},
    )
    page.figure(mark(fig), run_file)
