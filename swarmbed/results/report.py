"""``swarmbed report``: the bandwidth accounting of a run or a sweep as one HTML page.

The page is self-contained (plotly's script inlined, no network needed to open it), its plots are
interactive (hover, zoom), and every number on it names the file of the run directory it comes
from. For a run: totals with the ledger's conservation re-checked from ``network_ledger.csv``,
bytes and messages per agent and per message kind, bytes per second over simulated time per kind
and per sending agent, drops by reason over time, copies by sender and outcome, message sizes per
kind, the radio copy by copy where its models computed per-copy figures (delivery against
distance with the model's curve, runs of lost copies, delays: :mod:`.radio_pages`), and the run's
outcome beside its traffic. For a sweep: the same per scenario with 95 % confidence intervals,
and the cost-benefit plots (outcome against messages and against bytes, one point per run, one
colour per scenario).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd
import plotly.graph_objects as go

import swarmbed
from swarmbed.files import safefiles
from swarmbed.plugins.registry import registered_scenario
from swarmbed.records.run_folder import RECEIVER_LEDGER, TIMESERIES, TRAJECTORIES, TRANSPORT, RunDir, RunFileError
from swarmbed.records.summary import NetworkSummary, RunSummary
from swarmbed.results.campaign_folders import PARQUET, SOAK_PROCESSES, TABLE, read_table
from swarmbed.results.colours import DROP_COLORS, WALL_COLOUR
from swarmbed.results.page import Page, _fmt
from swarmbed.results.pooling import mixed_configurations
from swarmbed.results.radio_pages import radio_pages
from swarmbed.results.soak_page import soak_report

MAX_BINS = 300  # time series are binned to at most this many points: pages stay small for long runs


class ReportError(ValueError):
    """A folder that is neither a complete run nor a sweep."""


def _benefit(kind: str) -> str | None:
    return registered_scenario(kind).benefit_metric


def _outcomes(kind: str) -> list[str]:
    """A scenario's benefit metric, then its other outcome metrics ([] for a kind not registered here:
    a name read from a results folder is never imported)."""
    cls = registered_scenario(kind)
    return [m for m in (cls.benefit_metric, *cls.outcome_metrics) if m]


def _binned(frame: pd.DataFrame, ticks: int, dt: float, by: str, value: str) -> pd.DataFrame:
    """``value`` summed per time bin and per ``by``, as a rate per simulated second."""
    width = max(1, int(np.ceil(ticks / MAX_BINS)))
    frame = frame.assign(bin=(frame["tick"] // width) * width)
    table = frame.pivot_table(index="bin", columns=by, values=value, aggfunc="sum", fill_value=0)
    table = table.reindex(range(0, max(ticks, 1), width), fill_value=0)
    table.index = table.index * dt
    return table / (width * dt)


def run_report(run: Path) -> tuple[str, int]:
    """The HTML of one run's report and how many figures it has."""
    folder = RunDir(run)
    try:
        summary = folder.summary()
        config, dt, ticks = folder.config(), folder.dt(), folder.ticks()
        ledger, agents = folder.ledger(), folder.agents()
        wire = folder.json(TRANSPORT) if folder.has(TRANSPORT) else None
        receivers = folder.receivers() if folder.has(RECEIVER_LEDGER) else None
        series = folder.timeseries() if folder.has(TIMESERIES) else None
        walls = folder.walls()
        paths = folder.trajectories() if walls and folder.has(TRAJECTORIES) else None
    except RunFileError as exc:
        raise ReportError(str(exc)) from None
    sent = ledger[ledger["outcome"] == "sent"]
    copies = ledger[ledger["outcome"] != "sent"]  # one row per outcome of the copies
    page = _totals(summary, sent, copies, ticks, dt)
    if wire is not None:
        _on_the_wire(page, run, wire, agents)
    _per_agent(page, agents)
    _per_kind(page, summary.network, sent)
    _over_time(page, sent, copies, ticks, dt)
    _who_to_whom(page, receivers, copies, summary.agents)
    radio_pages(page, receivers, config)
    if walls:
        _map(page, walls, paths)
    _outcome_beside_traffic(page, _benefit(summary.scenario_kind), series)
    subtitle = (
        f"run {run} · seed {summary.seed} · swarmbed {swarmbed.__version__} · "
        f"report made {time.strftime('%Y-%m-%d %H:%M')}"
    )
    return page.render(subtitle), page.figures


