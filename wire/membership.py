"""Joining a run: fetching its configuration from the coordinator and announcing liveliness."""

from __future__ import annotations

import time

import zenoh

from wire.keys import Keys


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
