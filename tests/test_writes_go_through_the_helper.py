"""Nothing in the package writes, renames or removes a file but through ``swarmbed.files.safefiles``:
this walks every module's syntax tree and fails on a direct ``open(..., "w"/"a"/"x")``,
``Path.write_*``, ``mkdir``, ``unlink``, ``rename``/``replace``, ``rmdir``, ``touch``, an ``os``
or ``shutil`` call that changes the file system, or a library's writer (``to_csv(path)``,
``savefig``, ``write_html``, ...) handed anything but a path the helper's ``replacing`` gave.
The allow-list below says, for each exception, why it is not a file below a folder a user named."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HELPER = ROOT / "swarmbed" / "files" / "safefiles.py"

#: "path:function" -> why a direct call there is not a write below a folder someone else may have made
ALLOWED = {
    "swarmbed/launch/launcher.py:reset_peak_rss": "/proc/self/clear_refs, the kernel's own file of this process",
    "swarmbed/hosts/slurm_lab.py:_munge": "/run/munge, the system's folder for munged (the lab runs as root)",
    "netem/ledger.py:__init__": "pyarrow's ParquetWriter is handed a file object safefiles.open_fresh made, not a path",
}

OS_WRITES = {
    "remove",
    "unlink",
    "rename",
    "replace",
    "renames",
    "mkdir",
    "makedirs",
    "rmdir",
    "removedirs",
    "link",
    "symlink",
    "truncate",
    "chmod",
    "mkfifo",
}
SHUTIL_WRITES = {"rmtree", "copy", "copy2", "copyfile", "copytree", "move", "copyfileobj"}
PATH_WRITES = {"write_text", "write_bytes", "mkdir", "unlink", "rmdir", "touch", "rename", "symlink_to", "hardlink_to"}
#: a library handed a path to write (pandas, matplotlib, plotly, pyarrow); ``save`` is left out: ours are named so too
LIBRARY_WRITERS = {
    "to_csv",
    "to_parquet",
    "to_json",
    "to_markdown",
    "savefig",
    "write_html",
    "write_image",
    "ParquetWriter",
}


def _mode(call: ast.Call) -> str:
    mode = call.args[1] if len(call.args) > 1 else next((k.value for k in call.keywords if k.arg == "mode"), None)
    return mode.value if isinstance(mode, ast.Constant) and isinstance(mode.value, str) else ""


def _pinned_names(tree: ast.AST) -> set[str]:
    """Names bound by ``with ...replacing(...) as NAME``: paths the helper gave."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.With):
            for item in node.items:
                call = item.context_expr
                if (
                    isinstance(call, ast.Call)
                    and isinstance(call.func, ast.Attribute)
                    and call.func.attr == "replacing"
                    and isinstance(item.optional_vars, ast.Name)
                ):
                    names.add(item.optional_vars.id)
    return names


def _problem(call: ast.Call, pinned: set[str]) -> str | None:
    func = call.func
    if isinstance(func, ast.Name) and func.id == "open" and any(c in _mode(call) for c in "wax+"):
        target = call.args[0] if call.args else None
        if isinstance(target, ast.Constant) and isinstance(target.value, int):
            return None  # a descriptor (stdout), not a path
        if isinstance(target, ast.Name) and target.id in pinned:
            return None  # the path the helper's replacing() gave
        return f"open(..., {_mode(call)!r})"
    if not isinstance(func, ast.Attribute):
        return None
    owner = func.value.id if isinstance(func.value, ast.Name) else ""
    if owner == "safefiles":  # the helper itself
        return None
    if owner == "os" and func.attr in OS_WRITES:
        return f"os.{func.attr}"
    if owner == "os" and func.attr == "open" and len(call.args) > 1:
        flags = ast.unparse(call.args[1])
        if any(f in flags for f in ("O_CREAT", "O_TRUNC", "O_APPEND", "O_RDWR")) and "devnull" not in ast.unparse(
            call.args[0]
        ):
            return f"os.open(..., {flags[:40]})"
    if owner == "shutil" and func.attr in SHUTIL_WRITES:
        return f"shutil.{func.attr}"
    if func.attr in PATH_WRITES and owner not in ("os", "shutil"):
        return f".{func.attr}()"
    if func.attr == "replace" and len(call.args) == 1 and not call.keywords:  # Path.replace; str.replace takes two
        return ".replace(path)"
    if func.attr in LIBRARY_WRITERS and call.args:
        target = call.args[0]
        if not (isinstance(target, ast.Name) and target.id in pinned):
            return f".{func.attr}({ast.unparse(target)[:40]})"
    return None


def _sources() -> list[Path]:
    folders = [ROOT / n for n in ("swarmbed", "coordinator", "agent_runtime", "netem", "plugins")]
    return sorted(p for folder in folders for p in folder.rglob("*.py") if p != HELPER)


def _calls(tree: ast.AST):
    """(innermost function's name, call) for every call in ``tree``."""

    def walk(node: ast.AST, where: str):
        for child in ast.iter_child_nodes(node):
            inner = child.name if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) else where
            if isinstance(child, ast.Call):
                yield where, child
            yield from walk(child, inner)

    yield from walk(tree, "<module>")


def direct_writes() -> tuple[list[str], set[str]]:
    """The direct writes outside the allow-list, and the allow-list's places that still hold one."""
    found, allowed_seen = [], set()
    for path in _sources():
        tree = ast.parse(path.read_text())
        pinned = _pinned_names(tree)
        for function, call in _calls(tree):
            why = _problem(call, pinned)
            where = f"{path.relative_to(ROOT)}:{function}"
            if why and where in ALLOWED:
                allowed_seen.add(where)
            elif why:
                found.append(f"{path.relative_to(ROOT)}:{call.lineno} ({function}): {why}")
    return sorted(found), allowed_seen


def test_nothing_writes_renames_or_removes_a_file_but_through_the_helper():
    found, _ = direct_writes()
    assert not found, "write through swarmbed.files.safefiles instead:\n" + "\n".join(found)


def test_every_allowed_place_still_writes_directly():
    """An allow-list entry whose direct call went away is taken off the list."""
    _, seen = direct_writes()
    assert set(ALLOWED) <= seen, sorted(set(ALLOWED) - seen)


if __name__ == "__main__":
    print("\n".join(direct_writes()[0]))