def _totals(summary: RunSummary, sent: pd.DataFrame, copies: pd.DataFrame, ticks: int, dt: float) -> Page:
    """The page, opened with the run's totals (each with the file it comes from)."""
    net = summary.network
    page = Page(f"{summary.name}: bandwidth accounting")
    delivered = int(copies.loc[copies["outcome"] == "delivered", "messages"].sum())
    dropped = copies[copies["outcome"] != "delivered"].groupby("outcome")["messages"].sum()
    balanced = int(copies["messages"].sum()) == delivered + int(dropped.sum()) == net.copies
    page.heading(
        "Totals",
        "Messages count transmissions; copies count one per intended receiver. Payload bytes "
        "are the encoded messages as agents hand them to the radio.",
    )
    benefit = _benefit(summary.scenario_kind)
    rows = [
        ("scenario / allocator", f"{summary.scenario_kind} / {summary.allocator}", "summary.json"),
        ("agents, ticks, dt", f"{summary.agents}, {ticks}, {dt} s", "summary.json, config.yaml"),
        ("messages sent", int(sent["messages"].sum()), "network_ledger.csv (sent rows)"),
        ("payload bytes sent", int(sent["bytes"].sum()), "network_ledger.csv (sent rows)"),
        ("copies", int(copies["messages"].sum()), "network_ledger.csv (other rows)"),
        ("copies delivered", delivered, "network_ledger.csv"),
        *[(f"copies dropped: {reason}", int(n), "network_ledger.csv") for reason, n in dropped.items()],
        ("copies = delivered + dropped, and as summary.json says", balanced, "network_ledger.csv, summary.json"),
        ("agents' and proxy's byte counts agree", net.bytes_agree, "summary.json"),
    ]
    if benefit and benefit in summary.document:
        kb = max(net.bytes_sent, 1) / 1000
        rows += [
            (benefit.replace("_", " "), summary.outcome(benefit), "summary.json"),
            (f"{benefit.replace('_', ' ')} per kB sent", summary.outcome(benefit) / kb, "summary.json"),
        ]
    page.table(rows)
    return page


