"""``swarmbed replay``: a movie of a finished run, drawn from its recorded files only.

Needs ``run.record_trajectories: true`` (``trajectories.csv``: agents' positions per tick;
``markers.csv``: the tasks or victims on the map as they appear and vanish). With
``network.ledger: per_receiver`` it also draws, each tick, a line for every copy delivered that
tick (sender to receiver) and a dashed line, in the reason's colour, for every copy dropped that
tick. Rendering reads files and nothing else: it never runs or changes a run.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from swarmbed.files import safefiles
from swarmbed.records.run_folder import MARKERS, RECEIVER_LEDGER, SUMMARY, TRAJECTORIES, RunDir, RunFileError
from swarmbed.results.colours import DROP_COLORS, LABEL_COLORS, WALL_COLOUR
from swarmbed.results.progress import Progress

MAX_ID_LABELS = 60  # agents whose ids a frame writes beside them; more would hide the map
MAX_FRAMES = 600  # without --every, ticks are skipped so that a movie has at most this many frames


class ReplayError(ValueError):
    """A run that cannot be replayed (files missing, an empty window, no movie writer)."""


def _segments(rows: pd.DataFrame, pos: dict[int, tuple[float, float]]) -> list[list[tuple[float, float]]]:
    return [[pos[s], pos[r]] for s, r in zip(rows["sender"], rows["receiver"]) if s in pos and r in pos]


def _checked_output(
    run: Path, out: Path | None, start: float | None, end: float | None, fps: int, every: int | None
) -> Path:
    """The movie's path, once the run and the request are fit to make one (else a ReplayError)."""
    if not RunDir(run).complete:
        raise ReplayError(f"{run}: not a completed run (no {SUMMARY})")
    if not (run / TRAJECTORIES).exists() or not (run / MARKERS).exists():
        raise ReplayError(f"{run}: no {TRAJECTORIES}/{MARKERS}; run it again with --set run.record_trajectories=true")
    out = out or run / "replay.gif"
    if out.suffix not in (".gif", ".mp4"):
        raise ReplayError(f"{out}: a replay is a .gif or an .mp4")
    if out.suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise ReplayError("an .mp4 needs ffmpeg (not installed here); ask for a .gif instead")
    if fps < 1 or (every is not None and every < 1):
        raise ReplayError(f"--fps {fps} / --every {every}: both must be at least 1")
    for name, value in (("--from", start), ("--to", end)):
        if value is not None and not np.isfinite(value):
            raise ReplayError(f"{name} {value}: give a time in simulated seconds")
    return out


def _recorded(run: Path) -> tuple[float, int, pd.DataFrame, pd.DataFrame, pd.DataFrame | None, list]:
    """The run's tick length and ticks, its trajectories, its markers, (per-receiver ledger) its
    copies and its walls."""
    folder = RunDir(run)
    try:
        dt, ticks = folder.dt(), folder.ticks()
        traj, markers = folder.trajectories(), folder.markers()
        copies = folder.receivers() if folder.has(RECEIVER_LEDGER) else None
        walls = folder.walls()
    except RunFileError as exc:
        raise ReplayError(str(exc)) from None
    if traj.empty:
        raise ReplayError(f"{run / TRAJECTORIES}: no row")
    if "label" not in traj:  # recorded before agents had labels
        traj["label"] = ""
    return dt, ticks, traj, markers, copies, walls


def _frame_ticks(traj: pd.DataFrame, dt: float, start: float | None, end: float | None, every: int | None) -> list[int]:
    """The ticks drawn: within --from/--to, every ``every``-th (default: at most MAX_FRAMES)."""
    first, last = int(traj["tick"].min()), int(traj["tick"].max())
    lo = first if start is None else max(first, int(np.ceil(start / dt)))
    hi = last if end is None else min(last, int(end / dt))
    if hi < lo:
        raise ReplayError(f"no tick between {start} s and {end} s (the run has {first * dt}-{last * dt} s)")
    every = every or max(1, int(np.ceil((hi - lo + 1) / MAX_FRAMES)))
    return list(range(lo, hi + 1, every))


def _legend(ax: Any, copies: pd.DataFrame | None) -> None:
    """What the marks are (agents, tasks or victims), and, with the per-receiver ledger, delivered
    copies and each drop reason the run has; without it a note that links need that ledger."""
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], ls="", marker="o", color="#222222", label="agent (its id beside it)"),
        Line2D([], [], ls="", marker="s", color="#999999", label="task or victim"),
    ]
    if copies is not None:
        reasons = [r for r in DROP_COLORS if r != "run_ended" and r in set(copies["outcome"])]
        handles += [Line2D([], [], color="#1f77b4", lw=1, label="delivered")]
        handles += [Line2D([], [], color=DROP_COLORS[r], lw=1, ls="--", label=r.replace("_", " ")) for r in reasons]
    ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.8)
    if copies is None:
        ax.text(
            0.01,
            0.01,
            "links: run with network.ledger: per_receiver",
            transform=ax.transAxes,
            fontsize=8,
            color="#777777",
        )


