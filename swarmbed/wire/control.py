"""The control plane, typed: the reports agents and the proxy hand the coordinator, the swap
requests operators send it, and what a run's hub asks a host daemon (start, stop) and hears back.

Reports travel as msgpack maps (rare, and read by people too), swap and host requests as JSON; all
are decoded into these models only, with strict types and no unknown keys, so a crafted report is a
:class:`~swarmbed.wire.errors.WireError` that names the field, never a ``KeyError`` deep inside the
coordinator. An agent report's ``kind`` selects its model.
"""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from swarmbed.wire.codec import pack, unpack
from swarmbed.wire.errors import WireError

AgentId = Annotated[int, Field(ge=0)]


class _Message(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


_M = TypeVar("_M", bound=_Message)


class TcpCounters(_Message):
    sent: int
    received: int
    segments_out: int
    segments_in: int
    sockets: int


class SampleBytes(_Message):
    """Bytes of this process's per-tick samples, in and out."""

    in_: int = Field(alias="in")
    out: int


class Transport(_Message):
    """What a process measured on its own sockets (None where the kernel's counters cannot be read)."""

    tcp: TcpCounters | None = None
    samples: SampleBytes | None = None


# -- agent -> coordinator ---------------------------------------------------------------------------
class Fatal(_Message):
    """The agent's plugin or a node raised: the agent stops."""

    kind: Literal["fatal"]
    agent: AgentId
    tick: int
    error: str
    traceback: str = ""


class Final(_Message):
    """The run is over: what the agent sent (per kind: messages, bytes) and dropped as malformed."""

    kind: Literal["final"]
    agent: AgentId
    ticks: int = Field(ge=0)
    sent: dict[str, Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=2, max_length=2)]]
    malformed: int = Field(ge=0)
    transport: Transport | None = None


class Checkpoint(_Message):
    """The agent's state, asked for with ``ticket``, to restart it from."""

    kind: Literal["checkpoint"]
    agent: AgentId
    incarnation: int = Field(ge=0)
    ticks: int = Field(ge=0)
    state: bytes
    ticket: bytes


class Restored(_Message):
    """A new process of the agent restored its snapshot and is subscribed."""

    kind: Literal["restored"]
    agent: AgentId
    incarnation: int = Field(ge=0)


class SnapshotFailed(_Message):
    kind: Literal["snapshot_failed"]
    agent: AgentId
    incarnation: int = Field(ge=0)
    error: str


class RestoreFailed(_Message):
    kind: Literal["restore_failed"]
    agent: AgentId
    incarnation: int = Field(ge=0)
    error: str


AgentReport = Annotated[
    Fatal | Final | Checkpoint | Restored | SnapshotFailed | RestoreFailed, Field(discriminator="kind")
]


# -- netem proxy -> coordinator ---------------------------------------------------------------------
class NetemFinal(_Message):
    """The proxy's ledger at the end of the run."""

    kind: Literal["netem"]
    totals: dict[str, Any]  # checked with the summary that carries it (swarmbed.records.summary)
    per_sender: dict[str, dict[str, int]]
    per_kind: dict[str, dict[str, int]]
    malformed: int = Field(ge=0)
    ledger: list[str]
    transport: Transport | None = None
    shard: int = Field(0, ge=0, lt=64)  # which proxy of a split radio (swarmbed.netem.radio_split)


class NetemFatal(_Message):
    """The proxy failed; its error."""

    kind: Literal["fatal"]
    error: str


NetemReport = Annotated[NetemFinal | NetemFatal, Field(discriminator="kind")]

_AGENT = TypeAdapter(AgentReport)
_NETEM = TypeAdapter(NetemReport)


def _why(exc: ValidationError, what: str) -> WireError:
    err = exc.errors()[0]
    where = ".".join(str(p) for p in err["loc"])
    return WireError(f"{what}: {where}: {err['msg']}" if where else f"{what}: {err['msg']}")


def encode_report(report: BaseModel) -> bytes:
    return pack(report.model_dump(by_alias=True, exclude_none=True))


def decode_agent_report(data: bytes) -> Fatal | Final | Checkpoint | Restored | SnapshotFailed | RestoreFailed:
    try:
        return _AGENT.validate_python(unpack(data))
    except ValidationError as exc:
        raise _why(exc, "agent report") from None


