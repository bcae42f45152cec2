"""Per-strategy tables of search-and-rescue sweeps, as docs/reproduction.md prints them.

    python docs/scripts/strategies.py runs/world2/base_R20_V100
    python docs/scripts/strategies.py runs/world2/failures/actfail25 runs/world2/failures/actfail50 \\
        --against runs/world2/density/V100

One sweep: for each strategy, trials, victims rescued (mean and 95 % t-interval), expired, failed
rescues and their ratio to rescues, negotiations (rounds initiated), messages (broadcasts), copies
delivered (per receiver) and payload; then the robots' time budget, where the runs carry it.
Several sweeps ``--against`` a reference sweep of the same horizon: rescued in the reference and
in each sweep, with the change from the reference over the seeds both ran (sweeps of the same file
give run i the same seed) and its paired t-test, then the messages each sweep sent.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from swarmbed.results.analyze import ci95
from swarmbed.results.campaign_folders import read_table
from swarmbed.results.stats import paired_p

ORDER = ["tree", "comm", "cbba", "cbba-tree", "cbba-etc", "c-cbba"]


def runs(sweep: Path) -> pd.DataFrame:
    df = read_table(sweep)
    df = df[df["status"] == "ok"].copy()
    if "allocator.name" not in df:  # a plain experiment swept with --set: the runs' configs say
        dirs = [sweep / str(sc) / f"run_{int(r):03d}" for sc, r in zip(df["scenario"], df["run"])]
        df["allocator.name"] = [yaml.safe_load((d / "config.yaml").read_text())["allocator"]["name"] for d in dirs]
    df["strategy"] = df["allocator.name"].astype(str)
    return df


def _ci(values: pd.Series) -> str:
    low, high = ci95(values)
    return f"{np.mean(values):.1f} ({low:.1f}-{high:.1f})"


def one(df: pd.DataFrame) -> None:
    print(
        "| strategy | trials | rescued (95 % CI) | expired | failed rescues | failed / rescued | negotiations "
        "| messages | copies delivered | payload kB |"
    )
    print("| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for s in [s for s in ORDER if s in set(df["strategy"])]:
        d = df[df["strategy"] == s]
        nego = d["negotiations"].mean() if "negotiations" in d else np.nan  # none before a consensus strategy ran
        print(
            f"| {s} | {len(d)} | {_ci(d['rescued'])} | {d['expired'].mean():,.0f} | {d['failed_rescues'].mean():,.0f} "
            f"| {d['failed_rescues'].sum() / max(1, d['rescued'].sum()):.2f} "
            f"| {'-' if np.isnan(nego) or s in ('tree', 'comm') else f'{nego:,.0f}'} "
            f"| {d['network.messages_sent'].mean():,.0f} | {d['network.delivered'].mean():,.0f} "
            f"| {d['network.bytes_sent'].mean() / 1000:,.1f} |"
        )


BUDGET = ("moving", "inspecting", "inspecting_lost", "rescuing", "penalty", "idle")


def budget(df: pd.DataFrame) -> None:
    """Where the robots' time went, per strategy (runs of 2026-11-28 on carry ``time_budget``)."""
    columns = [f"time_budget.{k}" for k in BUDGET]
    if not set(columns) <= set(df):
        return
    print("\n| strategy | moving % | inspecting % | of it lost % | rescuing % | move penalty % | idle % |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for s in [s for s in ORDER if s in set(df["strategy"])]:
        d = df[df["strategy"] == s]
        print(f"| {s} | " + " | ".join(f"{100 * d[c].mean():.1f}" for c in columns) + " |")


def against(reference: pd.DataFrame, sweeps: list[tuple[str, pd.DataFrame]]) -> None:
    names = [name for name, _ in sweeps]
    print("| strategy | reference | " + " | ".join(names) + " | messages, " + " / ".join(names) + " |")
    print("| --- | ---: | " + " | ".join("---:" for _ in names) + " | ---: |")
    for s in ORDER:
        ref = reference[reference["strategy"] == s].set_index("seed")
        if ref.empty:
            continue
        cells, messages = [], []
        for _, df in sweeps:
            d = df[df["strategy"] == s].set_index("seed")
            seeds = sorted(set(ref.index) & set(d.index))
            if not seeds:
                cells.append("-")
                messages.append("-")
                continue
            r, v = ref.loc[seeds, "rescued"], d.loc[seeds, "rescued"]
            change = v.sum() / r.sum() - 1
            t_p, w_p = paired_p(v.to_numpy(), r.to_numpy())
            sign = f"{change:+.0%}".replace("-", "−")
            cells.append(f"{v.mean():.1f} ({sign}, p = {t_p:.2g}; signed-rank {w_p:.2g})")
            messages.append(f"{d['network.messages_sent'].mean():,.0f}")
        print(f"| {s} | {ref['rescued'].mean():.1f} | " + " | ".join(cells) + " | " + " / ".join(messages) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sweeps", type=Path, nargs="+")
    ap.add_argument("--against", type=Path, help="a reference sweep: print the change from it, paired by seed")
    args = ap.parse_args()
    if args.against is None:
        for sweep in args.sweeps:
            print(f"\n{sweep}:\n")
            table = runs(sweep)
            one(table)
            budget(table)
    else:
        against(runs(args.against), [(sweep.name, runs(sweep)) for sweep in args.sweeps])


if __name__ == "__main__":
    main()
