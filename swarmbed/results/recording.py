"""``swarmbed replay RUN --mcap FILE.mcap``: a finished run as an MCAP recording that Foxglove-class
viewers scrub, drawn from the run's files only (it never runs or changes a run).

Written with Foxglove's SDK and its well-known schemas where one fits, plain JSON schemas where none
does. Topics, all in the frame ``world`` (the arena's x, y; z up):

- ``/agents`` (foxglove.SceneUpdate): each agent as a sphere with an arrow along its heading (the
  direction it last moved: trajectories record positions only) and its label (current task or
  victim) as text and metadata;
- ``/agents/poses`` (foxglove.PosesInFrame): every agent's pose, for plots and followers;
- ``/markers`` (foxglove.SceneUpdate): tasks or victims as cubes while they are on the map, deleted
  when they vanish;
- ``/radio`` (foxglove.SceneUpdate): each tick's copies as lines from sender to receiver, one
  colour per outcome (delivered, or the drop reason), with ``network.ledger: per_receiver``;
- ``/walls`` (foxglove.SceneUpdate): the obstacles' walls as lines, once, living for the whole run
  (a run with ``obstacles:`` only);
- ``/counters`` (JSON): the run's counters of each tick (``timeseries.csv``);
- ``/agents/tree`` (JSON): each agent's behavior tree status changes of each tick, with
  ``run.record_bt`` (node uids as in ``bt/agent_<id>.btlog``, whose trees Groot2 opens).

Messages are stamped in simulated time from the epoch the .btlog files use (2000-01-01), so the same
run gives the same file.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from swarmbed.files import safefiles
from swarmbed.records.run_folder import (
    BT,
    MARKERS,
    RECEIVER_LEDGER,
    SUMMARY,
    TRAJECTORIES,
    RunDir,
    RunFileError,
    btlog_name,
    read_member,
)
from swarmbed.results.colours import DROP_COLORS, WALL_COLOUR
from swarmbed.wire.btlog import EPOCH_US, BtLogError, read_btlog

MAX_BTLOG_BYTES = 1 << 30  # one agent's tree log: far beyond a day's run

FRAME = "world"
EPOCH_NS = EPOCH_US * 1000
DELIVERED = "#1f77b4"
STATUS_NAMES = ("IDLE", "RUNNING", "SUCCESS", "FAILURE")
COUNTERS_SCHEMA = {"type": "object", "properties": {"tick": {"type": "integer"}, "time": {"type": "number"}}}
TREE_SCHEMA = {
    "type": "object",
    "properties": {
        "agent": {"type": "integer"},
        "tick": {"type": "integer"},
        "changes": {"type": "array", "items": {"type": "object"}},
    },
}


class RecordingError(ValueError):
    """A run that cannot be recorded (files missing, the SDK not installed)."""


def _rgba(hex_colour: str, alpha: float = 1.0):
    from foxglove.messages import Color

    h = hex_colour.lstrip("#")
    r, g, b = (int(h[i : i + 2], 16) / 255 for i in (0, 2, 4))
    return Color(r=r, g=g, b=b, a=alpha)


def _stamp(tick: int, dt: float):
    from foxglove.messages import Timestamp

    ns = round(tick * dt * 1e9)
    return Timestamp(sec=EPOCH_US // 1_000_000 + ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def _pose(x: float, y: float, heading: float):
    from foxglove.messages import Pose, Quaternion, Vector3

    half = heading / 2
    return Pose(position=Vector3(x=x, y=y, z=0.0), orientation=Quaternion(x=0, y=0, z=math.sin(half), w=math.cos(half)))


def _headings(traj: pd.DataFrame) -> np.ndarray:
    """Each row's heading: the direction its agent moved since its last row (0 until it first moves)."""
    heading = np.zeros(len(traj))
    for _agent, rows in traj.groupby("agent", sort=False):
        dx, dy = np.diff(rows["x"].to_numpy(), prepend=np.nan), np.diff(rows["y"].to_numpy(), prepend=np.nan)
        moved = np.hypot(dx, dy) > 1e-9
        angle = np.where(moved, np.arctan2(dy, dx), np.nan)
        heading[rows.index] = pd.Series(angle).ffill().fillna(0.0).to_numpy()
    return heading


