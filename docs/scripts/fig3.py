"""Tables of SPACE Fig. 3 sweeps (MT-SR: agents x range x allocator), as docs/reproduction.md prints them.

    python docs/scripts/fig3.py runs/space_fig3_code
    python docs/scripts/fig3.py runs/space_fig3_code --agents 50 --orderings
    python docs/scripts/fig3.py runs/space_cbba_range runs/space_cbba_scope --orderings   # sweeps together

Per cell (agent count, range) and allocator: runs, and for mission time, time to 95 % and 99 % of
the tasks, the mean travel distance per agent and the Gini coefficient of work per agent, the mean
over runs with its 95 % t-interval (SPACE plots one value per run; so do these tables). Runs that
never finished count at the run's cap for mission time and are flagged, and a table of the tasks
completed by the run's end says how far they got. ``--orderings`` (and the
effect of range per allocator, paired the same way): for every cell, each pair of allocators
compared over the seeds both ran (run i of every scenario has the same seed): the mean paired
difference, its 95 % t-interval, the paired t-test's p and beside it the Wilcoxon signed-rank test's
(which does not assume normal differences), so that a reader sees which orderings the runs settle
and which they do not.
"""

from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path

import pandas as pd
import yaml

from swarmbed.campaigns.sweep import collect, read_spec
from swarmbed.results.analyze import ci95
from swarmbed.results.stats import paired_p

ALLOCATORS = ["cbba", "grape", "fcg"]
METRICS = {
    "mission_time": "mission time, s",
    "time_95": "time to 95 % of tasks, s",
    "time_99": "time to 99 % of tasks, s",
    "distance_per_agent_mean": "distance per agent",
    "work_per_agent_gini": "Gini coefficient of work per agent",
    "tasks_completed": "tasks completed by the run's end",
}


def _allocator(value: object) -> str:
    """The allocator's name, with the parameters a sweep sets beside it (``cbba execute=first``)."""
    text = str(value)
    if not text.startswith("{"):
        return text
    spec = json.loads(text)
    rest = " ".join(f"{k}={v}" for k, v in sorted(spec.items()) if k != "name")
    return f"{spec['name']} {rest}" if rest else str(spec["name"])


def _allocators(df: pd.DataFrame) -> list[str]:
    """The allocators of the runs: SPACE's three in the paper's order, then any other, sorted."""
    present = set(df["allocator"])
    known = [a for a in ALLOCATORS if a in present]
    return known + sorted(present - set(known))


def _label(allocator: str) -> str:
    name, _, rest = allocator.partition(" ")
    return f"{name.upper()} {rest}".strip()


def runs(sweep: Path) -> pd.DataFrame:
    """Every finished run of the sweep, read from the runs' own summaries (a sweep still under way
    has no table yet; a finished one's table may predate a column, such as the Gini ones)."""
    df = collect(read_spec(sweep), sweep)
    df = df[df["status"] == "ok"].dropna(subset=["agents.count", "network.range"]).copy()
    df["allocator"] = (df["allocator.name"] if "allocator.name" in df else df["allocator"]).map(_allocator)
    on_grid = [k for k in df.columns if k.startswith(("allocator.", "scenario.")) and k != "allocator.name"]
    for key in sorted(on_grid):  # a grid's allocator or world parameter
        df["allocator"] = df["allocator"] + f" {key.split('.', 1)[1]}=" + df[key].astype(str)
    return _with_varying_parameters(df, sweep)


def _with_varying_parameters(df: pd.DataFrame, sweep: Path) -> pd.DataFrame:
    """Allocator parameters that a sweep's named scenarios set (not a grid column) and that differ
    between its runs, read from each run's config.yaml, join the allocator's label
    (``cbba stamp_every=100``); keys some runs lack are left out (an older install's runs)."""
    configs = []
    for scenario, run in zip(df["scenario"], df["run"]):
        path = sweep / str(scenario) / f"run_{int(run):03d}" / "config.yaml"
        configs.append((yaml.safe_load(path.read_text()) or {}).get("allocator", {}) if path.exists() else {})
    shared = set.intersection(*(set(c) for c in configs)) if configs else set()
    varying = sorted(k for k in shared - {"name"} if len({json.dumps(c[k], sort_keys=True) for c in configs}) > 1)
    labelled = [k for k in varying if f"allocator.{k}" not in df.columns]
    for key in labelled:
        df["allocator"] = df["allocator"] + [f" {key}={c[key]}" for c in configs]
    return df


def _ci(values: pd.Series) -> str:
    values = values.dropna()
    fmt = ",.0f" if values.abs().max() >= 10 else ".3f"
    if len(values) == 0:
        return "-"
    if len(values) == 1:
        return f"{values.iloc[0]:{fmt}}"
    low, high = ci95(values)
    return f"{values.mean():{fmt}} ({low:{fmt}}-{high:{fmt}})"


def cells(df: pd.DataFrame) -> list[tuple[int, float]]:
    return sorted({(int(a), float(r)) for a, r in zip(df["agents.count"], df["network.range"])})


