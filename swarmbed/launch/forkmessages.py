"""What the launcher and its agents' fork server (:mod:`.forkserver`) say to each other, typed: one
JSON line each way per message, each a tagged struct (``{"type": "spawned", ...}``) decoded into
these types only.

The pipe is the launcher's own (the server is its child), but a message that does not fit is still
a :class:`ForkProtocolError` naming it, never a ``KeyError`` in the reader thread. This module
imports nothing else of swarmbed: the server imports it before it preloads the agents' code.
"""

from __future__ import annotations

import msgspec


class ForkProtocolError(ValueError):
    """A line of the fork-server pipe that is not one of these messages."""


class SpawnRequest(msgspec.Struct, tag="spawn", tag_field="type", forbid_unknown_fields=True):
    """Launcher -> server: fork a child running the agent ``argv``, its output to ``log``."""

    name: str
    argv: list[str]
    log: str


class Ready(msgspec.Struct, tag="ready", tag_field="type", forbid_unknown_fields=True):
    """The server imported everything and takes requests."""

    pid: int


class Spawned(msgspec.Struct, tag="spawned", tag_field="type", forbid_unknown_fields=True):
    name: str
    pid: int


class Failed(msgspec.Struct, tag="failed", tag_field="type", forbid_unknown_fields=True):
    """The fork itself failed (the child's own failures are its exit code and log)."""

    name: str
    error: str


class Exited(msgspec.Struct, tag="exited", tag_field="type", forbid_unknown_fields=True):
    """A child was reaped: its exit code, negative if a signal killed it (as subprocess says)."""

    pid: int
    code: int


Event = Ready | Spawned | Failed | Exited

_encoder = msgspec.json.Encoder()
_events = msgspec.json.Decoder(Event)
_requests = msgspec.json.Decoder(SpawnRequest)


def encode(message: SpawnRequest | Event) -> bytes:
    """One line: the message's JSON and a newline."""
    return _encoder.encode(message) + b"\n"


def decode_event(line: bytes) -> Event:
    try:
        return _events.decode(line)
    except msgspec.DecodeError as exc:
        raise ForkProtocolError(f"fork server said {line[:80]!r}: {exc}") from None


def decode_request(line: bytes) -> SpawnRequest:
    try:
        return _requests.decode(line)
    except msgspec.DecodeError as exc:
        raise ForkProtocolError(f"spawn request {line[:80]!r}: {exc}") from None
