"""The files of a run directory: one place that names them for every process that writes them
(coordinator, netem proxy, launcher) and every command that reads them (sweeps, analysis, reports).

Formats: CSV tables with a header row and ``\\n`` line ends, written in whole rows (``rowfile``);
JSON objects with sorted keys; ``config.yaml`` as ``yaml.safe_dump`` writes it. A table still being
written is ``<name>.part``; one of a run that did not complete is ``partial_<name>``.
"""

from __future__ import annotations

CONFIG = "config.yaml"  # the resolved experiment
PROVENANCE = "provenance.json"  # which code made the run
SUMMARY = "summary.json"  # written last: its presence means the run completed
TIMESERIES = "timeseries.csv"
AGENTS = "agents.csv"
TRAJECTORIES = "trajectories.csv"  # with run.record_trajectories
MARKERS = "markers.csv"  # tasks or victims as they appear and vanish (with trajectories)
LEDGER = "network_ledger.csv"
RECEIVER_LEDGER = "network_ledger_receivers.parquet"  # network.ledger: per_receiver
SWAPS = "swaps.csv"
RESTARTS = "restarts.csv"
TIMINGS = "timings.json"  # wall-clock figures: of this machine and moment
TRANSPORT = "transport.json"  # measured bytes on the wire: of this machine and moment
DEPLOYMENT = "deployment.json"  # where each agent ran
LOGS = "logs"
BT = "bt"  # with run.record_bt: one Groot2-replayable file per agent


def btlog_name(agent: int) -> str:
    """An agent's behavior tree log in :data:`BT` (BehaviorTree.CPP's file-logger format)."""
    return f"agent_{agent}.btlog"


PART_SUFFIX = ".part"
PARTIAL_PREFIX = "partial_"

#: what a run that starts again into the same folder removes first, and what one that fails keeps
#: only as partial_<name> (deployment.json stays: it says where the failed run's processes were)
RESULT_FILES = (
    SUMMARY,
    TIMESERIES,
    AGENTS,
    TIMINGS,
    TRANSPORT,
    TRAJECTORIES,
    MARKERS,
    LEDGER,
    RECEIVER_LEDGER,
    DEPLOYMENT,
)

#: the files that are identical for the same configuration and seed, wherever the agents ran
REPRODUCIBLE = (
    CONFIG,
    PROVENANCE,
    SUMMARY,
    TIMESERIES,
    AGENTS,
    TRAJECTORIES,
    MARKERS,
    LEDGER,
    RECEIVER_LEDGER,
    RESTARTS,
)