def replay(
    run: Path,
    out: Path | None = None,
    start: float | None = None,
    end: float | None = None,
    fps: int = 10,
    every: int | None = None,
    progress: bool = False,
) -> tuple[Path, int]:
    """Write the movie (``.gif``, or ``.mp4`` where ffmpeg is installed); returns it and its frame count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import animation
    from matplotlib.collections import LineCollection

    out = _checked_output(run, out, start, end, fps, every)
    dt, ticks, traj, markers, copies, walls = _recorded(run)
    frames = _frame_ticks(traj, dt, start, end, every)

    marker_xy = markers.assign(
        x=pd.to_numeric(markers["x"], errors="coerce"), y=pd.to_numeric(markers["y"], errors="coerce")
    )
    marker_xy = marker_xy[np.isfinite(marker_xy["x"]) & np.isfinite(marker_xy["y"])]
    wall_xy = np.array(walls, dtype=float).reshape(-1, 2)
    xs = np.concatenate([traj["x"].to_numpy(dtype=float), marker_xy["x"].to_numpy(dtype=float), wall_xy[:, 0]])
    ys = np.concatenate([traj["y"].to_numpy(dtype=float), marker_xy["y"].to_numpy(dtype=float), wall_xy[:, 1]])
    pad = 0.05 * max(float(np.ptp(xs)), float(np.ptp(ys)), 1.0)
    by_tick = dict(tuple(traj.groupby("tick")))
    # a marker drawn where no number is (a crafted file) is left out; a vanishing one needs none
    markers = markers[(markers["event"] == "vanish") | markers.index.isin(marker_xy.index)]
    marker_events = markers.groupby("tick")
    marker_ticks = sorted(marker_events.groups)

    fig, ax = plt.subplots(figsize=(6.4, 6.4), dpi=80)
    ax.set_xlim(xs.min() - pad, xs.max() + pad)
    ax.set_ylim(ys.min() - pad, ys.max() + pad)
    ax.set_aspect("equal")
    ax.add_collection(LineCollection(walls, colors=WALL_COLOUR, linewidths=2.0, zorder=1))
    links = LineCollection([], colors="#1f77b4", linewidths=0.6, alpha=0.5)
    drops = LineCollection([], linewidths=0.8, linestyles="dashed", alpha=0.8)
    ax.add_collection(links)
    ax.add_collection(drops)
    marks = ax.scatter([], [], s=24, marker="s")
    agents = ax.scatter([], [], s=40, c="#222222", edgecolors="black", linewidths=1.2, zorder=3)
    label = ax.text(0.01, 0.99, "", transform=ax.transAxes, va="top", family="monospace")
    _legend(ax, copies)
    present: dict[int, tuple[float, float, str]] = {}
    applied = [-1]  # last tick whose marker events are in `present`
    ids: list[Any] = []  # the agents' id labels of the frame drawn

    def draw(k: int):
        for t in marker_ticks:
            if applied[0] < t <= k:
                for m, x, y, lab, event in marker_events.get_group(t)[["marker", "x", "y", "label", "event"]].values:
                    if event == "vanish":
                        present.pop(int(m), None)
                    else:
                        present[int(m)] = (float(x), float(y), str(lab))
        applied[0] = k
        now = by_tick.get(k)
        pos = {} if now is None else {int(a): (x, y) for a, x, y in now[["agent", "x", "y"]].values}
        agents.set_offsets(np.array(list(pos.values())) if pos else np.empty((0, 2)))
        if now is not None:
            agents.set_facecolor([LABEL_COLORS.get(lab, "#222222") for lab in now["label"]])
        for text in ids:
            text.remove()
        ids.clear()
        if len(pos) <= MAX_ID_LABELS:  # beyond, the ids would hide the map
            for a, (x, y) in pos.items():
                ids.append(ax.annotate(str(a), (x, y), xytext=(4, 4), textcoords="offset points", fontsize=6))
        if present:
            marks.set_offsets(np.array([(x, y) for x, y, _ in present.values()]))
            marks.set_color([LABEL_COLORS.get(lab, "#999999") for *_, lab in present.values()])
        else:
            marks.set_offsets(np.empty((0, 2)))
        if copies is not None:
            now_copies = copies[copies["tick"] == k]
            delivered = now_copies[now_copies["outcome"] == "delivered"]
            dropped = now_copies[~now_copies["outcome"].isin(["delivered", "run_ended"])]
            links.set_segments(_segments(delivered, pos))
            drop_rows = dropped[dropped["sender"].isin(pos) & dropped["receiver"].isin(pos)]
            drops.set_segments(_segments(drop_rows, pos))
            drops.set_color([DROP_COLORS.get(o, "#7f7f7f") for o in drop_rows["outcome"]])
        label.set_text(f"tick {k}  t = {k * dt:,.1f} s")
        return agents, marks, links, drops, label

    fig.tight_layout()
    movie = animation.FuncAnimation(fig, draw, frames=frames, blit=False)
    writer = animation.PillowWriter(fps=fps) if out.suffix == ".gif" else animation.FFMpegWriter(fps=fps)
    try:
        with safefiles.replacing(out) as tmp, Progress(len(frames), "replay", "frames", enabled=progress) as bar:
            movie.save(tmp, writer=writer, progress_callback=lambda i, _n: bar.update(i + 1))
    finally:
        plt.close(fig)
    return out, len(frames)
