"""Nothing a user receives makes a command write outside where the user asked (issue 74, items 1,
2 and 10): links planted in a sweep or run folder are replaced, never written through; MLflow logs
only the regular files inside a run folder; a bad tracking URI is one line, fast, without its
password. Every folder here is built from a real run and then made hostile."""

import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from swarmbed.files import safefiles
from tests.conftest import QUICKSTART, sweep_in_process

VICTIM = "a file the user owns\n"


@pytest.fixture(scope="module")
def swept(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("swept")
    (folder / "s.yaml").write_text(f"name: s\nbase: {QUICKSTART}\nruns: 2\n")
    sweep_in_process(folder / "s.yaml", folder / "out", "run.duration=40")
    return folder


def _swarmbed(*args, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "swarmbed", *map(str, args)], capture_output=True, text=True, timeout=300, **kwargs
    )


def _victims(tmp_path: Path, n: int) -> list[Path]:
    folder = tmp_path / "home"
    folder.mkdir(exist_ok=True)
    files = [folder / f"victim_{i}" for i in range(n)]
    for f in files:
        f.write_text(VICTIM)
    return files


def _plant(folder: Path, names: list[str], victims: list[Path]) -> None:
    for name, victim in zip(names, victims, strict=True):
        (folder / name).unlink(missing_ok=True)
        (folder / name).symlink_to(victim)


def test_analyze_and_report_replace_planted_links_and_never_write_through_them(swept, tmp_path):
    clean = tmp_path / "clean"
    shutil.copytree(swept / "out", clean, symlinks=True)
    assert _swarmbed("analyze", clean).returncode == 0
    written = sorted(p.name for p in clean.iterdir() if p.is_file() and p.name.startswith(("fig_", "scenario_")))
    assert "scenario_summary.csv" in written and any(n.endswith(".png") for n in written), written
    written.append("report.html")
    received = tmp_path / "received"
    shutil.copytree(swept / "out", received, symlinks=True)
    victims = _victims(tmp_path, len(written))
    _plant(received, written, victims)
    assert _swarmbed("analyze", received).returncode == 0
    assert _swarmbed("report", received).returncode == 0
    assert all(v.read_text() == VICTIM for v in victims)
    assert all((received / n).is_file() and not (received / n).is_symlink() for n in written)
    assert not [p for p in received.iterdir() if p.name.endswith(".part")]


def test_a_resumed_sweep_refuses_a_run_folder_that_is_a_link_and_writes_through_no_table_link(swept, tmp_path):
    received = tmp_path / "received"
    shutil.copytree(swept / "out", received, symlinks=True)
    victims = _victims(tmp_path, 3)
    _plant(received, ["sweep.csv", "sweep.parquet", "sweep.json"], victims)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copy(swept / "s.yaml", tmp_path / "s.yaml")
    again = ("--engine", "inprocess", "--no-progress", "--set", "run.duration=40")
    done = _swarmbed("sweep", tmp_path / "s.yaml", "--out", received, *again)
    assert done.returncode == 0, done.stderr
    assert all(v.read_text() == VICTIM for v in victims)
    assert not (received / "sweep.csv").is_symlink() and (received / "sweep.csv").stat().st_size > len(VICTIM)
    (received / "base" / "run_002").symlink_to(elsewhere, target_is_directory=True)
    done = _swarmbed("sweep", tmp_path / "s.yaml", "--out", received, "--runs", "3", *again)
    err = done.stderr.strip()
    assert done.returncode != 0 and len(err.splitlines()) == 1 and "run_002" in err and "link" in err, err
    assert list(elsewhere.iterdir()) == []


