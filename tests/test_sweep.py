"""Sweeps (parallel, resumable, failures recorded) and their analysis, on small real runs."""

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest

from swarmbed import config as cfg
from swarmbed.campaigns.sweep import load_sweep, run_seeds, run_sweep
from swarmbed.results.analyze import analyze
from tests.conftest import QUICKSTART

BOOM = textwrap.dedent("""
    from swarmbed.extension import Allocator

    class Boom(Allocator):
        def decide(self, view):
            raise RuntimeError("always")
""")


@pytest.fixture(scope="module")
def sweep_dir(tmp_path_factory):
    base = tmp_path_factory.mktemp("sweep")
    (base / "boom.py").write_text(BOOM)
    (base / "sweep.yaml").write_text(
        textwrap.dedent(f"""
        name: small
        base: {QUICKSTART}
        seed: 3
        runs: 2
        scenarios:
          - {{name: fast, set: {{agents.count: 3}}}}
          - {{name: broken, set: {{allocator: {{name: "{base / "boom.py"}:Boom"}}}}}}
        grid:
          network.range: [30, 60]
    """)
    )
    sweep = load_sweep(base / "sweep.yaml", extra=["run.duration=150"])
    run_sweep(sweep, base / "out", jobs=2, progress=False)
    return base


def test_sweep_table_has_one_row_per_run_with_params_seed_and_metrics(sweep_dir):
    table = pd.read_csv(sweep_dir / "out" / "sweep.csv")
    assert len(table) == 2 * 2 * 2
    assert set(table["scenario"]) == {"fast_range-30", "fast_range-60", "broken_range-30", "broken_range-60"}
    ok = table[table["status"] == "ok"]
    assert len(ok) == 4 and (ok["agents.count"] == 3).all()
    assert {"mission_time", "time_99", "network.messages_sent", "distance_per_agent_mean"} <= set(table.columns)
    # run r of every scenario shares its seed (paired); runs within a scenario differ
    assert sorted(set(table["seed"])) == sorted(run_seeds(3, 2))
    failed = table[table["status"] == "failed"]
    assert len(failed) == 4 and failed["error"].str.contains("always").all()


def test_rerunning_a_sweep_keeps_completed_runs_and_redoes_the_rest(sweep_dir):
    out = sweep_dir / "out"
    kept = out / "fast_range-30" / "run_000" / "summary.json"
    redo = out / "fast_range-60" / "run_001" / "summary.json"
    stamp = kept.stat().st_mtime_ns
    redo.unlink()
    sweep = load_sweep(sweep_dir / "sweep.yaml", extra=["run.duration=150"])
    table = run_sweep(sweep, out, jobs=2, progress=False)
    assert kept.stat().st_mtime_ns == stamp
    assert redo.exists()
    assert (table["status"] == "ok").sum() == 4


def test_a_rerun_under_another_configuration_never_reuses_completed_runs(sweep_dir, tmp_path):
    """The same sweep again with --set network.loss=0.3 into the same folder: the completed runs
    were made without loss, so the sweep refuses to pass them off as this configuration's, naming
    the first and what differs; with redo_mismatched it runs them again under the new one."""
    import shutil

    out = tmp_path / "out"
    shutil.copytree(sweep_dir / "out", out)
    # a folder whose runs of one scenario were made under two configurations (an older swarmbed made
    # such folders) is refused by analyze and report rather than pooled
    mixed = tmp_path / "mixed"
    shutil.copytree(sweep_dir / "out", mixed)
    config = mixed / "fast_range-30" / "run_001" / "config.yaml"
    config.write_text(config.read_text().replace("loss: 0.0", "loss: 0.3"))
    from swarmbed.results.analyze import AnalyzeError
    from swarmbed.results.report import ReportError, report

    with pytest.raises(AnalyzeError, match="run_000 and fast_range-30/run_001 were made under different"):
        analyze([mixed])
    with pytest.raises(ReportError, match="network.loss: 0.0 / 0.3"):
        report(mixed)
    changed = load_sweep(sweep_dir / "sweep.yaml", extra=["run.duration=150", "network.loss=0.3"])
    with pytest.raises(cfg.ConfigError) as info:
        run_sweep(changed, out, jobs=2, progress=False)
    assert "4 completed run(s) were made under another configuration" in str(info.value)
    assert "network.loss: 0.0 -> 0.3" in str(info.value) and "--redo-mismatched" in str(info.value)
    table = run_sweep(changed, out, jobs=2, progress=False, redo_mismatched=True)
    assert (table["status"] == "ok").sum() == 4
    assert "loss: 0.3" in (out / "fast_range-30" / "run_000" / "config.yaml").read_text()
    assert (table[table["status"] == "ok"]["network.dropped.loss"] > 0).all()


