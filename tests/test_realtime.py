"""The real-time clock: ticks follow the wall, and an agent that answers after the deadline misses
exactly that tick, with its messages booked as dropped ``late``; lock-step misses nothing."""

import textwrap

import pandas as pd
import pytest

from swarmbed.launch.runner import run_experiment
from tests.conftest import experiment, ledger_outcomes, read_ledger

SLEEPY = textwrap.dedent('''
    import time

    from swarmbed.plugins.noop import NoopAllocator, NoopParams


    class SleepyParams(NoopParams):
        agent: int = 1
        ticks: list[int] = []
        sleep: float = 0.0


    class Sleepy(NoopAllocator):
        """The no-op allocator (messages to its peers every tick) that sleeps on chosen ticks."""

        Params = SleepyParams

        def decide(self, view):
            if self.agent_id == self.params.agent and view.tick in self.params.ticks:
                time.sleep(self.params.sleep)
            return super().decide(view)
''')
SLOW_TICKS = [3, 7, 12, 19]  # 19 is the last: its late answer comes after the run stops


def _run(tmp_path, name, *clock):
    (tmp_path / "sleepy.py").write_text(SLEEPY)
    # 0.5 wall s per tick, answers due within 0.25 s; the sleeper answers 0.35 s in, in time for the next
    allocator = f"allocator={{name: '{tmp_path / 'sleepy.py'}:Sleepy', peers: 2, ticks: {SLOW_TICKS}, sleep: 0.35}}"
    exp = experiment(allocator, "agents.count=4", "run.duration=20", "run.stop_when_done=false", *clock)
    return run_experiment(exp, tmp_path / name, progress=False)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("realtime")
    return {
        "realtime": _run(base, "rt", "run.clock=realtime", "run.speed=2", "run.deadline=0.5"),
        "lockstep": _run(base, "ls"),
    }


def test_exactly_the_ticks_whose_answer_crossed_the_deadline_are_missed(runs):
    s = runs["realtime"].summary
    clock = s["realtime"]
    assert clock["late_ticks"] == {"1": len(SLOW_TICKS)} and clock["late_ticks_total"] == len(SLOW_TICKS)
    series = pd.read_csv(runs["realtime"].out_dir / "timeseries.csv")
    late = series.loc[series["late_agents"] > 0, "tick"] - 1  # a row describes the tick just applied
    assert list(late) == SLOW_TICKS and (series.loc[series["late_agents"] > 0, "late_agents"] == 1).all()
    assert clock["start_lag_ms"]["max"] is not None and clock["start_lag_ms"]["p50"] <= clock["start_lag_ms"]["max"]


def test_late_messages_are_booked_dropped_and_every_copy_is_accounted(runs):
    run = runs["realtime"]
    net = run.summary["network"]
    assert net["dropped"]["late"] == len(SLOW_TICKS) * 2  # two peers: two copies a message
    assert net["copies"] == net["delivered"] + sum(net["dropped"].values())
    assert net["bytes_agree"] is True  # the agent counted the late messages as sent; so did the ledger
    rows = read_ledger(run.out_dir)
    late = [r for r in rows if r["outcome"] == "late"]
    assert {r["sender"] for r in late} == {1} and sum(r["messages"] for r in late) == 2 * len(SLOW_TICKS)
    outcomes = ledger_outcomes(rows)
    assert outcomes["sent"] == net["messages_sent"] == 4 * 20


def test_lock_step_with_the_same_plugin_misses_nothing(runs):
    s = runs["lockstep"].summary
    assert "realtime" not in s and s["network"]["dropped"]["late"] == 0
    assert s["network"]["messages_sent"] == 4 * 20 and s["ticks"] == 20
    assert "late_agents" not in pd.read_csv(runs["lockstep"].out_dir / "timeseries.csv")


def test_real_time_paces_ticks_by_the_wall(runs):
    # 20 ticks at 0.5 wall s each: the run cannot be faster than the wall allows
    assert runs["realtime"].timings["run_s"] >= 19 * 0.5
    assert runs["lockstep"].timings["run_s"] < runs["realtime"].timings["run_s"]
