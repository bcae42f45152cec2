"""A variant of the CBBA-ETC baseline against the baseline itself, on the same seeds: a markdown table.

    python docs/scripts/variants.py runs/base_R20_V100 runs/alg3_topup [runs/etc_ibase10 ...]

For each strategy the variant ran: victims rescued, negotiations and messages per 3000 s trial (mean
and 95 % t-interval), in the baseline and in the variant, over the seeds both ran (sweeps of the
same file give run i the same seed), and the paired difference of rescues with its paired t-test.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from swarmbed.results.analyze import ci95
from swarmbed.results.campaign_folders import read_table
from swarmbed.results.stats import paired_p

ORDER = ["tree", "comm", "cbba", "cbba-tree", "cbba-etc", "c-cbba"]


def _runs(sweep: Path):
    df = read_table(sweep)
    df = df[df["status"] == "ok"].copy()
    df["strategy"] = df["allocator.name"].astype(str)
    return df


def _cell(values) -> str:
    low, high = ci95(values)
    return f"{np.mean(values):.1f} ({low:.1f}-{high:.1f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("baseline", type=Path)
    ap.add_argument("variants", type=Path, nargs="+")
    args = ap.parse_args()
    base = _runs(args.baseline)
    for variant_dir in args.variants:
        variant = _runs(variant_dir)
        print(f"\n**{variant_dir.name}** against {args.baseline.name} (same seeds):\n")
        print(
            "| strategy | trials | rescued, baseline | rescued, variant | paired change (t p; signed-rank p) "
            "| negotiations, baseline / variant | messages, baseline / variant |"
        )
        print("| --- | ---: | --- | --- | --- | --- | --- |")
        for s in [s for s in ORDER if s in set(variant["strategy"])]:
            b = base[base["strategy"] == s].set_index("seed")
            v = variant[variant["strategy"] == s].set_index("seed")
            seeds = sorted(set(b.index) & set(v.index))
            if not seeds:
                continue
            b, v = b.loc[seeds], v.loc[seeds]
            diff = v["rescued"].to_numpy() - b["rescued"].to_numpy()
            t_p, w_p = paired_p(v["rescued"].to_numpy(), b["rescued"].to_numpy())
            print(
                f"| {s} | {len(seeds)} | {_cell(b['rescued'])} | {_cell(v['rescued'])} "
                f"| {diff.mean():+.1f} ({t_p:.3f}; {w_p:.3f}) "
                f"| {b['negotiations'].mean():.0f} / {v['negotiations'].mean():.0f} "
                f"| {b['network.messages_sent'].mean():.0f} / {v['network.messages_sent'].mean():.0f} |"
            )


if __name__ == "__main__":
    main()
