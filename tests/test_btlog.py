"""Our .btlog against BehaviorTree.CPP's own FileLogger2: the same trees with the same leaf results
give the same tree (node types, names, uids, SubTree paths) and the same status changes, in order."""

import json
import re
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from swarmbed.bt import NodeRegistry, load_tree
from swarmbed.bt.groot_tree import ChangeRecorder, tree_xml
from swarmbed.wire.btlog import EPOCH_US, HEADER, BtLogError, file_head, read_btlog, records
from tests.bt_harness import Act, Cond, Script, btcpp_tree, random_case

bt = pytest.importorskip("behaviortreepy", reason="the reference needs the BehaviorTree.CPP bindings")

TICKS = 8
WITH_SUBTREES = (
    '<root BTCPP_format="4" main_tree_to_execute="Main">'
    '<BehaviorTree ID="Main"><Sequence name="top"><Cond name="c"/><SubTree ID="Sub"/>'
    '<SubTree ID="Sub" name="second"/><Inverter><Act name="a"/></Inverter></Sequence></BehaviorTree>'
    '<BehaviorTree ID="Sub"><Fallback><Cond name="x"/><SubTree ID="Leaf"/></Fallback></BehaviorTree>'
    '<BehaviorTree ID="Leaf"><Act name="deep"/></BehaviorTree></root>'
)
SUBTREE_SCRIPTS = {"c": ["SUCCESS"], "a": ["RUNNING", "FAILURE"], "x": ["FAILURE", "SUCCESS"], "deep": ["RUNNING"]}


def ours(xml: str, scripts: dict[str, list[str]], dt_us: int = 250_000) -> bytes:
    """Our engine's .btlog of ``TICKS`` ticks and a halt, stamped in simulated time."""
    registry = NodeRegistry()
    registry.register(Act)
    registry.register(Cond)
    script = Script(scripts)
    tree = load_tree("<test>", registry, text=xml, context=script)
    recorder = ChangeRecorder(tree)
    out = [file_head(tree_xml(tree))]
    for tick in range(TICKS):
        tree.tick_once()
        out.append(records(tick * dt_us, recorder.take()))
    tree.halt()
    out.append(records(TICKS * dt_us, recorder.take()))
    return b"".join(out)


