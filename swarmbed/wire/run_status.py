"""The coordinator's progress sample, typed: where a run is, for ``swarmbed watch`` and its map.

Published every second or so on the run's status key (wall-clock paced: never part of the results)
as a msgpack map. Anyone on the run's network could publish on that key (the access rules give it
to the coordinator alone, but a run may have none), so a watcher decodes it into :class:`RunStatus`
only: strict types, no unknown keys, bounded lengths; anything else is a
:class:`~swarmbed.wire.errors.WireError` naming the field, and the watcher counts it and goes on.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError

from swarmbed.wire.codec import pack, unpack
from swarmbed.wire.errors import WireError

#: the most agents or markers a status sample lists (far beyond any run's: 1,000 agents at most)
MAX_ITEMS = 100_000
#: the most bytes a status sample may have
MAX_STATUS_BYTES = 64 << 20

Name = Annotated[str, Field(max_length=200)]
Count = Annotated[int, Field(ge=0)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
# msgpack has no tuples: a triple arrives as a list, which a strict tuple refuses
Position = Annotated[tuple[Count, Finite, Finite], Strict(False)]
Marker = Annotated[tuple[Finite, Finite, Name], Strict(False)]


class _Sample(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class NetworkCounters(_Sample):
    """The ledger's running totals so far."""

    messages_sent: Count
    bytes_sent: Count
    copies: Count
    delivered: Count
    dropped: Count


class RunStatus(_Sample):
    """One progress sample: the run's name and kind, its tick and simulated time, the world's
    time-series row, the radio's totals and drops by reason, who is alive, and the map (agents'
    positions and labels, markers)."""

    name: Name
    scenario: Name
    allocator: Name
    tick: int = Field(ge=-1, description="the last tick stepped (-1 before the first)")
    time: Finite
    ticks: Count
    wall_s: Finite
    row: dict[Name, int | float] = Field(max_length=1000, description="the world's time-series row (timeseries.csv)")
    network: NetworkCounters
    drops: dict[Name, Count] = Field(max_length=1000, description="copies dropped so far, by reason")
    alive: list[Count] = Field(max_length=MAX_ITEMS)
    late_ticks: Count = 0
    positions: list[Position] = Field(default=[], max_length=MAX_ITEMS, description="agent, x, y")
    labels: dict[Count, Name] = Field(default={}, max_length=MAX_ITEMS, description="agent -> its label")
    markers: list[Marker] = Field(default=[], max_length=MAX_ITEMS, description="x, y, label")


def encode_status(status: RunStatus) -> bytes:
    return pack(status.model_dump())


def decode_status(data: bytes) -> RunStatus:
    """A progress sample, or a WireError naming what is wrong with it."""
    raw = unpack(data, max_bytes=MAX_STATUS_BYTES)
    try:
        return RunStatus.model_validate(raw)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(p) for p in err["loc"])
        raise WireError(f"status: {where}: {err['msg']}" if where else f"status: {err['msg']}") from None
