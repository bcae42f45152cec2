"""Compiled kernels for what every robot computes every tick, with their Python reference.

``exp``, ``path_gains``, ``distance_gains``, ``task_columns`` and ``best_bid`` here are the compiled
ones (``_compiled.pyx``, built by ``pip install`` with a C compiler) or, where none was built, the
Python reference (:mod:`swarmbed.kernels.reference`): the same operations in the same order, so
the same bits on every CPU either way (``tests/test_kernels.py`` compares them on recorded and random calls).
``SWARMBED_KERNELS=python`` runs the reference even where the compiled ones exist (to compare, or
to profile the Python). :func:`fallback_notice` is the one line a command says when it runs on the
reference."""

from __future__ import annotations

import os
from types import ModuleType

from swarmbed.kernels import reference

COMPILED = False
_implementation: ModuleType
if os.environ.get("SWARMBED_KERNELS", "compiled") != "python":
    try:
        from swarmbed.kernels import _compiled as _implementation

        COMPILED = True
    except ImportError:  # no C compiler at install time: the reference, slower, the same results
        _implementation = reference
else:
    _implementation = reference

exp = _implementation.exp
path_gains = _implementation.path_gains
distance_gains = _implementation.distance_gains
task_columns = _implementation.task_columns
best_bid = _implementation.best_bid
#: a CBBA receive (plugins/consensus.py), timestamps and Table 1 included, compiled; None where it
#: was not (plugins/consensus.py then decides task by task or with numpy masks, the Python it is
#: compared with)
receive = getattr(_implementation, "receive", None)
#: what a CBBA message tells and what changed since the last one (plugins/consensus.py), compiled
winners_changed = getattr(_implementation, "winners_changed", None)
#: a CBBA message's winner rows and timestamp columns packed (plugins/consensus.py), compiled
pack_winners = getattr(_implementation, "pack_winners", None)
pack_stamps = getattr(_implementation, "pack_stamps", None)

__all__ = [
    "COMPILED",
    "best_bid",
    "distance_gains",
    "exp",
    "fallback_notice",
    "pack_stamps",
    "pack_winners",
    "path_gains",
    "receive",
    "reference",
    "task_columns",
    "winners_changed",
]


def fallback_notice() -> str | None:
    """The line to say when the kernels run as Python (None when they are compiled)."""
    if COMPILED:
        return None
    if os.environ.get("SWARMBED_KERNELS") == "python":
        return "swarmbed: SWARMBED_KERNELS=python: the allocators' kernels run as Python (same results, slower)"
    return (
        "swarmbed: the compiled kernels were not built (no C compiler when swarmbed was installed): the "
        "allocators run their Python reference, with the same results, slower; reinstall with gcc to build them"
    )
