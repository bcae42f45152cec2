import csv
import json
import multiprocessing.process
import os
import signal
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import psutil
import pytest

from swarmbed import config as cfg
from swarmbed.wire.credentials import Identity, write_credentials

pytest_plugins = ("tests.netns",)  # the `lab` fixture: stand-in hosts in network namespaces

ROOT = Path(__file__).resolve().parent.parent
QUICKSTART = ROOT / "experiments" / "quickstart.yaml"
SAR_BASE = ROOT / "experiments" / "sar" / "_base.yaml"  # the search-and-rescue baseline


# A shell starts a background job with SIGINT ignored, and an ignored signal stays ignored across
# exec: the Ctrl-C tests would find every process they start deaf to it. Handle SIGINT here, so
# the processes the tests start get it at its default, as from a terminal.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def experiment(*overrides: str, base: Path = QUICKSTART) -> cfg.Experiment:
    return cfg.load(base, list(overrides))


RESULTS = ("summary.json", "timeseries.csv", "agents.csv", "network_ledger.csv", "config.yaml")


def reference_run(exp: cfg.Experiment, out_dir: Path):
    """The run a test holds a real one against ("watching, swapping, attacking, spreading over hosts
    changes no result"), stepped by the in-process engine: byte for byte the files of a real run of
    the same configuration (tests/test_engine.py), in a fraction of its time."""
    from swarmbed.launch.inprocess import run_in_process

    return run_in_process(exp, out_dir)


def sweep_in_process(spec: Path, out: Path, *extra: str):
    """A sweep file's runs on the in-process engine, two at once, and its table: for tests whose
    point is what is made of a sweep's results (tables, statistics, figures, hostile folders)."""
    from swarmbed.campaigns.sweep import load_sweep, run_sweep

    return run_sweep(load_sweep(spec, extra=list(extra)), out, jobs=2, progress=False, in_process=True)


def same_results(a: Path, b: Path, config: bool = True) -> None:
    """The result files of two runs are byte-identical (``config``: config.yaml too; not where the
    two runs were configured apart in a way that must not change a result, e.g. Zenoh's threads)."""
    for name in RESULTS if config else RESULTS[:-1]:
        assert (a / name).read_bytes() == (b / name).read_bytes(), f"{name} differs"


def under_way(run_dir: Path) -> bool:
    """Whether the run writing to ``run_dir`` has routed its first tick (the proxy logs it)."""
    try:
        return "tick 0 routed" in (run_dir / "logs" / "netem.log").read_text()
    except OSError:
        return False


def read_ledger(run_dir: Path) -> list[dict]:
    with open(run_dir / "network_ledger.csv") as f:
        return [
            {
                **r,
                "tick": int(r["tick"]),
                "sender": int(r["sender"]),
                "messages": int(r["messages"]),
                "bytes": int(r["bytes"]),
            }
            for r in csv.DictReader(f)
        ]


def ledger_outcomes(rows: list[dict]) -> dict[str, int]:
    out: dict[str, int] = defaultdict(int)
    for r in rows:
        out[r["outcome"]] += r["messages"]
    return dict(out)


@pytest.fixture(autouse=True)
def fast_lane_starts_no_process(request, monkeypatch):
    """A test of the fast lane (``-m "not slow"``) starts no process: one that does (a run, a sweep,
    a command) is marked slow, by its module in SLOW_MODULES or by ``@pytest.mark.slow`` itself."""
    if request.node.get_closest_marker("slow") is None:

        def refuse(*args, **kwargs):
            raise AssertionError(
                f"{request.node.nodeid} started a process but is not marked slow "
                "(tests/conftest.py SLOW_MODULES, or @pytest.mark.slow on the test)"
            )

        monkeypatch.setattr(subprocess.Popen, "_execute_child", refuse)
        monkeypatch.setattr(os, "fork", refuse)
        monkeypatch.setattr(os, "posix_spawn", refuse)
        monkeypatch.setattr(multiprocessing.process.BaseProcess, "start", refuse)
    yield


@pytest.fixture(autouse=True)
def no_orphans():
    """Every process a test starts must be gone when it ends."""
    yield
    me = psutil.Process()
    left = [
        (p, cmdline(p))
        for p in me.children(recursive=True)
        if p.is_running()
        and p.status() != psutil.STATUS_ZOMBIE
        # the standard library's helper for spawned pools: it lives as long as this process does
        and "multiprocessing.resource_tracker" not in cmdline(p)
    ]
    for p, _ in left:
        p.kill()
    assert not left, f"processes left behind: {[(p.pid, line[:200]) for p, line in left]}"