CASES = {f"random {seed}": random_case(seed) for seed in range(40)} | {"subtrees": (WITH_SUBTREES, SUBTREE_SCRIPTS)}


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, bytes]:
    """BehaviorTree.CPP's FileLogger2 file of every case's ticks and halt, written in a process of
    its own: its writer thread runs behind the ticks, and only the logger's end (destroyed, its
    file closed) says a file is complete."""
    folder = tmp_path_factory.mktemp("reference")
    plan = folder / "cases.json"
    plan.write_text(
        json.dumps(
            {name: [xml, scripts, str(folder / f"{i}.btlog")] for i, (name, (xml, scripts)) in enumerate(CASES.items())}
        )
    )
    done = subprocess.run(
        [sys.executable, "-m", "tests.test_btlog", str(plan)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=Path(__file__).parent.parent,
    )
    assert done.returncode == 0, done.stderr
    return {name: Path(out).read_bytes() for name, (_, _, out) in json.loads(plan.read_text()).items()}


def _write_references(plan_file: str) -> None:
    for xml, scripts, out in json.loads(Path(plan_file).read_text()).values():
        _write_reference(xml, scripts, Path(out))


def _write_reference(xml: str, scripts: dict[str, list[str]], out: Path) -> None:
    tree = btcpp_tree(xml, scripts)
    logger = bt.FileLogger(tree, str(out))
    for _ in range(TICKS):
        tree.tick_exactly_once()
    tree.halt_tree()
    # its writer thread empties its queue every 10 ms and drops what is left when destroyed: wait
    # until the file has stopped growing for a while, then destroy it (which closes the file)
    settled = 0
    while settled < 5:
        size = out.stat().st_size
        time.sleep(0.02)
        logger.flush()
        settled = settled + 1 if out.stat().st_size == size else 0
    del logger, tree


def shape(xml: str) -> list[tuple]:
    """Every BehaviorTree element and node Groot2 reads: tag, ID, name, _fullpath, _uid."""
    root = ET.fromstring(xml)
    out = []
    for tree in root.findall("BehaviorTree"):
        out.append(("BehaviorTree", tree.get("ID"), tree.get("_fullpath")))
        for node in tree.iter():
            if node is not tree:
                out.append((node.tag, node.get("ID"), node.get("name"), node.get("_fullpath"), node.get("_uid")))
    return out


def compare(name: str, reference: bytes) -> None:
    mine = ours(*CASES[name])
    assert mine.startswith(HEADER) and reference.startswith(HEADER)
    my_xml, my_first, my_records = read_btlog(mine)
    ref_xml, _, ref_records = read_btlog(reference)
    assert shape(my_xml) == shape(ref_xml)
    assert [(uid, code) for _, uid, code in my_records] == [(uid, code) for _, uid, code in ref_records]
    assert my_first == EPOCH_US


@pytest.mark.parametrize("seed", range(40))
def test_random_trees_log_the_status_changes_btcpp_logs(seed, reference):
    compare(f"random {seed}", reference[f"random {seed}"])


def test_subtree_instances_get_btcpps_uids_and_paths(reference):
    compare("subtrees", reference["subtrees"])


def test_records_are_stamped_in_simulated_time_and_the_file_is_the_same_every_time():
    first, again = ours(WITH_SUBTREES, SUBTREE_SCRIPTS), ours(WITH_SUBTREES, SUBTREE_SCRIPTS)
    assert first == again
    _, _, stamped = read_btlog(first)
    assert {t for t, _, _ in stamped} <= {tick * 250_000 for tick in range(TICKS + 1)}
    assert stamped[0][0] == 0 and stamped[-1][0] == TICKS * 250_000


def test_a_torn_or_foreign_file_is_named_not_misread():
    good = ours(WITH_SUBTREES, SUBTREE_SCRIPTS)
    for bad, why in ((b"PK\x03\x04", "does not start"), (good[:30], "inside the tree"), (good[:-4], "whole number")):
        with pytest.raises(BtLogError, match=why):
            read_btlog(bad)


if __name__ == "__main__":  # the reference's own process (see the reference fixture)
    _write_references(sys.argv[1])


# -- a run's agents, recorded ---------------------------------------------------------------------
SAR_RUN = ["allocator.name=cbba-etc", "run.duration=30"]


@pytest.mark.slow
def test_a_recorded_run_has_one_btlog_per_agent_identical_on_a_rerun_with_swaps_and_the_same_results(tmp_path):
    from swarmbed.launch.runner import run_experiment
    from swarmbed.records.run_folder import BT
    from tests.conftest import QUICKSTART, RESULTS, experiment

    sar = QUICKSTART.parent / "sar" / "_base.yaml"
    swaps = "swaps=[{agent: 1, tick: 20, to: local}, {agent: 3, tick: 60, to: local}, {agent: 1, tick: 90, to: local}]"
    run_experiment(experiment(*SAR_RUN, base=sar), tmp_path / "plain", progress=False)
    run_experiment(experiment(*SAR_RUN, "run.record_bt=true", base=sar), tmp_path / "recorded", progress=False)
    moved = run_experiment(
        experiment(*SAR_RUN, "run.record_bt=true", swaps, base=sar), tmp_path / "moved", progress=False
    )
    for name in RESULTS[:-1]:  # config.yaml says record_bt: true
        assert (tmp_path / "plain" / name).read_bytes() == (tmp_path / "recorded" / name).read_bytes(), name
    n, ticks = moved.summary["agents"], moved.summary["ticks"]
    files = sorted(p.name for p in (tmp_path / "recorded" / BT).iterdir())
    assert files == sorted(f"agent_{i}.btlog" for i in range(n)) and not (tmp_path / "plain" / BT).exists()
    for name in files:
        data = (tmp_path / "recorded" / BT / name).read_bytes()
        assert data == (tmp_path / "moved" / BT / name).read_bytes(), f"{name} differs after swaps"
        xml, first, stamped = read_btlog(data)
        uids = {int(n.get("_uid")) for n in ET.fromstring(xml).iter() if n.get("_uid")}
        assert first == EPOCH_US and uids == set(range(1, len(uids) + 1))
        assert {uid for _, uid, _ in stamped} <= uids and {code for _, _, code in stamped} >= {1, 2}
        times = sorted({t for t, _, _ in stamped})
        assert times[0] == 0 and times[-1] == (ticks - 1) * 250_000  # every tick changes the root's status
        assert all(t % 250_000 == 0 for t in times)


def test_crafted_tree_change_samples_are_named():
    from swarmbed.wire.btlog import TreeChanges, decode_tree_changes, encode_tree_changes
    from swarmbed.wire.codec import pack
    from swarmbed.wire.errors import WireError

    boards = {"Main": {"count": 3, "half": 2.5, "word": "hi", "path": [1, None, "a"], "none": None}, "S::3": None}
    xml = '<root><A _uid="1"/><B _uid="2"/><C _uid="3"/></root>'
    good = TreeChanges(4, 1_000_000, [(1, 1), (3, 2)], xml, [(1, 1)], boards)
    assert decode_tree_changes(encode_tree_changes(good), n_nodes=3) == good
    # the tree a sample brings decides its size, whatever a uid in it claims (a gateway allocates by it)
    for tree, why in (
        ('<root><A _uid="50000000"/></root>', "at most 5 digits"),
        ('<root><A _uid="1"/><B _uid="9"/></root>', "not 1 to 2"),
        ('<root><A _uid="1"/><B _uid="1"/></root>', "not 1 to 2"),
        ('<root><A _uid="' + "7" * 5000 + '"/></root>', "at most 5 digits"),
        ('<root><A _uid="\u00b2"/></root>', "at most 5 digits"),
    ):
        with pytest.raises(WireError, match=re.escape(why)):
            decode_tree_changes(pack([4, 0, b"", tree, b"", {}]))
    with pytest.raises(WireError, match="no node 4"):  # statuses beyond the tree it comes with
        decode_tree_changes(pack([4, 0, b"", xml, b"\x04\x00\x01", {}]), n_nodes=9)
    crafted = {
        pack([4, 0, b"\x01\x00", None, b"", {}]): "changes must be whole 3-byte",
        pack([-1, 0, b"", None, b"", {}]): "tick must be a count",
        pack([4, True, b"", None, b"", {}]): "time_us must be a count",
        pack([4, 0, b"\x01\x00\x07", None, b"", {}]): "no node 1 with status 7",
        pack([4, 0, b"", None, b"\x09\x00\x01", {}]): "no node 9",
        pack([4, 0, b"", "import os", b"", {}]): "xml must be",
        pack({"tick": 4}): "not [tick, time_us, changes, xml, statuses, blackboards]",
        pack([4, 0, b"", None, b""]): "not [tick, time_us, changes, xml, statuses, blackboards]",
        pack([4, 0, b"", None, b"", [1]]): "blackboards must be a map",
        pack([4, 0, b"", None, b"", {b"Main": {}}]): "a blackboard's name must be text",
        pack([4, 0, b"", None, b"", {"Main": [1]}]): "blackboard 'Main' must be a map",
        pack([4, 0, b"", None, b"", {"Main": {"a": {"b": 1}}}]): "entry 'a' is not a number",
        pack([4, 0, b"", None, b"", {"Main": {"a": [[1]]}}]): "entry 'a' is not a number",
        pack([4, 0, b"", None, b"", {"Main": {"a": True}}]): "entry 'a' is not a number",
        pack([4, 0, b"", None, b"", {"Main": {"a": "z" * 5000}}]): "entry 'a' is not a number",
        pack([4, 0, b"", None, b"", {"Main": {"a": list(range(65))}}]): "entry 'a' is not a number",
        pack([4, 0, b"", None, b"", {"Main": {str(i): 1 for i in range(257)}}]): "at most 256 entries",
    }
    for data, why in crafted.items():
        with pytest.raises(WireError, match=re.escape(why)):
            decode_tree_changes(data, n_nodes=3)