def test_a_resumed_run_whose_folder_holds_planted_links_writes_no_file_through_them(swept, tmp_path):
    received = tmp_path / "received"
    shutil.copytree(swept / "out", received, symlinks=True)
    run = received / "base" / "run_001"
    (run / "summary.json").unlink()  # an unfinished run: the resumed sweep runs it again, in processes
    names = ["config.yaml", "timeseries.csv.part", "network_ledger.csv.part", "attempts.jsonl", "claim.lock"]
    victims = _victims(tmp_path, len(names))
    _plant(run, names, victims)
    shutil.rmtree(run / "logs")
    (run / "logs").symlink_to(victims[0].parent, target_is_directory=True)
    shutil.copy(swept / "s.yaml", tmp_path / "s.yaml")
    done = _swarmbed("sweep", tmp_path / "s.yaml", "--out", received, "--no-progress", "--set", "run.duration=40")
    assert all(v.read_text() == VICTIM for v in victims)
    assert sorted(p.name for p in victims[0].parent.iterdir()) == sorted(v.name for v in victims)
    assert done.returncode == 1 and "run_001" in done.stderr and "link" in done.stderr, done.stderr
    (run / "logs").unlink()  # the link the run refused is gone: the same command completes it
    done = _swarmbed("sweep", tmp_path / "s.yaml", "--out", received, "--no-progress", "--set", "run.duration=40")
    assert done.returncode == 0, done.stderr
    assert all(v.read_text() == VICTIM for v in victims)
    assert json.loads((run / "summary.json").read_text())["ticks"] == 40


def test_the_helper_replaces_links_refuses_link_folders_and_lists_only_regular_files(tmp_path):
    victim = _victims(tmp_path, 1)[0]
    (tmp_path / "f.txt").symlink_to(victim)
    safefiles.write_text(tmp_path / "f.txt", "new")
    assert victim.read_text() == VICTIM and (tmp_path / "f.txt").read_text() == "new"
    (tmp_path / "g.log").symlink_to(victim)
    with safefiles.open_fresh(tmp_path / "g.log") as f:
        f.write(b"log")
    assert victim.read_text() == VICTIM and not (tmp_path / "g.log").is_symlink()
    (tmp_path / "a.jsonl").symlink_to(victim)
    with safefiles.open_append(tmp_path / "a.jsonl") as f:
        f.write(b"line")
    assert victim.read_text() == VICTIM and (tmp_path / "a.jsonl").read_bytes() == b"line"
    root = tmp_path / "root"
    root.mkdir()
    (root / "sub").symlink_to(victim.parent, target_is_directory=True)
    with pytest.raises(safefiles.LinkRefused):
        safefiles.make_dirs(root, root / "sub" / "deeper")
    assert not (victim.parent / "deeper").exists()
    with pytest.raises(safefiles.LinkRefused):
        safefiles.inside(root, root / ".." / "x")
    (root / "real.txt").write_text("x")
    (root / "link.txt").symlink_to(victim)
    os.mkfifo(root / "fifo")
    assert safefiles.regular_files(root) == [root / "real.txt"]
    with pytest.raises(ZeroDivisionError), safefiles.replacing(root / "out.txt") as tmp:
        tmp.write_text("half")
        raise ZeroDivisionError
    assert not (root / "out.txt").exists() and sorted(p.name for p in root.iterdir()) == [
        "fifo",
        "link.txt",
        "real.txt",
        "sub",
    ]


# -- MLflow (items 2 and 10) ---------------------------------------------------------------------


def test_mlflow_logs_only_regular_files_inside_the_run_and_takes_hostile_keys(tmp_path):
    pytest.importorskip("mlflow")
    from mlflow.tracking import MlflowClient

    from swarmbed.campaigns.tracking import TAG, MlflowLog, default_uri

    secret = tmp_path / "shadow"
    secret.write_text("root:$6$secret\n")
    (tmp_path / "s.yaml").write_text(f"name: tracked\nbase: {QUICKSTART}\nruns: 1\n")
    out = tmp_path / "out"
    sweep_in_process(tmp_path / "s.yaml", out, "run.duration=20")
    run = out / "base" / "run_000"
    (run / "shadow").symlink_to(secret)
    (run / "logs" / "shadow_too").symlink_to(secret)
    (run / "logs" / "note.txt").write_text("a regular file")
    (run / "linked_dir").symlink_to(tmp_path, target_is_directory=True)
    summary = json.loads((run / "summary.json").read_text())
    summary["../../x"] = 1.5
    (run / "summary.json").write_text(json.dumps(summary))
    log = MlflowLog(default_uri(out), "tracked")
    assert log.log(run, "base/run_000")
    client = MlflowClient(tracking_uri=default_uri(out))
    experiment = client.get_experiment_by_name("tracked")
    (logged,) = client.search_runs([experiment.experiment_id], filter_string=f"tags.`{TAG}` = 'base/run_000'")
    assert logged.data.metrics["x"] == 1.5
    names = {f.path for f in client.list_artifacts(logged.info.run_id, "run")}
    assert "run/summary.json" in names and "run/shadow" not in names and "run/linked_dir" not in names
    inner = {f.path for f in client.list_artifacts(logged.info.run_id, "run/logs")}
    assert inner and "run/logs/shadow_too" not in inner
    store = out / "mlruns"
    assert not any("secret" in p.read_text(errors="replace") for p in store.rglob("*") if p.is_file())


