"""Joining a run: fetching its configuration from the coordinator and announcing liveliness."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

import zenoh
from pydantic import BaseModel, ValidationError

M = TypeVar("M", bound=BaseModel)


class JoinError(RuntimeError):
    pass


def fetch_spec(session: zenoh.Session, key: str, model: type[M], what: str, timeout: float = 60.0) -> M:
    """A process's spec (JSON of ``model``), asked of the coordinator's queryable on ``key``
    (retried until ``timeout``) and validated; a malformed one is a JoinError naming ``what``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.get(key, timeout=2.0):
            if reply.ok is not None:
                try:
                    return model.model_validate_json(reply.ok.payload.to_bytes())
                except ValidationError as exc:
                    raise JoinError(f"{what} on {key} is malformed: {exc}") from None
        time.sleep(0.05)
    raise JoinError(f"no coordinator answered on {key} within {timeout:.0f} s")


def fetch_bytes(session: zenoh.Session, key: str, timeout: float = 30.0) -> bytes:
    """The payload the queryable on ``key`` answers with (an error reply is a JoinError)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.get(key, timeout=min(5.0, timeout)):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
            if reply.err is not None:
                raise JoinError(f"{key}: {reply.err.payload.to_string()}")
        time.sleep(0.05)
    raise JoinError(f"nothing answered on {key} within {timeout:.0f} s")


def serve_text(session: zenoh.Session, key: str, text: str) -> zenoh.Queryable:
    """Answer every query on ``key`` with ``text``; keep the returned queryable alive."""
    return session.declare_queryable(key, lambda query: query.reply(key, text))


def is_alive(session: zenoh.Session, token_key: str, timeout: float = 2.0) -> bool:
    """Whether some process holds the liveliness token ``token_key`` now."""
    return any(reply.ok is not None for reply in session.liveliness().get(token_key, timeout=timeout))


def hand_over(session: zenoh.Session, key: str, payload: bytes, timeout: float = 30.0) -> bool:
    """Deliver ``payload`` to the queryable on ``key`` and wait until it acknowledges.

    A plain put may still be queued when the process closes its session and exits, and is then
    lost; a query is answered only once the other side holds the payload."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.get(
            key, payload=payload, timeout=min(5.0, timeout), congestion_control=zenoh.CongestionControl.BLOCK
        ):
            if reply.ok is not None:
                return True
        time.sleep(0.05)
    return False


def accept_handovers(session: zenoh.Session, key: str, deliver: Callable[[str, bytes], object]) -> zenoh.Queryable:
    """The receiving side of :func:`hand_over`: ``deliver(key, payload)``, then acknowledge."""

    def on_query(query: zenoh.Query) -> None:
        payload = query.payload
        if payload is not None:
            deliver(str(query.key_expr), payload.to_bytes())
        query.reply(query.key_expr, b"ok")

    return session.declare_queryable(key, on_query)