def test_every_run_records_the_code_that_made_it_and_analyze_will_not_pool_two_versions(sweep_dir, tmp_path):
    import json
    import shutil

    from swarmbed.campaigns.sweep import collect, read_spec, write_tables
    from swarmbed.results.analyze import AnalyzeError

    runs = sorted((sweep_dir / "out").glob("fast_*/run_*/provenance.json"))
    made = [json.loads(p.read_text()) for p in runs]
    assert len(runs) == 4 and all(m == made[0] for m in made)  # nothing of the machine or the moment
    assert made[0]["scenario"] == {"target": "swarmbed.scenarios.mtsr:MTSR", "version": "1"}, made[0]["scenario"]
    assert set(made[0]["libraries"]) == {"numpy", "eclipse-zenoh", "msgpack", "pydantic"}
    assert made[0]["git"] is None or len(made[0]["git"]["commit"]) == 40
    table = pd.read_csv(sweep_dir / "out" / "sweep.csv")
    assert (table[table["status"] == "ok"]["provenance.scenario.version"] == 1).all()

    out = tmp_path / "out"
    shutil.copytree(sweep_dir / "out", out)
    bumped = out / "fast_range-60" / "run_001" / "provenance.json"
    record = json.loads(bumped.read_text())
    record["scenario"]["version"] = "2"
    bumped.write_text(json.dumps(record))
    write_tables(collect(read_spec(out), out), out)
    with pytest.raises(AnalyzeError, match="runs made by scenario mtsr in versions 1, 2"):
        analyze([out])
    assert analyze([out], mixed_versions_ok=True)


def test_analyze_writes_tables_and_figures(sweep_dir):
    written = analyze(sweep_dir / "out")
    names = {p.name for p in written}
    assert {"scenario_summary.csv", "scenario_summary.md", "fig_mission_time.png"} <= names
    summary = pd.read_csv(sweep_dir / "out" / "scenario_summary.csv")
    row = summary[(summary["scenario"] == "fast_range-30") & (summary["metric"] == "mission_time")].iloc[0]
    assert row["n"] == 2 and row["ci95_low"] <= row["mean"] <= row["ci95_high"]
    # SPACE's panels, one value per run each
    assert {
        "fig_distance_per_agent_mean.png",
        "fig_work_per_agent_gini.png",
        "fig_distance_per_agent_gini.png",
    } <= names
    # the same sweep again rewrites the table: what analyze made of the old one goes with it
    run_sweep(
        load_sweep(sweep_dir / "sweep.yaml", extra=["run.duration=150"]), sweep_dir / "out", jobs=2, progress=False
    )
    assert not list((sweep_dir / "out").glob("fig_*")) and not list((sweep_dir / "out").glob("scenario_summary.*"))


def test_per_agent_values_pool_every_agent_of_every_run(sweep_dir):
    """A per-agent metric named as such (``work_per_agent``) draws one value per agent of every run."""
    from swarmbed.results.analyze import _values, load

    df = load([sweep_dir / "out"])
    for _, rows in df.groupby("scenario"):
        work = _values(rows, "work_per_agent")
        assert len(work) == rows["agents"].sum() and len(rows) == 2
        assert work.sum() == pytest.approx(rows["work_total"].sum())


def test_gini_matches_the_mean_absolute_difference_definition(sweep_dir):
    """Gini = sum_i sum_j |x_i - x_j| / (2 n^2 mean), checked on random values and on every run's
    work per agent in the sweep's table."""
    import json

    import numpy as np

    from swarmbed.campaigns.sweep import gini

    def reference(x):
        x = np.asarray(x, dtype=float)
        return np.abs(x[:, None] - x[None, :]).sum() / (2 * len(x) ** 2 * x.mean())

    rng = np.random.default_rng(5)
    for n in (1, 2, 7, 50):
        x = rng.exponential(size=n)
        assert gini(list(x)) == pytest.approx(reference(x))
    assert gini([3.0, 3.0, 3.0]) == pytest.approx(0.0) and gini([0.0, 0.0, 4.0]) == pytest.approx(2 / 3)
    assert gini([1.0, -1.0]) is None and gini([0.0, 0.0]) is None
    table = pd.read_csv(sweep_dir / "out" / "sweep.csv")
    ok = table[table["status"] == "ok"]
    for _, row in ok.iterrows():
        summary = json.loads(
            (sweep_dir / "out" / row["scenario"] / f"run_{row['run']:03d}" / "summary.json").read_text()
        )
        assert row["work_per_agent_gini"] == pytest.approx(reference(summary["work_per_agent"]))


def test_plain_experiment_sweeps_with_a_command_line_grid():
    sweep = load_sweep(QUICKSTART, runs=5, grid=["allocator.name=cbba,grape"])
    assert [s.name for s in sweep.scenarios] == ["allocator-cbba", "allocator-grape"]
    assert sweep.runs == 5 and sweep.factors == ["allocator.name"]