def decode_netem_report(data: bytes) -> NetemFinal | NetemFatal:
    try:
        return _NETEM.validate_python(unpack(data))
    except ValidationError as exc:
        raise _why(exc, "netem report") from None


# -- operator -> coordinator: swaps -----------------------------------------------------------------
class SwapRequest(_Message):
    """Move ``agent`` to host ``to`` before the next tick."""

    agent: AgentId
    to: str = Field(pattern=r"^[A-Za-z0-9_.-]{1,64}$")  # a host name (or "local"), as placements name them


class SwapQuery(_Message):
    """What became of swap number ``swap``."""

    swap: int = Field(ge=0)


_SWAP = TypeAdapter(SwapRequest | SwapQuery)


#: a swap request or query is a few dozen bytes of JSON; anything far larger is refused unread
MAX_SWAP_BYTES = 1024


def decode_swap(data: bytes | None) -> SwapRequest | SwapQuery:
    """A swap request or a query of one, from its JSON; WireError names what is wrong (a request of
    more than :data:`MAX_SWAP_BYTES`, nested past what JSON's parser takes, or a host name that is
    not one)."""
    if data is not None and len(data) > MAX_SWAP_BYTES:
        raise WireError(f"a swap request of {len(data):,} bytes (at most {MAX_SWAP_BYTES})")
    try:
        return _SWAP.validate_python(json.loads(data) if data is not None else None)
    except RecursionError:
        raise WireError("not JSON: nested too deep") from None
    except ValueError as exc:  # ValidationError is a ValueError too
        if isinstance(exc, ValidationError):
            raise WireError('a swap request is {"agent": I, "to": HOST}, a query {"swap": N}') from None
        raise WireError(f"not JSON: {str(exc)[:80]}") from None


# -- what the coordinator did to agents: swaps and restarts ------------------------------------------
Millis = Annotated[float, Field(ge=0, allow_inf_nan=False)]
HostName = Annotated[str, Field(max_length=64)]


class _Record(BaseModel):
    """A record the coordinator fills in as it acts (not frozen), written as one CSV row."""

    model_config = ConfigDict(extra="forbid", strict=True, populate_by_name=True)

    @classmethod
    def columns(cls) -> list[str]:
        """The CSV header: the fields in order, by their names in the file."""
        return [f.alias or name for name, f in cls.model_fields.items()]

    def row(self) -> list[Any]:
        return list(self.model_dump(by_alias=True).values())


class SwapRecord(_Record):
    """One swap (swaps.csv; the answer to an operator's query of its swap): agent ``agent`` moved,
    or not, from host ``from`` to host ``to`` before tick ``tick``."""

    tick: int = Field(ge=0)
    agent: AgentId
    from_host: HostName = Field(alias="from")
    to: HostName
    outcome: Literal["ok", "failed"] = "failed"
    reason: Annotated[str, Field(max_length=2000)] = ""
    snapshot_bytes: int = Field(0, ge=0)
    pause_ms: Millis = 0.0


class RestartRecord(_Record):
    """One try at restarting agent ``agent`` (restarts.csv): lost at ``lost_at_tick``, started again
    before ``tick`` as process ``incarnation`` on ``host`` from the checkpoint of
    ``checkpoint_tick`` ("" : fresh)."""

    tick: int = Field(ge=0)
    agent: AgentId
    lost_at_tick: int = Field(ge=0)
    incarnation: int = Field(ge=1)
    host: HostName
    checkpoint_tick: int | Literal[""] = ""
    outcome: Literal["ok", "failed", "retrying"] = "failed"
    reason: str = ""
    wait_ms: Millis = 0.0


class SwapPending(_Message):
    pending: Literal[True]


class SwapQueued(_Message):
    queued: int = Field(ge=0)


class SwapRefused(_Message):
    error: Annotated[str, Field(max_length=2000)]


#: what the coordinator answers an operator's swap request or query
SwapAnswer = SwapRecord | SwapPending | SwapQueued | SwapRefused
_SWAP_ANSWER: TypeAdapter[SwapAnswer] = TypeAdapter(SwapAnswer)