def _on_the_wire(page: Page, run: Path, wire: dict, agents: pd.DataFrame) -> None:
    """What agents' samples and sockets carried, beside the radio payload (transport.json)."""
    t = wire.get("totals")
    if not isinstance(t, dict):
        raise ReportError(f"{run / TRANSPORT}: no totals object")
    page.heading(
        "On the wire",
        "Payload: the radio messages as agents encode them (reproducible). Samples: "
        "the per-tick Zenoh samples agents publish (actions, radio messages, framing of ours) and "
        "receive (observation, inbox). TCP: what each process's sockets sent and received, as the "
        "kernel counts it (Zenoh framing, control traffic, keep-alives; not IP/TCP headers). "
        "Measured, so not reproducible byte for byte.",
    )
    page.table(
        [
            ("radio payload bytes sent", t["radio_payload_bytes"], "transport.json, summary.json"),
            ("per-tick sample bytes agents published", t["agent_sample_bytes_out"], "transport.json"),
            ("per-tick sample bytes agents received", t["agent_sample_bytes_in"], "transport.json"),
            ("TCP bytes agents sent", t["agent_tcp_bytes_sent"], "transport.json"),
            ("TCP bytes agents received", t["agent_tcp_bytes_received"], "transport.json"),
            ("overhead: TCP bytes agents sent / radio payload bytes", t["overhead_ratio"], "transport.json"),
            (
                "TCP bytes all processes sent / received",
                f"{_fmt(t['tcp_bytes_sent'])} / {_fmt(t['tcp_bytes_received'])}",
                "transport.json",
            ),
        ]
    )
    procs = {
        n: wire["processes"][n]
        for n in sorted(
            (n for n in wire["processes"] if n.startswith("agent_")),
            key=lambda n: tuple(int(x) for x in n.removeprefix("agent_").split(".") if x.isdigit()),
        )
    }
    names = [n.removeprefix("agent_") for n in procs]  # agent 2 before agent 10, as every other chart
    sent_by = agents.set_index("agent")["bytes_sent"]
    fig = go.Figure(
        [
            go.Bar(x=names, y=[sent_by.get(int(n), 0) for n in names], name="radio payload"),
            go.Bar(
                x=names,
                y=[(p.get("samples") or {}).get("out") for p in procs.values()],
                name="per-tick samples published",
            ),
            go.Bar(x=names, y=[(p.get("tcp") or {}).get("sent") for p in procs.values()], name="TCP bytes sent"),
        ]
    )
    fig.update_layout(
        title="What each agent sent, layer by layer",
        xaxis_title="agent",
        yaxis_title="bytes",
        barmode="group",
        xaxis={"type": "category", "categoryorder": "array", "categoryarray": names},
    )
    page.figure(fig, "transport.json, agents.csv")


def _map(page: Page, walls: list, paths: pd.DataFrame | None) -> None:
    """The obstacles' walls, and each agent's path where trajectories were recorded."""
    page.heading("Map", "the walls of the run's obstacles; each agent's path with run.record_trajectories")
    xs = [v for (a, b) in walls for v in (a[0], b[0], None)]
    ys = [v for (a, b) in walls for v in (a[1], b[1], None)]
    traces = [go.Scatter(x=xs, y=ys, mode="lines", name="walls", line={"color": WALL_COLOUR, "width": 3})]
    if paths is not None:
        for agent, rows in paths.groupby("agent", sort=True):
            traces.append(
                go.Scattergl(x=rows["x"], y=rows["y"], mode="lines", name=f"agent {agent}", line={"width": 1})
            )
    fig = go.Figure(traces)
    fig.update_layout(title="Walls and paths", yaxis={"scaleanchor": "x"}, legend=LEGEND_BELOW)
    page.figure(fig, "config.yaml, trajectories.csv")


def _per_agent(page: Page, agents: pd.DataFrame) -> None:
    page.heading("Per agent")
    fig = go.Figure(
        _side_by_side(
            agents["agent"], agents["bytes_sent"], "payload bytes sent", agents["messages_sent"], "messages sent"
        )
    )
    fig.update_layout(
        title="Bytes and messages each agent sent",
        xaxis_title="agent",
        yaxis_title="bytes",
        yaxis2=_count_axis("messages", agents["messages_sent"]),
        barmode="group",
        xaxis={"type": "category"},
        legend=LEGEND_BELOW,
    )
    page.figure(fig, "agents.csv")


def _per_kind(page: Page, net: NetworkSummary, sent: pd.DataFrame) -> None:
    page.heading("Per message kind")
    per_kind = {kind: {"messages": t.messages, "bytes": t.bytes} for kind, t in net.per_kind.items()}
    kinds = pd.DataFrame(per_kind).T.reset_index(names="kind") if per_kind else pd.DataFrame()
    if len(kinds):
        fig = go.Figure(_side_by_side(kinds["kind"], kinds["bytes"], "payload bytes", kinds["messages"], "messages"))
        fig.update_layout(
            title="Bytes and messages per kind",
            yaxis_title="bytes",
            barmode="group",
            yaxis2=_count_axis("messages", kinds["messages"]),
            legend=LEGEND_BELOW,
        )
        page.figure(fig, "summary.json (network.per_kind)")
        sizes = sent.assign(size=sent["bytes"] / sent["messages"])
        fig = go.Figure([go.Histogram(x=g["size"], name=k, opacity=0.7) for k, g in sizes.groupby("kind")])
        fig.update_layout(
            title="Message sizes per kind (mean per sender and tick)",
            xaxis_title="bytes",
            yaxis_title="count",
            barmode="overlay",
        )
        page.figure(fig, "network_ledger.csv (sent rows)")