def write_mcap(run: Path, out: Path) -> dict:
    """Write ``run`` as an MCAP file at ``out``; returns what was written (messages per topic, bytes,
    seconds). The file is written under a temporary name and renamed when complete: an interrupted
    or failed recording never stands under ``out``."""
    with safefiles.replacing(out) as tmp:
        return _write_mcap(run, tmp)


def _write_mcap(run: Path, out: Path) -> dict:
    try:
        import foxglove
        from foxglove import channels
        from foxglove.messages import PosesInFrame, SceneUpdate
    except ImportError:
        raise RecordingError("an MCAP recording needs Foxglove's SDK: pip install 'swarmbed[viewers]'") from None
    if not RunDir(run).complete:
        raise RecordingError(f"{run}: not a completed run (no {SUMMARY})")
    if not (run / TRAJECTORIES).exists():
        raise RecordingError(f"{run}: no {TRAJECTORIES}; run it again with --set run.record_trajectories=true")
    started = time.perf_counter()
    dt, traj, markers, counters, copies, trees = _recorded(run)
    try:
        walls = RunDir(run).walls()
    except RunFileError as exc:
        raise RecordingError(str(exc)) from None
    traj["heading"] = _headings(traj)
    span = max(float(np.ptp(traj["x"])), float(np.ptp(traj["y"])), 1.0)
    size = span / 100  # an agent's sphere: a hundredth of the arena's extent

    context = foxglove.Context()
    safefiles.remove(out)
    writer = foxglove.open_mcap(out, context=context)
    agents_ch = channels.SceneUpdateChannel("/agents", context=context)
    poses_ch = channels.PosesInFrameChannel("/agents/poses", context=context)
    markers_ch = channels.SceneUpdateChannel("/markers", context=context)
    radio_ch = channels.SceneUpdateChannel("/radio", context=context)
    counters_ch = foxglove.Channel(
        "/counters", schema=_json_schema("swarmbed.Counters", COUNTERS_SCHEMA), message_encoding="json", context=context
    )
    tree_ch = foxglove.Channel(
        "/agents/tree",
        schema=_json_schema("swarmbed.TreeChanges", TREE_SCHEMA),
        message_encoding="json",
        context=context,
    )
    sent = dict.fromkeys(("/agents", "/agents/poses", "/markers", "/radio", "/counters", "/agents/tree"), 0)
    if walls:
        walls_ch = channels.SceneUpdateChannel("/walls", context=context)
        first = int(traj["tick"].min())
        walls_ch.log(_walls_update(walls, _stamp(first, dt)), log_time=EPOCH_NS + round(first * dt * 1e9))
        sent["/walls"] = 1

    marker_rows = {int(t): r for t, r in markers.groupby("tick")} if markers is not None else {}
    copy_rows = {int(t): r for t, r in copies.groupby("tick")} if copies is not None else {}
    counter_rows = {int(row["tick"]): row for row in counters.to_dict("records")}
    traj_rows = {int(t): rows for t, rows in traj.groupby("tick")}
    where: dict[int, tuple[float, float]] = {}  # each agent's last known position, for the radio's lines
    for tick in sorted(set(traj_rows) | set(counter_rows) | set(marker_rows) | set(copy_rows) | set(trees)):
        stamp, log_time = _stamp(tick, dt), EPOCH_NS + round(tick * dt * 1e9)
        rows = traj_rows.get(tick)
        if rows is not None:
            where.update((int(a), (float(x), float(y))) for a, x, y in zip(rows["agent"], rows["x"], rows["y"]))
            entities, poses = _agent_entities(rows, stamp, size)
            agents_ch.log(SceneUpdate(entities=entities), log_time=log_time)
            poses_ch.log(PosesInFrame(timestamp=stamp, frame_id=FRAME, poses=poses), log_time=log_time)
            sent["/agents"] += 1
            sent["/agents/poses"] += 1
        if tick in marker_rows:
            markers_ch.log(_marker_update(marker_rows[tick], stamp, size), log_time=log_time)
            sent["/markers"] += 1
        if tick in copy_rows:
            radio_ch.log(_radio_update(copy_rows[tick], where, stamp, dt), log_time=log_time)
            sent["/radio"] += 1
        if tick in counter_rows:
            counters_ch.log({k: _plain(v) for k, v in counter_rows[tick].items()}, log_time=log_time)
            sent["/counters"] += 1
        for agent, changes in trees.get(tick, []):
            named = [{"uid": uid, "status": STATUS_NAMES[code]} for uid, code in changes]
            tree_ch.log({"agent": agent, "tick": tick, "changes": named}, log_time=log_time)
            sent["/agents/tree"] += 1
    writer.close()
    return {"messages": sent, "bytes": out.stat().st_size, "seconds": time.perf_counter() - started}


