"""Results folders as data anyone may have crafted (issue 42, items 1, 4, 10): reading one never runs
code it names, never follows a link out of it, never allocates by what it claims, and turns a bad
file into one line naming it while the good runs are still tabled. Every hostile folder is built
here from a real run."""

import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from swarmbed.launch.runner import run_experiment
from swarmbed.results.analyze import AnalyzeError, analyze
from swarmbed.results.replay import ReplayError, replay
from swarmbed.results.report import ReportError, report
from tests.conftest import QUICKSTART, experiment, sweep_in_process

RECORDED = [
    "run.duration=30",
    "run.stop_when_done=false",
    "run.record_trajectories=true",
    "run.record_bt=true",
    "network.ledger=per_receiver",
]

#: a module a crafted folder ships beside its files: importing it leaves a mark
EVIL = "from pathlib import Path\nPath(__file__).with_name('IMPORTED').write_text('ran')\nclass X: pass\n"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("recorded") / "run"
    run_experiment(experiment(*RECORDED), run, progress=False)
    return run


@pytest.fixture(scope="module")
def swept(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("swept")
    (folder / "s.yaml").write_text(f"name: s\nbase: {QUICKSTART}\nruns: 3\n")
    sweep_in_process(folder / "s.yaml", folder / "out", "run.duration=60")
    return folder


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst, symlinks=True)
    return dst


def _swarmbed(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "swarmbed", *map(str, args)], capture_output=True, text=True)


def _one_line_naming(done: subprocess.CompletedProcess, name: str) -> None:
    err = done.stderr.strip()
    assert done.returncode == 2 and "Traceback" not in err and len(err.splitlines()) == 1, err
    assert name in err, err


def test_a_folder_that_names_its_own_code_never_has_it_run(recorded, swept, tmp_path):
    run = _copy(recorded, tmp_path / "run")
    (run / "evil.py").write_text(EVIL)
    summary = (run / "summary.json").read_text()
    (run / "summary.json").write_text(summary.replace('"scenario_kind": "mtsr"', f'"scenario_kind": "{run}/evil.py:X"'))
    assert "evil.py" in (run / "summary.json").read_text()
    assert report(run).exists()
    sweep = _copy(swept / "out", tmp_path / "sweep")
    (sweep / "evil.py").write_text(EVIL)
    table = pd.read_csv(sweep / "sweep.csv")
    table["scenario_kind"] = f"{sweep}/evil.py:X"
    table.to_csv(sweep / "sweep.csv", index=False)
    (sweep / "sweep.parquet").unlink()
    assert analyze(sweep) and report(sweep).exists()
    assert _swarmbed("analyze", sweep).returncode == 0
    assert not (run / "IMPORTED").exists() and not (sweep / "IMPORTED").exists()


def test_links_out_of_a_run_and_values_no_run_has_are_refused_in_one_line(recorded, tmp_path):
    outside = tmp_path / "secret.csv"
    outside.write_text("tick,agent,x,y,label\n0,0,1,1,\n")
    cases = {
        "link": lambda run: ((run / "trajectories.csv").unlink(), (run / "trajectories.csv").symlink_to(outside)),
        "inf": lambda run: _edit(
            run / "trajectories.csv", lambda t: t.assign(x=t["x"].astype(float).where(t.index != 3, float("inf")))
        ),
        "dt0": lambda run: (run / "config.yaml").write_text(
            (run / "config.yaml").read_text().replace("dt: 1.0", "dt: 0")
        ),
        "tick": lambda run: _edit(
            run / "trajectories.csv", lambda t: t.assign(tick=t["tick"].where(t.index != 2, 10**15))
        ),
        "fifo": lambda run: ((run / "trajectories.csv").unlink(), __import__("os").mkfifo(run / "trajectories.csv")),
    }
    for name, spoil in cases.items():
        run = _copy(recorded, tmp_path / name)
        spoil(run)
        with pytest.raises(ReplayError) as caught:
            replay(run, tmp_path / f"{name}.gif", start=1.0)
        assert "\n" not in str(caught.value) and str(run) in str(caught.value), (name, caught.value)
        done = _swarmbed("replay", run, "--mcap", tmp_path / f"{name}.mcap")
        _one_line_naming(done, str(run))
        assert not (tmp_path / f"{name}.mcap").exists() and not list(tmp_path.glob("*.part"))


def _edit(path: Path, change) -> None:
    table = pd.read_csv(path, keep_default_na=False)
    change(table).to_csv(path, index=False)


def test_a_tree_log_that_claims_more_than_it_holds_is_one_line(recorded, tmp_path):
    import struct

    run = _copy(recorded, tmp_path / "run")
    log = run / "bt" / "agent_0.btlog"
    data = bytearray(log.read_bytes())
    struct.pack_into("<I", data, 19, 4_000_000_000)  # a 4 GB tree
    log.write_bytes(bytes(data))
    done = _swarmbed("replay", run, "--mcap", tmp_path / "r.mcap")
    _one_line_naming(done, "agent_0.btlog")
    assert not (tmp_path / "r.mcap").exists()