def _over_time(page: Page, sent: pd.DataFrame, copies: pd.DataFrame, ticks: int, dt: float) -> None:
    page.heading("Over simulated time")
    for by, what in (("kind", "message kind"), ("sender", "sending agent")):
        rate = _binned(sent, ticks, dt, by, "bytes")
        fig = go.Figure(
            [go.Scatter(x=rate.index, y=rate[c], name=str(c), stackgroup="one", mode="lines") for c in rate.columns]
        )
        fig.update_layout(
            title=f"Payload bytes per second by {what} (stacked)",
            xaxis_title="simulated time (s)",
            yaxis_title="bytes/s",
        )
        page.figure(fig, "network_ledger.csv (sent rows)")
    drops = copies[copies["outcome"] != "delivered"]
    if len(drops):
        rate = _binned(drops, ticks, dt, "outcome", "messages")
        fig = go.Figure(
            [
                go.Scatter(x=rate.index, y=rate[c], name=str(c), mode="lines", line={"color": DROP_COLORS.get(str(c))})
                for c in rate.columns
            ]
        )
        fig.update_layout(
            title="Dropped copies per second by reason", xaxis_title="simulated time (s)", yaxis_title="copies/s"
        )
        page.figure(fig, "network_ledger.csv (drop rows)")


def _who_to_whom(page: Page, receivers: pd.DataFrame | None, copies: pd.DataFrame, agents: int) -> None:
    if receivers is not None:
        page.heading(
            "Who sent what to whom, and what became of it",
            "One cell per sender and receiver: copies delivered, and copies dropped (any reason).",
        )
        per_copy = receivers
        ids = [str(i) for i in range(agents)]
        for title, rows in (
            ("delivered", per_copy["outcome"] == "delivered"),
            ("dropped", per_copy["outcome"] != "delivered"),
        ):
            cells = per_copy[rows].groupby(["sender", "receiver"]).size().unstack(fill_value=0)
            cells = cells.reindex(index=range(len(ids)), columns=range(len(ids)), fill_value=0)
            fig = go.Figure(
                go.Heatmap(
                    z=cells.values,
                    x=ids,
                    y=ids,
                    colorscale="Blues" if title == "delivered" else "Reds",
                    hovertemplate=f"sender %{{y}} to receiver %{{x}}<br>%{{z}} copies {title}<extra></extra>",
                )
            )
            fig.update_layout(
                title=f"Copies {title}, sender by receiver",
                xaxis_title="receiver",
                yaxis_title="sender",
                yaxis_autorange="reversed",
            )
            page.figure(fig, RECEIVER_LEDGER)
    else:
        page.heading(
            "Who sent what, and what became of it",
            "Copies by sending agent and outcome (network.ledger: per_receiver adds the sender by receiver matrices).",
        )
        matrix = copies.pivot_table(index="outcome", columns="sender", values="messages", aggfunc="sum", fill_value=0)
        fig = go.Figure(
            go.Heatmap(
                z=matrix.values,
                x=[str(c) for c in matrix.columns],
                y=list(matrix.index),
                colorscale="Blues",
                hovertemplate="sender %{x}<br>%{y}: %{z} copies<extra></extra>",
            )
        )
        fig.update_layout(title="Copies by sender and outcome", xaxis_title="sender")
        page.figure(fig, "network_ledger.csv")