def decode_swap_answer(data: bytes) -> SwapAnswer:
    """The coordinator's answer to a swap request or query; WireError names what is wrong."""
    if len(data) > 8 * MAX_SWAP_BYTES:
        raise WireError(f"a swap answer of {len(data):,} bytes (at most {8 * MAX_SWAP_BYTES})")
    try:
        return _SWAP_ANSWER.validate_python(json.loads(data))
    except RecursionError:
        raise WireError("swap answer: not JSON: nested too deep") from None
    except ValidationError as exc:
        raise _why(exc, "swap answer") from None
    except ValueError as exc:
        raise WireError(f"swap answer: not JSON: {str(exc)[:80]}") from None


def encode_swap_answer(answer: SwapAnswer) -> str:
    return json.dumps(answer.model_dump(by_alias=True))


# -- hub -> host daemon: agent processes ------------------------------------------------------------
RunId = Annotated[str, Field(pattern=r"^[A-Za-z0-9]{1,64}$")]
HostAgentId = Annotated[int, Field(ge=0, lt=10**6)]


class StartAgents(_Message):
    """Start ``agents`` of run ``run_id`` on the host. A swap or restart starts one agent at a later
    ``incarnation``, restored from the checkpoint the coordinator hands it. The daemon builds the
    agents' command lines from these fields alone: nothing in a request reaches an argv as text."""

    run_id: RunId
    agents: Annotated[list[HostAgentId], Field(min_length=1, max_length=1000)]
    incarnation: int = Field(0, ge=0)
    restore: bool = False
    log_max_mb: int = Field(20, ge=1)
    log_backups: int = Field(2, ge=0)

    def agent_args(self) -> list[str]:
        restore = ["--restore"] if self.restore else []
        rotation = ["--log-max-mb", str(self.log_max_mb), "--log-backups", str(self.log_backups)]
        return ["--incarnation", str(self.incarnation), *restore, *rotation]


class StopAgents(_Message):
    """Stop ``agents`` (every agent of the run where None) of ``run_id`` at ``incarnation``."""

    run_id: RunId
    agents: Annotated[list[HostAgentId], Field(max_length=1000)] | None = None
    incarnation: int = Field(0, ge=0)


class HostAnswer(_Message):
    """A host daemon's answer: what it started or stopped, where their logs are, or why it refused."""

    started: list[HostAgentId] = []
    stopped: list[HostAgentId] = []
    logs: str | None = None
    error: str | None = None


class HostInfo(_Message):
    """What a host daemon says of itself (``swarmbed hosts``, deployment.json, a soak's process
    list): its name, cores, free memory, process id, the router its agents connect to, and the
    agents it runs per run."""

    name: HostName
    cores: int | None = Field(ge=1)
    mem_free_mb: int = Field(ge=0)
    pid: int = Field(ge=1)
    endpoint: Annotated[str, Field(max_length=300)]
    agents: Annotated[dict[RunId, Annotated[list[HostAgentId], Field(max_length=1000)]], Field(max_length=1000)]


#: the most bytes of a host daemon's request or answer read (a few hundred in practice)
MAX_HOST_MESSAGE_BYTES = 1 << 20


def _decode_json(model: type[_M], data: bytes | None, what: str) -> _M:
    if data is not None and len(data) > MAX_HOST_MESSAGE_BYTES:
        raise WireError(f"{what}: {len(data):,} bytes, more than {MAX_HOST_MESSAGE_BYTES:,}")
    try:
        value = json.loads(data) if data is not None else None
    except RecursionError:
        raise WireError(f"{what}: not JSON: nested too deep") from None
    except ValueError as exc:
        raise WireError(f"{what}: not JSON: {exc}") from None
    try:
        return model.model_validate(value)
    except ValidationError as exc:
        raise _why(exc, what) from None


def decode_start(data: bytes | None) -> StartAgents:
    return _decode_json(StartAgents, data, "start request")


def decode_stop(data: bytes | None) -> StopAgents:
    return _decode_json(StopAgents, data, "stop request")


def decode_host_answer(data: bytes | None) -> HostAnswer:
    return _decode_json(HostAnswer, data, "host answer")


def decode_host_info(data: bytes | None) -> HostInfo:
    return _decode_json(HostInfo, data, "host information")


def encode_json(message: BaseModel) -> str:
    return message.model_dump_json(exclude_defaults=True)
