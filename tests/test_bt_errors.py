"""Trees that cannot load say which file, line and node; the palette describes our nodes."""

import xml.etree.ElementTree as ET

import pytest

from swarmbed.bt import BTError, load_tree
from swarmbed.cli.main import main
from swarmbed.extension.space_nodes import SPACE_TREE, space_registry


def load(text):
    return load_tree("trees/t.xml", space_registry(), text=text)


@pytest.mark.parametrize(
    "body, needle",
    [
        (
            '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence></BehaviorTree></root>',
            "trees/t.xml:1: malformed XML",
        ),
        (
            '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n  <Teleport/>\n</BehaviorTree></root>',
            "trees/t.xml:3 <Teleport>: unknown node type 'Teleport'",
        ),
        (
            '<root BTCPP_format="4">\n<BehaviorTree ID="M">\n<Repeat name="r"><AlwaysSuccess/></Repeat>\n'
            "</BehaviorTree></root>",
            "trees/t.xml:3 <Repeat name='r'>: required port 'num_cycles' is missing",
        ),
        (
            '<root BTCPP_format="4"><BehaviorTree ID="M"><ExplorationNode duraton="5"/></BehaviorTree></root>',
            "unknown port 'duraton'",
        ),
        ('<root BTCPP_format="3"><BehaviorTree ID="M"><AlwaysSuccess/></BehaviorTree></root>', 'BTCPP_format="4"'),
        ('<root BTCPP_format="4"><BehaviorTree ID="M"><Inverter/></BehaviorTree></root>', "exactly one child"),
        ('<root BTCPP_format="4"><BehaviorTree ID="M"><SubTree ID="M"/></BehaviorTree></root>', "includes itself"),
        ('<root BTCPP_format="4"><BehaviorTree ID="M"><SubTree ID="Nope"/></BehaviorTree></root>', "no <BehaviorTree"),
    ],
)
def test_load_errors_name_file_line_and_node(body, needle):
    with pytest.raises(BTError) as info:
        load(body)
    assert needle in str(info.value)


def test_default_tree_loads_and_uses_the_space_nodes():
    tree = load_tree(SPACE_TREE, space_registry())
    ids = {type(n).ID for n in tree.nodes}
    assert {"LocalSensingNode", "DecisionMakingNode", "TaskExecutingNode", "ExplorationNode"} <= ids


def test_palette_lists_custom_nodes_with_ports(capsys):
    assert main(["bt", "palette", "--scenario", "mtsr", "--allocator", "fcg"]) == 0
    root = ET.fromstring(capsys.readouterr().out.split("\n", 1)[1])
    model = root.find("TreeNodesModel")
    nodes = {el.get("ID"): el for el in model}
    assert set(nodes) == {"LocalSensingNode", "DecisionMakingNode", "TaskExecutingNode", "ExplorationNode"}
    ports = {p.get("name"): p.get("default") for p in nodes["ExplorationNode"]}
    assert ports == {"duration": "{exploration_duration}", "reach": "{arrival_radius}"}
    assert "Sequence" not in nodes  # Groot2 knows the built-ins


def test_bt_check_command_reports_every_bad_file(tmp_path, capsys):
    bad = tmp_path / "bad.xml"
    bad.write_text('<root BTCPP_format="4"><BehaviorTree ID="M"><Nope/></BehaviorTree></root>')
    worse = tmp_path / "worse.xml"
    worse.write_text('<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence>')
    assert main(["bt", "check", str(bad), str(SPACE_TREE), str(worse)]) == 2
    out, err = capsys.readouterr()
    assert f"{bad}:1 <Nope>: unknown node type" in err and f"{worse}:1: malformed XML" in err
    assert f"{SPACE_TREE}: ok" in out


def test_palette_of_an_allocator_has_the_nodes_its_trees_use(capsys):
    assert main(["bt", "palette", "--scenario", "sar", "--allocator", "cbba-etc"]) == 0
    ids = {el.get("ID") for el in ET.fromstring(capsys.readouterr().out.split("\n", 1)[1]).find("TreeNodesModel")}
    assert {"IsTargetValid", "ExplorationNode"} <= ids and "DecisionMakingNode" in ids
    assert main(["bt", "palette"]) == 0  # every registered scenario and allocator
    every = {el.get("ID") for el in ET.fromstring(capsys.readouterr().out.split("\n", 1)[1]).find("TreeNodesModel")}
    assert ids <= every


def test_check_allocator_command(capsys, tmp_path):
    assert main(["check-allocator", "fcg", "--set", "mode=Random"]) == 0
    assert capsys.readouterr().out.count("PASS") == 6  # check_snapshot and check_team_tasks among them
    bad = tmp_path / "bad.py"
    bad.write_text(
        "from swarmbed.extension import Allocator\n"
        "class Liar(Allocator):\n"
        "    def decide(self, view):\n"
        "        return 10**6\n"
    )
    assert main(["check-allocator", f"{bad}:Liar"]) == 1
    assert "does not exist" in capsys.readouterr().out
