"""``summary.json``: the model of a completed run's outcome, shared by the coordinator that writes it
and the sweeps, reports and soak pages that read it.

The keys every run has are declared here; the scenario's own outcome keys (its ``summary_keys``)
and the allocator's event counters sit beside them at the top level (``extra``). The coordinator
builds the summary as this model (:meth:`RunSummary.of`) before it writes it, so a run never
completes with a summary its readers cannot read; readers load it with
:func:`swarmbed.records.run_folder.read_summary`, which checks it the same way. The model keeps
the document it was made from (:attr:`RunSummary.document`): ``summary.json`` is that document,
key for key, and a sweep's table flattens it as written.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError

from swarmbed.wire.errors import WireError


class KindTotals(BaseModel):
    """One message kind's traffic: messages, their bytes and copies, then the copies of each
    outcome that occurred (``delivered`` and every drop reason met, as extra keys)."""

    model_config = ConfigDict(extra="allow")
    __pydantic_extra__: dict[str, int] = Field(init=False)
    messages: int = Field(ge=0)
    bytes: int = Field(ge=0)
    copies: int = Field(ge=0)


class Malformed(BaseModel):
    """Samples each kind of process received, could not decode, and dropped."""

    model_config = ConfigDict(extra="forbid")
    coordinator: int = Field(ge=0)
    netem: int = Field(ge=0)
    agents: int = Field(ge=0)


class NetworkSummary(BaseModel):
    """The radio's ledger totals: every copy of every message delivered or dropped with a reason."""

    model_config = ConfigDict(extra="forbid")
    messages_sent: int = Field(ge=0, description="radio messages the agents sent (one per broadcast)")
    bytes_sent: int = Field(ge=0, description="their payload bytes")
    copies: int = Field(ge=0, description="copies: one per message and intended receiver")
    delivered: int = Field(ge=0)
    delivered_bytes: int = Field(ge=0)
    dropped: dict[str, int] = Field(description="copies dropped, by reason")
    dropped_total: int = Field(ge=0)
    per_kind: dict[str, KindTotals]
    bytes_sent_by_agents: int | None = Field(description="what the agents counted themselves; None after restarts")
    bytes_agree: bool | None = Field(description="the agents' count equals the ledger's")
    malformed: Malformed


class RunSummary(BaseModel):
    """A completed run. ``extra``: the scenario's outcome keys and the allocator's event counters."""

    model_config = ConfigDict(extra="allow")
    name: str
    scenario_kind: str
    seed: int
    allocator: str
    agents: int = Field(ge=1)
    ticks: int = Field(ge=0)
    events: dict[str, int] = Field(description="every event counter the allocator reported, summed")
    agents_lost: dict[str, int] = Field(description="agent -> tick at which it was lost")
    agent_restarts: int | None = Field(None, ge=0, description="restarts that succeeded (runs that restart agents)")
    realtime: dict[str, Any] | None = Field(None, description="how the real-time clock was kept (real-time runs)")
    network: NetworkSummary
    _document: dict[str, Any] = PrivateAttr(default_factory=dict)

    @classmethod
    def of(cls, document: dict[str, Any]) -> RunSummary:
        """``document`` checked against the model; a WireError names its first refused field."""
        try:
            summary = cls.model_validate(document)
        except ValidationError as exc:
            err = exc.errors()[0]
            where = ".".join(map(str, err["loc"]))
            raise WireError(f"summary.json: {where}: {err['msg']}") from None
        summary._document = document
        return summary

    @property
    def document(self) -> dict[str, Any]:
        """The summary as ``summary.json`` holds it: the declared keys, the scenario's outcome keys
        and the allocator's counters (a sweep's row flattens this)."""
        return self._document

    def outcome(self, key: str) -> Any:
        """One of the scenario's outcome keys or the allocator's counters (see ``summary_keys``);
        KeyError if this run has none of that name."""
        extra = self.model_extra or {}
        if key not in extra:
            raise KeyError(key)
        return extra[key]
