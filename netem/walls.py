"""Walls in the radio: COST 231's multi-wall model and a line-of-sight switch.

A copy whose straight path from sender to receiver crosses walls loses, in dB, the sum of their
materials' losses (``network.walls.loss_db``; COST 231 Final Report, 1999, section 4.7.3, the
multi-wall model's sum over wall types, without its floor term)::

    P_rx = P_tx - PL(d) - S_ij + 10 log10(g_ij) - sum_w L_w

so with ``network.propagation`` walls feed the sensitivity and packet-error stages (a copy behind
two heavy walls arrives 13.8 dB weaker). With ``network.walls.line_of_sight: true`` the ``walls``
stage drops every copy that crosses any wall as ``blocked_by_wall``, with the disc model or any
other: it comes right after the range check, before anything draws a random number for the copy.

The walls are tested once per tick for each unordered pair of robots among the copies still in
play (a wall between two robots is between them both ways), vectorised over pairs and walls: which
side of each wall's line every robot lies on is computed once, and only the pairs on both sides of
a line are tested in full.
Nothing here draws a random number, so walls never shift another model's draws.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from swarmbed.netem.stage import Stage, TickCopies

if TYPE_CHECKING:
    from swarmbed.netem.radio import Radio

BLOCKED_BY_WALL = "blocked_by_wall"


def wall_loss_db(radio: Radio, copies: TickCopies, at: np.ndarray) -> np.ndarray:
    """The dB the copies ``at`` lose to the walls on their straight paths (kept for the tick)."""
    walls = radio.walls
    if walls is None or not len(walls) or not len(at):
        return np.zeros(len(at))
    if copies.wall_loss is None:
        copies.wall_loss = np.full(len(copies.rows), np.nan)
    todo = at[np.isnan(copies.wall_loss[at])]
    if len(todo):
        n = len(copies.alive)
        # a wall between two robots is between them both ways: one test per unordered pair
        lo, hi = (
            np.minimum(copies.from_rows[todo], copies.rows[todo]),
            np.maximum(copies.from_rows[todo], copies.rows[todo]),
        )
        unique, back = np.unique(lo * n + hi, return_inverse=True)
        hit = walls.crossings_among(copies.x, copies.y, unique // n, unique % n)
        loss, crossed = hit.astype(float) @ walls.loss_db, np.asarray(hit.any(axis=1))
        copies.wall_loss[todo] = loss[back]
        copies.crossed = copies.crossed if copies.crossed is not None else np.zeros(len(copies.rows), dtype=bool)
        copies.crossed[todo] = crossed[back]
    return copies.wall_loss[at]


def _blocked(radio: Radio, copies: TickCopies, at: np.ndarray) -> np.ndarray:
    wall_loss_db(radio, copies, at)
    if copies.crossed is None:
        return np.zeros(len(at), dtype=bool)
    return copies.crossed[at]


#: on with ``network.walls.line_of_sight``; a run without obstacles has no wall to cross
WALLS_STAGE = Stage(BLOCKED_BY_WALL, "#843c39", lambda p: p.walls is not None and p.walls.line_of_sight, _blocked)
