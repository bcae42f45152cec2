"""The colours every view of a run shares (report, replay, live map), so that a reason or a label
looks the same in each."""

from swarmbed.netem.ledger import DROP_REASONS
from swarmbed.netem.radio import STAGES

_OTHER_DROPS = {  # the reasons that are not a radio stage's (a stage names its own colour)
    "queue_full": "#ff7f0e",
    "receiver_dead": "#7f7f7f",
    "no_such_receiver": "#8c564b",
    "run_ended": "#bcbd22",
    "late": "#17becf",
}
_STAGE_COLORS = {stage.reason: stage.colour for stage in STAGES}
#: every drop reason's colour: the disk's reasons in the ledger's order, then the models' stages
DROP_COLORS = {
    reason: _STAGE_COLORS.get(reason) or _OTHER_DROPS[reason]
    for reason in DROP_REASONS + tuple(r for r in _STAGE_COLORS if r not in DROP_REASONS)
}
WALL_COLOUR = "#3b3b3b"  # obstacles' walls, in every view that draws the map
LABEL_COLORS = {"red": "#d62728", "green": "#2ca02c", "blue": "#1f77b4"}  # SAR's robot and victim colours

# Strategies as the papers name and order them (CBBA-ETC Section 5.2; SPACE Fig. 3), each with one
# colour in every figure (Okabe-Ito, safe for colour-blind readers and in greyscale print).
STRATEGY_LABELS = {
    "tree": "Tree",
    "comm": "Comm",
    "cbba": "CBBA",
    "cbba-tree": "CBBA-Tree",
    "cbba-etc": "CBBA-ETC",
    "c-cbba": "C-CBBA",
    "grape": "GRAPE",
    "fcg": "FCG",
    "noop": "no-op",
}
STRATEGY_ORDER = tuple(STRATEGY_LABELS)
STRATEGY_COLORS = {
    "tree": "#999999",
    "comm": "#E69F00",
    "cbba": "#56B4E9",
    "cbba-tree": "#009E73",
    "cbba-etc": "#D55E00",
    "c-cbba": "#CC79A7",
    "grape": "#009E73",
    "fcg": "#E69F00",
    "noop": "#000000",
}
_SPARE = ("#0072B2", "#F0E442", "#882255", "#44AA99", "#117733", "#332288")


def strategy_label(name: str) -> str:
    return STRATEGY_LABELS.get(name, name)


def strategy_color(name: str) -> str:
    """The strategy's colour; an unknown one gets a spare colour fixed by its name."""
    if name in STRATEGY_COLORS:
        return STRATEGY_COLORS[name]
    return _SPARE[sum(name.encode()) % len(_SPARE)]
