"""Soak tests: a run left going for a wall-clock time under faults, every process watched, a verdict.

Real runs: agents are OS processes on real Zenoh sessions, killed and stopped with real signals;
the loss burst reaches the real proxy on its control key."""

import csv
import json
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from swarmbed import config as cfg
from swarmbed.campaigns.chaos import CHAOS_COLUMNS, CUT_SHORT, Chaos, ChaosError, ChaosPlan, check_plan, load_chaos
from swarmbed.campaigns.soak import (
    PROCESSES,
    RUN,
    VERDICT,
    Thresholds,
    fault_breaches,
    fault_counts,
    parse_duration,
    plan_coverage,
    rss_growth,
    soak,
    speed_trends,
    tick_rates,
)
from swarmbed.coordinator.live import LiveStatus
from swarmbed.engine import results
from swarmbed.launch.access import OWNER, RunAccess, remove_orphaned_folders
from swarmbed.launch.runner import run_experiment
from swarmbed.records.rowfile import RowFile
from swarmbed.results.report import report
from swarmbed.wire.keys import Keys
from tests.conftest import ROOT, experiment, whole_rows
from tests.test_report import CHROMIUM, NO_CHROMIUM, assert_renders

SOAK = ROOT / "experiments" / "soak" / "sar_soak.yaml"
# A minute's soak extrapolates its slopes to an hour, so a one-off step of a few MB (allocators
# reaching their working size) reads as hundreds of %/h here; the leaking allocator below grows by >20,000 %/h
SHORT = Thresholds(max_rss_slope_pct_h=3000.0, max_fd_growth_h=1000.0, max_stall_s=10.0)


def test_a_streamed_table_is_the_table_written_at_once_and_parses_at_every_moment(tmp_path):
    rows = [[i, f"a,{i}", i / 3, "" if i % 2 else None] for i in range(10)]
    results.write_csv(tmp_path / "whole.csv", ["n", "text", "x", "maybe"], rows)
    table = RowFile(tmp_path / "streamed.csv", ["n", "text", "x", "maybe"], chunk_rows=3, chunk_s=3600)
    for i, row in enumerate(rows):
        table.write(row)
        on_disk = pd.read_csv(table.part)  # whole rows only, a header always: what a kill would leave
        assert len(on_disk) == (i + 1) // 3 * 3
    assert table.finish().read_bytes() == (tmp_path / "whole.csv").read_bytes()
    left = RowFile(tmp_path / "cut.csv", ["n"])
    left.write([1])
    kept = left.abandon()
    assert kept == tmp_path / "partial_cut.csv" and kept.read_text() == "n\n1\n"
    assert not (tmp_path / "cut.csv").exists() and not (tmp_path / "cut.csv.part").exists()


def test_rss_growth_is_judged_only_where_it_is_there():
    """The wiggle of the issue (71.6-72.1 MB over 30 s, which extrapolated to 81 %/h) is too short
    to judge; the same wiggle over two hours is steady; a real leak over a minute grows."""
    rng = np.random.default_rng(1)
    limits = Thresholds()
    t = np.arange(0.0, 31.0)
    wiggle = 71.6 + np.linspace(0, 0.3, len(t)) + rng.uniform(0, 0.2, len(t))
    assert rss_growth(t, wiggle, limits)["rss"] == "too short to judge"
    hours = np.arange(0.0, 7200.0, 30.0)
    assert rss_growth(hours, 72 + rng.uniform(-0.3, 0.3, len(hours)), limits)["rss"] == "steady"
    leak = np.arange(0.0, 60.0)
    judged = rss_growth(leak, 72 + 0.5 * leak + rng.uniform(-0.3, 0.3, len(leak)), limits)
    assert judged["rss"] == "grows" and judged["rss_growth_mb"] > 25
    slow = rss_growth(hours, 72 + hours / 7200 * 20 + rng.uniform(-0.3, 0.3, len(hours)), limits)  # 12 %/h
    assert slow["rss"] == "grows" and slow["rss_slope_low_pct_h"] > 0


