"""Result tables written as a run goes, so that a long run holds none of them in memory.

A :class:`RowFile` appends CSV rows to ``<name>.part`` in whole-row chunks: rows wait in a small
buffer and reach the file (flushed to the kernel) every ``chunk_rows`` rows or ``chunk_s`` wall
seconds, whichever comes first. A process killed at any moment therefore leaves a ``.part`` file
that parses (a header and whole rows) and lacks at most the last chunk. :meth:`RowFile.finish`
moves the complete file to its name; :meth:`RowFile.abandon` keeps what was written as
``partial_<name>`` for a run that did not complete (never under a result's name).

The bytes are those of :func:`csv.writer` with ``\\n`` line ends: a table streamed here equals
the same table written in one go.

A write that fails part way (a full disk) never leaves a torn row: the file is cut back to the
end of the last whole row it held, and the error says what happened where in one line
(:class:`TableWriteError`). Abandoning a table after such an error keeps the whole rows and does
not raise again, so the first error is the one reported.
"""

from __future__ import annotations

import csv
import errno
import io
import os
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from swarmbed.files.safefiles import create_fresh, rename
from swarmbed.records.run_folder import PART_SUFFIX, PARTIAL_PREFIX


class TableWriteError(OSError):
    """A table could not be written (the file holds whole rows only); one line says why and where."""

    def __str__(self) -> str:
        return str(self.strerror)


def write_error(exc: OSError, where: Path) -> TableWriteError:
    """``exc`` as a one-line error naming the folder: "no space left on device in runs/x"."""
    if exc.errno == errno.ENOSPC:
        text = f"no space left on device in {where}"
    elif exc.errno == errno.EDQUOT:
        text = f"disk quota exceeded in {where}"
    else:
        text = f"cannot write in {where}: {exc.strerror or exc}"
    return TableWriteError(exc.errno or 0, text)


class RowFile:
    def __init__(self, path: Path, columns: Sequence[str], chunk_rows: int = 4096, chunk_s: float = 5.0) -> None:
        self.path = path
        self.part = path.with_name(path.name + PART_SUFFIX)
        self.chunk_rows = chunk_rows
        self.chunk_s = chunk_s
        self.rows = 0
        self._buffer = io.StringIO()
        self._writer = csv.writer(self._buffer, lineterminator="\n")
        self._waiting = 0
        self._flushed_at = time.monotonic()
        self._fd: int | None = create_fresh(self.part)
        self._size = 0  # bytes of whole rows in the file
        self.failed = False
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
        """Hand every waiting row to the file in one write of whole rows; on a failed write, cut
        the file back to its last whole row and raise :class:`TableWriteError`."""
        if self._fd is None:
            return
        data = self._buffer.getvalue().encode()
        if data:
            try:
                view = memoryview(data)
                while view:
                    view = view[os.write(self._fd, view) :]
            except OSError as exc:
                self.failed = True
                os.ftruncate(self._fd, self._size)
                os.lseek(self._fd, self._size, os.SEEK_SET)
                raise write_error(exc, self.path.parent) from None
            self._size += len(data)
            self._buffer.seek(0)
            self._buffer.truncate()
        self._waiting = 0
        self._flushed_at = time.monotonic()

    def finish(self) -> Path:
        """The table is complete: synced and renamed to its own name."""
        self.flush()
        assert self._fd is not None, f"{self.path.name} finished twice or after abandon()"
        try:
            os.fsync(self._fd)
        except OSError as exc:
            raise write_error(exc, self.path.parent) from None
        os.close(self._fd)
        self._fd = None
        rename(self.part, self.path)
        return self.path

    def abandon(self) -> Path | None:
        """The run did not complete: keep what was written as ``partial_<name>`` (None if finished).
        Never raises for a write that fails here: the run's first error is what counts."""
        if self._fd is None:
            return None
        if not self.failed:
            try:
                self.flush()
            except OSError:
                pass  # cut back to whole rows already
        os.close(self._fd)
        self._fd = None
        return keep_partial(self.part)


def keep_partial(part: Path) -> Path | None:
    """Rename ``<name>.part`` left by an unfinished run to ``partial_<name>`` (if it exists)."""
    if not part.exists():
        return None
    name = part.name.removesuffix(PART_SUFFIX)
    target = part.with_name(PARTIAL_PREFIX + name)
    rename(part, target)
    return target