def _recorded(run: Path) -> tuple[float, pd.DataFrame, pd.DataFrame | None, pd.DataFrame, pd.DataFrame | None, dict]:
    """What a recording is made of: the tick length, trajectories, markers (those with a position),
    the counters, the per-receiver copies and the trees' changes, each read as a crafted file may be."""
    folder = RunDir(run)
    try:
        dt, ticks = folder.dt(), folder.ticks()
        traj = folder.trajectories()
        markers = folder.markers() if folder.has(MARKERS) else None
        counters = folder.timeseries()
        copies = folder.receivers() if folder.has(RECEIVER_LEDGER) else None
        trees = _tree_changes(run, dt, ticks)
    except RunFileError as exc:
        raise RecordingError(str(exc)) from None
    if markers is not None:  # a marker where no number is (a crafted file) is left out
        xy = markers[["x", "y"]].apply(pd.to_numeric, errors="coerce")
        markers = markers[(markers["event"] != "appear") | np.isfinite(xy.to_numpy(dtype=float)).all(axis=1)]
    return dt, traj, markers, counters, copies, trees


def _agent_entities(rows: pd.DataFrame, stamp: Any, size: float) -> tuple[list, list]:
    """Each agent of a tick as a sphere, a heading arrow and its id and label, and its pose."""
    from foxglove.messages import ArrowPrimitive, KeyValuePair, SceneEntity, SpherePrimitive, TextPrimitive, Vector3

    agent_colour = _rgba("#222222")
    entities, poses = [], []
    for agent, x, y, heading, label in zip(rows["agent"], rows["x"], rows["y"], rows["heading"], rows["label"]):
        pose = _pose(float(x), float(y), float(heading))
        poses.append(pose)
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=FRAME,
                id=f"agent/{agent}",
                metadata=[KeyValuePair(key="label", value=str(label))],
                spheres=[SpherePrimitive(pose=pose, size=Vector3(x=size, y=size, z=size), color=agent_colour)],
                arrows=[
                    ArrowPrimitive(
                        pose=pose,
                        shaft_length=2 * size,
                        shaft_diameter=size / 4,
                        head_length=size,
                        head_diameter=size / 2,
                        color=agent_colour,
                    )
                ],
                texts=[
                    TextPrimitive(
                        pose=_pose(float(x), float(y) + size, 0.0),
                        billboard=True,
                        font_size=12,
                        scale_invariant=True,
                        color=agent_colour,
                        text=f"{agent} {label}".strip(),
                    )
                ],
            )
        )
    return entities, poses


def _marker_update(rows: pd.DataFrame, stamp: Any, size: float) -> Any:
    """A tick's markers: a cube for each that appeared, a deletion for each that vanished."""
    from foxglove.messages import (
        CubePrimitive,
        KeyValuePair,
        SceneEntity,
        SceneEntityDeletion,
        SceneEntityDeletionType,
        SceneUpdate,
        Vector3,
    )

    appeared, vanished = [], []
    for marker, x, y, label, event in rows[["marker", "x", "y", "label", "event"]].itertuples(index=False):
        if event == "appear":
            cube = CubePrimitive(
                pose=_pose(float(x), float(y), 0.0),
                size=Vector3(x=size, y=size, z=size),
                color=_rgba("#2ca02c"),
            )
            appeared.append(
                SceneEntity(
                    timestamp=stamp,
                    frame_id=FRAME,
                    id=f"marker/{marker}",
                    metadata=[KeyValuePair(key="label", value=str(label))],
                    cubes=[cube],
                )
            )
        else:
            vanished.append(
                SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.MatchingId, id=f"marker/{marker}")
            )
    return SceneUpdate(entities=appeared, deletions=vanished)