def _soak_tables(minutes: float, coordinator_ms, rate=100.0, seed=2):
    """A soak's process and run tables, sampled every 5 s: a coordinator whose CPU per tick is
    ``coordinator_ms(t)`` and agents at a steady 10 ms a tick, ``rate`` ticks a second."""
    rng = np.random.default_rng(seed)
    wall = np.arange(5.0, minutes * 60 + 1, 5.0)
    ticks = np.cumsum(np.full(len(wall), rate * 5.0))
    procs, runs = [], []
    for t, tick in zip(wall, ticks):
        noise = rng.uniform(0.97, 1.03)
        procs.append({"wall_s": t, "kind": "coordinator", "cpu_pct": coordinator_ms(t) * rate / 10 * noise})
        procs.append({"wall_s": t, "kind": "agent", "cpu_pct": 10.0 * rate / 10 * noise})
        runs.append({"wall_s": t, "tick": tick, "ticks_per_s": rate * noise})
    return pd.DataFrame(procs), pd.DataFrame(runs)


def test_a_cost_per_tick_that_grows_is_a_breach_and_a_steady_one_is_not():
    """Issue 82 item 17: a 15-minute soak passed while the coordinator's CPU per tick rose from 3.8
    to 4.9 ms. Here it rises as much over an hour; a steady one and a short window are not breaches."""
    limits = Thresholds()
    procs, runs = _soak_tables(60, lambda t: 3.8 + 1.1 * t / 3600)
    speed = speed_trends(procs, runs, limits)
    assert speed["cpu_ms_per_tick"]["coordinator"]["trend"] == "grows"
    assert speed["cpu_ms_per_tick"]["agent"]["trend"] == "steady"
    assert speed["ticks_per_s"]["trend"] == "steady"
    assert speed["cpu_ms_per_tick"]["coordinator"]["mean"] == pytest.approx(4.6, rel=0.05)
    steady = speed_trends(*_soak_tables(60, lambda t: 3.8), limits)
    assert steady["cpu_ms_per_tick"]["coordinator"]["trend"] == "steady"
    short = speed_trends(*_soak_tables(4, lambda t: 3.8 + 1.1 * t / 240), limits)
    assert short["cpu_ms_per_tick"]["coordinator"]["trend"] == "too short to judge"


def test_the_verdict_counts_faults_by_action_in_time_order_and_says_what_the_plan_could_not_show():
    plan = ChaosPlan.model_validate(
        {"events": [{"action": "kill_agent", "every": 120}, {"action": "stop_agent", "at": [10, 500], "for": 2}]}
    )
    notes = plan_coverage(plan, 300.0)
    assert any("kill_agent every 120 s" in n and "too few" in n for n in notes)
    assert any("stop_agent at 500 s" in n for n in notes)
    assert plan_coverage(plan, 3600.0) == []
    faults = [{"action": "kill_agent"}, {"action": "stop_agent"}, {"action": "kill_agent"}]
    assert fault_counts(faults) == {"kill_agent": 2, "stop_agent": 1}


def test_tick_rates_leave_out_the_window_cut_short_as_the_soak_stops():
    """The issue's 60 s soak: every full 5 s window ran 295-403 ticks/s, the last sample came 0.4 s
    after the one before with a handful of ticks, and the verdict said 132.1 at the end."""
    wall = np.array([5.0 * k for k in range(1, 13)] + [60.4])
    rates = np.array([385.2, 390, 403, 380, 360, 350, 340, 330, 320, 310, 300, 295, 132.1])
    start, end = tick_rates(wall, rates)
    assert start == pytest.approx(385.2) and end == pytest.approx(295.0)
    assert tick_rates(np.array([]), np.array([])) == (0.0, 0.0)
    assert tick_rates(np.array([5.0, 10.0]), np.array([100.0, 120.0])) == (100.0, 120.0)


