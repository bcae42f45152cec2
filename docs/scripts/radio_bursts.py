"""The six CBBA-ETC strategies under independent loss and under Gilbert-Elliott loss of the same mean:
a markdown table from the sweep of experiments/radio/sar_bursts.yaml.

    swarmbed sweep experiments/radio/sar_bursts.yaml --runs 3 --out runs/radio_sar_bursts
    python docs/scripts/radio_bursts.py runs/radio_sar_bursts

Per strategy and loss model: victims rescued per trial (mean and 95 % CI, Student t), messages and
copies delivered per trial, the strategy's rank by rescues under each model, and Welch's t-test of
rescues between the two models, side by side (``swarmbed analyze`` gives each model's statistics
and bars on their own).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy import stats

from swarmbed.results.analyze import ci95
from swarmbed.results.campaign_folders import read_table

ORDER = ["tree", "comm", "cbba", "cbba-tree", "cbba-etc", "c-cbba"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sweep", type=Path)
    args = ap.parse_args()
    df = read_table(args.sweep)
    df = df[df["status"] == "ok"].copy()
    df["model"] = df["scenario"].str.split("_").str[0]
    df["strategy"] = df["allocator"].astype(str)
    means = df.groupby(["model", "strategy"])["rescued"].mean()
    rank = {m: means[m].rank(ascending=False).astype(int) for m in ("iid", "ge")}
    print(
        "| strategy | runs | rescued, iid (95 % CI) | rescued, GE (95 % CI) | change | Welch p | rank iid | rank GE "
        "| messages iid / GE | copies delivered iid / GE |"
    )
    print("| --- | ---: | --- | --- | ---: | ---: | ---: | ---: | --- | --- |")
    for s in [s for s in ORDER if s in set(df["strategy"])]:
        a = df[(df["model"] == "iid") & (df["strategy"] == s)]
        b = df[(df["model"] == "ge") & (df["strategy"] == s)]
        if a.empty or b.empty:
            continue
        p = stats.ttest_ind(a["rescued"], b["rescued"], equal_var=False).pvalue if len(a) > 1 and len(b) > 1 else np.nan
        (la, ha), (lb, hb) = ci95(a["rescued"]), ci95(b["rescued"])
        print(
            f"| {s} | {len(a)} / {len(b)} | {a['rescued'].mean():.1f} ({la:.1f}-{ha:.1f}) "
            f"| {b['rescued'].mean():.1f} ({lb:.1f}-{hb:.1f}) | {b['rescued'].mean() - a['rescued'].mean():+.1f} "
            f"| {p:.3f} | {rank['iid'][s]} | {rank['ge'][s]} "
            f"| {a['network.messages_sent'].mean():.0f} / {b['network.messages_sent'].mean():.0f} "
            f"| {a['network.delivered'].mean():.0f} / {b['network.delivered'].mean():.0f} |"
        )


if __name__ == "__main__":
    main()
