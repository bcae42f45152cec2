"""Nothing a run computes changes: every shipped experiment, run by two installs, gives byte-identical
result files.

    python benchmarks/same_results.py --old /tmp/old/bin/python --new .venv/bin/python
    python benchmarks/same_results.py --old ... --new ... --duration 200 --only sar
    python benchmarks/same_results.py --old ... --new ... --set run.zenoh_threads=single
    python benchmarks/same_results.py --old ... --new ... --engine inprocess

Each interpreter runs each shipped experiment file (``experiments/**/*.yaml`` that is neither a
sweep nor a chaos plan) through ``swarmbed run``, its horizon cut to ``--duration`` simulated seconds
(0: the file's own), in lock-step; then the reproducible result files are compared byte for byte
(``config.yaml`` and ``provenance.json`` too, unless the versions' configurations are meant to
differ: ``--skip-config``; ``--ignore-bytes`` leaves out every column and key that counts bytes, for a
change of a message's encoding; ``--new-summary-key K`` compares ``summary.json`` without the key K the new
install adds, a figure reported beside the results, not a result that changed; ``--new-set`` sets the
keys that give back the old behaviour in the new install's runs only). Prints one line per
experiment and exits 1 if any differs. Part of every commit that touches the tick path (issue 43).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
COMPARED = (
    "summary.json",
    "timeseries.csv",
    "agents.csv",
    "network_ledger.csv",
    "trajectories.csv",
    "markers.csv",
    "network_ledger_receivers.parquet",
)


def experiments(only: str | None) -> list[Path]:
    out = []
    for path in sorted((ROOT / "experiments").rglob("*.yaml")):
        data = yaml.safe_load(path.read_text()) or {}
        if "base" in data or "events" in data or set(data) <= {"obstacles"} or (only and only not in str(path)):
            continue  # a sweep, a chaos plan, or an obstacles map file
        out.append(path)
    return out


def run(python: str, path: Path, out: Path, duration: float, extra: list[str], engine: str = "processes") -> str | None:
    """The error of one run, or None."""
    sets = ["--set", f"run.duration={duration}"] if duration else []
    sets += ["--engine", engine] if engine != "processes" else []
    sets += [arg for value in extra for arg in ("--set", value)]
    done = subprocess.run(
        [python, "-m", "swarmbed", "run", str(path), "--out", str(out), "--no-progress", *sets],
        capture_output=True,
        text=True,
        cwd=tempfile.gettempdir(),  # not the checkout: its swarmbed/ folder would shadow the install
    )
    return None if done.returncode == 0 else (done.stderr.strip().splitlines() or ["failed"])[-1]


def compare(a: Path, b: Path, config: bool, new_keys: tuple[str, ...] = (), ignore_bytes: bool = False) -> list[str]:
    """The compared files that differ between run folders ``a`` (old) and ``b`` (new); with
    ``ignore_bytes``, every column and summary key that counts bytes left out (a change of a
    message's encoding: the same decisions, other byte counts)."""
    names = [*COMPARED, *(("config.yaml",) if config else ())]
    if ignore_bytes:
        return [n for n in names if _without_bytes(a / n) != _without_bytes(b / n)]
    return [n for n in names if _read(a / n, new_keys, n) != _read(b / n, new_keys, n)]


def _without_bytes(path: Path) -> object:
    """A result file's content without what counts bytes: CSV and Parquet columns, summary keys
    (and the allocator's version, which such a change bumps)."""
    import pandas as pd

    if not path.exists():
        return None
    if path.suffix == ".json":

        def strip(value: object) -> object:
            if isinstance(value, dict):
                return {k: strip(v) for k, v in value.items() if "bytes" not in k and k != "allocator_version"}
            return value

        return strip(json.loads(path.read_bytes()))
    if path.suffix in (".csv", ".parquet"):
        table = pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path)
        return table[[c for c in table.columns if "bytes" not in c]].to_csv(index=False)
    return path.read_bytes()


def _read(path: Path, new_keys: tuple[str, ...], name: str) -> bytes | None:
    """The file's bytes; for a summary the new install adds keys to, its document without them."""
    if not path.exists():
        return None
    if not new_keys or name != "summary.json":
        return path.read_bytes()
    document = json.loads(path.read_bytes())
    return json.dumps({k: v for k, v in document.items() if k not in new_keys}, sort_keys=True).encode()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old", required=True, help="the python of the install before the change")
    ap.add_argument("--new", default=sys.executable, help="the python of the install after it")
    ap.add_argument("--duration", type=float, default=300.0, help="simulated seconds per run (0: the file's)")
    ap.add_argument("--only", help="only files whose path contains this")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="for every run of both")
    ap.add_argument(
        "--new-set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="for the new install's runs only: the keys that give back the old behaviour",
    )
    ap.add_argument(
        "--engine", choices=["processes", "inprocess"], default="processes", help="the engine both installs run on"
    )
    ap.add_argument("--skip-config", action="store_true", help="do not compare config.yaml (new keys were added)")
    ap.add_argument(
        "--new-summary-key", action="append", default=[], metavar="KEY", help="a summary key only the new install has"
    )
    ap.add_argument(
        "--ignore-bytes",
        action="store_true",
        help="leave out every column and summary key that counts bytes (a message encoding changed)",
    )
    args = ap.parse_args()
    differs = 0
    with tempfile.TemporaryDirectory() as tmp:
        for path in experiments(args.only):
            name = str(path.relative_to(ROOT))
            old, new = Path(tmp) / name / "old", Path(tmp) / name / "new"
            errors = [
                run(args.old, path, old, args.duration, args.set, args.engine),
                run(args.new, path, new, args.duration, [*args.set, *args.new_set], args.engine),
            ]
            if all(e and "--engine inprocess:" in e for e in errors):  # what only processes can run
                print(f"skipped   {name}: {errors[1]}")
                continue
            if any(errors):
                print(f"FAILED    {name}: {errors}")
                differs += 1
                continue
            bad = compare(old, new, not args.skip_config, tuple(args.new_summary_key), args.ignore_bytes)
            differs += bool(bad)
            print(f"{'DIFFERS' if bad else 'identical'} {name}{': ' + ', '.join(bad) if bad else ''}", flush=True)
    return 1 if differs else 0


if __name__ == "__main__":
    sys.exit(main())