def test_an_interrupted_recording_never_stands_under_its_name(recorded, tmp_path, monkeypatch):
    import foxglove

    from swarmbed.results.recording import write_mcap

    calls = {"n": 0}
    log = foxglove.Channel.log

    def interrupted(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] > 20:
            raise KeyboardInterrupt
        return log(self, *args, **kwargs)

    monkeypatch.setattr(foxglove.Channel, "log", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_mcap(recorded, tmp_path / "r.mcap")
    assert calls["n"] > 20 and not list(tmp_path.iterdir())


def test_a_report_asked_into_a_folder_lands_in_it_whole(recorded, tmp_path):
    target = tmp_path / "reports"
    target.mkdir()
    done = _swarmbed("report", recorded, "-o", target)
    assert done.returncode == 0, done.stderr
    assert [p.name for p in target.iterdir()] == ["report.html"]


def test_one_bad_run_file_is_named_and_the_others_are_tabled(swept, tmp_path):
    sweep = _copy(swept / "out", tmp_path / "sweep")
    runs = sorted(sweep.glob("base/run_*"))
    (runs[0] / "summary.json").write_text('{"name": ')  # torn
    (runs[1] / "transport.json").write_text("[]")
    again = _swarmbed("sweep", tmp_path / "none.yaml")  # a missing file: one line
    assert again.returncode == 2
    shutil.copy(swept / "s.yaml", tmp_path / "s.yaml")
    resumed = _swarmbed("sweep", tmp_path / "s.yaml", "--out", sweep, "--set", "run.duration=60", "--no-progress")
    assert "Traceback" not in resumed.stderr, resumed.stderr
    assert str(runs[0]) in resumed.stderr and str(runs[1]) in resumed.stderr
    table = pd.read_csv(sweep / "sweep.csv")
    assert list(table["status"]) == ["unreadable", "unreadable", "ok"], table


def test_torn_tables_and_a_foreign_plan_are_one_line(swept, tmp_path):
    sweep = _copy(swept / "out", tmp_path / "sweep")
    (sweep / "sweep.parquet").write_bytes(b"PAR1 torn")
    assert analyze(sweep)  # the CSV still serves
    (sweep / "sweep.csv").write_text("scenario,run,st")
    for command in ("analyze", "report"):
        _one_line_naming(_swarmbed(command, sweep), "sweep")
    with pytest.raises((AnalyzeError, ReportError)):
        analyze(sweep)
    fresh = _copy(swept / "out", tmp_path / "plan")
    (fresh / "sweep.json").write_text("[]")
    _one_line_naming(_swarmbed("analyze", fresh), "sweep.json")
    _one_line_naming(_swarmbed("sweep", "--status", fresh), "sweep.json")


def _bounded(*args, env: dict | None = None) -> subprocess.CompletedProcess:
    """``swarmbed ARGS`` in at most 3 GB of address space and 120 s: a reader that allocates by what
    a folder claims dies here instead of taking the machine."""
    import os
    import resource

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    return subprocess.run(
        [sys.executable, "-m", "swarmbed", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=limit,
        env={**os.environ, **(env or {})},
    )


def test_a_link_to_a_compressed_table_is_not_inflated(recorded, tmp_path):
    import gzip

    run = _copy(recorded, tmp_path / "run")
    ledger = pd.read_csv(run / "network_ledger.csv")
    rows = "".join(f"{i % 30},0,fcg,delivered,1,10\n" for i in range(2_000_000))
    (run / "big.csv.gz").write_bytes(gzip.compress(("tick,sender,kind,outcome,messages,bytes\n" + rows).encode()))
    (run / "network_ledger.csv").unlink()
    (run / "network_ledger.csv").symlink_to("big.csv.gz")  # inside the folder: a name pandas would inflate
    _one_line_naming(_bounded("report", run, "-o", tmp_path / "r.html"), "network_ledger.csv")
    (run / "network_ledger.csv").unlink()
    shutil.copy(run / "big.csv.gz", run / "network_ledger.csv")  # compressed bytes under a CSV name
    done = _bounded("report", run, "-o", tmp_path / "r.html")
    _one_line_naming(done, "network_ledger.csv")
    assert len(ledger) < 1000 and not (tmp_path / "r.html").exists()


def test_a_table_of_more_rows_than_a_reader_takes_is_refused_before_it_is_read(recorded, tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    run = _copy(recorded, tmp_path / "run")
    receivers = pq.read_table(run / "network_ledger_receivers.parquet")
    many = pa.concat_tables([receivers] * (5000 // receivers.num_rows + 2))
    pq.write_table(many, run / "network_ledger_receivers.parquet")
    bound = {"SWARMBED_MAX_TABLE_ROWS": "5000"}  # the same check as 10 M, on a table a test can write
    _one_line_naming(_bounded("report", run, "-o", tmp_path / "r.html", env=bound), "network_ledger_receivers")
    _one_line_naming(_bounded("replay", run, "--mcap", tmp_path / "r.mcap", env=bound), "network_ledger_receivers")
    assert _bounded("report", run, "-o", tmp_path / "r.html").returncode == 0  # within the default bound


def test_counts_a_folder_claims_are_bounded_before_anything_is_allocated(recorded, swept, tmp_path):
    import json

    run = _copy(recorded, tmp_path / "run")
    summary = json.loads((run / "summary.json").read_text())
    summary["agents"] = 12000
    (run / "summary.json").write_text(json.dumps(summary))
    _one_line_naming(_bounded("report", run, "-o", tmp_path / "r.html"), "summary.json")
    run = _copy(recorded, tmp_path / "config")
    text = (run / "config.yaml").read_text()
    (run / "config.yaml").write_text(text + "padding:\n" + "".join(f"  k{i}: {i}\n" for i in range(200_000)))
    _one_line_naming(_bounded("report", run, "-o", tmp_path / "r.html"), "config.yaml")
    sweep = _copy(swept / "out", tmp_path / "sweep")
    plan = json.loads((sweep / "sweep.json").read_text())
    plan["runs"] = 100_000_000
    (sweep / "sweep.json").write_text(json.dumps(plan))
    _one_line_naming(_bounded("sweep", "--status", sweep), "sweep.json")