def _walls_update(walls: list, stamp: Any) -> Any:
    """The obstacles' walls as one entity of lines that never expires."""
    from foxglove.messages import LinePrimitive, LinePrimitiveLineType, Point3, SceneEntity, SceneUpdate

    points = [Point3(x=float(x), y=float(y), z=0.0) for wall in walls for x, y in wall]
    line = LinePrimitive(
        type=LinePrimitiveLineType.LineList,
        thickness=2.0,
        scale_invariant=True,
        points=points,
        color=_rgba(WALL_COLOUR),
    )
    return SceneUpdate(entities=[SceneEntity(timestamp=stamp, frame_id=FRAME, id="walls", lines=[line])])


def _radio_update(rows: pd.DataFrame, where: dict[int, tuple[float, float]], stamp: Any, dt: float) -> Any:
    """A tick's copies as lines from sender to receiver, one colour per outcome, living one tick."""
    from foxglove.messages import LinePrimitive, LinePrimitiveLineType, Point3, SceneEntity, SceneUpdate

    lines = []
    for outcome, group in rows.groupby("outcome", sort=True):
        points = [
            Point3(x=p[0], y=p[1], z=0.0)
            for s, r in zip(group["sender"], group["receiver"])
            if int(s) in where and int(r) in where
            for p in (where[int(s)], where[int(r)])
        ]
        if points:
            colour = DELIVERED if outcome == "delivered" else DROP_COLORS.get(str(outcome), "#7f7f7f")
            lines.append(
                LinePrimitive(
                    type=LinePrimitiveLineType.LineList,
                    thickness=1.0,
                    scale_invariant=True,
                    points=points,
                    color=_rgba(colour, 0.6),
                )
            )
    entity = SceneEntity(timestamp=stamp, frame_id=FRAME, id="radio", lifetime=_duration(dt), lines=lines)
    return SceneUpdate(entities=[entity])


def _json_schema(name: str, schema: dict):
    import foxglove

    return foxglove.Schema(name=name, encoding="jsonschema", data=json.dumps(schema).encode())


def _duration(seconds: float):
    from foxglove.messages import Duration

    ns = round(seconds * 1e9)
    return Duration(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def _plain(value: object) -> object:
    """A JSON value of a table cell (numpy scalars become Python numbers)."""
    return value.item() if isinstance(value, np.generic) else value


def _tree_changes(run: Path, dt: float, ticks: int) -> dict[int, list[tuple[int, list[tuple[int, int]]]]]:
    """tick -> [(agent, [(uid, status code)])] from the run's .btlog files, if it recorded them (a
    RunFileError for a file that is not one, or whose records fall outside the run's ticks)."""
    folder = run / BT
    out: dict[int, list[tuple[int, list[tuple[int, int]]]]] = {}
    if not folder.is_dir():
        return out
    tick_us = dt * 1_000_000
    agent = 0
    while (folder / btlog_name(agent)).exists():
        name = f"{BT}/{btlog_name(agent)}"
        try:
            _, _, records = read_btlog(read_member(run, name, MAX_BTLOG_BYTES))
        except (BtLogError, UnicodeDecodeError) as exc:
            raise RunFileError(f"{run / name}: {exc}") from None
        by_tick: dict[int, list[tuple[int, int]]] = {}
        for offset, uid, code in records:
            tick = round(offset / tick_us)
            if tick > ticks or code >= len(STATUS_NAMES):
                raise RunFileError(f"{run / name}: a record at tick {tick} with status {code}, not of this run")
            by_tick.setdefault(tick, []).append((uid, code))
        for tick, changes in by_tick.items():
            out.setdefault(tick, []).append((agent, changes))
        agent += 1
    return out
