"""Every ``swarmbed run`` and ``swarmbed sweep`` of a shipped experiment that the README, docs/ and the
experiment files show checks clean with ``--check`` (the plan and its estimate, no process
started): a renamed key, a moved file or a preset that went would leave a documented command that
fails, and this test names it."""

import re
import shlex

import pytest

from swarmbed.cli.main import main
from tests.conftest import ROOT

COMMAND = re.compile(r"swarmbed (run|sweep) (experiments/[\w./-]+\.yaml)([^`\n&|;#]*)")
#: flags whose value is kept (they change what is planned), and those dropped with their value
KEPT = {"--set", "--grid", "--runs", "--engine", "--seed"}
DROPPED = {"--out", "--listen", "--admit", "--foxglove", "--jobs", "--chaos", "--duration", "--executor"}


def _documented() -> list[tuple[str, str]]:
    """(where, command line) of every documented command over a shipped experiment, once each."""
    pages = [
        ROOT / "README.md",
        *sorted((ROOT / "docs").rglob("*.md")),
        *sorted((ROOT / "experiments").rglob("*.yaml")),
    ]
    found: dict[str, str] = {}
    for page in pages:
        for verb, path, rest in COMMAND.findall(page.read_text()):
            line = f"{verb} {path}{rest.rstrip().removesuffix(chr(92)).rstrip()}"
            if "$" in line or "<" in line or ".py:" in line:
                continue  # a shell loop's variable, a placeholder, a file of the reader's own
            found.setdefault(line, str(page.relative_to(ROOT)))
    return sorted((where, line) for line, where in found.items())


def _argv(line: str) -> list[str]:
    words = shlex.split(line)
    argv, k = words[:2], 2
    while k < len(words):
        word = words[k]
        if not word.startswith("--"):
            break  # the prose after a command written in a sentence
        flag = word.split("=", 1)[0]
        takes_value = "=" not in word and k + 1 < len(words) and not words[k + 1].startswith("--")
        if flag in KEPT:
            argv += words[k : k + 2] if takes_value else [word] if "=" in word else []  # cut by a line end: dropped
        elif flag not in DROPPED and flag not in ("--force", "--yes", "--slurm"):
            raise AssertionError(f"{line}: {word} is neither kept nor dropped by this test: say which")
        k += 2 if takes_value and (flag in KEPT or flag in DROPPED) else 1
    return [*argv, "--check", "--yes"] if argv[0] == "sweep" else [*argv, "--check"]


DOCUMENTED = _documented()


def test_the_docs_show_commands_over_shipped_experiments():
    assert len(DOCUMENTED) > 30, DOCUMENTED


@pytest.mark.parametrize("where, line", DOCUMENTED, ids=[line for _, line in DOCUMENTED])
def test_a_documented_command_checks_clean(where, line, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    rc = main(_argv(line))
    err = capsys.readouterr().err
    assert rc == 0, f"{where}: swarmbed {line}\n{err}"
