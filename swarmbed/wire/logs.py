"""Logs of swarmbed's processes: one format, and a log file that rotates (hours-long soaks must not
fill the disk with one agent's warnings)."""

from __future__ import annotations

import logging
import logging.handlers
import os
import sys

LOG_FORMAT = "%(asctime)s %(name)s %(levelname)s %(message)s"


class RotatingStderr(logging.handlers.RotatingFileHandler):
    """Logging into the file this process's stdout and stderr were sent to, rotated at
    ``max_bytes`` into ``name.log.1`` .. ``name.log.<backups>``. The process's own stdout and
    stderr follow the file to each new one (``dup2``), so prints and tracebacks land in the
    current file too, and everything is appended through one open file."""

    def __init__(self, path: str, max_bytes: int, backups: int) -> None:
        super().__init__(path, mode="a", maxBytes=max_bytes, backupCount=backups)
        self._follow()

    def _follow(self) -> None:
        if self.stream is not None:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(self.stream.fileno(), 1)
            os.dup2(self.stream.fileno(), 2)

    def doRollover(self) -> None:
        super().doRollover()
        self._follow()


def setup_logging(max_mb: int | None, backups: int) -> None:
    """Log to stderr; where stderr is a file (as the launcher starts children) and ``max_mb`` is
    set, rotate it at that size keeping ``backups`` older files."""
    try:
        path = os.readlink("/proc/self/fd/2") if max_mb else ""
    except OSError:
        path = ""
    if max_mb and path.startswith("/") and os.path.isfile(path):
        handler = RotatingStderr(path, max_mb * 2**20, backups)
        handler.setFormatter(logging.Formatter(LOG_FORMAT))
        logging.basicConfig(level=logging.INFO, handlers=[handler])
    else:
        logging.basicConfig(level=logging.INFO, format=LOG_FORMAT, stream=sys.stderr)
