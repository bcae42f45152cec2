"""Our engine against BehaviorTree.CPP itself, tick by tick (root status and every leaf call)."""

import pytest

from tests.bt_harness import random_case, run_btcpp, run_ours

bt = pytest.importorskip("behaviortreepy", reason="conformance needs the BehaviorTree.CPP bindings")

HAND_WRITTEN = {
    "sequence resumes at the running child": (
        "<Sequence><Act name='a'/><Act name='b'/><Cond name='c'/></Sequence>",
        {"a": ["SUCCESS"], "b": ["RUNNING", "RUNNING", "SUCCESS"], "c": ["FAILURE", "SUCCESS"]},
    ),
    "reactive sequence halts the running child when an earlier one runs": (
        "<ReactiveSequence><Act name='a'/><Act name='b'/></ReactiveSequence>",
        {"a": ["RUNNING", "SUCCESS", "RUNNING", "FAILURE"], "b": ["RUNNING"]},
    ),
    "reactive fallback preempts a lower-priority running child": (
        "<ReactiveFallback><Cond name='c'/><Act name='b'/></ReactiveFallback>",
        {"c": ["FAILURE", "FAILURE", "SUCCESS", "FAILURE"], "b": ["RUNNING"]},
    ),
    "parallel with thresholds": (
        "<Parallel success_count='2' failure_count='2'><Act name='a'/><Act name='b'/><Act name='c'/></Parallel>",
        {
            "a": ["RUNNING", "SUCCESS"],
            "b": ["RUNNING", "RUNNING", "FAILURE"],
            "c": ["RUNNING", "RUNNING", "RUNNING", "SUCCESS"],
        },
    ),
    "repeat yields between synchronous cycles": (
        "<Repeat num_cycles='3'><Cond name='c'/></Repeat>",
        {"c": ["SUCCESS", "SUCCESS", "SUCCESS", "FAILURE", "SUCCESS"]},
    ),
    "retry restarts a failed stateful action": (
        "<RetryUntilSuccessful num_attempts='3'><Act name='a'/></RetryUntilSuccessful>",
        {"a": ["RUNNING", "FAILURE", "RUNNING", "FAILURE", "SUCCESS"]},
    ),
    "keep running until failure": (
        "<KeepRunningUntilFailure><Act name='a'/></KeepRunningUntilFailure>",
        {"a": ["SUCCESS", "RUNNING", "SUCCESS", "FAILURE"]},
    ),
    "decorators around running children": (
        "<Sequence><Inverter><Cond name='c'/></Inverter><ForceSuccess><Act name='a'/></ForceSuccess>"
        "<ForceFailure><Act name='b'/></ForceFailure></Sequence>",
        {"c": ["FAILURE"], "a": ["RUNNING", "FAILURE"], "b": ["RUNNING", "SUCCESS"]},
    ),
}


def _xml(body: str) -> str:
    return f'<root BTCPP_format="4"><BehaviorTree ID="Main">{body}</BehaviorTree></root>'


@pytest.mark.parametrize("case", sorted(HAND_WRITTEN))
def test_hand_written_trees_match_btcpp(case):
    body, scripts = HAND_WRITTEN[case]
    xml = _xml(body)
    ours, _ = run_ours(xml, scripts, ticks=8)
    theirs, _ = run_btcpp(xml, scripts, ticks=8)
    assert ours == theirs


def test_random_trees_match_btcpp():
    mismatches = []
    for seed in range(300):
        xml, scripts = random_case(seed)
        ours, _ = run_ours(xml, scripts, ticks=10)
        theirs, _ = run_btcpp(xml, scripts, ticks=10)
        if ours != theirs:
            mismatches.append((seed, xml))
    assert not mismatches, f"{len(mismatches)} of 300 random trees differ, first: {mismatches[0]}"


def test_subtree_remapping_and_autoremap_match_btcpp():
    xml = """<root BTCPP_format="4" main_tree_to_execute="Main">
      <BehaviorTree ID="Main">
        <Sequence>
          <SetBlackboard value="7" output_key="shared"/>
          <SubTree ID="Inner" target="{goal}" mode="fast"/>
          <SubTree ID="Auto" _autoremap="true"/>
        </Sequence>
      </BehaviorTree>
      <BehaviorTree ID="Inner">
        <Sequence>
          <SetBlackboard value="42" output_key="target"/>
          <SetBlackboard value="private" output_key="local_only"/>
        </Sequence>
      </BehaviorTree>
      <BehaviorTree ID="Auto">
        <Sequence>
          <SetBlackboard value="via-autoremap" output_key="copied"/>
          <SetBlackboard value="x" output_key="_private"/>
        </Sequence>
      </BehaviorTree>
    </root>"""
    _, our_bb = run_ours(xml, {}, ticks=1)
    _, tree = run_btcpp(xml, {}, ticks=1)
    theirs = tree.root_blackboard()
    their_keys = sorted(k for k in theirs.get_keys())
    assert our_bb.keys() == their_keys == ["copied", "goal", "shared"]
    for key in their_keys:
        assert str(our_bb.get(key)) == theirs.get_string(key)
