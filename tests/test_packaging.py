"""The install layout: the mission's folders at the root and swarmbed/ install as one ``swarmbed.*``
namespace, every package folder is listed, no two modules share a name, and the layers import only
downward."""

import ast
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _setuptools() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def _folder_of(package: str, package_dir: dict[str, str]) -> Path:
    """Where ``package`` lives in the checkout, through the longest mapped parent."""
    parts = package.split(".")
    for cut in range(len(parts), 0, -1):
        mapped = package_dir.get(".".join(parts[:cut]))
        if mapped is not None:
            return ROOT / mapped / Path(*parts[cut:])
    raise AssertionError(f"{package} has no package-dir mapping")


def test_every_package_folder_is_installed():
    st = _setuptools()
    listed, mapping = set(st["packages"]), st["package-dir"]
    for pkg in listed:
        assert _folder_of(pkg, mapping).is_dir(), f"{pkg} is listed but {_folder_of(pkg, mapping)} is missing"
    for top, folder in mapping.items():
        for d in (ROOT / folder).rglob("*"):
            if (
                d.is_dir()
                and d.name != "__pycache__"
                and (any(d.glob("*.py")) or any(d.glob("*.xml")) or any(d.glob("*.yaml")))
            ):
                pkg = ".".join([top, *d.relative_to(ROOT / folder).parts])
                assert pkg in listed, f"{d.relative_to(ROOT)} holds files but {pkg} is not in pyproject's packages"


def test_no_top_level_names_but_swarmbed():
    assert {p.split(".")[0] for p in _setuptools()["packages"]} == {"swarmbed"}


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
    return names


def test_benchmarks_import_the_installed_package():
    for path in (ROOT / "benchmarks").glob("*.py"):
        assert "sys.path.insert" not in path.read_text(), f"{path.name} patches sys.path"


