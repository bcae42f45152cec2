"""The quickstart experiment end to end: real processes, real Zenoh on loopback."""

import csv
import json
import time

import pytest

from swarmbed.launch.runner import run_experiment
from tests.conftest import experiment, ledger_outcomes, read_ledger

DETERMINISTIC_FILES = ["summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv", "config.yaml"]


@pytest.fixture(scope="module")
def quickstart_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("quickstart")
    runs = {}
    for name, seed in (("a", 1), ("b", 1), ("c", 2)):
        runs[name] = run_experiment(experiment(f"run.seed={seed}"), base / name, progress=False)
    return runs


def test_quickstart_completes_every_task(quickstart_runs):
    s = quickstart_runs["a"].summary
    assert s["all_tasks_completed"] is True
    assert s["tasks_completed"] == s["tasks_total"] == 20
    assert s["time_99"] is not None and s["time_99"] <= s["mission_time"]
    # time to 95 % / 99 %: the first recorded time at which the world had done 19 / 20 of its 20
    # tasks, read independently from the per-tick timeseries
    rows = list(csv.DictReader((quickstart_runs["a"].out_dir / "timeseries.csv").open()))
    for key, need in (("time_95", 19), ("time_99", 20)):
        first = min(float(r["time"]) for r in rows if int(r["tasks_completed"]) >= need)
        assert s[key] == pytest.approx(first), key
    # the work done equals the workload of the tasks: nothing over-counted, nothing left
    assert s["work_total"] > 20 * 6
    assert s["network"]["messages_sent"] > 0
    assert all(code == 0 for code in quickstart_runs["a"].timings["exit_codes"].values())


def test_same_seed_gives_identical_result_files(quickstart_runs):
    a, b = quickstart_runs["a"].out_dir, quickstart_runs["b"].out_dir
    for name in DETERMINISTIC_FILES:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_another_seed_gives_different_results(quickstart_runs):
    a, c = quickstart_runs["a"].out_dir, quickstart_runs["c"].out_dir
    assert (a / "summary.json").read_bytes() != (c / "summary.json").read_bytes()
    assert (a / "network_ledger.csv").read_bytes() != (c / "network_ledger.csv").read_bytes()


def test_ledger_conserves_every_copy(quickstart_runs):
    for run in quickstart_runs.values():
        net = run.summary["network"]
        assert net["copies"] == net["delivered"] + sum(net["dropped"].values())
        outcomes = ledger_outcomes(read_ledger(run.out_dir))
        assert outcomes["sent"] == net["messages_sent"]
        copies = sum(v for k, v in outcomes.items() if k != "sent")
        assert copies == net["copies"]
        assert outcomes.get("delivered", 0) == net["delivered"]


def test_agents_and_proxy_agree_on_bytes(quickstart_runs):
    net = quickstart_runs["a"].summary["network"]
    assert net["bytes_agree"] is True
    assert net["bytes_sent_by_agents"] == net["bytes_sent"] > 0


def test_summary_is_written_last_and_names_its_metrics(quickstart_runs):
    out = quickstart_runs["a"].out_dir
    summary = json.loads((out / "summary.json").read_text())
    for key in (
        "mission_time",
        "time_95",
        "time_99",
        "tasks_total",
        "tasks_completed",
        "distance_total",
        "work_total",
        "distance_per_agent",
        "work_per_agent",
        "ticks",
        "network",
    ):
        assert key in summary
    for key in ("messages_sent", "bytes_sent", "copies", "delivered", "dropped"):
        assert key in summary["network"]
    assert not list(out.glob("*.part"))
    assert (out / "summary.json").stat().st_mtime_ns >= max(
        (out / f).stat().st_mtime_ns for f in ("timeseries.csv", "agents.csv", "timings.json", "network_ledger.csv")
    )


@pytest.mark.parametrize("allocator", ["cbba", "grape"])
def test_quickstart_completes_with_each_allocator(tmp_path, allocator):
    result = run_experiment(experiment(f"allocator={{name: {allocator}}}"), tmp_path, progress=False)
    s = result.summary
    assert s["all_tasks_completed"] is True and s["tasks_completed"] == 20
    assert s["network"]["per_kind"][allocator]["messages"] > 0
    assert s["network"]["bytes_agree"] is True


def test_timings_count_each_agent_ticks_wakeups_and_cpu_over_the_tick_loop(quickstart_runs):
    """timings.json's per-agent-tick figures (benchmarks/lockstep.py prints them): every kind of
    run process woke and worked during the tick loop; an agent wakes at least once per tick (its
    tick arrives) and, with Zenoh's default threads, a few times more."""
    per = quickstart_runs["a"].timings["per_agent_tick"]
    woke, cpu = per["wakeups"], per["cpu_us"]
    assert 1.0 <= woke["agents"] < 50 and woke["netem"] > 0 and woke["hub"] > 0
    assert woke["total"] == pytest.approx(woke["agents"] + woke["netem"] + woke["hub"])
    assert cpu["agents"] > 0 and cpu["netem"] > 0 and cpu["hub"] > 0


def test_one_receiving_zenoh_worker_wakes_agents_less_and_changes_no_result(tmp_path):
    """run.zenoh_threads: default (one worker receives and answers, one transmits) and single (every
    runtime on one worker) against Zenoh's own layout (zenoh): the same files, fewer wake-ups per
    agent-tick (counts, not times); single fewest."""
    sets = ["agents.count=12", "allocator={name: noop, peers: 5}", "run.duration=200", "run.stop_when_done=false"]
    runs = {
        layout: run_experiment(experiment(*sets, f"run.zenoh_threads={layout}"), tmp_path / layout, progress=False)
        for layout in ("zenoh", "default", "single")
    }
    for name in DETERMINISTIC_FILES[:-1]:  # config.yaml names the setting
        assert len({(r.out_dir / name).read_bytes() for r in runs.values()}) == 1, name
    woke = {layout: r.timings["per_agent_tick"]["wakeups"]["agents"] for layout, r in runs.items()}
    assert woke["single"] < woke["default"] < 0.85 * woke["zenoh"], woke


def test_answers_too_large_for_the_single_workers_callback_go_out_from_the_main_thread(tmp_path):
    """On the single worker a tick is answered inside the subscriber's callback, on Zenoh's only
    thread; a put that overfills the transmit queue there would wait for that very thread. Answers
    of 256 KB (4 messages of 64 KB) are put from the main thread instead: the same files, on time."""
    sets = ["agents.count=6", "allocator={name: noop, peers: 5, payload_bytes: 65536, messages: 4}", "run.duration=30"]
    sets += ["run.stop_when_done=false", "network.range=null", "network.rate=null", "network.loss=0"]
    default = run_experiment(experiment(*sets), tmp_path / "default", progress=False)
    started = time.monotonic()
    single = run_experiment(experiment(*sets, "run.zenoh_threads=single"), tmp_path / "single", progress=False)
    assert time.monotonic() - started < 60  # a stalled put waits 5 s a time: 30 ticks would take minutes
    for name in DETERMINISTIC_FILES[:-1]:
        assert (default.out_dir / name).read_bytes() == (single.out_dir / name).read_bytes(), name
    assert single.summary["network"]["delivered"] == 4 * 6 * 5 * 29  # every copy but the last tick's