def _outcome_beside_traffic(page: Page, benefit: str | None, series: pd.DataFrame | None) -> None:
    if benefit and series is not None and {benefit, "time", "bytes_sent"} <= set(series.columns):
        fig = go.Figure(
            [
                go.Scatter(x=series["time"], y=series[benefit], name=benefit.replace("_", " ")),
                go.Scatter(x=series["time"], y=series["bytes_sent"] / 1000, name="kB sent (cumulative)", yaxis="y2"),
            ]
        )
        fig.update_layout(
            title="Outcome beside traffic",
            xaxis_title="simulated time (s)",
            yaxis_title=benefit.replace("_", " "),
            yaxis2={"title": "kB sent", "overlaying": "y", "side": "right"},
            legend=LEGEND_BELOW,
        )
        page.figure(fig, "timeseries.csv")


#: a legend under the plot: at the right it covers the title of a second y axis
LEGEND_BELOW = {"orientation": "h", "yanchor": "top", "y": -0.2, "xanchor": "left", "x": 0}


def _side_by_side(x, left, left_name: str, right, right_name: str) -> list:
    """Two bar series on two y axes, drawn beside each other: plotly groups bars only within an
    axis, so each series gets its own offset group (else the second is drawn over the first)."""
    return [
        go.Bar(x=x, y=left, name=left_name, offsetgroup="left"),
        go.Bar(x=x, y=right, name=right_name, yaxis="y2", offsetgroup="right", opacity=0.7),
    ]


def _count_axis(title: str, counts) -> dict:
    """A right-hand axis of counts: whole-number ticks from zero (never 0.136, 0.272, ...)."""
    top = max(float(pd.Series(counts).max() or 0), 1.0)
    magnitude = 10 ** int(np.floor(np.log10(top / 5))) if top >= 5 else 1
    step = next(m * magnitude for m in (1, 2, 5, 10) if m * magnitude * 5 >= top)  # about five ticks
    return {
        "title": title,
        "overlaying": "y",
        "side": "right",
        "rangemode": "tozero",
        "tick0": 0,
        "dtick": step,
        "showgrid": False,
    }


def _ci(values: pd.Series) -> float:
    from scipy import stats  # 0.4 s to import: only a sweep's page needs it

    n = values.count()
    return float(stats.t.ppf(0.975, n - 1) * values.std(ddof=1) / np.sqrt(n)) if n > 1 else 0.0