def test_space_fig3_has_27_scenarios():
    sweep = load_sweep(QUICKSTART.parent / "space_fig3.yaml", runs=1)
    assert len(sweep.scenarios) == 27 and sweep.runs == 1
    with pytest.raises(cfg.ConfigError):
        load_sweep(QUICKSTART, grid=["agents.count"])


@pytest.mark.parametrize(
    ("subset", "prefixes"),
    [("space_fig3_code_a50.yaml", ("a50_",)), ("space_fig3_code_a10_a30.yaml", ("a10_", "a30_"))],
)
def test_a_cell_subset_sweep_plans_the_figure_sweeps_runs(tmp_path, subset, prefixes):
    """space_fig3_code_a50.yaml and space_fig3_code_a10_a30.yaml add runs to some of
    space_fig3_code.yaml's cells: same folders, same seeds, same settings, so they can share one
    output folder."""
    from swarmbed.campaigns.sweep import plan

    def key(spec):
        return (Path(spec.out_dir).relative_to(tmp_path), spec.seed, spec.base, spec.scenario.overrides, spec.extra)

    whole = plan(load_sweep(QUICKSTART.parent / "space_fig3_code.yaml", runs=3), tmp_path)
    part = plan(load_sweep(QUICKSTART.parent / subset, runs=3), tmp_path)
    assert len(part) == 9 * 3 * len(prefixes)
    assert sorted(map(key, part)) == sorted(key(s) for s in whole if s.scenario.name.startswith(prefixes))


def _runs(out):
    return [d for d in out.glob("*/run_*") if d.is_dir()]