def cmdline(p: psutil.Process) -> str:
    """A process's command line, or "" once it is gone: a child listed a moment ago (the launcher's
    one-off ``git`` for provenance.json, say) may have exited before it is read."""
    try:
        return " ".join(p.cmdline())
    except (psutil.NoSuchProcess, psutil.ZombieProcess):
        return ""


class Operator:
    """An operator's credentials file, as ``swarmbed credentials FILE --user NAME`` makes it: admit
    ``identity`` to a run (``admit=[operator.identity]``), hand ``args`` to a client command."""

    def __init__(self, folder: Path) -> None:
        self.identity = Identity.new("tester", "operator")
        self.path = write_credentials(folder / "operator.json", self.identity)
        self.args = ["--credentials", str(self.path)]


@pytest.fixture
def operator(tmp_path) -> Operator:
    return Operator(tmp_path)


class SwapAsked:
    """``swarmbed swap`` run from another terminal once a run's members joined: ``on_ready`` starts
    it and holds the run until the coordinator queued the swap (or refused it), so a loaded machine
    cannot finish the run before the request arrives; ``wait()`` gives (returncode, stdout, stderr)."""

    def __init__(self, operator: Operator, agent: int, to: str) -> None:
        self.argv = ["--agent", str(agent), "--to", to, *operator.args]
        self.proc: subprocess.Popen | None = None
        self.first_line = ""

    def on_ready(self, keys, endpoint: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "swarmbed", "swap", "--connect", endpoint, "--run", keys.run_id, *self.argv],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        self.first_line = self.proc.stdout.readline()  # "... queued; ...", or "" once it exits refused

    def wait(self, timeout: float = 120) -> tuple[int, str, str]:
        assert self.proc is not None, "the run never called on_ready"
        out, err = self.proc.communicate(timeout=timeout)
        return self.proc.returncode, self.first_line + out, err


def whole_rows(path: Path) -> int:
    """The data rows of CSV file ``path``, asserting that none is torn: the file ends at a line end
    and every row has as many fields as the header (pandas would read a torn last row silently)."""
    import csv

    text = path.read_text()
    assert text.endswith("\n"), f"{path.name} ends in the middle of a row: {text[-40:]!r}"
    rows = list(csv.reader(text.splitlines()))
    assert rows and all(len(r) == len(rows[0]) for r in rows), f"{path.name} holds a row of another width"
    return len(rows) - 1


#: modules whose tests start real processes (runs, host daemons, browsers) and take seconds each:
#: marked ``slow``. ``pytest -m "not slow"`` is the fast lane for day-to-day work; CI runs everything.
SLOW_MODULES = frozenset(
    {
        "test_ros2_run",
        "test_envs",
        "test_access",
        "test_disk_full",
        "test_e2e",
        "test_examples",
        "test_failures",
        "test_forkserver",
        "test_hostile_folders",
        "test_hosts",
        "test_netem_e2e",
        "test_readme",
        "test_realtime",
        "test_recording",
        "test_report",
        "test_safe_writes",
        "test_sar_e2e",
        "test_soak",
        "test_swaps",
        "test_sweep",
        "test_sweep_executors",
        "test_tls",
        "test_watch",
    }
)


#: seconds each test file took in a recorded run (``pytest --record-durations``); the suite runs
#: the longest files first, so that on the workers no long file starts last (longest first is
#: what a greedy split of unequal jobs over workers wants)
FILE_DURATIONS = Path(__file__).with_name("file_durations.json")


def pytest_addoption(parser):
    parser.addoption(
        "--record-durations", action="store_true", help=f"write each test file's seconds to {FILE_DURATIONS.name}"
    )


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.module is not None and item.module.__name__.rsplit(".", 1)[-1] in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)
    seconds = json.loads(FILE_DURATIONS.read_text()) if FILE_DURATIONS.exists() else {}
    items.sort(key=lambda item: -seconds.get(item.nodeid.split("::", 1)[0], 0.0))  # stable within a file


_recorded: dict[str, float] = defaultdict(float)


def pytest_runtest_logreport(report):
    _recorded[report.nodeid.split("::", 1)[0]] += report.duration  # setup, call and teardown


def pytest_sessionfinish(session):
    """With ``--record-durations``, on the process that ran or gathered every test (not an xdist
    worker), write the seconds of each file."""
    if session.config.getoption("--record-durations") and not hasattr(session.config, "workerinput"):
        table = {name: round(seconds, 1) for name, seconds in sorted(_recorded.items(), key=lambda kv: -kv[1])}
        FILE_DURATIONS.write_text(json.dumps(table, indent=1) + "\n")
