"""What a lying leader of a centralized baseline costs is bounded (issue 82, item 13): a follower
that reaches an assigned goal and finds no task there never takes it again, and after
``max_phantoms`` such goals in a row it treats the leader as failed and follows the next lowest id.
Before, a leader that sent followers after tasks no run has stretched the quick start's mission
from 333 s to 848 s."""

import swarmbed
from tests.conftest import QUICKSTART, ROOT

LIAR = f"{ROOT / 'tests' / 'liar_leader.py'}:LyingLeader"


def _run(tmp_path, name: str, *sets: str) -> swarmbed.Results:
    exp = swarmbed.load(QUICKSTART, overrides=[f"allocator.name={name}", "run.duration=3000", *sets])
    return swarmbed.run(exp, tmp_path / name.split(":")[-1], engine="inprocess")


def test_a_lying_leader_costs_a_bounded_detour_and_is_left(tmp_path):
    honest = _run(tmp_path, "sga")
    lied = _run(tmp_path, LIAR)
    followers = honest.summary.agents - 1
    assert lied.summary.outcome("all_tasks_completed")
    assert lied.summary.outcome("mission_time") <= 1.5 * honest.summary.outcome("mission_time")
    assert 0 < lied.summary.events["phantom_goals"] <= 3 * followers
    assert "phantom_goals" not in honest.summary.events


def test_max_phantoms_sets_how_many_lies_a_follower_takes(tmp_path):
    once = _run(tmp_path, LIAR, "allocator.max_phantoms=1")
    assert 0 < once.summary.events["phantom_goals"] <= once.summary.agents - 1
