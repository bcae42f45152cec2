"""Joining a run: fetching its configuration from the coordinator and announcing liveliness."""

from __future__ import annotations

import time

import zenoh

from swarmbed.wire.keys import Keys


class JoinError(RuntimeError):
    pass


def fetch_config_text(session: zenoh.Session, keys: Keys, timeout: float = 60.0) -> str:
    """The resolved experiment YAML, asked of the coordinator's queryable (retried until ``timeout``)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.get(keys.config, timeout=2.0):
            if reply.ok is not None:
                return reply.ok.payload.to_string()
        time.sleep(0.05)
    raise JoinError(f"no coordinator answered on {keys.config} within {timeout:.0f} s")


def serve_config(session: zenoh.Session, keys: Keys, text: str):
    """Answer every query on the config key with ``text``; keep the returned queryable alive."""
    return session.declare_queryable(keys.config, lambda query: query.reply(keys.config, text))


def hand_over(session: zenoh.Session, key: str, payload: bytes, timeout: float = 30.0) -> bool:
    """Deliver ``payload`` to the queryable on ``key`` and wait until it acknowledges.

    A plain put may still be queued when the process closes its session and exits, and is then
    lost; a query is answered only once the other side holds the payload."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.get(key, payload=payload, timeout=min(5.0, timeout),
                                 congestion_control=zenoh.CongestionControl.BLOCK):
            if reply.ok is not None:
                return True
        time.sleep(0.05)
    return False


def accept_handovers(session: zenoh.Session, key: str, deliver):
    """The receiving side of :func:`hand_over`: ``deliver(key, payload)``, then acknowledge."""

    def on_query(query: zenoh.Query) -> None:
        payload = query.payload
        if payload is not None:
            deliver(str(query.key_expr), payload.to_bytes())
        query.reply(query.key_expr, b"ok")

    return session.declare_queryable(key, on_query)
