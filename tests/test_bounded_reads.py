"""Reads of files someone else made or a shared machine holds stay bounded and never block, and a
bad input or setting is one line that names it (issue 82, items 7 to 11)."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from swarmbed.campaigns import claims
from swarmbed.campaigns.sweep import _last_attempt
from swarmbed.launch.access import OWNER, remove_orphaned_folders
from tests.conftest import QUICKSTART, sweep_in_process


@pytest.fixture(scope="module")
def swept(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("swept")
    (folder / "s.yaml").write_text(f"name: s\nbase: {QUICKSTART}\nruns: 2\n")
    sweep_in_process(folder / "s.yaml", folder / "out", "run.duration=40")
    return folder / "out"


def _swarmbed(*args, env=None, timeout=120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "swarmbed", *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env
    )


def _fifo_and_zero(folder: Path, name: str) -> list[Path]:
    """``folder/a/name`` a FIFO and ``folder/b/name`` a link to /dev/zero."""
    (folder / "a").mkdir(parents=True)
    (folder / "b").mkdir(parents=True)
    os.mkfifo(folder / "a" / name)
    (folder / "b" / name).symlink_to("/dev/zero")
    return [folder / "a", folder / "b"]


def test_claims_and_attempts_that_are_fifos_or_dev_zero_are_read_as_missing_at_once(tmp_path):
    t0 = time.monotonic()
    for run_dir in _fifo_and_zero(tmp_path / "claims", claims.CLAIM):
        assert claims.holder(run_dir) is None
    for run_dir in _fifo_and_zero(tmp_path / "attempts", "attempts.jsonl"):
        assert _last_attempt(run_dir) == {}
    assert time.monotonic() - t0 < 5


@pytest.mark.slow  # starts the CLI
def test_sweep_status_of_a_folder_with_a_fifo_claim_answers(swept, tmp_path):
    import shutil

    received = tmp_path / "received"
    shutil.copytree(swept, received, symlinks=True)
    (received / "base" / "run_000" / "summary.json").unlink()  # not complete: its claim is read
    os.mkfifo(received / "base" / "run_000" / claims.CLAIM)
    (received / "base" / "run_001" / "summary.json").unlink()
    (received / "base" / "run_001" / "attempts.jsonl").unlink()
    (received / "base" / "run_001" / "attempts.jsonl").symlink_to("/dev/zero")
    done = _swarmbed("sweep", "--status", received, timeout=60)
    assert done.returncode == 0, done.stderr


def test_orphaned_run_folders_are_looked_for_only_among_this_users_own(tmp_path):
    dead = json.dumps({"pid": 999_999_999, "started": 1.0})  # a launcher long gone
    mine = tmp_path / "swarmbed-run-mine"
    mine.mkdir()
    (mine / OWNER).write_text(dead)
    theirs = tmp_path / "swarmbed-run-theirs"
    theirs.mkdir()
    (theirs / OWNER).write_text(dead)
    if os.getuid() == 0:
        os.chown(theirs, 65534, 65534)  # another local user's folder
    (tmp_path / "swarmbed-run-link").symlink_to(mine, target_is_directory=True)
    for planted in _fifo_and_zero(tmp_path / "x", OWNER):
        planted.rename(tmp_path / f"swarmbed-run-{planted.name}")
    t0 = time.monotonic()
    removed = remove_orphaned_folders(tmp_path)
    assert time.monotonic() - t0 < 5
    assert removed == [mine] and not mine.exists()
    assert (tmp_path / "swarmbed-run-a").exists() and (tmp_path / "swarmbed-run-b").exists()
    if os.getuid() == 0:
        assert theirs.exists()


@pytest.mark.slow  # starts the CLI
def test_a_read_error_names_the_file():
    done = _swarmbed("run", "/proc/self/mem", "--check")
    err = done.stderr.strip()
    assert done.returncode == 2 and len(err.splitlines()) == 1 and "/proc/self/mem" in err, err


@pytest.mark.slow  # starts the CLI
def test_analyze_takes_a_cell_nested_deep_and_refuses_a_table_of_nul_bytes_at_once(swept, tmp_path):
    import shutil

    deep = tmp_path / "deep"
    shutil.copytree(swept, deep, symlinks=True)
    (deep / "sweep.parquet").unlink()
    lines = (deep / "sweep.csv").read_text().splitlines()
    header = lines[0].split(",")
    at = header.index("allocator.name") if "allocator.name" in header else header.index("allocator")
    nested = '"' + '{""a"":' * 100_000 + "1" + "}" * 100_000 + '"'
    rows = [line.split(",") for line in lines[1:]]
    for row in rows:
        row[at] = nested
    (deep / "sweep.csv").write_text("\n".join([lines[0], *(",".join(r) for r in rows)]) + "\n")
    done = _swarmbed("analyze", deep)
    assert "Traceback" not in done.stderr and "RecursionError" not in done.stderr, done.stderr[-2000:]
    nul = tmp_path / "nul"
    shutil.copytree(swept, nul, symlinks=True)
    (nul / "sweep.parquet").unlink()
    with open(nul / "sweep.csv", "wb") as f:
        f.truncate(32 << 20)  # 32 MB of NUL bytes, under the cap
    t0 = time.monotonic()
    done = _swarmbed("analyze", nul)
    err = done.stderr.strip()
    assert done.returncode != 0 and "NUL" in err and len(err.splitlines()) == 1, err
    assert time.monotonic() - t0 < 20


@pytest.mark.slow  # starts the CLI
def test_a_limit_set_to_a_digit_python_reads_but_int_refuses_is_named(swept):
    env = dict(os.environ, SWARMBED_MAX_SWEEP_TABLE_BYTES="²")
    done = _swarmbed("analyze", swept, env=env)
    err = done.stderr.strip()
    assert done.returncode != 0 and "SWARMBED_MAX_SWEEP_TABLE_BYTES" in err and len(err.splitlines()) == 1, err


@pytest.mark.slow  # MLflow's client starts a process
def test_mlflow_takes_every_normalised_key_and_names_two_that_collide(tmp_path, capsys):
    """Issue 82 item 14: ``a//b`` and ``a/`` stopped a sweep's logging; ``x?`` and ``x!`` merged silently."""
    pytest.importorskip("mlflow")
    from mlflow.entities import Param
    from mlflow.tracking import MlflowClient

    from swarmbed.campaigns.tracking import default_uri, safe_keys

    os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
    client = MlflowClient(tracking_uri=default_uri(tmp_path))
    run = client.create_run(client.create_experiment("keys"))
    keys = safe_keys({"a//b": "1", "a/": "2", "x?": "3", "x!": "4", "plain.key": "5", "../up": "6"}, "parameter")
    client.log_batch(run.info.run_id, params=[Param(k, v) for k, v in keys.items()])
    logged = client.get_run(run.info.run_id).data.params
    assert logged == {"a.b": "1", "a": "2", "x_": "4", "plain.key": "5", "up": "6"}, logged
    err = capsys.readouterr().err
    assert "'x?'" in err and "'x!'" in err and "not logged" in err, err


def test_the_report_of_an_in_process_sweep_says_tcp_was_not_measured(swept):
    """Issue 82 item 23: no ``nan ± 0.0 (n=0)`` row and no empty chart for what in-process runs cannot measure."""
    import re

    from swarmbed.results.report import sweep_report

    page, figures = sweep_report(swept)
    text = re.sub(r"<script.*?</script>", "", page, flags=re.S)  # plotly's own code holds "(n=0)"
    assert "nan ±" not in text and "(n=0)" not in text
    assert "not measured in-process" in text
    assert "wire.agent_tcp_bytes_sent per scenario" not in page
    assert figures >= 2  # the radio's own figures are still drawn
