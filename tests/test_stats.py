"""Strategy comparison statistics on data with known effects, and a real two-sweep SAR analysis."""

import numpy as np
import pandas as pd
import pytest

from swarmbed.results.analyze import analyze, load
from swarmbed.results.stats import cohens_d, compare
from tests.conftest import ROOT, sweep_in_process


def test_anova_dunnett_and_cohens_d_find_the_shifted_group():
    rng = np.random.default_rng(0)
    df = pd.DataFrame(
        {
            "allocator": ["control"] * 40 + ["same"] * 40 + ["better"] * 40,
            "rescued": np.concatenate([rng.normal(100, 5, 40), rng.normal(100, 5, 40), rng.normal(110, 5, 40)]),
        }
    )
    table = compare(df, "allocator", ["rescued"], control="control").set_index("strategy")
    assert table.loc["better", "anova_p"] < 1e-6
    assert table.loc["better", "dunnett_p"] < 1e-6 and table.loc["same", "dunnett_p"] > 0.05
    assert table.loc["better", "cohens_d"] == pytest.approx(2.0, abs=0.6)
    assert abs(table.loc["same", "cohens_d"]) < 0.6
    with pytest.raises(ValueError, match="control"):
        compare(df, "allocator", ["rescued"], control="missing")


def test_the_same_table_gives_the_same_statistics_to_the_last_bit():
    """Dunnett's p-values come from randomized integration; a seeded one makes statistics.csv reproducible."""
    rng = np.random.default_rng(1)
    df = pd.DataFrame({"allocator": ["c"] * 5 + ["a"] * 5 + ["b"] * 5, "rescued": rng.normal(10, 2, 15).round(0)})
    first, second = (compare(df, "allocator", ["rescued"], control="c") for _ in range(2))
    assert first.to_csv() == second.to_csv()


def test_cohens_d_uses_the_pooled_standard_deviation():
    a, b = np.array([2.0, 4.0, 6.0]), np.array([1.0, 3.0, 5.0])
    assert cohens_d(a, b) == pytest.approx(0.5)  # means differ by 1, pooled sd is 2


@pytest.mark.slow  # a sweep's pool workers (its runs on the in-process engine) and the figures
def test_sar_analysis_of_two_sweeps(tmp_path):
    base = ROOT / "experiments" / "sar" / "_base.yaml"
    dirs = []
    for victims in (10, 20):  # the second leaves the base's victim count as it is (20)
        spec = tmp_path / f"v{victims}.yaml"
        setting = f"set: {{scenario.victims: {victims}}}\n" if victims == 10 else ""
        spec.write_text(
            f"name: v{victims}\nbase: {base}\nruns: 2\n{setting}grid: {{allocator.name: [tree, cbba-etc]}}\n"
        )
        extra = ["agents.count=4", "run.duration=15"] + ([] if victims == 10 else [f"scenario.victims={victims}"])
        sweep_in_process(spec, tmp_path / f"out{victims}", *extra)
        dirs.append(tmp_path / f"out{victims}")
    names = {p.name for p in analyze(dirs, control="cbba-etc")}
    # one rescued/expired figure per sweep: trials of different sweeps are not pooled in one bar
    assert {
        "statistics.csv",
        "statistics.md",
        "fig_rescued_expired_v10.png",
        "fig_rescued_expired_v20.png",
        "fig_boxplots.png",
        "fig_rescued_vs_messages.png",
        "fig_messages_vs_victims.png",
        "fig_rescued_vs_victims.png",
    } <= names
    assert sorted(load(dirs).groupby("sweep")["scenario.victims"].unique().map(list).sum()) == [10, 20]
    for png in (n for n in names if n.endswith(".png")):  # vector copies for papers, the papers' names
        assert (dirs[0] / png).with_suffix(".pdf").stat().st_size > 0
        svg = (dirs[0] / png).with_suffix(".svg").read_text()
        assert "CBBA-ETC" in svg and "Tree" in svg, png
    stats = pd.read_csv(dirs[0] / "statistics.csv")
    assert set(stats["sweep"]) == {"v10", "v20"} and set(stats["strategy"]) == {"tree"}
    row = stats[(stats["sweep"] == "v10") & (stats["metric"] == "network.messages_sent")].iloc[0]
    assert row["mean"] == 0 and row["control_mean"] > 0 and row["cohens_d"] < 0