@pytest.mark.slow  # starts processes
def test_import_directions_hold():
    """The layers and independence rules of pyproject's ``[tool.importlinter]`` (run by CI too).
    Slow: import-linter runs on the installed layout that ``.ci/installed-view`` builds, a process."""
    run = subprocess.run([str(ROOT / ".ci" / "importlint")], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert "0 broken" in run.stdout


@pytest.mark.slow  # starts processes
def test_the_proxy_process_loads_no_plugin_and_no_tree_engine():
    code = "import sys, swarmbed.netem.proxy; print('\\n'.join(m for m in sys.modules if m.startswith('swarmbed.')))"
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert "swarmbed.netem.proxy" in loaded
    assert not [
        m
        for m in loaded
        if m.startswith(
            (
                "swarmbed.plugins",
                "swarmbed.experiments",
                "swarmbed.scenarios",
                "swarmbed.agent_runtime",
                "swarmbed.bt",
                "swarmbed.coordinator",
            )
        )
    ], loaded


@pytest.mark.slow  # starts processes
def test_agents_and_the_proxy_import_no_analysis_library():
    """What the fork server preloads for every agent (the agent runtime and every shipped
    allocator) and the proxy process stay lean: none of the launcher's and the reports'
    libraries (each would be held by hundreds of agent processes)."""
    heavy = ("pandas", "scipy", "matplotlib", "plotly", "pyarrow", "rich", "tqdm", "psutil", "yaml")
    code = (
        "import sys; from swarmbed.launch.forkserver import _preload; _preload(); "
        "import swarmbed.netem.proxy; print('\\n'.join(sys.modules))"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = set(run.stdout.split())
    assert "swarmbed.agent_runtime.process" in loaded and "swarmbed.plugins.cbba" in loaded
    assert not [m for m in heavy if m in loaded], sorted(m for m in heavy if m in loaded)


def test_experiments_holds_experiment_files_and_no_code():
    """experiments/ is data: experiment files and maps, and the empty package markers that ship
    them; the application lives in its own packages (cli, campaigns, hosts, launch, results, checks)."""
    folder = ROOT / "experiments"
    code = [p for p in folder.rglob("*.py") if p.name != "__init__.py"]
    assert not code, code
    for marker in folder.rglob("__init__.py"):
        tree = ast.parse(marker.read_text())
        assert all(isinstance(node, ast.Expr) for node in tree.body), f"{marker} holds more than a docstring"
    assert list(folder.rglob("*.yaml")), "no experiment files"


def test_no_two_modules_share_a_file_name():
    """A traceback's file name says where it is, and one concept has one name: no two installed
    modules share a file name (the dunder entries ``__init__`` and ``__main__`` aside)."""
    by_name: dict[str, list[str]] = {}
    setuptools = _setuptools()
    for package in setuptools["packages"]:
        folder = _folder_of(package, setuptools["package-dir"])
        for path in folder.glob("*.py"):
            if not path.name.startswith("__"):
                by_name.setdefault(path.name, []).append(f"{package}.{path.stem}")
    shared = {name: where for name, where in by_name.items() if len(where) > 1}
    assert not shared, shared


#: what the repository's root holds: the mission's folders (the process roles, the plugins, the
#: experiment files), the tests, docs and benchmarks, and swarmbed/ for every other package
ROOT_FOLDERS = {
    "coordinator",
    "agent_runtime",
    "netem",
    "plugins",
    "experiments",
    "tests",
    "docs",
    "benchmarks",
    "swarmbed",
}


def test_the_root_shows_the_mission_and_everything_else_is_in_swarmbed():
    made_here = {"runs", "build", "__pycache__"}  # what runs, builds and Python leave (.gitignore)
    folders = {
        p.name
        for p in ROOT.iterdir()
        if p.is_dir() and not p.name.startswith(".") and p.name not in made_here and not p.name.endswith(".egg-info")
    }
    assert folders == ROOT_FOLDERS, f"the root's folders: {sorted(folders)}"
    mapped = set(_setuptools()["package-dir"].values())
    assert mapped == {"swarmbed", "coordinator", "agent_runtime", "netem", "plugins", "experiments"}, mapped


@pytest.mark.slow  # starts processes
def test_a_small_in_process_run_imports_no_analysis_library(tmp_path):
    """Issue 84 item 3: pandas (0.5 s) and SciPy's KD-tree (about 1 s) stay off a run's path."""
    code = (
        "import sys; from swarmbed.cli.main import main; "
        f"main(['run', {str(ROOT / 'experiments' / 'quickstart.yaml')!r}, '--engine', 'inprocess', "
        f"'--out', {str(tmp_path / 'run')!r}, '--no-progress']); "
        "print('imported:', *(m for m in ('pandas', 'scipy', 'matplotlib', 'plotly') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip().splitlines()[-1] == "imported:", done.stdout[-500:]


def test_the_kernels_are_compiled_where_a_c_compiler_is():
    """setup.py builds the kernels as optional (an install without a compiler still works), so a
    build that broke would pass unseen; where a C compiler is found, the compiled module must load."""
    import os
    import sysconfig

    compiler = (os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc").split()[0]
    if not shutil.which(compiler):
        pytest.skip(f"no C compiler ({compiler}) on this machine: the kernels run as their Python reference")
    from swarmbed.kernels import _compiled  # noqa: F401 (an ImportError here is the failure)


@pytest.mark.slow  # pip builds the package (about 15 s)
def test_an_install_without_a_c_compiler_goes_on_without_the_kernels(tmp_path):
    """A machine whose C compiler fails still installs the package (CC=/bin/false), without the
    compiled module; what it installs runs on the Python reference."""
    import os

    pytest.importorskip("Cython", reason="the test extra's Cython builds the package without fetching it")
    # the sources without what a build left: a working tree's build/ folder or in-place module (an
    # editable install's) would hand pip a compiled module that no compiler made here
    source = tmp_path / "source"
    left = shutil.ignore_patterns("build", "*.so", "_compiled.c", "*.egg-info", ".git", ".venv", "__pycache__")
    shutil.copytree(ROOT, source, ignore=left)
    target = tmp_path / "site"
    env = {**os.environ, "CC": "/bin/false"}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "--no-compile",
            "--target",
            str(target),
            str(source),
        ],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    kernels = target / "swarmbed" / "kernels"
    assert (kernels / "reference.py").exists() and not list(kernels.glob("_compiled*.so"))
    probe = "import swarmbed.kernels as k; print(k.COMPILED, k.fallback_notice() is not None)"
    shown = subprocess.run(
        [sys.executable, "-P", "-c", probe],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(target)},
        check=True,
    )
    assert shown.stdout.split() == ["False", "True"]
