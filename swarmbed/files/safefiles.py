"""Files of folders a user may have received: no write ever follows a link, no read is unbounded.

A results folder, a sweep folder or an ``--out`` folder can hold links someone planted
(``scenario_summary.csv -> ~/.bashrc``). Every command writes through this module alone:

* a file is written under a fresh name inside a private folder (``mkdtemp``, mode 700, beside the
  target) and renamed over the target, so the rename replaces a link that stands there instead of
  writing through it, and nobody can plant a link at the temporary name;
* a file that is written as it grows (a log, a table, a tree log) is opened with ``O_EXCL`` and
  ``O_NOFOLLOW`` after whatever stood at its name is removed;
* a sub-folder is made (or reused) only when no part of it below the folder the user named is a link.

The folder the user named is theirs: a link *there* is what they asked for and is followed.

Reading a file a user names (an experiment, a map, a sweep, a tree) goes through
:func:`read_regular`: it must be a regular file (not ``/dev/zero``, a FIFO or a link loop) and is
read with a bounded read, never trusting ``st_size``.
"""

from __future__ import annotations

import errno
import os
import shutil
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO


class LinkRefused(OSError):
    """A write that would have gone through a symbolic link or out of its folder; one line: the CLI
    prints ``error: <why>: <path>``."""

    def __init__(self, path: Path | str, why: str = "a symbolic link stands there: not written through") -> None:
        super().__init__(errno.ELOOP, why, str(path))


def inside(root: Path, path: Path) -> Path:
    """``path`` (below ``root``) checked: no existing part of it below ``root`` is a link, and it
    stays inside ``root``. Returns ``path``."""
    root, path = Path(root), Path(path)
    try:
        parts = path.relative_to(root).parts
    except ValueError:
        raise LinkRefused(path, f"outside the folder {root}: not written") from None
    if ".." in parts:
        raise LinkRefused(path, f"leaves the folder {root}: not written")
    here = root
    for part in parts[:-1]:
        here = here / part
        if here.is_symlink():
            raise LinkRefused(here)
    return path


def make_dirs(root: Path, path: Path) -> Path:
    """``path`` made as folders below ``root`` (``root`` itself as the user named it), refusing a
    link or a non-folder anywhere below ``root``; returns ``path``."""
    root, path = Path(root), Path(path)
    root.mkdir(parents=True, exist_ok=True)
    inside(root, path / "x")
    here = root
    for part in path.relative_to(root).parts:
        here = here / part
        try:
            here.mkdir()
        except FileExistsError:
            st = os.lstat(here)
            if stat.S_ISLNK(st.st_mode):
                raise LinkRefused(here) from None
            if not stat.S_ISDIR(st.st_mode):
                raise NotADirectoryError(errno.ENOTDIR, "not a folder", str(here)) from None
    return path


def _check_parent(path: Path) -> None:
    """The folder ``path`` goes into must exist; a link named ``path`` is fine (it is replaced),
    a folder named ``path`` is not."""
    if not path.parent.is_dir():
        raise FileNotFoundError(errno.ENOENT, "no such folder", str(path.parent))
    if path.is_dir() and not path.is_symlink():
        raise IsADirectoryError(errno.EISDIR, "a folder stands there", str(path))


@contextmanager
def replacing(path: Path | str) -> Iterator[Path]:
    """A fresh path to write in any way (a library's ``save(path)``); when the block ends without
    an error, what was written is renamed over ``path`` (replacing a link there, never following
    it). On an error nothing stands under ``path`` that was not there before."""
    path = Path(path)
    _check_parent(path)
    # not "*.part": the cleanups that remove a run's torn "<name>.part" files must never meet this folder
    private = Path(tempfile.mkdtemp(prefix=f".{path.name[:40]}.", suffix=".writing", dir=path.parent))
    try:
        tmp = private / path.name
        yield tmp
        if tmp.exists():
            os.replace(tmp, path)
    finally:
        shutil.rmtree(private, ignore_errors=True)


def write_bytes(path: Path | str, data: bytes, fsync: bool = False) -> Path:
    """``data`` as the whole file ``path``, complete or not at all (see :func:`replacing`)."""
    path = Path(path)
    with replacing(path) as tmp, open(tmp, "wb") as f:
        f.write(data)
        if fsync:
            f.flush()
            os.fsync(f.fileno())
    return path


def write_text(path: Path | str, text: str, fsync: bool = False) -> Path:
    return write_bytes(path, text.encode("utf-8"), fsync)


def create_fresh(path: Path | str, mode: int = 0o644) -> int:
    """A descriptor of ``path`` opened for writing as a new regular file: whatever stood at the
    name (a link, an old file) is removed first and the file is created with ``O_EXCL | O_NOFOLLOW``."""
    path = Path(path)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        pass
    else:
        if stat.S_ISDIR(st.st_mode):
            raise IsADirectoryError(errno.EISDIR, "a folder stands there", str(path))
        path.unlink()
    return os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, mode)


def open_fresh(path: Path | str, mode: int = 0o644) -> BinaryIO:
    """:func:`create_fresh` as a binary file object."""
    return os.fdopen(create_fresh(path, mode), "wb")


def open_append(path: Path | str, mode: int = 0o644) -> BinaryIO:
    """``path`` opened to append to (created if missing); a link standing there is removed first
    and the file is opened with ``O_NOFOLLOW``, so nothing is appended through a link."""
    path = Path(path)
    if path.is_symlink():
        path.unlink()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, mode)
    return os.fdopen(fd, "ab")


class UnreadableFile(ValueError):
    """A file a command will not read; the message is one line naming it and why (never its content)."""


def read_regular(path: Path | str, max_bytes: int) -> bytes:
    """The bytes of ``path``, a regular file of at most ``max_bytes``; opened without blocking (a
    FIFO never hangs the reader), checked on the open descriptor, read with a bounded read."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        why = "a loop of symbolic links" if exc.errno == errno.ELOOP else (exc.strerror or str(exc))
        raise UnreadableFile(f"{path}: cannot read: {why}") from None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise UnreadableFile(f"{path}: not a regular file (a device, a FIFO or a folder): not read")
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise UnreadableFile(f"{path}: larger than the {max_bytes:,} bytes read here")
    return data


def regular_files(folder: Path) -> list[Path]:
    """Every regular file below ``folder`` reached without following a link, sorted: what may be
    copied out of a folder someone else may have made (links, FIFOs and devices are left out)."""
    found: list[Path] = []
    for top, dirs, files in os.walk(folder, followlinks=False):
        dirs[:] = sorted(d for d in dirs if not os.path.islink(os.path.join(top, d)))
        for name in sorted(files):
            full = Path(top) / name
            if stat.S_ISREG(os.lstat(full).st_mode):
                found.append(full)
    return found