def test_mlflow_an_unreachable_server_fails_fast_in_one_line_without_its_password(tmp_path):
    pytest.importorskip("mlflow")
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    (tmp_path / "s.yaml").write_text(f"name: t\nbase: {QUICKSTART}\nruns: 1\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("MLFLOW_")}
    started = time.monotonic()
    done = _swarmbed(
        "sweep", tmp_path / "s.yaml", "--out", tmp_path / "out", "--engine", "inprocess", "--no-progress",
        "--mlflow", f"http://user:hunter2@127.0.0.1:{port}/", env=env,
    )  # fmt: skip
    took = time.monotonic() - started
    err = done.stderr.strip()
    assert done.returncode != 0 and "hunter2" not in done.stderr + done.stdout, err
    assert len(err.splitlines()) == 1 and "127.0.0.1" in err and "***" in err, err
    assert took < 60, took
    done = _swarmbed(
        "sweep", tmp_path / "s.yaml", "--out", tmp_path / "out2", "--engine", "inprocess", "--no-progress",
        "--mlflow", f"sqlite:///{tmp_path}/m.db", env=env,
    )  # fmt: skip
    err = done.stderr.strip()
    assert done.returncode != 0 and len(err.splitlines()) == 1 and "pip install mlflow" in err, err


def test_analyze_and_report_refuse_a_sweep_table_larger_than_they_read_in_one_line(swept, tmp_path):
    received = tmp_path / "received"
    shutil.copytree(swept / "out", received, symlinks=True)
    (received / "sweep.parquet").unlink()
    text = (received / "sweep.csv").read_text()
    head, rows = text.split("\n", 1)
    (received / "sweep.csv").write_text(head + "\n" + rows * 200)  # a table far larger than its sweep
    small = {**os.environ, "SWARMBED_MAX_SWEEP_TABLE_BYTES": str(len(text) * 50)}
    for command in ("analyze", "report"):
        started = time.monotonic()
        done = _swarmbed(command, received, env=small)
        err = done.stderr.strip()
        assert done.returncode != 0 and len(err.splitlines()) == 1 and "sweep.csv" in err and "bytes" in err, err
        assert time.monotonic() - started < 60
    assert _swarmbed("analyze", received).returncode == 0  # within the default bound


# -- issue 82, items 1-6: a folder opened once, nothing below it reached through a link ------------
def _received(swept: Path, tmp_path: Path) -> Path:
    received = tmp_path / "received"
    shutil.copytree(swept / "out", received, symlinks=True)
    shutil.copy(swept / "s.yaml", tmp_path / "s.yaml")
    return received


def _outside(tmp_path: Path) -> tuple[Path, Path]:
    """A folder outside the sweep holding one file a user owns: (folder, file)."""
    folder = tmp_path / "outside"
    (folder / "base" / "run_000").mkdir(parents=True)
    victim = folder / "base" / "run_000" / "mine.txt"
    victim.write_text(VICTIM)
    return folder, victim


def _untouched(folder: Path, victim: Path) -> None:
    assert victim.read_text() == VICTIM
    assert sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*")) == [
        "base",
        "base/run_000",
        "base/run_000/mine.txt",
    ]


INPROCESS = ("--engine", "inprocess", "--no-progress", "--set", "run.duration=40")


def test_verify_through_a_planted_verify_link_deletes_and_writes_nothing_outside(swept, tmp_path):
    received, (outside, victim) = _received(swept, tmp_path), _outside(tmp_path)
    (received / ".verify").symlink_to(outside, target_is_directory=True)
    done = _swarmbed("sweep", tmp_path / "s.yaml", "--out", received, "--verify", "1", *INPROCESS)
    assert done.returncode != 0 and "link" in done.stderr.strip().splitlines()[-1], done.stderr
    _untouched(outside, victim)


