"""One-use tickets for the state the coordinator asks of an agent (a swap's snapshot, a checkpoint).

Agent state is restored into a process, so the coordinator must never take state it did not ask
for: a stray handover, a replayed checkpoint or one from another agent's key. Each order carries a
ticket, an HMAC of (what, agent, incarnation, serial) under a key made for this run in the
coordinator's memory; agents, hosts and the proxy never hold it. An answer is taken only with the
ticket of the order still open for that agent and kind, and only once.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import threading

TICKET_BYTES = 16


class Tickets:
    def __init__(self) -> None:
        self._key = secrets.token_bytes(32)
        self._serial = 0
        self._open: dict[tuple[str, int], bytes] = {}  # (what, agent) -> the ticket of the open order
        self._lock = threading.Lock()  # redeemed from Zenoh's threads, issued from the clock's

    def issue(self, what: str, agent: int, incarnation: int) -> bytes:
        """A ticket for order ``what`` to ``agent``'s process ``incarnation``; it replaces any open one."""
        with self._lock:
            self._serial += 1
            msg = f"{what}/{agent}/{incarnation}/{self._serial}".encode()
            ticket = hmac.new(self._key, msg, hashlib.sha256).digest()[:TICKET_BYTES]
            self._open[(what, agent)] = ticket
            return ticket

    def redeem(self, what: str, agent: int, ticket: object) -> bool:
        """Whether ``ticket`` is that of the open order ``what`` to ``agent`` (which it then closes)."""
        with self._lock:
            wanted = self._open.get((what, agent))
            if wanted is None or not isinstance(ticket, bytes) or not hmac.compare_digest(wanted, ticket):
                return False
            del self._open[(what, agent)]
            return True

    def cancel(self, what: str, agent: int) -> None:
        with self._lock:
            self._open.pop((what, agent), None)
