"""The README's measured facts come from real runs (docs/scripts/readme_facts.py): they cannot drift."""

import importlib.util

from tests.conftest import ROOT


def _script():
    spec = importlib.util.spec_from_file_location("readme_facts", ROOT / "docs" / "scripts" / "readme_facts.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_readme_states_what_the_quickstart_sends(tmp_path):
    facts = _script()
    measured, stated = facts.measure(tmp_path), facts.stated(facts.README.read_text())
    q, c = measured["quickstart"], measured["cbba10"]
    # reproducible: exactly; measured on the wire: within a tenth (the run's timing moves them a little)
    assert stated["quickstart"]["ticks"] == q["ticks"] and stated["quickstart"]["payload"] == q["payload"]
    assert stated["cbba10"]["payload"] == c["payload"], "README.md: run docs/scripts/readme_facts.py --write"
    for label in ("quickstart", "cbba10"):
        assert abs(stated[label]["tcp"] - measured[label]["tcp"]) <= 0.1 * measured[label]["tcp"], (label, measured)
