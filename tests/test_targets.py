"""Plugin files named by path: one module per file's contents, whatever folder it sits in."""

import subprocess
import sys
import textwrap

import pytest

from swarmbed.extension.allocator import Allocator
from swarmbed.wire.state import pack_state, unpack_state
from swarmbed.wire.targets import load_target

PLUGIN = """
from dataclasses import dataclass

from swarmbed.extension.allocator import Allocator
from swarmbed.wire.state import state_type


@state_type
@dataclass
class Memory:
    seen: int


class Picker(Allocator):
    FLAVOUR = {flavour!r}
"""


def _write(folder, flavour):
    folder.mkdir()
    path = folder / "picker.py"
    path.write_text(PLUGIN.format(flavour=flavour))
    return path


def test_two_files_of_one_name_stay_two_plugins(tmp_path):
    """A sweep worker hosting runs of a/picker.py and b/picker.py must run each its own file."""
    a = load_target(f"{_write(tmp_path / 'a', 'a')}:Picker", Allocator)
    b = load_target(f"{_write(tmp_path / 'b', 'b')}:Picker", Allocator)
    assert (a.FLAVOUR, b.FLAVOUR) == ("a", "b")
    assert a.__module__ != b.__module__


@pytest.mark.slow  # starts processes
def test_a_copied_file_restores_a_snapshot_made_from_the_original(tmp_path):
    """Another host loads its own copy of the file: same bytes, same module name, so a snapshot's
    type names resolve there (checked in a fresh interpreter standing in for that host)."""
    original = _write(tmp_path / "here", "same")
    cls = load_target(f"{original}:Picker", Allocator)
    memory = sys.modules[cls.__module__].Memory(seen=7)
    blob = tmp_path / "snapshot.bin"
    blob.write_bytes(pack_state({"memory": memory}))
    copy = _write(tmp_path / "there", "same")
    code = textwrap.dedent(f"""
        from pathlib import Path
        from swarmbed.extension.allocator import Allocator
        from swarmbed.wire.state import unpack_state
        from swarmbed.wire.targets import load_target
        load_target({str(copy)!r} + ":Picker", Allocator)
        print(unpack_state(Path({str(blob)!r}).read_bytes())["memory"].seen)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "7"
    assert unpack_state(blob.read_bytes())["memory"] == memory


def test_an_agent_refuses_a_plugin_file_that_differs_from_the_one_the_launcher_checked(tmp_path):
    """A host daemon's agent resolves ``file.py:Class`` on its own machine: the spec carries the
    file's digest as the launcher read it, and another file under that path is refused."""
    from swarmbed import config as cfg
    from swarmbed.agent_runtime.runtime import AgentRuntime
    from swarmbed.schema.experiment import agent_spec
    from swarmbed.wire.targets import TargetError
    from tests.conftest import experiment

    plugin = tmp_path / "mine.py"
    plugin.write_text(
        "from swarmbed.plugins.fcg import FirstClaimedGreedy\n\nclass Mine(FirstClaimedGreedy):\n    pass\n"
    )
    exp = experiment(f"allocator.name={plugin}:Mine", "agents.count=2")
    spec = agent_spec(exp, cfg.resolve_experiment(exp).targets)
    assert list(spec.targets.digests) == [str(plugin)]
    AgentRuntime(spec, 0)  # the file the launcher checked
    plugin.write_text(plugin.read_text() + "\nFLAVOUR = 'another'\n")  # the same path, other bytes
    with pytest.raises(TargetError, match="not the file the launcher checked"):
        AgentRuntime(spec, 1)