def test_a_planted_submitit_link_is_refused_before_submitit_writes_a_script(swept, tmp_path):
    received, (outside, victim) = _received(swept, tmp_path), _outside(tmp_path)
    (received / ".submitit").symlink_to(outside, target_is_directory=True)
    done = _swarmbed("sweep", tmp_path / "s.yaml", "--out", received, "--executor", "slurm", "--no-progress")
    err = done.stderr.strip()
    assert done.returncode != 0 and len(err.splitlines()) == 1 and ".submitit" in err and "link" in err, err
    _untouched(outside, victim)


def test_a_planted_mlruns_link_is_refused_for_the_default_store(swept, tmp_path):
    received, (outside, victim) = _received(swept, tmp_path), _outside(tmp_path)
    (received / "mlruns").symlink_to(outside, target_is_directory=True)
    done = _swarmbed("sweep", tmp_path / "s.yaml", "--out", received, "--mlflow", *INPROCESS)
    err = done.stderr.strip()
    assert done.returncode != 0 and len(err.splitlines()) == 1 and "mlruns" in err and "link" in err, err
    _untouched(outside, victim)


def test_redo_mismatched_through_a_linked_scenario_folder_deletes_no_summary_outside(swept, tmp_path):
    received = _received(swept, tmp_path)
    outside = tmp_path / "outside"
    shutil.move(received / "base", outside)
    (received / "base").symlink_to(outside, target_is_directory=True)
    summaries = {p: p.read_bytes() for p in outside.rglob("summary.json")}
    assert summaries
    again = ("--engine", "inprocess", "--no-progress", "--set", "run.duration=41", "--redo-mismatched")
    done = _swarmbed("sweep", tmp_path / "s.yaml", "--out", received, *again)
    err = done.stderr.strip()
    assert done.returncode != 0 and len(err.splitlines()) == 1 and "link" in err, err
    assert {p: p.read_bytes() for p in outside.rglob("summary.json")} == summaries


def test_a_resumed_sweep_never_appends_to_a_hard_linked_attempts_file(swept, tmp_path):
    received = _received(swept, tmp_path)
    run = received / "base" / "run_001"
    (run / "summary.json").unlink()  # unfinished: the resumed sweep runs it again and records the attempt
    victim = _victims(tmp_path, 1)[0]
    (run / "attempts.jsonl").unlink()
    os.link(victim, run / "attempts.jsonl")
    done = _swarmbed("sweep", tmp_path / "s.yaml", "--out", received, *INPROCESS)
    assert done.returncode == 0, done.stderr
    assert victim.read_text() == VICTIM and victim.stat().st_nlink == 1
    lines = (run / "attempts.jsonl").read_text().splitlines()
    assert [json.loads(line)["event"] for line in lines[-2:]] == ["start", "end"]


def test_a_folder_swapped_for_a_link_while_a_run_writes_gets_no_file_outside(tmp_path):
    """The run's bt/ folder is swapped for a link to a folder outside, over and over, while the
    run's coordinator creates and renames its tree logs there; nothing may land outside (the run
    may refuse the link and fail: that is the point)."""
    import threading

    run, outside, stop = tmp_path / "run", tmp_path / "outside", threading.Event()
    outside.mkdir()

    def swap() -> None:
        real = tmp_path / "bt_real"
        while not stop.is_set():
            try:
                if (run / "bt").is_dir() and not (run / "bt").is_symlink():
                    os.rename(run / "bt", real)
                    (run / "bt").symlink_to(outside, target_is_directory=True)
                    time.sleep(0.001)
                    (run / "bt").unlink()
                    os.rename(real, run / "bt")
            except OSError:
                pass

    swapper = threading.Thread(target=swap, daemon=True)
    swapper.start()
    try:
        _swarmbed(
            "run",
            QUICKSTART,
            "--out",
            run,
            "--no-progress",
            "--set",
            "run.record_bt=true",
            "--set",
            "run.duration=600",
            "--set",
            "agents.count=8",
        )
    finally:
        stop.set()
        swapper.join()
    assert list(outside.iterdir()) == []
