"""A full disk: result tables keep whole rows only, the error is one line naming the folder, and a
run that could not finish leaves no result under a complete name. Each test mounts a small tmpfs
of its own (root only)."""

from __future__ import annotations

import os
import subprocess

import pytest

from swarmbed.engine import results
from swarmbed.engine.run_errors import RunError
from swarmbed.launch.runner import run_experiment
from swarmbed.records.rowfile import RowFile, TableWriteError
from tests.conftest import experiment, whole_rows


@pytest.fixture
def small_disk(tmp_path):
    """A folder on a tmpfs of 256 KiB, mounted for this test."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    where = tmp_path / "disk"
    where.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(where)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    yield where
    subprocess.run(["umount", "-l", str(where)], check=False)


def test_a_table_that_fills_the_disk_keeps_whole_rows_and_says_where(small_disk):
    table = RowFile(small_disk / "t.csv", ["n", "text", "x", "outcome"], chunk_rows=7)
    with pytest.raises(TableWriteError) as info:
        for n in range(10**6):
            table.write([n, "delivered" * (n % 5), n / 7, "lost"])
    assert str(info.value) == f"no space left on device in {small_disk}"
    rows = whole_rows(table.part)
    assert 0 < rows < table.rows and rows % 7 == 0  # chunks of 7 rows, the failed one cut away
    kept = table.abandon()  # does not raise again
    assert kept is not None and kept.name == "partial_t.csv" and whole_rows(kept) == rows


def test_a_whole_file_written_to_a_full_disk_leaves_no_temporary_behind(small_disk):
    (small_disk / "filler").write_bytes(b"\0" * (256 * 1024 - 4096))
    with pytest.raises(TableWriteError, match=f"^no space left on device in {small_disk}$"):
        results.write_json(small_disk / "summary.json", {"x": "y" * 10_000})
    assert sorted(p.name for p in small_disk.iterdir()) == ["filler"]


def test_a_run_that_fills_the_disk_fails_in_one_line_and_leaves_no_result_under_its_name(small_disk):
    exp = experiment(
        "agents.count=5",
        "allocator={name: noop, peers: 4}",
        "scenario.initial_tasks=0",
        "run.stop_when_done=false",
        "run.duration=50000",
    )
    with pytest.raises(RunError) as info:
        run_experiment(exp, small_disk / "run", progress=False)
    assert "no space left on device in" in str(info.value).splitlines()[0], str(info.value)
    out = small_disk / "run"
    for name in ("summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv", "timings.json"):
        assert not (out / name).exists(), f"{name} under its complete name after a failed run"
    partials = sorted(out.glob("partial_*.csv"))
    assert partials, sorted(p.name for p in out.iterdir())
    for path in partials:
        whole_rows(path)
    assert not list(out.glob("*.part"))
