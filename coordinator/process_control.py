"""How the coordinator starts and stops agent processes: the placement interface it is given.

The coordinator decides *when* an agent needs a new process (a swap to another host, a restart
after a crash) and the launcher knows *how* (a fork server on this machine, a host daemon on
another). The launcher hands the coordinator an object with these three methods; a run that
cannot start processes (a test driving a coordinator by hand) hands it none, and swaps and
restarts are then refused with that reason.
"""

from __future__ import annotations

from typing import Protocol


class Placement(Protocol):
    def place(self, agent: int, host: str, incarnation: int, restore: bool = True) -> None:
        """Start process ``incarnation`` of ``agent`` on ``host``: restoring the snapshot the
        coordinator holds for it, or fresh. Raises when the host refuses or cannot be reached."""

    def unplace(self, agent: int, host: str, incarnation: int) -> None:
        """Stop process ``incarnation`` of ``agent`` on ``host`` (one that failed to take over)."""

    def exit_status(self, process: str) -> str:
        """How a local child process ended and how its log ends ('' while it runs or is unknown)."""