@pytest.mark.slow  # a sweep's pool workers (its runs on the in-process engine) and the figures
def test_strategies_are_compared_within_each_setting_of_a_sweeps_other_factors(tmp_path):
    """A sweep over strategies and a loss level: the statistics and the per-strategy bars are made
    per loss level, never over both pooled."""
    base = ROOT / "experiments" / "sar" / "_base.yaml"
    spec = tmp_path / "levels.yaml"
    grid = "{allocator.name: [tree, cbba-etc], network.loss: [0.0, 0.5]}"
    spec.write_text(f"name: levels\nbase: {base}\nruns: 2\ngrid: {grid}\n")
    sweep_in_process(spec, tmp_path / "out", "agents.count=4", "run.duration=15")
    names = {p.name for p in analyze(tmp_path / "out", control="cbba-etc")}
    assert {"fig_rescued_expired_levels_loss-0.png", "fig_rescued_expired_levels_loss-0.5.png"} <= names, names
    table = pd.read_csv(tmp_path / "out" / "statistics.csv")
    assert set(table["sweep"]) == {"levels_loss-0", "levels_loss-0.5"}
    assert (table["n"] == 2).all()  # two runs per strategy in each setting, not four pooled


def test_a_run_without_a_disk_has_its_own_group_in_the_range_figures(tmp_path, monkeypatch):
    """``network.range: null`` (a propagation model alone) is a group of its own, after the ranges,
    not a NaN that every comparison drops."""
    from swarmbed.results import analyze as views

    drawn: list[list[int]] = []
    monkeypatch.setattr(views, "_boxes", lambda ax, data, *rest: drawn.append([len(d) for d in data]))
    df = pd.DataFrame(
        {
            "scenario": ["disk", "disk", "logdistance", "logdistance"],
            "agents.count": [30] * 4,
            "network.range": [100.0, 100.0, np.nan, np.nan],
            "allocator": ["cbba"] * 4,
            "mission_time": [6000.0, 6100.0, 5200.0, 5300.0],
        }
    )
    canvas = views.Canvas(tmp_path, "", {})
    assert views._by_range_one(df, "mission_time", canvas) is not None
    assert drawn == [[2, 2]]  # both groups drawn, two runs each
    assert views._range_label(float("nan")) == "no disk" and views._range_label(100.0) == "100"


def test_tost_agrees_with_the_ninety_percent_interval_and_calls_only_close_groups_equivalent():
    """TOST at 0.05 says "equivalent within the margin" exactly when Welch's 90 % confidence interval
    of the difference (scipy's own) lies inside it: checked on many random pairs of groups."""
    from scipy import stats

    from swarmbed.results.stats import tost_p

    rng = np.random.default_rng(7)
    agree = 0
    for _ in range(300):
        a = rng.normal(rng.uniform(-1, 1), rng.uniform(0.5, 2), int(rng.integers(5, 60)))
        b = rng.normal(0, rng.uniform(0.5, 2), int(rng.integers(5, 60)))
        margin = float(rng.uniform(0.2, 1.5))
        low, high = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.90)
        inside = -margin < low and high < margin
        agree += (tost_p(a, b, margin) < 0.05) == inside
    assert agree == 300
    same = rng.normal(100, 5, 200)
    table = compare(
        pd.DataFrame(
            {
                "g": ["c"] * 200 + ["s"] * 200 + ["far"] * 200,
                "m": [*same, *rng.normal(100, 5, 200), *rng.normal(120, 5, 200)],
            }
        ),
        "g",
        ["m"],
        "c",
    ).set_index("strategy")
    assert table.loc["s", "tost_p"] < 0.05 and table.loc["far", "tost_p"] > 0.5
    assert table.loc["s", "tost_margin"] == pytest.approx(0.05 * same.mean())