def test_durations_and_chaos_files_are_checked_with_clear_errors(tmp_path):
    assert parse_duration("90") == 90 and parse_duration("2h") == 7200 and parse_duration("1h30m") == 5400
    with pytest.raises(ValueError, match="not a duration"):
        parse_duration("soon")
    for short in ("0s", "0", "5s"):
        with pytest.raises(ValueError, match="at least 10 s"):
            parse_duration(short)
    bad = tmp_path / "chaos.yaml"
    bad.write_text("events:\n  - action: loss_burst\n    at: [3]\n    for: 2\n")
    with pytest.raises(ChaosError, match=r"chaos.yaml: events\.0.*needs `loss`"):
        load_chaos(bad)
    bad.write_text("events:\n  - action: melt_cpu\n    at: [3]\n")
    with pytest.raises(ChaosError, match=r"events\.0\.action"):
        load_chaos(bad)
    out = subprocess.run(
        [sys.executable, "-m", "swarmbed", "soak", str(SOAK), "--duration", "15s", "--chaos", str(bad)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert out.returncode == 2 and "melt_cpu" not in out.stdout and "action" in out.stderr
    # a rate cap mid-run in a radio split by region (no proxy keeps every sender's queue): refused
    capped = tmp_path / "capped.yaml"
    capped.write_text("events:\n  - action: rate_cap\n    at: [3]\n    for: 2\n    rate: 500\n")
    split = ["--set", "radio_split.shards=2", "--set", "network.draws=per_copy"]
    for rate, refused in ((["--set", "network.rate=null"], True), (["--set", "network.rate=4000"], False)):
        exp = cfg.load(SOAK, [a for a in split + rate if a != "--set"])
        if refused:
            with pytest.raises(ChaosError, match="rate_cap: the radio is split by region"):
                check_plan(load_chaos(capped), exp)
        else:
            check_plan(load_chaos(capped), exp)
    out = subprocess.run(
        [sys.executable, "-m", "swarmbed", "soak", str(SOAK), "--duration", "15s", "--chaos", str(capped), *split],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert out.returncode == 2 and out.stderr.count("\n") == 1 and "split by region" in out.stderr, out.stderr


def test_faults_are_scheduled_only_where_their_window_ends_in_the_run_and_one_cut_short_is_no_breach(tmp_path):
    """A stop or a radio change still in force at the end tests nothing: it is not started. A kill
    moments before the end whose restart could not be seen is logged as cut short, not unresolved."""

    def plan(duration: float) -> ChaosPlan:
        return ChaosPlan.model_validate(
            {
                "seed": 4,
                "events": [
                    {"action": "rate_cap", "every": 10, "for": duration, "rate": 50},
                    {"action": "stop_agent", "at": [5, 95], "for": 2},
                ],
            }
        )

    short, long = Chaos(plan(1), 100, 0).schedule(), Chaos(plan(30), 100, 0).schedule()
    assert all(d.at + d.event.duration <= 100 for d in short + long)
    assert [d.at for d in short if d.event.action == "stop_agent"] == [5, 95]
    caps = [d.at for d in short if d.event.action == "rate_cap"]
    assert [t for t in caps if t <= 70] == [d.at for d in long if d.event.action == "rate_cap"]  # the same draws
    assert max(caps) > 70  # some were left out of the long-window plan
    chaos = Chaos(plan(1), 100, 0)
    quiet = LiveStatus(8, 8.0, (0,) * 5, {}, frozenset(range(4)), frozenset(), {}, {}, {}, ())  # no restart, no loss
    chaos.run = SimpleNamespace(coordinator=SimpleNamespace(live=lambda: quiet))
    chaos.table = RowFile(tmp_path / "chaos.csv", CHAOS_COLUMNS, chunk_rows=1)
    for give_up in (time.monotonic() + 20, time.monotonic() - 1):
        chaos._pending.append(
            (
                give_up,
                {
                    "wall_s": 99.0,
                    "tick": 7,
                    "action": "kill_agent",
                    "target": 3,
                    "detail": "SIGKILL",
                    "kind": "kill",
                    "agent": 3,
                },
            )
        )
    chaos._resolve(final=True)
    assert [row[-1] for row in chaos.rows] == [CUT_SHORT, "unresolved: no ending within 30 s"]
    rows = [dict(zip(CHAOS_COLUMNS, row)) for row in chaos.rows]
    assert fault_breaches(rows) == ["kill_agent at 99.0 s: unresolved: no ending within 30 s"]


@pytest.fixture(scope="module")
def chaos_soak(tmp_path_factory):
    """Kills (each agent restarted from its checkpoint), a stop, a loss burst and a rate cap, in a
    60-second soak of 8 agents."""
    plan = ChaosPlan.model_validate(
        {
            "events": [
                {"action": "kill_agent", "at": [8, 22, 38]},
                {"action": "stop_agent", "at": [15], "for": 1.5},
                {"action": "loss_burst", "at": [28], "for": 9, "loss": 0.6},
                {"action": "rate_cap", "at": [46], "for": 4, "rate": 30},
            ]
        }
    )
    out = tmp_path_factory.mktemp("chaos") / "soak"
    # checkpoints every 100 ticks: the first kill (8 s in) finds one even on a loaded machine
    return out, soak(
        # I_base 10 s: cbba-etc's fallback rounds every 30-80 s, so that the 9 s loss burst meets copies
        # (a 5 s burst on a loaded machine once met none: 118 ticks, no round)
        experiment("agents.count=8", "run.snapshot_every=100", "allocator.base_interval=10", base=SOAK),
        out,
        60,
        plan,
        interval=1.0,
        limits=SHORT,
    )


def test_a_minute_of_chaos_is_survived_accounted_and_judged(chaos_soak, tmp_path):
    """The verdict passes, every fault says how it ended, the ledger balances."""
    out, v = chaos_soak
    assert v["passed"], v["breaches"]
    assert v["wall_s"] >= 59 and v["conserved"] and v["restarts"] == 3
    outcomes = {f["action"]: [] for f in v["faults"]}
    for f in v["faults"]:
        outcomes[f["action"]].append(f["outcome"])
    assert len(outcomes["kill_agent"]) == 3
    assert all(o.startswith("restarted before tick") and "checkpoint of tick" in o for o in outcomes["kill_agent"])
    assert outcomes["stop_agent"][0].startswith("resumed at tick")
    assert outcomes["loss_burst"][0].startswith("in force ticks") and " loss" in outcomes["loss_burst"][0]
    assert outcomes["rate_cap"][0].startswith("in force ticks")
    with open(out / "chaos.csv") as f:
        assert len(list(csv.DictReader(f))) == 6
    restarts = pd.read_csv(out / "restarts.csv")
    assert list(restarts["outcome"]) == ["ok"] * 3 and (restarts["checkpoint_tick"] % 100 == 0).all()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["agent_restarts"] == 3 and summary["agents_lost"] == {}
    assert summary["network"]["dropped"]["loss"] > 0  # only the burst loses copies: the run's loss is 0
    assert summary["network"]["bytes_agree"] is None  # restarted agents' own counters began again
    procs = pd.read_csv(out / PROCESSES)
    assert set(procs["kind"]) == {"coordinator", "netem", "forkserver", "agent"}
    assert procs["process"].str.fullmatch(r"agent_\d+\.1").sum() > 0  # the restarted processes were watched
    run = pd.read_csv(out / RUN)
    assert (run["in_flight"] >= 0).all() and run["tick"].is_monotonic_increasing
    assert json.loads((out / VERDICT).read_text())["passed"]
    page = report(out, tmp_path / "soak.html").read_text()
    assert "Verdict: passed" in page and page.count("restarted before tick") == 3


@pytest.mark.skipif(CHROMIUM is None, reason=NO_CHROMIUM)
def test_the_soak_page_draws_every_plot_in_a_real_browser(chaos_soak, tmp_path):
    assert_renders(report(chaos_soak[0], tmp_path / "soak.html").read_text(), tmp_path)


LEAKY = textwrap.dedent('''
    from swarmbed.plugins.noop import NoopAllocator

    class Leaky(NoopAllocator):
        """Keeps 1 MB more every tick, forever: what a soak is there to catch."""
        hoard = []

        def decide(self, view):
            self.hoard.append(bytearray(1 << 20))
            return super().decide(view)
''')


def test_an_allocator_that_leaks_fails_the_verdict_on_its_rss(tmp_path):
    plugin = tmp_path / "leaky.py"
    plugin.write_text(LEAKY)
    exp = experiment(f"allocator={{name: '{plugin}:Leaky'}}", "agents.count=3", "run.dt=0.1")
    v = soak(exp, tmp_path / "soak", 16, interval=1.0, limits=SHORT)
    assert not v["passed"]
    assert v["by_kind"]["agent"]["rss_slope_pct_h"] > SHORT.max_rss_slope_pct_h
    assert v["by_kind"]["agent"]["rss"] == "grows"
    assert any(b.startswith("RSS of agent_") for b in v["breaches"])
    assert not any("coordinator" in b or "netem" in b for b in v["breaches"])


CHATTY = textwrap.dedent('''
    import logging

    from swarmbed.plugins.noop import NoopAllocator

    class Chatty(NoopAllocator):
        """Logs 4 KB and prints a line every tick: an agent that would fill a disk in a long soak."""

        def decide(self, view):
            logging.getLogger("chatty").warning("tick %d %s", view.tick, "x" * 4000)
            print(f"printed at tick {view.tick}", flush=True)
            return super().decide(view)
''')


def test_process_logs_rotate_at_their_size_keeping_their_backups(tmp_path):
    plugin = tmp_path / "chatty.py"
    plugin.write_text(CHATTY)
    exp = experiment(
        f"allocator={{name: '{plugin}:Chatty'}}",
        "agents.count=2",
        "run.stop_when_done=false",
        "run.duration=1000",
        "run.dt=1",
        "run.log_max_mb=1",
        "run.log_backups=2",
    )
    run_experiment(exp, tmp_path / "run", progress=False)
    logs = tmp_path / "run" / "logs"
    for agent in (0, 1):
        files = [logs / f"agent_{agent}.log", logs / f"agent_{agent}.log.1", logs / f"agent_{agent}.log.2"]
        assert all(f.exists() for f in files) and not (logs / f"agent_{agent}.log.3").exists()
        assert all(f.stat().st_size <= 2**20 + 5000 for f in files)
        newest = files[0].read_text()
        assert "printed at tick 999" in newest and "tick 999 xxx" in newest  # prints follow the rotation
        assert "tick 0 xxx" not in "".join(f.read_text() for f in files)  # the oldest went


def test_a_killed_soak_leaves_files_that_parse(tmp_path):
    out = tmp_path / "soak"
    cmd = [
        sys.executable,
        "-m",
        "swarmbed",
        "soak",
        str(SOAK),
        "--duration",
        "10m",
        "--out",
        str(out),
        "--interval",
        "0.5",
        "--set",
        "agents.count=4",
    ]
    soak_proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 90

    def rows(name: str) -> int:
        part = out / (name + ".part")
        return len(part.read_text().splitlines()) - 1 if part.exists() else 0

    while rows(RUN) < 8 or rows("timeseries.csv") < 1:  # the time series is flushed every 5 s
        assert soak_proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.2)
    soak_proc.send_signal(signal.SIGKILL)  # no clean-up at all: the children follow (PR_SET_PDEATHSIG)
    soak_proc.wait()
    time.sleep(1.0)
    for name in (RUN, PROCESSES, "timeseries.csv", "network_ledger.csv"):
        whole_rows(out / (name + ".part"))  # a header and whole rows, the last one too
        assert len(pd.read_csv(out / (name + ".part")).columns) > 3, name
    assert len(pd.read_csv(out / ("timeseries.csv.part"))) > 0
    assert not (out / "summary.json").exists() and not (out / VERDICT).exists()
    assert "No verdict" in report(out, tmp_path / "killed.html").read_text()  # reported from its .part files
    # its private credentials folder outlived it; the next run's launcher removes it, and no live run's
    left = [
        f
        for f in Path(tempfile.gettempdir()).glob("swarmbed-*-*")
        if (f / OWNER).exists() and json.loads((f / OWNER).read_text())["pid"] == soak_proc.pid
    ]
    assert len(left) <= 1  # another launcher on this machine (a test beside this one) may have cleared it
    live = RunAccess(Keys("live"), [0])  # a new run's launcher clears what dead launchers left
    try:
        assert not any(f.exists() for f in left) and live.folder.exists()
        assert live.folder not in remove_orphaned_folders()  # a live launcher's folder stays
    finally:
        live.close()


def test_a_run_that_stops_keeps_its_rows_as_partial_files(tmp_path):
    """A run that fails after ticks ran keeps the rows it streamed, never under a result's name."""
    from swarmbed.engine.run_errors import RunError
    from swarmbed.launch.runner import run_experiment

    plugin = tmp_path / "boom.py"
    plugin.write_text(
        textwrap.dedent("""
        from swarmbed.extension import Allocator

        class Boom(Allocator):
            def decide(self, view):
                if view.tick == 30 and self.agent_id == 1:
                    raise RuntimeError("boom")
                return None
    """)
    )
    out = tmp_path / "run"
    with pytest.raises(RunError, match="boom"):
        run_experiment(experiment(f"allocator={{name: '{plugin}:Boom'}}"), out, progress=False)
    series = pd.read_csv(out / "partial_timeseries.csv")
    assert 25 <= len(series) <= 31
    assert "outcome" in pd.read_csv(out / "partial_network_ledger.csv").columns
    assert not list(out.glob("*.part")) and not (out / "timeseries.csv").exists()
    assert not (out / "summary.json").exists()


@pytest.mark.parametrize("policy", ["continue", "restart"])
def test_a_killed_agent_is_lost_or_restarted_and_copies_to_it_are_booked(policy, tmp_path):
    """on_agent_loss: continue loses the agent for good (the copies its peers address to it are
    receiver_dead); restart (no checkpoints here) starts it fresh before the next tick (copies
    routed while the proxy saw it gone are receiver_dead: none, if it came back first)."""
    plan = ChaosPlan.model_validate({"events": [{"action": "kill_agent", "at": [3], "agents": [2]}]})
    exp = experiment(
        "agents.count=5", "allocator={name: noop, peers: 4}", "run.stop_when_done=false", f"run.on_agent_loss={policy}"
    )
    v = soak(exp, tmp_path / "soak", 10, plan, interval=1.0, limits=SHORT)
    assert v["passed"], v["breaches"]
    outcome = v["faults"][0]["outcome"]
    summary = json.loads((tmp_path / "soak" / "summary.json").read_text())
    assert v["conserved"]
    if policy == "continue":
        assert list(v["agents_lost"]) == ["2"] and v["restarts"] == 0
        assert outcome.startswith("lost at tick") and "continue" in outcome
        assert summary["network"]["dropped"]["receiver_dead"] > 0
    else:
        assert v["agents_lost"] == {} and v["restarts"] == 1 and outcome.startswith("restarted") and "fresh" in outcome
        alive = pd.read_csv(tmp_path / "soak" / "agents.csv")
        assert alive.loc[2, "alive"] == 1 and alive.loc[2, "messages_sent"] > 0


def _frozen_agent_soak(tmp_path, seconds: float, max_stall: float, *sets: str, lost: bool = True) -> dict:
    """A soak of 3 agents in which agent 1 is SIGSTOPped for 24 s at 2 s (no keep-alive either, as
    a host cut off), going on without it once it is lost; its verdict. ``lost``: check that the
    agent was lost (False: leave that to the caller)."""
    plan = ChaosPlan.model_validate({"events": [{"action": "stop_agent", "at": [2], "for": 24, "agents": [1]}]})
    exp = experiment(
        "agents.count=3",
        "allocator={name: noop, peers: 2}",
        "run.stop_when_done=false",
        "run.on_agent_loss=continue",
        *sets,
    )
    limits = Thresholds(max_rss_slope_pct_h=3000.0, max_fd_growth_h=1000.0, max_stall_s=max_stall)
    v = soak(exp, tmp_path / "soak", seconds, plan, interval=0.5, limits=limits)
    assert v["passed"], v["breaches"]
    if lost:
        assert list(v["agents_lost"]) == ["1"], v["agents_lost"]
    return v


def test_a_frozen_agent_is_given_up_within_zenohs_lease_on_the_default_thread_layout(tmp_path):
    """Issue 58: the default thread layout keeps Zenoh's 10 s lease, so an agent that stops
    answering altogether (SIGSTOP for 24 s: no keep-alive either, as a host cut off) is given up
    by the hub after Zenoh's lease (measured: the ticks stall 14 s), not the single worker's minute,
    and the run goes on without it."""
    v = _frozen_agent_soak(tmp_path, 30, 30.0, "run.tick_timeout=40")
    assert 8.0 < v["longest_stall_s"] < 20.0, v["longest_stall_s"]  # the lease, not the 24 s freeze


def test_on_the_single_worker_layout_a_frozen_agent_stalls_the_ticks_for_its_freeze_and_is_lost_when_it_wakes(
    tmp_path,
):
    """Issue 74 item 19: under ``run.zenoh_threads: single`` the agent's session has a 60 s lease, so
    the hub waits out a 24 s freeze (the ticks stall about as long, not the default layout's 10 s
    lease). When the agent runs again, two things race in its Zenoh runtime: the check of the hub's
    10 s lease, long expired, which closes its session (the hub then loses it a tick or two after
    it froze), and the hub's keep-alives queued in its socket, which renew the lease; the check
    wins most times here (4 of 5 under load), the keep-alives sometimes, and then the agent simply
    answers on. Either way the stall is the freeze (docs/benchmarks.md, the key's description)."""
    v = _frozen_agent_soak(tmp_path, 36, 50.0, "run.tick_timeout=60", "run.zenoh_threads=single", lost=False)
    assert 22.0 < v["longest_stall_s"] < 40.0, v["longest_stall_s"]  # the freeze, not 10 s, not 60 s
    froze = v["faults"][0]["tick"]
    if v["agents_lost"]:
        assert list(v["agents_lost"]) == ["1"], v["agents_lost"]
        assert 0 < v["agents_lost"]["1"] - froze <= 3, (froze, v["agents_lost"])
    else:  # it kept its session: it is alive at the end and was heard after the freeze
        alive = pd.read_csv(tmp_path / "soak" / "agents.csv")
        assert alive.loc[1, "alive"] == 1
        ledger = pd.read_csv(tmp_path / "soak" / "network_ledger.csv")
        sent = ledger[(ledger.sender == 1) & (ledger.outcome == "sent")]
        assert sent.tick.max() > froze + 100, (froze, sent.tick.max())


def test_on_the_real_time_clock_a_stopped_agent_misses_ticks_and_the_soak_says_how_many(tmp_path):
    """SIGSTOP for 1.5 s at 10 ticks per second: the agent misses about 15 ticks (booked late), the
    run's clock goes on, and the fault's outcome counts them."""
    plan = ChaosPlan.model_validate({"events": [{"action": "stop_agent", "at": [3], "for": 1.5, "agents": [1]}]})
    exp = experiment(
        "agents.count=4",
        "allocator={name: noop, peers: 3}",
        "run.stop_when_done=false",
        "run.clock=realtime",
        "run.dt=1",
        "run.speed=10",
    )
    v = soak(exp, tmp_path / "soak", 8, plan, interval=1.0, limits=SHORT)
    assert v["passed"], v["breaches"]
    late = int(v["faults"][0]["outcome"].split(", ")[1].split()[0])
    assert 10 <= late <= 20, v["faults"][0]["outcome"]
    summary = json.loads((tmp_path / "soak" / "summary.json").read_text())
    missed = summary["realtime"]["late_ticks"]
    assert missed["1"] == late  # on a loaded machine another agent may miss a deadline once or twice
    assert all(n <= 2 for agent, n in missed.items() if agent != "1"), missed
    assert summary["network"]["dropped"]["late"] > 0 and v["conserved"]
    run = pd.read_csv(tmp_path / "soak" / RUN)
    assert run["start_lag_ms"].notna().any()


def test_host_daemons_on_this_machine_and_their_agents_are_watched(lab, tmp_path):
    """Agents placed on a stand-in host (a network namespace with its own daemon) are sampled
    under their host's name, and so is the daemon."""
    lab.add_host("h1")
    exp = experiment(
        "agents.count=4", "allocator={name: noop, peers: 2}", "run.stop_when_done=false", "placement={h1: '0-1'}"
    )
    v = soak(exp, tmp_path / "soak", 8, interval=0.5, limits=SHORT, hub=lab.hub_options())
    assert v["passed"], v["breaches"]
    procs = pd.read_csv(tmp_path / "soak" / PROCESSES)
    assert {"host_h1", "agent_0@h1", "agent_1@h1", "agent_2", "agent_3"} <= set(procs["process"])
    assert v["by_kind"]["host"]["processes"] == 1 and v["by_kind"]["agent"]["processes"] == 4


def test_a_host_cut_off_for_a_window_stalls_the_ticks_and_its_agents_come_back(lab, tmp_path):
    """A stand-in host's links go down for 3 s (within Zenoh's 10 s lease): lock-step waits for
    its agents, the links come back, every agent keeps its session and the run goes on."""
    lab.add_host("h1")
    exp = experiment(
        "agents.count=4", "allocator={name: noop, peers: 3}", "run.stop_when_done=false", "placement={h1: '0-1'}"
    )
    plan = ChaosPlan.model_validate({"events": [{"action": "cut_host", "at": [2], "for": 3}]})
    v = soak(exp, tmp_path / "soak", 10, chaos=plan, interval=0.5, limits=SHORT, hub=lab.hub_options())
    assert v["passed"], v["breaches"]
    (fault,) = v["faults"]
    assert (fault["action"], fault["target"]) == ("cut_host", "h1")
    assert fault["outcome"].startswith("reconnected, every agent kept its session"), fault
    assert v["longest_stall_s"] > 2.0  # the ticks waited for the cut-off agents
    run = pd.read_csv(tmp_path / "soak" / RUN)
    assert run["tick"].iloc[-1] > run.loc[run["wall_s"] <= 5.5, "tick"].max()  # and went on afterwards
    assert netns_links_up(lab)


def test_a_restart_that_finds_its_host_away_is_tried_again_once_the_host_is_back(lab, tmp_path):
    """A 20 s cut outlasts Zenoh's lease: the host's two agents are lost. The first tries to start
    them find the host away and fail; later tries, after the cut, bring both back."""
    lab.add_host("h1")
    exp = experiment(
        "agents.count=4",
        "allocator={name: noop, peers: 3}",
        "run.stop_when_done=false",
        "placement={h1: '0-1'}",
        "run.on_agent_loss=restart",
        "run.restart_attempts=4",
        "run.restart_backoff=2",
        "run.tick_timeout=30",
    )
    plan = ChaosPlan.model_validate({"events": [{"action": "cut_host", "at": [2], "for": 20}]})
    limits = Thresholds(max_rss_slope_pct_h=3000.0, max_fd_growth_h=1000.0, max_stall_s=30.0)
    v = soak(exp, tmp_path / "soak", 45, chaos=plan, interval=1.0, limits=limits, hub=lab.hub_options())
    assert v["passed"], v["breaches"]
    restarts = pd.read_csv(tmp_path / "soak" / "restarts.csv")
    assert "retrying" in set(restarts["outcome"]) and "failed" not in set(restarts["outcome"]), restarts
    assert set(restarts.loc[restarts["outcome"] == "ok", "agent"]) == {0, 1}
    assert not restarts.duplicated(["agent", "incarnation"]).any()  # each try its own: a late joiner is never taken
    (fault,) = v["faults"]
    assert "agents restarted: [0, 1]; agents lost: none" in fault["outcome"], fault
    assert netns_links_up(lab)


def netns_links_up(lab) -> bool:
    from swarmbed.hosts.netns import _ip

    return all("state DOWN" not in _ip("-o", "link", "show", ns=ns).stdout for ns in lab.namespaces)


def test_sessions_map_no_shared_memory_pools():
    """With Zenoh's shared-memory transport on, a message over 3 KB gives its sender a 16 MB pool
    that every receiving session maps and keeps: 16 MB per agent in the hub, never given back
    when an agent restarts. Our sessions send large payloads as bytes on the link."""
    import zenoh

    from swarmbed.launch.hub import open_hub
    from swarmbed.wire.membership import accept_handovers, hand_over
    from swarmbed.wire.zenoh_session import zenoh_config

    def pools() -> list[str]:
        with open("/proc/self/maps") as maps:
            return [line for line in maps if ".zenoh" in line]

    got: list[int] = []
    hub, endpoint = open_hub()
    with hub, zenoh.open(zenoh_config("client", connect=[endpoint])) as client:
        hub.declare_subscriber("shm/put", lambda sample: got.append(len(sample.payload.to_bytes())))
        accept_handovers(hub, "shm/query", lambda key, data: got.append(len(data)))
        time.sleep(0.3)
        client.put("shm/put", bytes(64_000))
        assert hand_over(client, "shm/query", bytes(64_000), timeout=5)
        deadline = time.monotonic() + 5
        while len(got) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert got == [64_000, 64_000]
        assert pools() == []


def test_a_centralized_allocator_survives_its_leader_killed_and_the_next_lowest_id_leads(tmp_path):
    """Issue 60: SGA's leader is agent 0 (the lowest id alive). Its process is killed mid-run; the
    followers stop hearing it, and ``heard_within`` simulated seconds later the lowest id they hear
    leads: assignments go out again every tick and tasks go on being completed."""
    plan = ChaosPlan.model_validate({"events": [{"action": "kill_agent", "at": [3], "agents": [0]}]})
    exp = experiment(
        "agents.count=5",
        "allocator={name: sga, heard_within: 5}",
        "run.stop_when_done=false",
        "run.on_agent_loss=continue",
        "network.range=null",  # everyone in reach of everyone: one leader
        base=ROOT / "experiments" / "space_mtsr_code.yaml",
    )
    v = soak(exp, tmp_path / "soak", 10, plan, interval=1.0, limits=SHORT)
    assert v["passed"], v["breaches"]
    killed = v["agents_lost"]["0"]
    rows = pd.read_csv(tmp_path / "soak" / "timeseries.csv")
    rows["sent"] = rows["assignments_sent"].diff()  # the event columns are running totals
    before, after = rows[(rows["tick"] > 5) & (rows["tick"] < killed)], rows[rows["tick"] > killed + 20]
    assert (before["sent"] == 1).all()  # one leader, one assignment a tick
    assert len(after) > 100 and (after["sent"] == 1).all()  # and again one, once the next is elected
    assert after["tasks_completed"].iloc[-1] > after["tasks_completed"].iloc[0]  # the work goes on
