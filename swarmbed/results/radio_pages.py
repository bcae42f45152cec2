"""The radio's pages of a run's report: what a wireless-networking reviewer looks for first.

From the per-receiver ledger (``network.ledger: per_receiver``) of a run whose radio computed per-copy
figures (a propagation model, bursts or a delay): the delivery ratio against distance with the
model's curve over it, the outages of working links (runs of lost copies between deliveries), and
the delays of delivered
copies. (Drops by reason over time are on the report's own page.)
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import plotly.graph_objects as go
from pydantic import ValidationError

from swarmbed.netem.propagation import delivery_probability
from swarmbed.records.run_folder import RECEIVER_LEDGER, RunFileError
from swarmbed.results.page import Page
from swarmbed.schema.experiment import NetworkSection

DISTANCE_BINS = 25
LONGEST_RUN_SHOWN = 40


def _wilson(k: np.ndarray, n: np.ndarray, z: float = 1.96) -> tuple[np.ndarray, np.ndarray]:
    """95 % Wilson score interval of k successes in n trials."""
    p = k / np.maximum(n, 1)
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def loss_runs(copies: pd.DataFrame) -> np.ndarray:
    """Lengths of the runs of consecutive lost copies on a link (sender to receiver, in sending
    order) between two delivered copies: the outages of a link that works, not the silence of a
    pair out of reach (a run before a link's first delivery or after its last is not counted)."""
    ordered = copies.sort_values(["sender", "receiver", "tick"], kind="stable")
    delivered = (ordered["outcome"] == "delivered").to_numpy()
    link = ordered["sender"].to_numpy().astype(np.int64) * 1_000_003 + ordered["receiver"].to_numpy()
    runs: list[int] = []
    length, previous, opened = 0, None, False
    for ok, key in zip(delivered, link):
        if key != previous:
            length, previous, opened = 0, key, False
        if ok:
            if opened and length:
                runs.append(length)
            length, opened = 0, True
        elif opened:
            length += 1
    return np.asarray(runs, dtype=int)


def radio_pages(page: Page, copies: pd.DataFrame | None, config: dict) -> None:
    """The per-copy figures of a run whose per-receiver ledger is ``copies`` (None: it has none)."""
    if copies is None or "distance" not in copies:
        return
    distance = pd.to_numeric(copies["distance"], errors="coerce")
    if not np.isfinite(distance).any():
        return
    try:
        network = NetworkSection.model_validate(config.get("network"))
    except ValidationError as exc:
        raise RunFileError(f"config.yaml: network: {exc.errors()[0]['msg']}") from None
    copies = copies.assign(distance=distance)
    page.heading(
        "The radio, copy by copy",
        "From the per-receiver ledger: each copy's distance, outcome and delay as the radio's models drew them.",
    )
    heard = copies[np.isfinite(copies["distance"])]
    edges = np.linspace(0.0, float(heard["distance"].max()) * 1.0001, DISTANCE_BINS + 1)
    which = np.clip(np.digitize(heard["distance"], edges) - 1, 0, DISTANCE_BINS - 1)
    n = np.bincount(which, minlength=DISTANCE_BINS).astype(float)
    k = np.bincount(which, weights=(heard["outcome"] == "delivered").to_numpy(float), minlength=DISTANCE_BINS)
    centres, has = (edges[:-1] + edges[1:]) / 2, n > 0
    low, high = _wilson(k[has], n[has])
    ratio = k[has] / n[has]
    traces = [
        go.Scatter(
            x=centres[has],
            y=ratio,
            mode="markers",
            name="delivered / copies",
            error_y={"type": "data", "symmetric": False, "array": high - ratio, "arrayminus": ratio - low},
        )
    ]
    curve_d = np.linspace(edges[0], edges[-1], 200)
    payload = float(heard["bytes"].median())
    if network.propagation is not None:
        curve = delivery_probability(network.propagation, curve_d, payload)
        what = f"log-distance model, {payload:.0f}-byte copies"
    else:
        curve, what = np.ones_like(curve_d), "disk"
    curve = curve * (1 - network.loss)
    if network.range is not None:
        curve = np.where(curve_d <= network.range, curve, 0.0)
    traces.append(go.Scatter(x=curve_d, y=curve, mode="lines", name=f"model ({what}, independent loss, disk cap)"))
    fig = go.Figure(traces)
    fig.update_layout(
        title="Delivery ratio against distance (95 % Wilson intervals) and the model's curve",
        xaxis_title="distance (m)",
        yaxis_title="delivered / copies",
        yaxis_range=[-0.02, 1.02],
    )
    page.figure(fig, f"{RECEIVER_LEDGER}; netem.propagation.delivery_probability (burst loss and channel not in it)")

    runs = loss_runs(copies)
    if len(runs):
        shown = np.bincount(np.minimum(runs, LONGEST_RUN_SHOWN), minlength=LONGEST_RUN_SHOWN + 1)[1:]
        fig = go.Figure(go.Bar(x=np.arange(1, LONGEST_RUN_SHOWN + 1), y=shown, name="runs"))
        fig.update_layout(
            title=f"Outages of working links: {len(runs)} runs of lost copies between deliveries, "
            f"mean {runs.mean():.2f}, longest {runs.max()} (last bar: {LONGEST_RUN_SHOWN} or more)",
            xaxis_title="consecutive copies lost on one link",
            yaxis_title="runs",
            yaxis_type="log",
        )
        page.figure(fig, f"{RECEIVER_LEDGER} (per link in sending order, runs between two delivered copies)")

    if "delay_s" in copies:
        delays = copies.loc[copies["outcome"] == "delivered", "delay_s"].dropna()
        if len(delays) and delays.max() > 0:
            fig = go.Figure(go.Histogram(x=delays, nbinsx=60, name="delivered copies"))
            fig.update_layout(
                title=f"Delay of delivered copies: mean {delays.mean() * 1000:.1f} ms, "
                f"p99 {np.percentile(delays, 99) * 1000:.1f} ms",
                xaxis_title="added delay (s)",
                yaxis_title="copies",
            )
            page.figure(fig, f"{RECEIVER_LEDGER} (delay_s of delivered copies)")
