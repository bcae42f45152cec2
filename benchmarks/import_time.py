"""What each ``swarmbed`` verb pays to import before it does anything: ``python -X importtime`` of
the command line module plus the modules that verb imports when it runs, in a fresh interpreter
each time (the median of ``--repeat`` runs, microseconds summed over the top-level imports).

    python benchmarks/import_time.py [--repeat 5]

Run it on an otherwise idle machine: under load every figure grows by the same factor, which is
why the ratio to the bare interpreter floor (``python -c pass`` with numpy imported, the least any
verb imports) is printed beside each.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys

#: verb -> the modules its command imports (cli/main.py's cmd_* functions)
VERBS = {
    "--help": [],
    "run": ["swarmbed.launch.runner", "swarmbed.launch.hub"],
    "sweep": ["swarmbed.campaigns.sweep"],
    "report": ["swarmbed.results.report"],
    "replay": ["swarmbed.results.replay"],
    "analyze": ["swarmbed.results.analyze"],
    "watch": ["swarmbed.results.watch"],
    "params": [],
    "credentials": ["swarmbed.wire.credentials"],
}


def import_us(modules: list[str]) -> int:
    """Microseconds the top-level imports of ``modules`` took in a fresh interpreter."""
    code = "; ".join(f"import {m}" for m in modules) or "pass"
    done = subprocess.run([sys.executable, "-X", "importtime", "-c", code], capture_output=True, text=True, check=True)
    total = 0
    for line in done.stderr.splitlines():
        parts = line.split("|")
        if len(parts) == 3 and parts[1].strip().isdigit() and not parts[2].startswith("  "):  # a top-level import
            total += int(parts[1])
    return total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    floor = statistics.median(import_us(["numpy"]) for _ in range(args.repeat))
    print(f"floor (numpy alone): {floor / 1000:.0f} ms")
    print(f"{'verb':<12} {'import ms':>10} {'x floor':>8}")
    for verb, modules in VERBS.items():
        us = statistics.median(import_us(["swarmbed.cli.main", *modules]) for _ in range(args.repeat))
        print(f"{verb:<12} {us / 1000:>10.0f} {us / floor:>8.1f}")


if __name__ == "__main__":
    main()
