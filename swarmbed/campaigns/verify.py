"""``swarmbed sweep --verify K``: K of a sweep's completed runs run again in processes, and every
reproducible result file compared byte for byte with the sweep's.

The in-process engine claims the result files of a run of processes; a sweep made in-process
checks that claim on its own runs (the K of lowest seed, so the same K every time). The runs
again go to ``<sweep>/.verify/<scenario>/run_NNN``, where a user can diff what differs.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from swarmbed.campaigns.sweep import RunSpec, experiment_for
from swarmbed.files import safefiles
from swarmbed.launch.runner import run_experiment
from swarmbed.records.run_folder import REPRODUCIBLE, RunDir

VERIFY = ".verify"  # a leading dot: never the name of a scenario folder


def differing_files(made: Path, again: Path) -> list[str]:
    """The reproducible result files that differ between two run folders (or are in one only)."""
    differ = []
    for name in REPRODUCIBLE:
        a, b = made / name, again / name
        if a.exists() != b.exists() or (a.exists() and a.read_bytes() != b.read_bytes()):
            differ.append(name)
    return differ


def verify_in_processes(planned: Sequence[RunSpec], out: Path, k: int) -> bool:
    """Run ``k`` completed runs of ``planned`` again in processes and compare; print what was found.
    True when every file of every run compared is the same."""
    done = sorted((spec for spec in planned if RunDir(spec.out_dir).complete), key=lambda s: (s.seed, s.out_dir))
    chosen = done[:k]
    if len(chosen) < k:
        print(f"verify: only {len(chosen)} of the {k} runs asked for are complete")
    same = True
    for done_count, spec in enumerate(chosen):
        print(f"verify: run {done_count + 1} of {len(chosen)} again in processes: {spec.out_dir}", flush=True)
        made = Path(spec.out_dir)
        again = out / VERIFY / made.relative_to(out)
        with safefiles.rooted(out, create=False):  # .verify and the folders in it: never through a link
            safefiles.remove_tree(again)
            safefiles.make_folder(again)
            run_experiment(experiment_for(spec.base, spec.scenario, spec.seed, spec.extra), again, progress=False)
        differ = differing_files(made, again)
        if differ:
            same = False
            print(f"verify: {made} DIFFERS from the same run in processes ({again}): {', '.join(differ)}")
        else:
            print(f"verify: {made}: every reproducible file is the same in processes")
    print(f"verify: {len(chosen)} runs again in processes; {'all the same' if same else 'SOME FILES DIFFER'}")
    return same