def sweep_report(sweep: Path) -> tuple[str, int]:
    """The HTML of one sweep's report and how many figures it has."""
    table = read_table(sweep)
    ok = table[table["status"] == "ok"]
    if ok.empty:
        raise ReportError(f"{sweep}: no completed run in sweep.csv")
    mixed = mixed_configurations(sweep, table)
    if mixed:
        raise ReportError(f"{sweep}: {mixed}; a scenario's runs may differ only in their seed")
    kinds = ok["scenario_kind"].dropna().unique() if "scenario_kind" in ok else []
    # the outcome to set against the cost: the scenario's benefit metric, or where that is the same in
    # every run (MT-SR's tasks completed, when every run completes its mission) the first outcome that varies
    outcomes = [
        m
        for kind in kinds
        for m in _outcomes(kind)
        if m in ok and pd.api.types.is_numeric_dtype(ok[m]) and not pd.api.types.is_bool_dtype(ok[m])
    ]
    benefit = next((m for m in outcomes if ok[m].nunique() > 1), outcomes[0] if outcomes else None)
    page = Page(f"{sweep.name}: bandwidth accounting of a sweep")
    page.heading("Per scenario", "Means over the completed runs with 95 % confidence intervals (t).")
    metrics = [
        m
        for m in (
            "network.messages_sent",
            "network.bytes_sent",
            "wire.agent_tcp_bytes_sent",
            "wire.overhead_ratio",
            benefit,
        )
        if m and m in ok
    ]
    rows = []
    for scenario, group in ok.groupby("scenario"):
        for m in metrics:
            n = int(group[m].count())
            shown = f"{group[m].mean():,.1f} ± {_ci(group[m]):,.1f} (n={n})" if n else _NOT_MEASURED.get(m, "no value")
            rows.append((f"{scenario}: {m}", shown, "sweep.csv"))
    page.table(rows, ("scenario: figure", "mean ± 95 % CI", "from"))
    metrics = [m for m in metrics if ok[m].count()]  # a chart of nothing is left out
    for m in metrics:
        g = ok.groupby("scenario")[m]
        fig = go.Figure(
            go.Bar(x=list(g.mean().index), y=g.mean().values, error_y={"type": "data", "array": [_ci(v) for _, v in g]})
        )
        fig.update_layout(title=f"{m} per scenario (95 % CI)", yaxis_title=m)
        page.figure(fig, "sweep.csv")
    if benefit:
        page.heading("Cost and benefit", f"One point per run: {benefit} against what it cost on the radio.")
        for cost in [
            c
            for c in ("network.messages_sent", "network.bytes_sent", "wire.agent_tcp_bytes_sent")
            if c in ok and ok[c].count()
        ]:
            fig = go.Figure(
                [
                    go.Scatter(
                        x=g[cost],
                        y=g[benefit],
                        mode="markers",
                        name=str(s),
                        hovertemplate=f"{s}<br>run %{{text}}<extra></extra>",
                        text=g["run"],
                    )
                    for s, g in ok.groupby("scenario")
                ]
            )
            fig.update_layout(
                title=f"{benefit} against {cost}",
                xaxis_title=cost,
                yaxis_title=benefit,
                xaxis_type="log" if (ok[cost] > 0).all() else "linear",
            )
            page.figure(fig, "sweep.csv")
    subtitle = (
        f"sweep {sweep} · {len(ok)} of {len(table)} runs complete · swarmbed {swarmbed.__version__} · "
        f"report made {time.strftime('%Y-%m-%d %H:%M')}"
    )
    return page.render(subtitle), page.figures


#: why a figure of a sweep has no value in any run (a run on the in-process engine has no sockets)
_NOT_MEASURED = {
    "wire.agent_tcp_bytes_sent": "not measured in-process (no sockets)",
    "wire.overhead_ratio": "not measured in-process (no sockets)",
}


def is_soak(folder: Path) -> bool:
    return (folder / SOAK_PROCESSES).exists() or (folder / (SOAK_PROCESSES + ".part")).exists()


def _report_text(folder: Path) -> str:
    if is_soak(folder):
        return soak_report(folder)[0]
    if RunDir(folder).complete:
        return run_report(folder)[0]
    if (folder / TABLE).exists() or (folder / PARQUET).exists():
        return sweep_report(folder)[0]
    raise ReportError(
        f"{folder}: neither a completed run (no summary.json), a sweep (no sweep.csv) nor a soak "
        "(no soak_processes.csv)"
    )


def report(folder: Path, out: Path | None = None) -> Path:
    """Write the report of a soak, a run or a sweep folder; returns the file (``out`` a folder: the
    report goes into it). Written under a temporary name, renamed when complete."""
    out = out or folder / "report.html"
    if out.is_dir():
        out = out / "report.html"
    if not out.parent.is_dir():  # said before the folder is read: the user's typo, not our temporary file
        raise ReportError(f"-o {out}: the folder {out.parent} does not exist")
    try:
        text = _report_text(folder)
    except ReportError:
        raise
    except RunFileError as exc:
        raise ReportError(str(exc)) from None
    except (KeyError, ValueError, TypeError) as exc:  # a file of the right shape holding the wrong things
        raise ReportError(
            f"{folder}: a file of it holds what a report cannot draw ({type(exc).__name__}: {exc})"
        ) from None
    safefiles.write_text(out, text)
    return out
