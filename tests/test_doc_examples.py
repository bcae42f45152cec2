"""Every code example of the README and docs/ runs or checks clean, so none can go stale.

A ``python`` block is run as a reader would paste it, from the repository's root; a block the page
names a file for (```python file=NAME) belongs to its page's own test (test_extending,
test_ros2_run). A ``yaml`` block is what a reader adds to an experiment: a whole experiment file or
some of its sections, checked by ``swarmbed run --check`` over the quick start; a chaos file
(``events:``) is read by the soak's own loader."""

import re
import textwrap

import pytest
import yaml

from swarmbed.campaigns.chaos import load_chaos
from swarmbed.cli.main import main
from tests.conftest import ROOT

BLOCK = re.compile(r"^```(python|yaml)([^\n]*)\n(.*?)^```", flags=re.S | re.M)
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: blocks that need what this test cannot give them, each with why
NOT_HERE = {
    "placement:": "names the reader's own hosts; tests/test_hosts.py checks placement over real host daemons",
}


def _blocks(language: str) -> list[tuple[str, str]]:
    found = []
    for page in PAGES:
        for lang, info, body in BLOCK.findall(page.read_text()):
            if lang == language and "file=" not in info:
                found.append((f"{page.relative_to(ROOT)}:{body.splitlines()[0][:50]}", textwrap.dedent(body)))
    return found


PYTHON = _blocks("python")
YAML = [(where, body) for where, body in _blocks("yaml") if not any(body.startswith(k) for k in NOT_HERE)]


def test_the_docs_have_examples_of_both_kinds():
    assert len(PYTHON) >= 2 and len(YAML) >= 4, (PYTHON, YAML)


@pytest.mark.slow
@pytest.mark.parametrize("where, code", PYTHON, ids=[w for w, _ in PYTHON])
def test_a_python_example_runs(where, code, monkeypatch, tmp_path):
    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("TMPDIR", str(tmp_path))  # an example's run folder lands here
    exec(compile(code, where, "exec"), {"__name__": "__doc_example__"})


def _merged(base: dict, extra: dict) -> dict:
    out = dict(base)
    for key, value in extra.items():
        out[key] = _merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


@pytest.mark.parametrize("where, text", YAML, ids=[w for w, _ in YAML])
def test_a_yaml_example_checks_clean(where, text, tmp_path, capsys, monkeypatch):
    data = yaml.safe_load(text)
    if "events" in data:
        load_chaos(_write(tmp_path / "chaos.yaml", data))
        return
    if "scenario" in data and "kind" in data["scenario"] and ".py:" in str(data["scenario"]["kind"]):
        pytest.skip("a user's own plugin files: tests/test_extending.py runs this example")
    quickstart = yaml.safe_load((ROOT / "experiments" / "quickstart.yaml").read_text())
    if "obstacles" in data:  # walls in a map of their own size: the arena must hold them
        quickstart["scenario"].update(width=1000, height=1000)
    path = _write(tmp_path / "example.yaml", _merged(quickstart, data))
    monkeypatch.chdir(ROOT)
    rc = main(["run", str(path), "--check"])
    assert rc == 0, f"{where}\n{capsys.readouterr().err}"


def _write(path, data):
    path.write_text(yaml.safe_dump(data))
    return path
