"""docs/ARCHITECTURE.md's picture is the code's: its diagram of the packages draws exactly the
imports that no longer path already implies (the transitive reduction of the real import graph:
an arrow with no import behind it fails, and so does an import the picture cannot reach), and its
folder table lists, for each package, the packages it really imports.

``python tests/test_architecture.py`` prints both as the page should hold them."""

import ast
import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "ARCHITECTURE.md"


def packages() -> dict[str, Path]:
    """Every first-level part of ``swarmbed``: the mapped folders at the root, swarmbed/'s subpackages
    and its top-level modules (``api``, ``config``)."""
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = {name.split(".")[1]: ROOT / folder for name, folder in setuptools["package-dir"].items() if "." in name}
    for path in sorted((ROOT / "swarmbed").iterdir()):
        if path.is_dir() and (path / "__init__.py").exists():
            found[path.name] = path
        elif path.suffix == ".py" and not path.name.startswith("__"):
            found[path.stem] = path
    return found


def _imported(path: Path):
    """The modules ``path`` imports, at any depth, but under ``if TYPE_CHECKING:``."""
    tree = ast.parse(path.read_text())
    typing_only = {
        id(inner)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
        for inner in ast.walk(node)
    }
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield from (f"swarmbed.{a.name}" for a in node.names) if node.module == "swarmbed" else [node.module]
        elif isinstance(node, ast.Import):
            yield from (a.name for a in node.names)


def import_graph() -> dict[str, set[str]]:
    """package -> the other packages its modules import."""
    found = packages()
    graph: dict[str, set[str]] = {}
    for name, where in found.items():
        sources = [where] if where.is_file() else sorted(where.rglob("*.py"))
        graph[name] = {
            module.split(".")[1]
            for source in sources
            for module in _imported(source)
            if module.startswith("swarmbed.") and module.split(".")[1] in found and module.split(".")[1] != name
        }
    return graph


def reduction(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    """The arrows of ``graph`` (acyclic) that no longer path implies."""

    def reaches(start: str, goal: str, without: tuple[str, str]) -> bool:
        stack, seen = [b for b in graph[start] if (start, b) != without], set()
        while stack:
            node = stack.pop()
            if node == goal:
                return True
            if node not in seen:
                seen.add(node)
                stack.extend(graph[node])
        return False

    return {(a, b) for a, targets in graph.items() for b in targets if not reaches(a, b, (a, b))}


def drawn_arrows() -> set[tuple[str, str]]:
    block = PAGE.read_text().split("```mermaid\n", 1)[1].split("```", 1)[0]
    packages_part = block.split("subgraph packages", 1)[1]
    arrows = set()
    for line in packages_part.splitlines():
        match = re.fullmatch(r"\s*(\w+) --> (\w+)\s*", line)
        if match:
            arrows.add((match.group(1), match.group(2)))
    return arrows


def table_imports() -> dict[str, set[str]]:
    """package -> what the folder table's last column says it imports."""
    rows = {}
    for line in PAGE.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 4 and cells[1].startswith("`swarmbed."):
            name = cells[1].strip("`").split(".")[1]
            rows[name] = set(re.findall(r"`(\w+)`", cells[3]))
    return rows


def test_every_arrow_is_an_import_and_every_import_is_reached():
    expected, drawn = reduction(import_graph()), drawn_arrows()
    assert drawn, "docs/ARCHITECTURE.md: no arrows in the packages diagram"
    assert not drawn - expected, f"arrows with no import behind them (or implied by others): {sorted(drawn - expected)}"
    assert not expected - drawn, f"imports the picture lacks: {sorted(expected - drawn)}"


def test_the_folder_table_says_what_each_package_imports():
    graph, table = import_graph(), table_imports()
    assert set(table) == set(graph), f"packages the table lacks or invents: {sorted(set(table) ^ set(graph))}"
    wrong = {name: (sorted(table[name]), sorted(graph[name])) for name in graph if table[name] != graph[name]}
    assert not wrong, f"the table's imports against the code's (package: table, code): {wrong}"


if __name__ == "__main__":
    graph = import_graph()
    for a, b in sorted(reduction(graph)):
        print(f"    {a} --> {b}")
    for name in sorted(graph):
        print(name, ", ".join(f"`{n}`" for n in sorted(graph[name])) or "nothing of swarmbed")
