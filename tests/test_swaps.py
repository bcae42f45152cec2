"""Live swaps on one machine: an agent moves to a new process with its whole state, scripted or on
request, and the run's files stay byte-identical to a run where nothing moved; failures leave the
old process running."""

import csv
import textwrap

import numpy as np
import pytest

from swarmbed import config as cfg
from swarmbed.checks.allocator_kit import ConformanceError, check_snapshot
from swarmbed.launch.hub import HubOptions
from swarmbed.launch.runner import run_experiment
from swarmbed.plugins.registry import register
from tests.conftest import QUICKSTART, SwapAsked, experiment, reference_run, same_results

SAR = QUICKSTART.parent / "sar" / "_base.yaml"


def _swaps(run_dir):
    with open(run_dir / "swaps.csv") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize(
    "base, sets",
    [
        (QUICKSTART, ["allocator.name=cbba", "run.duration=120", "run.stop_when_done=false"]),
        (SAR, ["allocator.name=cbba-etc", "run.duration=30"]),
        # ticks answered in the subscriber's callback; the orders on the main thread
        (
            QUICKSTART,
            ["allocator.name=cbba", "run.duration=120", "run.stop_when_done=false", "run.zenoh_threads=single"],
        ),
    ],
    ids=["mtsr-cbba", "sar-cbba-etc", "mtsr-cbba-single-worker"],
)
def test_swapped_agents_give_the_files_of_a_run_where_nothing_moved(tmp_path, base, sets):
    still = [x for x in sets if not x.startswith("run.zenoh_threads")]
    reference_run(experiment(*still, base=base), tmp_path / "still")
    rng = np.random.default_rng(7)
    n = cfg.load(base).agents.count
    ticks = sorted(int(t) for t in rng.choice(np.arange(1, 100), 6, replace=False))
    swaps = ", ".join(f"{{agent: {int(rng.integers(n))}, tick: {t}, to: local}}" for t in ticks)
    run_experiment(experiment(*sets, f"swaps=[{swaps}]", base=base), tmp_path / "moved", progress=False)
    same_results(tmp_path / "still", tmp_path / "moved", config=still == sets)
    records = _swaps(tmp_path / "moved")
    assert [r["outcome"] for r in records] == ["ok"] * 6 and all(int(r["snapshot_bytes"]) > 0 for r in records)


def test_a_swap_asked_for_during_a_run_moves_the_agent(tmp_path, operator):
    sets = ["allocator.name=cbba", "run.duration=1000", "run.stop_when_done=false"]
    bad, good = SwapAsked(operator, 99, "local"), SwapAsked(operator, 2, "local")
    nowhere = SwapAsked(operator, 1, "nowhere")  # no host of this run: refused at once, never queued

    def from_another_terminal(keys, endpoint):
        bad.on_ready(keys, endpoint)
        nowhere.on_ready(keys, endpoint)
        good.on_ready(keys, endpoint)

    run_experiment(
        experiment(*sets),
        tmp_path / "moved",
        progress=False,
        on_ready=from_another_terminal,
        hub=HubOptions(admit=[operator.identity]),
    )
    rc, out, err = good.wait()
    assert rc == 0, err
    assert "swap 0 of agent 2 to local queued" in out
    assert "swap of agent 2 from local to local before tick" in out and ": ok," in out
    rc, _, err = bad.wait()
    assert rc == 2 and "a swap request is" in err
    rc, out, err = nowhere.wait()
    assert rc == 2 and "'nowhere' is not a host of this run" in err and "queued" not in out, (out, err)
    assert [r["agent"] for r in _swaps(tmp_path / "moved")] == ["2"]
    reference_run(experiment(*sets), tmp_path / "still")
    same_results(tmp_path / "still", tmp_path / "moved")


STUCK = textwrap.dedent('''
    import threading

    from swarmbed.plugins.fcg import FirstClaimedGreedy


    class Pinned(FirstClaimedGreedy):
        """Holds what cannot move (a lock), and says so."""

        snapshottable = False

        def __init__(self, *args):
            super().__init__(*args)
            self.lock = threading.Lock()


    class Silent(FirstClaimedGreedy):
        """Holds a lock and does not say so: its snapshot fails when taken."""

        def __init__(self, *args):
            super().__init__(*args)
            self.lock = threading.Lock()
''')


def test_state_that_cannot_move_is_refused_and_the_old_process_goes_on(tmp_path):
    plugin = tmp_path / "stuck.py"
    plugin.write_text(STUCK)
    with pytest.raises(cfg.ConfigError, match="cannot move between processes"):
        experiment(f"allocator={{name: '{plugin}:Pinned'}}", "swaps=[{agent: 0, tick: 5, to: local}]")
    sets = [f"allocator={{name: '{plugin}:Silent'}}", "run.duration=60", "run.stop_when_done=false"]
    run_experiment(experiment(*sets, "swaps=[{agent: 0, tick: 5, to: local}]"), tmp_path / "tried", progress=False)
    (record,) = _swaps(tmp_path / "tried")
    assert record["outcome"] == "failed" and "snapshot_failed" in record["reason"]
    assert "state.allocator.lock: cannot snapshot a _thread.lock" in record["reason"]  # names what and where
    reference_run(experiment(*sets), tmp_path / "still")
    same_results(tmp_path / "still", tmp_path / "tried")


def test_a_swap_to_a_host_that_is_not_there_fails_and_the_old_process_goes_on(tmp_path):
    sets = ["allocator.name=cbba", "run.duration=60", "run.stop_when_done=false"]
    run_experiment(experiment(*sets, "swaps=[{agent: 1, tick: 5, to: nowhere}]"), tmp_path / "tried", progress=False)
    (record,) = _swaps(tmp_path / "tried")
    assert record["outcome"] == "failed" and "cannot start it on nowhere" in record["reason"]
    reference_run(experiment(*sets), tmp_path / "still")
    same_results(tmp_path / "still", tmp_path / "tried")


def test_the_snapshot_check_fails_for_an_allocator_that_forgets_its_state():
    from swarmbed.plugins.fcg import FirstClaimedGreedy

    class Forgetful(FirstClaimedGreedy):
        def snapshot(self):
            return {}  # its rng and claims stay behind

    register("forgetful-test", f"{__name__}:Forgetful", "mtsr")
    globals()["Forgetful"] = Forgetful
    with pytest.raises(ConformanceError, match="after moving through a snapshot"):
        check_snapshot("forgetful-test", {"mode": "Random"}, "mtsr")


def test_snapshots_restore_named_tuples_as_their_own_type():
    """A TaskBook's tasks are named tuples (TaskInfo): a snapshot gives them back as TaskInfo, not
    as plain tuples or lists."""
    from swarmbed.extension.view import TaskInfo
    from swarmbed.wire.state import pack_state, unpack_state

    known = {7: TaskInfo(7, 1.5, -2.0, 30.0), 9: TaskInfo(9, 0.0, 0.0, 5.0, color=2)}
    back = unpack_state(pack_state({"known": known, "pair": (1, 2)}))
    assert back == {"known": known, "pair": (1, 2)}
    assert all(type(v) is TaskInfo for v in back["known"].values())
