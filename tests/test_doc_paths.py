"""Every path a doc or a docstring names exists: a reader who follows ``swarmbed/launch/runner.py``
or ``experiments/sar/baseline.yaml`` finds it. Paths are read where they begin with a folder of
this repository (or of swarmbed/, which a reader would look for at the root); files a run, a sweep
or a user makes (``runs/``, ``logs/``, ``summary.json``) are not this repository's and are not read."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: the folders a path may begin with: the root's and swarmbed/'s
TOPS = {p.name for p in ROOT.iterdir() if p.is_dir() and not p.name.startswith(".")} | {
    p.name for p in (ROOT / "swarmbed").iterdir() if p.is_dir() and not p.name.startswith("__")
}
TOPS -= {"runs", "build", "__pycache__"}
#: a path: folder/.../name.ext, or folder/.../ beginning with one of TOPS (in a doc's backticks, a
#: link or a docstring)
PATH = re.compile(
    r"(?<![\w./~$<-])((?:[A-Za-z_][\w.-]*/)+(?:[\w.-]+\.(?:py|md|yaml|yml|xml|mmd|json|sh|toml|csv))?)(?![\w/])"
)
#: a file is checked wherever it points; these are the docs' stand-ins for a user's own files
PLACEHOLDERS = ("path/", "a/", "b/", "trees/main.xml")
#: paths in another project's repository, each named beside that project (checked)
OTHER_PROJECTS = {
    "docs/design.md": "rmw_zenoh's",
    "plugins/cbba/cbba.py": "SPACE's code",
    "plugins/greedy/greedy.py": "SPACE's code",
}


def _docs() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def _sources() -> list[Path]:
    folders = [ROOT / n for n in ("swarmbed", "coordinator", "agent_runtime", "netem", "plugins", "benchmarks")]
    return [p for folder in folders for p in sorted(folder.rglob("*.py"))]


def _docstrings(path: Path) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                found.append((node.body[0].lineno, doc))
    return found


def _missing(text: str, base: Path) -> list[str]:
    """The paths in ``text`` that begin with a folder of the repository and do not exist (from the
    root, or from ``base`` for a doc's relative link)."""
    missing = []
    for match in PATH.finditer(text):
        path = match.group(1)
        if path.endswith("/") and path.split("/")[0] not in TOPS:
            continue  # a folder of a run, a sweep or a user's
        if path.startswith(PLACEHOLDERS) and not path.endswith(".csv") or path.split("/")[0] in ("runs", "logs"):
            continue
        if path in OTHER_PROJECTS and OTHER_PROJECTS[path] in text[max(0, match.start() - 60) : match.start()]:
            continue
        if not ((ROOT / path).exists() or (base / path).exists()):
            missing.append(path)
    return missing


def test_every_path_a_doc_names_exists():
    problems = [f"{doc.relative_to(ROOT)}: {path}" for doc in _docs() for path in _missing(doc.read_text(), doc.parent)]
    assert not problems, "\n".join(sorted(set(problems)))


def test_every_path_a_docstring_names_exists():
    problems = [
        f"{source.relative_to(ROOT)}:{line}: {path}"
        for source in _sources()
        for line, doc in _docstrings(source)
        for path in _missing(doc, source.parent)
    ]
    assert not problems, "\n".join(sorted(set(problems)))
