"""The rounds of a cbba-etc run, from its agents' logs: which triggers fired, the conflict Lc and
how the adaptive interval moved (CBBA-ETC paper, Algorithm 4 and Eqs. 2-4).

    swarmbed run experiments/sar/_base.yaml --set allocator.trace_rounds=true --out runs/etc_trace
    python docs/scripts/cbba_etc_rounds.py runs/etc_trace [--agent 0] [--figure docs/images/reproduction/x.png]

Writes ``rounds.csv`` in the run directory (one row per round of every robot) and a figure of one
robot's interval over the run with the trigger of each round; prints how often each trigger fired.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from swarmbed.results.analyze import COLUMN_IN, STYLE  # noqa: E402

LINE = re.compile(
    r"round t=(?P<t>[\d.]+) triggers=(?P<triggers>[\w,]*) Lc=(?P<lc>-?\d+) dLc=(?P<dlc>-?\d+) "
    r"interval=(?P<before>[\d.]+)->(?P<after>[\d.]+)"
)
TRIGGERS = ("tr_init", "tr_delta_bid", "tr_conflict", "tr_fallback")
MARKERS = {"tr_init": "o", "tr_delta_bid": "^", "tr_conflict": "s", "tr_fallback": "x"}


def rounds(run: Path) -> pd.DataFrame:
    rows = []
    for log in sorted((run / "logs").glob("agent_*.log")):
        agent = int(log.stem.split("_")[1])
        for m in LINE.finditer(log.read_text()):
            fired = set(m["triggers"].split(",")) - {""}
            rows.append(
                {
                    "agent": agent,
                    "time": float(m["t"]),
                    "lc": int(m["lc"]),
                    "dlc": int(m["dlc"]),
                    "interval_before": float(m["before"]),
                    "interval_after": float(m["after"]),
                    **{t: t in fired for t in TRIGGERS},
                }
            )
    if not rows:
        raise SystemExit(f"{run}: no round lines in logs/agent_*.log (run with allocator.trace_rounds=true)")
    return pd.DataFrame(rows).sort_values(["agent", "time"], ignore_index=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path)
    ap.add_argument("--agent", type=int, default=0)
    ap.add_argument("--figure", type=Path, help="where the figure goes (default: the run directory)")
    args = ap.parse_args()
    df = rounds(args.run)
    df.to_csv(args.run / "rounds.csv", index=False)
    n = len(df)
    print(f"{n} rounds by {df['agent'].nunique()} robots; a round may have several triggers")
    for t in TRIGGERS:
        alone = (df[t] & (df[list(TRIGGERS)].sum(axis=1) == 1)).sum()
        print(f"  {t:<13} fired in {df[t].sum():5d} rounds ({100 * df[t].mean():5.1f} %), alone in {alone}")
    gaps = df.groupby("agent")["time"].diff().dropna()
    print(
        f"  time between a robot's rounds: median {gaps.median():.1f} s, p10 {gaps.quantile(0.1):.1f} s, "
        f"p90 {gaps.quantile(0.9):.1f} s; Lc: mean {df['lc'].mean():.2f}, max {df['lc'].max()}"
    )
    one = df[df["agent"] == args.agent]
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(COLUMN_IN, 2.4))
        ax.step(one["time"], one["interval_after"], where="post", color="#D55E00", lw=1, label="I_adapt after round")
        for t, marker in MARKERS.items():
            hit = one[one[t]]
            ax.scatter(
                hit["time"],
                hit["interval_before"],
                marker=marker,
                s=14,
                color="0.2",
                label=t,
                facecolors="none" if marker in "os^" else None,
                linewidths=0.8,
            )
        ax.set_xlabel("time (s)")
        ax.set_ylabel("interval (s)")
        ax.set_ylim(0, one["interval_after"].max() * 1.15)
        ax.set_title(f"cbba-etc, robot {args.agent}: rounds and the adaptive interval")
        ax.legend(frameon=False, ncol=3, fontsize=6, loc="lower right")
        out = args.figure or args.run / f"fig_rounds_agent_{args.agent}.png"
        fig.savefig(out, dpi=200)
        for ext in ("pdf", "svg"):
            fig.savefig(out.with_suffix(f".{ext}"))
    print(f"figure: {out}")


if __name__ == "__main__":
    main()