def test_paired_signed_rank_p_is_the_exact_share_of_sign_flips_at_least_as_extreme():
    """paired_p's Wilcoxon p against its definition: with no ties, every assignment of signs to the
    ranks of |d| is equally likely under the null; p is the share of the 2^n whose statistic is at
    least as far from its mean as the observed one (enumerated here). Its t p is scipy's paired t."""
    import itertools

    from scipy import stats

    from swarmbed.results.stats import paired_p

    rng = np.random.default_rng(11)
    for n in (3, 6, 9, 12):
        for _ in range(10):
            x, y = rng.normal(0.4, 1, n), rng.normal(0, 1, n)
            d = x - y
            ranks = stats.rankdata(np.abs(d))
            observed = ranks[d > 0].sum()
            middle = n * (n + 1) / 4
            flips = [sum(r for r, s in zip(ranks, signs) if s) for signs in itertools.product((0, 1), repeat=n)]
            exact = np.mean([abs(w - middle) >= abs(observed - middle) - 1e-9 for w in flips])
            t_p, w_p = paired_p(x, y)
            assert w_p == pytest.approx(exact, rel=1e-9), (n, w_p, exact)
            assert t_p == pytest.approx(stats.ttest_rel(x, y).pvalue, rel=1e-12)
    assert all(np.isnan(paired_p(np.ones(5), np.ones(5))))
    assert all(np.isnan(paired_p(np.ones(1), np.zeros(1))))


def test_holm_is_the_closed_test_of_bonferroni_tests():
    """Holm's adjusted p of hypothesis i is, by its definition as a closed testing procedure, the
    largest over every family S holding i of |S| * min p in S (capped at 1): checked by enumerating
    every subset of random families, NaN entries left out of the family."""
    from itertools import combinations

    from swarmbed.results.stats import holm

    rng = np.random.default_rng(11)
    for _ in range(200):
        m = int(rng.integers(1, 7))
        p = rng.uniform(0, 0.3, m) ** rng.uniform(1, 3)
        if m > 2 and rng.uniform() < 0.3:
            p[int(rng.integers(m))] = np.nan
        present = [i for i in range(m) if not np.isnan(p[i])]
        closed = {
            i: max(
                min(1.0, len(s) * min(p[j] for j in s))
                for k in range(1, len(present) + 1)
                for s in combinations(present, k)
                if i in s
            )
            for i in present
        }
        got = holm(list(p))
        for i in range(m):
            if i in closed:
                assert got[i] == pytest.approx(closed[i], rel=1e-12)
            else:
                assert np.isnan(got[i])


def test_welch_holm_sees_a_silent_strategy_that_dunnett_pooled_variance_hides():
    """Message counts as they fall: one strategy sends nothing, the control a few hundred with a small
    spread, two others thousands with a spread of thousands. Dunnett's pooled variance drowns the silent
    strategy's difference; Welch's test (each group its own variance) does not, and a strategy drawn
    from the control's own distribution stays unremarkable under both."""
    rng = np.random.default_rng(3)
    n = 10
    df = pd.DataFrame(
        {
            "allocator": ["control"] * n + ["silent"] * n + ["like"] * n + ["wide1"] * n + ["wide2"] * n,
            "messages": np.concatenate(
                [
                    rng.normal(300, 30, n),
                    np.zeros(n),
                    rng.normal(300, 30, n),
                    rng.normal(5000, 4000, n),
                    rng.normal(8000, 6000, n),
                ]
            ),
        }
    )
    table = compare(df, "allocator", ["messages"], control="control").set_index("strategy")
    assert table.loc["silent", "dunnett_p"] > 0.05
    assert table.loc["silent", "welch_holm_p"] < 1e-6
    assert table.loc["like", "welch_holm_p"] > 0.05
    from scipy import stats

    pair = df[df["allocator"].isin(["control", "like"])]  # a family of one: Holm leaves Welch's p as it is
    alone = compare(pair, "allocator", ["messages"], control="control").set_index("strategy")
    welch = stats.ttest_ind(df["messages"][20:30], df["messages"][:10], equal_var=False).pvalue
    assert alone.loc["like", "welch_holm_p"] == pytest.approx(welch, rel=1e-12)
    constant = pd.DataFrame({"allocator": ["control"] * 3 + ["a"] * 3 + ["b"] * 3, "m": [1.0] * 6 + [2.0] * 3})
    flat = compare(constant, "allocator", ["m"], control="control").set_index("strategy")
    assert flat.loc["a", "welch_holm_p"] == 1.0 and flat.loc["b", "welch_holm_p"] == 0.0
