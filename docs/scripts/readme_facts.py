"""The measured facts docs/results.md states about the quick start's bytes, from real runs:
``python docs/scripts/readme_facts.py`` prints them, ``--write`` puts them into docs/results.md
between its ``readme-facts`` markers, and ``tests/test_readme.py`` runs the same runs and holds the
page to them (payload bytes and ticks
exactly, being reproducible; TCP bytes within a tolerance, being measured).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
from pathlib import Path

from swarmbed import config as cfg
from swarmbed.launch.runner import run_experiment

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "docs" / "results.md"
START, END = "<!-- readme-facts -->", "<!-- /readme-facts -->"
#: the runs the paragraph speaks of: (label, overrides)
RUNS = (("quickstart", ()), ("cbba10", ("agents.count=10", "allocator.name=cbba")))


def measure(folder: Path) -> dict[str, dict[str, int]]:
    """Ticks, payload bytes and the agents' TCP bytes of each run of :data:`RUNS`."""
    facts = {}
    for label, overrides in RUNS:
        out = folder / label
        exp = cfg.load(ROOT / "experiments" / "quickstart.yaml", list(overrides))
        result = run_experiment(exp, out, progress=False)
        wire = json.loads((out / "transport.json").read_text())["totals"]
        facts[label] = {
            "ticks": int(result.summary["ticks"]),
            "payload": int(result.summary["network"]["bytes_sent"]),
            "tcp": int(wire["agent_tcp_bytes_sent"]),
        }
    return facts


def paragraph(facts: dict[str, dict[str, int]]) -> str:
    q, c = facts["quickstart"], facts["cbba10"]
    return (
        f"The quickstart (5 agents, FCG, {q['ticks']} ticks) sends {q['payload']:,} payload bytes and "
        f"{q['tcp']:,} TCP bytes\nfrom its agents ({q['tcp'] / q['payload']:.1f} x: lock-step sends a sample per "
        f"agent per tick, messages or not); 10 agents\nwith CBBA send {c['payload']:,} payload bytes and "
        f"{c['tcp']:,} TCP bytes ({c['tcp'] / c['payload']:.1f} x)."
    )


def stated(text: str) -> dict[str, dict[str, int]]:
    """The facts the page states between its markers."""
    block = text.split(START, 1)[1].split(END, 1)[0]
    numbers = [int(n.replace(",", "")) for n in re.findall(r"\d[\d,]*(?= (?:ticks|payload|TCP))", block)]
    q_ticks, q_payload, q_tcp, c_payload, c_tcp = numbers
    return {
        "quickstart": {"ticks": q_ticks, "payload": q_payload, "tcp": q_tcp},
        "cbba10": {"payload": c_payload, "tcp": c_tcp},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--write", action="store_true", help="put the facts into docs/results.md")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        facts = measure(Path(tmp))
    text = paragraph(facts)
    print(text)
    if args.write:
        readme = README.read_text()
        head, rest = readme.split(START, 1)
        README.write_text(f"{head}{START}\n{text}\n{END}{rest.split(END, 1)[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
