"""The public API (``import swarmbed``): an experiment loaded with overrides, run on either engine
with the same result files, read back; an allocator registered under a name of the caller's; and the
processes of a run never load the API's imports."""

import subprocess
import sys

import pytest

import swarmbed
from swarmbed.records.run_folder import REPRODUCIBLE
from tests.conftest import ROOT

QUICKSTART = ROOT / "experiments" / "quickstart.yaml"


def test_load_applies_overrides_and_seed_and_names_a_bad_key():
    exp = swarmbed.load(QUICKSTART, overrides=["agents.count=7"], seed=4)
    assert exp.agents.count == 7 and exp.run.seed == 4
    with pytest.raises(swarmbed.ConfigError, match="agents.count"):
        swarmbed.load(QUICKSTART, overrides=["agents.count=-1"])


def test_a_registered_name_runs_as_the_class_it_names(tmp_path):
    swarmbed.register_allocator("api_test_nearest", "swarmbed.plugins.nearest:NearestTask")
    mine = swarmbed.load(QUICKSTART, overrides=["allocator.name=api_test_nearest", "run.duration=150"])
    builtin = swarmbed.load(QUICKSTART, overrides=["allocator.name=nearest", "run.duration=150"])
    a = swarmbed.run(mine, tmp_path / "mine", engine="inprocess")
    b = swarmbed.run(builtin, tmp_path / "builtin", engine="inprocess")
    assert a.summary.allocator == "api_test_nearest"
    assert a.folder.timeseries().equals(b.folder.timeseries())
    with pytest.raises(swarmbed.PluginError):
        swarmbed.register_allocator("api_test_nearest", "swarmbed.plugins.fcg:FirstClaimedGreedy")


def test_an_unknown_engine_is_refused(tmp_path):
    with pytest.raises(ValueError, match="engine"):
        swarmbed.run(swarmbed.load(QUICKSTART), tmp_path, engine="threads")  # type: ignore[arg-type]


@pytest.mark.slow  # starts the run's processes
def test_both_engines_write_the_same_files_and_open_run_reads_them(tmp_path):
    exp = swarmbed.load(QUICKSTART, overrides=["run.duration=300"], seed=2)
    inproc = swarmbed.run(exp, tmp_path / "inprocess", engine="inprocess")
    procs = swarmbed.run(exp, tmp_path / "processes", engine="processes")
    for name in REPRODUCIBLE:
        if (tmp_path / "inprocess" / name).exists():
            assert (tmp_path / "inprocess" / name).read_bytes() == (tmp_path / "processes" / name).read_bytes(), name
    again = swarmbed.open_run(tmp_path / "processes")
    assert again.summary.document == procs.summary.document == inproc.summary.document
    assert len(again.folder.ledger()) > 0


@pytest.mark.slow  # starts an interpreter
def test_importing_a_role_loads_no_launcher():
    code = "import sys, swarmbed.netem.proxy, swarmbed.agent_runtime.process; print(' '.join(sys.modules))"
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert not [m for m in loaded if m.startswith(("swarmbed.api", "swarmbed.launch", "swarmbed.config"))], loaded


def test_the_package_root_hands_on_exactly_the_api():
    """The root lists the API's names without importing it (its processes stay lean): the two lists
    are one, and each name reaches the object the API module holds."""
    from swarmbed import api

    assert swarmbed.__all__ == api.__all__
    for name in api.__all__:
        assert getattr(swarmbed, name) is getattr(api, name)
