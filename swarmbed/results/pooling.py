"""Which runs may be pooled in one analysis: those of a scenario made under one configuration (all
but the seed) and, unless told otherwise, by one version of each scenario and allocator."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pandas as pd

from swarmbed.files.yamlfile import YamlFileError, parse_yaml
from swarmbed.records import run_folder as rundir
from swarmbed.results.campaign_folders import dotted
from swarmbed.schema.experiment import SAFE_NAME

VERSIONED = ("provenance.scenario.version", "provenance.allocator.version")


def mixed_versions(table: pd.DataFrame) -> str | None:
    """Why the completed runs of ``table`` were made by code that must not be pooled, or None: one
    scenario kind (or allocator) in two versions. Runs that predate provenance records are not counted."""
    ok = table[table["status"] == "ok"]
    for column, by in zip(VERSIONED, ("scenario_kind", "allocator")):
        if column not in ok or by not in ok:
            continue
        seen = ok.dropna(subset=[column]).groupby(by)[column].unique()
        for name, versions in seen.items():
            if len(versions) > 1:
                what = column.split(".")[1]
                return f"{what} {name} in versions {', '.join(sorted(map(str, versions)))}"
    return None


def mixed_configurations(sweep_dir: Path, table: pd.DataFrame) -> str | None:
    """Why the completed runs of ``table`` cannot be pooled per scenario, or None: within a
    scenario every run's ``config.yaml`` must be the same but for ``run.seed``."""
    ok = table[table["status"] == "ok"]
    for scenario, group in ok.groupby("scenario"):
        first: tuple[str, dict[str, Any]] | None = None
        for run in group["run"]:
            if not (isinstance(scenario, str) and re.fullmatch(SAFE_NAME, scenario)):
                return f"a scenario named {str(scenario)[:40]!r} in the table: not a scenario folder"
            name = f"{scenario}/run_{int(run):03d}"
            try:
                text = rundir.read_member(sweep_dir / name, rundir.CONFIG).decode(errors="replace")
                config = dotted(parse_yaml(text, name) or {})
            except (rundir.RunFileError, YamlFileError) as exc:
                return f"{name}: no readable {rundir.CONFIG} ({exc})"
            config.pop("run.seed", None)
            if first is None:
                first = (name, config)
            elif config != first[1]:
                keys = sorted(k for k in config.keys() | first[1].keys() if config.get(k) != first[1].get(k))
                return (
                    f"{first[0]} and {name} were made under different configurations "
                    f"({', '.join(f'{k}: {first[1].get(k)!r} / {config.get(k)!r}' for k in keys[:3])})"
                )
    return None