def tables(df: pd.DataFrame) -> None:
    allocators = _allocators(df)
    for metric, label in METRICS.items():
        if metric not in df.columns:
            continue
        print(f"\n{label} (mean of the runs, 95 % t-interval in brackets; runs per cell in the last column):\n")
        print("| agents | range | " + " | ".join(_label(a) for a in allocators) + " | runs |")
        print("| ---: | ---: | " + " | ".join("---:" for _ in allocators) + " | --- |")
        for agents, rng in cells(df):
            cell = df[(df["agents.count"] == agents) & (df["network.range"] == rng)]
            values, counts = [], []
            for a in allocators:
                d = cell[cell["allocator"] == a]
                unfinished = int((~d["all_tasks_completed"].astype(bool)).sum())
                values.append(_ci(d[metric]) + (f" ({unfinished} unfinished)" if unfinished else ""))
                counts.append(str(len(d)))
            print(f"| {agents} | {rng:.0f} | " + " | ".join(values) + f" | {'/'.join(counts)} |")


def _paired(first: pd.Series, second: pd.Series) -> str | None:
    """``| seeds | mean difference (95 % CI) | t p | signed-rank p |`` of first minus second over the
    seeds both ran; None with fewer than two, or where every pair is level (runs that all stopped at
    the cap, or all completed every task: nothing to compare)."""
    if not (first.index.is_unique and second.index.is_unique):
        raise SystemExit("fig3.py: a seed appears twice in one cell (the sweep has other factors than agents x range)")
    both = first.index.intersection(second.index)
    pairs = pd.concat([first.loc[both], second.loc[both]], axis=1).dropna()
    if len(pairs) < 2:
        return None
    diff = pairs.iloc[:, 0] - pairs.iloc[:, 1]
    if not diff.any():
        return None
    low, high = ci95(diff)
    t_p, w_p = paired_p(pairs.iloc[:, 0].to_numpy(), pairs.iloc[:, 1].to_numpy())
    return f"| {len(diff)} | {diff.mean():+,.0f} ({low:+,.0f} to {high:+,.0f}) | {t_p:.3f} | {w_p:.3f} |"


def orderings(df: pd.DataFrame, metric: str) -> None:
    allocators = _allocators(df)
    print(f"\n{METRICS[metric]}: paired by seed, first minus second (mean, 95 % t-interval, t and signed-rank p):\n")
    print("| agents | range | pair | seeds | difference (95 % CI) | t p | signed-rank p |")
    print("| ---: | ---: | --- | ---: | --- | ---: | ---: |")
    for agents, rng in cells(df):
        cell = df[(df["agents.count"] == agents) & (df["network.range"] == rng)]
        by = {a: cell[cell["allocator"] == a].set_index("seed")[metric] for a in allocators}
        for first, second in itertools.combinations(allocators, 2):
            row = _paired(by[first], by[second])
            if row:
                print(f"| {agents} | {rng:.0f} | {_label(first)} - {_label(second)} {row}")


def range_effect(df: pd.DataFrame, metric: str) -> None:
    """Per agent count and allocator: each range against the shortest, paired by seed (the issue's
    question whether range slows GRAPE, as SPACE's code does)."""
    allocators = _allocators(df)
    what = "each range minus the shortest, paired by seed (mean, 95 % t-interval, t and signed-rank p)"
    print(f"\n{METRICS[metric]}: {what}:\n")
    print("| agents | allocator | ranges | seeds | difference (95 % CI) | t p | signed-rank p |")
    print("| ---: | --- | --- | ---: | --- | ---: | ---: |")
    for agents in sorted({a for a, _ in cells(df)}):
        sub = df[df["agents.count"] == agents]
        ranges = sorted(set(sub["network.range"]))
        for a in allocators:
            by = {
                r: sub[(sub["allocator"] == a) & (sub["network.range"] == r)].set_index("seed")[metric] for r in ranges
            }
            for r in ranges[1:]:
                row = _paired(by[r], by[ranges[0]])
                if row:
                    print(f"| {agents} | {_label(a)} | {r:.0f} - {ranges[0]:.0f} {row}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweep", type=Path, nargs="+", help="sweep folders, read as one (pairs by seed across them)")
    parser.add_argument("--agents", type=int, nargs="*", help="only these agent counts")
    parser.add_argument("--orderings", action="store_true", help="paired comparisons between allocators")
    args = parser.parse_args()
    df = pd.concat([runs(folder) for folder in args.sweep], ignore_index=True)
    if args.agents:
        df = df[df["agents.count"].isin(args.agents)]
    tables(df)
    if args.orderings:
        for metric in ("mission_time", "time_95", "time_99", "tasks_completed"):
            if metric in df.columns:
                orderings(df, metric)
        for metric in ("mission_time", "time_95", "distance_per_agent_mean", "tasks_completed"):
            if metric in df.columns:
                range_effect(df, metric)
    print(f"\n{len(df)} runs, {df['seed'].nunique()} seeds")


if __name__ == "__main__":
    main()
