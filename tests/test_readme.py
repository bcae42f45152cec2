"""The docs' measured facts come from real runs (docs/scripts/readme_facts.py): they cannot drift; README and
docs/ARCHITECTURE.md name every benchmark."""

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
    assert stated["cbba10"]["payload"] == c["payload"], "docs/results.md: run docs/scripts/readme_facts.py --write"
    for label in ("quickstart", "cbba10"):
        assert abs(stated[label]["tcp"] - measured[label]["tcp"]) <= 0.1 * measured[label]["tcp"], (label, measured)


def test_the_readme_names_every_benchmark_in_both_its_lists():
    """README's Benchmarks section and the folder table of docs/ARCHITECTURE.md name every script in
    benchmarks/."""
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    readme = (root / "README.md").read_text()
    section = readme.split("## Benchmarks", 1)[1].split("\n## ", 1)[0]
    folders = (root / "docs" / "ARCHITECTURE.md").read_text()
    row = next(line for line in folders.splitlines() if line.startswith("| `benchmarks/` |"))
    for script in sorted(p.name for p in (root / "benchmarks").glob("*.py") if p.name != "__init__.py"):
        assert f"`{script}`" in section, f"{script} missing from the Benchmarks section"
        assert f"`{script}`" in row, f"{script} missing from the folder table of docs/ARCHITECTURE.md"