def test_ctrl_c_stops_a_sweep_at_once_and_the_same_command_resumes(tmp_path):
    """SIGINT to the sweep's process group, as a terminal sends it: the runs under way stop, nothing
    new starts, no interrupt is recorded as a failure, the message says what completed, and the
    same command then does only the rest."""
    import os
    import signal
    import subprocess
    import sys
    import time

    import psutil

    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "swarmbed",
        "sweep",
        str(QUICKSTART),
        "--runs",
        "4",
        "--jobs",
        "2",
        "--out",
        str(out),
        "--no-progress",
        "--set",
        "run.duration=1500",
        "--set",
        "run.stop_when_done=false",
    ]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not list(out.glob("*/run_*/summary.json")):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.1)
    time.sleep(0.5)  # let the next runs get under way
    family = psutil.Process(proc.pid).children(recursive=True)
    os.killpg(proc.pid, signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "interrupted:" in stderr and "of 4 runs are complete" in stderr
    _, alive = psutil.wait_procs(family, timeout=10)
    assert not alive, [p.pid for p in alive]
    done = list(out.glob("*/run_*/summary.json"))
    assert not list(out.rglob("error.txt")) and not list(out.rglob("*.part"))
    assert len(_runs(out)) <= len(done) + 2  # only the two runs under way were cut short
    assert f"{len(done)} of 4 runs are complete" in stderr
    table = pd.read_csv(out / "sweep.csv")  # what completed is in the table, ready for analyze
    assert (table["status"] == "ok").sum() == len(done) and len(table) == 4, table
    cut = [d for d in _runs(out) if not (d / "summary.json").exists()]
    for run_dir in cut:  # attempts.jsonl says how each run cut short ended, and --status agrees
        assert '"outcome": "interrupted"' in (run_dir / "attempts.jsonl").read_text().splitlines()[-1]
    assert (table["status"] == "interrupted").sum() == len(cut)
    first = {p: p.stat().st_mtime_ns for p in done}
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert "4 of 4 runs complete" in again.stdout
    assert all(p.stat().st_mtime_ns == t for p, t in first.items())  # completed runs were kept, not redone


@pytest.mark.parametrize("flag, value", [("--runs", "-2"), ("--runs", "0"), ("--jobs", "0"), ("--runs", "two")])
def test_sweep_refuses_counts_below_one(flag, value, capsys):
    from swarmbed.cli.main import main

    with pytest.raises(SystemExit) as info:
        main(["sweep", str(QUICKSTART), flag, value])
    assert info.value.code == 2 and flag in capsys.readouterr().err


def test_analyze_refuses_a_control_the_sweeps_do_not_have(sweep_dir, capsys):
    from swarmbed.cli.main import main

    out = sweep_dir / "out"
    (out / "statistics.md").write_text("stale")
    assert main(["analyze", str(out), "--control", "nosuch"]) == 2
    assert "--control nosuch: no such strategy" in capsys.readouterr().err
    assert (out / "statistics.md").read_text() == "stale"  # refused before anything was written
    assert main(["analyze", str(out)]) == 0
    assert not (out / "statistics.md").exists()  # MT-SR sweep: no statistics, and no stale ones left


def test_ctrl_c_while_a_resumed_sweep_plans_still_leaves_the_table_of_what_completed(tmp_path, monkeypatch):
    from swarmbed.campaigns import sweep as sweeps

    (tmp_path / "s.yaml").write_text(f"name: s\nbase: {QUICKSTART}\nruns: 2\n")
    plan = sweeps.load_sweep(tmp_path / "s.yaml", extra=["run.duration=60"])
    sweeps.run_sweep(plan, tmp_path / "out", jobs=2, progress=False)
    (tmp_path / "out" / "sweep.csv").unlink()

    def interrupted(*_args, **_kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(sweeps, "_check_completed", interrupted)
    with pytest.raises(sweeps.SweepInterrupted, match="interrupted while planning: nothing was started; 2 of 2"):
        sweeps.run_sweep(plan, tmp_path / "out", jobs=2, progress=False)
    table = pd.read_csv(tmp_path / "out" / "sweep.csv")
    assert list(table["status"]) == ["ok", "ok"]


def test_a_sweep_logs_each_completed_run_to_mlflow_once(tmp_path):
    """Issue 62: ``--mlflow`` logs every completed run to a local MLflow store: the sweep as the
    experiment, the resolved configuration as params, the summary's figures as metrics, the run's
    folder as artifacts. Running the sweep again logs nothing twice; a run added later is logged."""
    import json
    import os

    from mlflow.tracking import MlflowClient

    from swarmbed.campaigns.tracking import TAG, default_uri
    from swarmbed.cli.main import main

    (tmp_path / "s.yaml").write_text(
        f"name: tracked\nbase: {QUICKSTART}\nruns: 1\nscenarios:\n"
        "  - {name: a, set: {run.duration: 40}}\n  - {name: b, set: {run.duration: 40, network.loss: 0.2}}\n"
    )
    out = tmp_path / "out"
    args = ["sweep", str(tmp_path / "s.yaml"), "--out", str(out), "--engine", "inprocess", "--no-progress", "--mlflow"]
    assert main(args) == 0
    os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
    client = MlflowClient(tracking_uri=default_uri(out))
    experiment = client.get_experiment_by_name("tracked")

    def logged():
        return {r.data.tags[TAG]: r for r in client.search_runs([experiment.experiment_id])}

    runs = logged()
    assert set(runs) == {"a/run_000", "b/run_000"}
    b = runs["b/run_000"]
    summary = json.loads((out / "b" / "run_000" / "summary.json").read_text())
    assert (
        b.data.params["network.loss"] == "0.2"
        and b.data.params["agents.count"] == runs["a/run_000"].data.params["agents.count"]
    )
    assert b.data.metrics["ticks"] == summary["ticks"] == 40
    assert b.data.metrics["network.delivered"] == summary["network"]["delivered"]
    artifacts = {f.path for f in client.list_artifacts(b.info.run_id, "run")}
    assert {"run/summary.json", "run/config.yaml", "run/timeseries.csv"} <= artifacts
    assert main(args) == 0 and len(client.search_runs([experiment.experiment_id])) == 2  # resumed: none twice
    assert main([*args, "--runs", "2"]) == 0
    assert set(logged()) == {"a/run_000", "b/run_000", "a/run_001", "b/run_001"}


def test_a_claim_whose_holder_was_killed_a_moment_ago_is_taken_over_not_reported_held(tmp_path):
    """Issue 74 item 14: a sweep resumed right after its predecessor's process group was killed found
    runs "held by" dying processes. A holder that is killed but not yet reaped (a zombie) holds
    nothing; a live one is still reported."""
    import signal

    from swarmbed.campaigns import claims

    hold = (
        "import sys, time\nfrom pathlib import Path\nfrom swarmbed.campaigns import claims\n"
        "c = claims.take(Path(sys.argv[1]))\nprint('held', flush=True)\ntime.sleep(60)\n"
    )
    holders = []
    for name in ("killed", "alive"):
        proc = subprocess.Popen([sys.executable, "-c", hold, str(tmp_path / name)], stdout=subprocess.PIPE, text=True)
        assert proc.stdout.readline().strip() == "held"
        holders.append(proc)
    killed, alive = holders
    try:
        os.kill(killed.pid, signal.SIGKILL)  # not waited for: a zombie until it is reaped
        time.sleep(0.3)
        taken = claims.take(tmp_path / "killed")
        assert isinstance(taken, claims.Claim), taken
        taken.release()
        held = claims.take(tmp_path / "alive")
        assert isinstance(held, claims.Holder) and held.pid == alive.pid
    finally:
        for proc in holders:
            proc.kill()
            proc.wait()
