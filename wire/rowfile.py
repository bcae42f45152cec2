"""Result tables written as a run goes, so that a long run holds none of them in memory.

A :class:`RowFile` appends CSV rows to ``<name>.part`` in whole-row chunks: rows wait in a small
buffer and reach the file (flushed to the kernel) every ``chunk_rows`` rows or ``chunk_s`` wall
seconds, whichever comes first. A process killed at any moment therefore leaves a ``.part`` file
that parses (a header and whole rows) and lacks at most the last chunk. :meth:`RowFile.finish`
moves the complete file to its name; :meth:`RowFile.abandon` keeps what was written as
``partial_<name>`` for a run that did not complete (never under a result's name).

The bytes are those of :func:`csv.writer` with ``\\n`` line ends: a table streamed here equals
the same table written in one go.
"""

from __future__ import annotations

import csv
import io
import os
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

PARTIAL_PREFIX = "partial_"


class RowFile:
    def __init__(self, path: Path, columns: Sequence[str], chunk_rows: int = 4096, chunk_s: float = 5.0) -> None:
        self.path = path
        self.part = path.with_name(path.name + ".part")
        self.chunk_rows = chunk_rows
        self.chunk_s = chunk_s
        self.rows = 0
        self._buffer = io.StringIO()
        self._writer = csv.writer(self._buffer, lineterminator="\n")
        self._waiting = 0
        self._flushed_at = time.monotonic()
        self._file: io.TextIOWrapper | None = open(self.part, "w", newline="")
        self._writer.writerow(columns)
        self.flush()

    def write(self, row: Sequence[Any]) -> None:
        self._writer.writerow(row)
        self._waiting += 1
        self.rows += 1
        if self._waiting >= self.chunk_rows:
            self.flush()

    def write_many(self, rows: Iterable[Sequence[Any]]) -> None:
        for row in rows:
            self.write(row)

    def tick(self) -> None:
        """Flush if the oldest waiting row is older than ``chunk_s`` (call once in a while)."""
        if self._waiting and time.monotonic() - self._flushed_at >= self.chunk_s:
            self.flush()

    def flush(self) -> None:
        """Hand every waiting row to the file in one write of whole rows."""
        if self._file is None:
            return
        text = self._buffer.getvalue()
        if text:
            self._file.write(text)
            self._file.flush()
            self._buffer.seek(0)
            self._buffer.truncate()
        self._waiting = 0
        self._flushed_at = time.monotonic()

    def finish(self) -> Path:
        """The table is complete: synced and renamed to its own name."""
        self.flush()
        assert self._file is not None, f"{self.path.name} finished twice or after abandon()"
        os.fsync(self._file.fileno())
        self._file.close()
        self._file = None
        os.replace(self.part, self.path)
        return self.path

    def abandon(self) -> Path | None:
        """The run did not complete: keep what was written as ``partial_<name>`` (None if finished)."""
        if self._file is None:
            return None
        self.flush()
        self._file.close()
        self._file = None
        return keep_partial(self.part)


def keep_partial(part: Path) -> Path | None:
    """Rename ``<name>.part`` left by an unfinished run to ``partial_<name>`` (if it exists)."""
    if not part.exists():
        return None
    name = part.name.removesuffix(".part")
    target = part.with_name(PARTIAL_PREFIX + name)
    os.replace(part, target)
    return target
