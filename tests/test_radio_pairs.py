"""Up to ``PAIRWISE_UP_TO`` agents the radio finds a broadcast's receivers by comparing every pair
instead of building SciPy's KD-tree (whose import costs a process about a second): the copies it
then decides are SciPy's, checked against ``cKDTree`` on random layouts and on whole runs."""

import numpy as np
import pytest

import swarmbed
from swarmbed.netem import radio
from swarmbed.netem.radio import _EPS, neighbours
from swarmbed.records.run_folder import REPRODUCIBLE
from tests.conftest import QUICKSTART


def _kept(x, y, senders, candidates, reach):
    """What the radio keeps of the candidates: the others within ``reach`` by its own distance."""
    keep = candidates != senders
    keep[keep] = (
        np.hypot(x[senders[keep]] - x[candidates[keep]], y[senders[keep]] - y[candidates[keep]]) <= reach + _EPS
    )
    return senders[keep], candidates[keep]


@pytest.mark.parametrize("seed", range(20))
def test_every_pair_finds_what_the_kd_tree_finds(seed):
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, radio.PAIRWISE_UP_TO + 1))
    x, y = rng.uniform(0, 300, n), rng.uniform(0, 200, n)
    x[: n // 3], y[: n // 3] = np.round(x[: n // 3]), np.round(y[: n // 3])  # points exactly on a range's edge
    rows = np.sort(rng.choice(n, size=int(rng.integers(1, n + 1)), replace=False)).astype(np.int64)
    reach = float(rng.choice([1.0, 5.0, 60.0, 100.0, rng.uniform(1, 150)]))
    query = reach + _EPS + 1e-6 * max(1.0, reach)  # as Radio._near asks
    points = np.column_stack((x, y))
    found = cKDTree(points).query_ball_point(points[rows], query, return_sorted=True)
    tree = (np.repeat(rows, [len(f) for f in found]), np.array([c for f in found for c in f], dtype=np.int64))
    pairs = neighbours(x, y, rows, query)
    for mine, theirs in zip(_kept(x, y, *pairs, reach), _kept(x, y, *tree, reach)):
        assert np.array_equal(mine, theirs)


def test_a_run_gives_the_same_files_either_way(tmp_path, monkeypatch):
    exp = swarmbed.load(QUICKSTART, overrides=["agents.count=12", "run.duration=400", "network.range=40"])
    swarmbed.run(exp, tmp_path / "pairs", engine="inprocess")
    monkeypatch.setattr(radio, "PAIRWISE_UP_TO", 0)
    swarmbed.run(exp, tmp_path / "tree", engine="inprocess")
    for name in REPRODUCIBLE:
        if (tmp_path / "tree" / name).exists():
            assert (tmp_path / "pairs" / name).read_bytes() == (tmp_path / "tree" / name).read_bytes(), name
