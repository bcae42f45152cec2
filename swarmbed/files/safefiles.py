"""Files of folders a user may have received: no write ever follows a link, no read is unbounded.

A results folder, a sweep folder or an ``--out`` folder can hold links someone planted
(``scenario_summary.csv -> ~/.bashrc``), and a link can be swapped in while a run writes. Every
command writes, renames and removes files through this module alone (``tests/test_safe_writes.py``
walks the package's syntax trees to hold that):

* the folder the user named is opened once (:func:`rooted`, :class:`Folder`), and everything below
  it is reached from that handle, part by part with ``O_NOFOLLOW`` (``openat``, ``mkdirat``,
  ``renameat``, ``unlinkat``): a link anywhere below it is refused, never followed;
* a file is written under a fresh name (``O_EXCL``) and renamed over the target, so the rename
  replaces a link that stands there instead of writing through it;
* a file that is written as it grows (a log, a table, a tree log) is created with ``O_EXCL`` and
  ``O_NOFOLLOW`` after whatever stood at its name is removed; one appended to is never a link nor a
  file with another hard link.

The folder the user named is theirs: a link *there* is what they asked for and is followed, once.

Reading a file a user names (an experiment, a map, a sweep, a tree) goes through
:func:`read_regular`: it must be a regular file (not ``/dev/zero``, a FIFO or a link loop) and is
read with a bounded read, never trusting ``st_size``.
"""

from __future__ import annotations

import errno
import os
import shutil
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO


class LinkRefused(OSError):
    """A write that would have gone through a symbolic link or out of its folder; one line: the CLI
    prints ``error: <why>: <path>``."""

    def __init__(self, path: Path | str, why: str = "a symbolic link stands there: not written through") -> None:
        super().__init__(errno.ELOOP, why, str(path))


# -- the folders a process writes below, each opened once -----------------------------------------
#: the folders the user named that this process writes below (a run's folder, a sweep's, an
#: analysis's): absolute path -> the folder opened once. A path below one of them is reached from
#: its handle, part by part with O_NOFOLLOW; any other path from its own parent folder.
_ROOTS: dict[Path, Folder] = {}


@contextmanager
def rooted(path: Path | str, create: bool = True) -> Iterator[Folder]:
    """The folder ``path`` opened once, and every write below it through this module reached from
    that handle until the block ends (a link swapped in anywhere below it is refused, never
    followed). A process names the folder the user gave it this way before it writes there."""
    key = Path(os.path.abspath(path))
    if key in _ROOTS:  # opened already (the launcher around a run it starts in this process)
        yield _ROOTS[key]
        return
    above = _root_of(key)  # a run folder of a sweep: reached from the sweep's handle, never through a link
    folder = above[1].child(key.relative_to(above[0]), create) if above else Folder.open(key, create)
    _ROOTS[key] = folder
    try:
        yield folder
    finally:
        del _ROOTS[key]
        folder.close()


def _root_of(path: Path) -> tuple[Path, Folder] | None:
    for root in sorted(_ROOTS, key=lambda r: len(r.parts), reverse=True):
        if root == path or root in path.parents:
            return root, _ROOTS[root]
    return None


@contextmanager
def _folder_of(path: Path | str, create: bool = False) -> Iterator[tuple[Folder, str]]:
    """The folder ``path`` goes into, opened (from a registered root's handle, part by part, or as
    the parent the user named), and ``path``'s name in it."""
    path = Path(os.path.abspath(path))
    if ".." in Path(path).parts:
        raise LinkRefused(path, "leaves its folder: not written")
    found = _root_of(path.parent)
    if found is None:
        folder = Folder.open(path.parent, create=False)
    else:
        root, top = found
        folder = top.child(path.parent.relative_to(root), create=create)
    try:
        yield folder, path.name
    finally:
        folder.close()


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
    """``path`` made as folders below ``root`` (``root`` itself as the user named it, made if
    missing), each part made or opened from the one above with O_NOFOLLOW; returns ``path``."""
    root, path = Path(root), Path(path)
    inside(root, path / "x")
    with rooted(root) as top:
        relative = Path(os.path.abspath(path)).relative_to(Path(os.path.abspath(root)))
        if relative.parts:
            top.child(relative).close()
    return path


def make_folder(path: Path | str) -> Path:
    """The folder ``path`` made if missing: below a folder opened with :func:`rooted`, part by part
    from its handle with O_NOFOLLOW (a link is refused); elsewhere as the user named it."""
    path = Path(os.path.abspath(path))
    found = _root_of(path)
    if found is None:
        path.mkdir(parents=True, exist_ok=True)  # the folder the user named: theirs to place
    elif found[0] != path:
        found[1].child(path.relative_to(found[0])).close()
    return path


def open_lock(path: Path | str) -> int:
    """A descriptor of the lock file ``path`` (made if missing, never through a link) to ``flock``."""
    with _folder_of(path) as (folder, name):
        st = folder.lstat(name)
        if st is not None and not stat.S_ISREG(st.st_mode):
            folder.remove(name)
        return os.open(name, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644, dir_fd=folder.fd)


def read_file(path: Path | str, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path`` in a folder someone else may have made: not a link, a
    FIFO or a device, at most ``max_bytes``, read without blocking (see :meth:`Folder.read_bytes`)."""
    try:
        with _folder_of(path) as (folder, name):
            return folder.read_bytes(name, max_bytes)
    except OSError as exc:
        raise UnreadableFile(f"{path}: cannot read: {exc.strerror or exc}") from None


@contextmanager
def replacing(path: Path | str) -> Iterator[Path]:
    """A fresh path to write in any way (a library's ``save(path)``); when the block ends without
    an error, what was written is renamed over ``path`` (replacing a link there, never following
    it). On an error nothing stands under ``path`` that was not there before."""
    with _folder_of(path) as (folder, name):
        if folder.is_dir(name):
            raise IsADirectoryError(errno.EISDIR, "a folder stands there", str(path))
        with folder.replacing(name) as tmp:
            yield tmp


def write_bytes(path: Path | str, data: bytes, fsync: bool = False, mode: int = 0o644) -> Path:
    """``data`` as the whole file ``path`` (created with ``mode``), complete or not at all (see
    :meth:`Folder.write_bytes`)."""
    with _folder_of(path) as (folder, name):
        folder.write_bytes(name, data, fsync, mode)
    return Path(path)


def write_text(path: Path | str, text: str, fsync: bool = False, mode: int = 0o644) -> Path:
    return write_bytes(path, text.encode("utf-8"), fsync, mode)


def own_folders(parent: Path, pattern: str) -> list[Path]:
    """The folders in ``parent`` (a shared one, such as the temporary folder) matching ``pattern``
    that belong to this user and are not links: another local user's are never looked into."""
    found = []
    for path in sorted(Path(parent).glob(pattern)):
        try:
            st = os.lstat(path)
        except OSError:
            continue
        if stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid():
            found.append(path)
    return found


def create_fresh(path: Path | str, mode: int = 0o644) -> int:
    """A descriptor of ``path`` opened for writing as a new regular file: whatever stood at the
    name (a link, an old file) is removed first and the file is created with ``O_EXCL | O_NOFOLLOW``."""
    with _folder_of(path) as (folder, name):
        return folder.create_fresh(name, mode)


def open_fresh(path: Path | str, mode: int = 0o644) -> BinaryIO:
    """:func:`create_fresh` as a binary file object."""
    return os.fdopen(create_fresh(path, mode), "wb")


def open_append(path: Path | str, mode: int = 0o644) -> BinaryIO:
    """``path`` opened to append to (created if missing), never through a link and never to a file
    with another hard link (see :meth:`Folder.open_append`)."""
    with _folder_of(path) as (folder, name):
        return folder.open_append(name, mode)


def remove(path: Path | str) -> bool:
    """The file or link ``path`` removed (a link's target untouched); True if it was there."""
    try:
        with _folder_of(path) as (folder, name):
            return folder.remove(name)
    except FileNotFoundError:  # its folder is gone: so is it
        return False


def remove_tree(path: Path | str) -> None:
    """``path`` and everything below it removed, never following a link; nothing if missing."""
    try:
        with _folder_of(path) as (folder, name):
            folder.remove_tree(name)
    except FileNotFoundError:
        pass


def rename(old: Path | str, new: Path | str) -> None:
    """``old`` renamed to ``new`` in the same folder (a link at ``new`` is replaced, never followed)."""
    if Path(os.path.abspath(old)).parent != Path(os.path.abspath(new)).parent:
        raise LinkRefused(new, "a rename across folders: not made")
    with _folder_of(old) as (folder, name):
        folder.rename(name, Path(new).name)


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
    return _bounded(fd, path, max_bytes)


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


# -- a folder opened once: every operation below it relative to its handle -----------------------
_DIR_FLAGS = os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC
_FRESH_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC


class Folder:
    """A folder the user named, opened once; every file below it is made, replaced, appended to,
    renamed or removed relative to that handle (``openat``, ``mkdirat``, ``renameat``,
    ``unlinkat``), so no path below it is ever resolved twice and a link swapped in meanwhile is
    never followed. Each sub-folder is opened component by component with ``O_NOFOLLOW``.

    The folder itself is the user's: a link at the path they named is followed, once, when it is
    opened. A file with more than one hard link is replaced, never appended to or truncated (it
    may be somebody else's file linked in). Names are single path components; ``..`` is refused.

    A library that takes a path (pandas, plotly, MLflow) is handed :meth:`pinned`: a path through
    ``/proc/self/fd`` that reaches this very folder whatever happens to its name meanwhile.

    Use it as a context manager, or :meth:`close` it."""

    def __init__(self, fd: int, path: Path) -> None:
        self.fd, self.path = fd, Path(path)

    @classmethod
    def open(cls, path: Path | str, create: bool = True) -> Folder:
        """The folder ``path`` (made with its parents if missing and ``create``), opened."""
        path = Path(path)
        if create:
            path.mkdir(parents=True, exist_ok=True)  # noqa: the folder the user named, theirs to place
        try:
            return cls(os.open(path, _DIR_FLAGS), path)
        except NotADirectoryError:
            raise NotADirectoryError(errno.ENOTDIR, "not a folder", str(path)) from None

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    def __enter__(self) -> Folder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except OSError:
            pass

    def __repr__(self) -> str:
        return f"Folder({str(self.path)!r})"

    # -- names ---------------------------------------------------------------------------------
    def _name(self, name: str) -> str:
        if not name or name in (".", "..") or "/" in name or "\0" in name:
            raise LinkRefused(self.path / str(name), f"not a name of a file in the folder {self.path}: not used")
        return name

    def pinned(self, name: str = "") -> Path:
        """A path to ``name`` in this folder through its open handle, for a library that wants a
        path: it reaches this folder even if its name is swapped for a link meanwhile."""
        return Path(f"/proc/self/fd/{self.fd}") / (self._name(name) if name else "")

    def lstat(self, name: str) -> os.stat_result | None:
        """What stands at ``name`` (a link is not followed), or None."""
        try:
            return os.stat(self._name(name), dir_fd=self.fd, follow_symlinks=False)
        except FileNotFoundError:
            return None

    def is_file(self, name: str) -> bool:
        st = self.lstat(name)
        return st is not None and stat.S_ISREG(st.st_mode)

    def is_dir(self, name: str) -> bool:
        st = self.lstat(name)
        return st is not None and stat.S_ISDIR(st.st_mode)

    def names(self) -> list[str]:
        """The names in this folder, sorted."""
        return sorted(os.listdir(self.fd))

    # -- folders -------------------------------------------------------------------------------
    def child(self, relative: str | Path, create: bool = True) -> Folder:
        """The sub-folder ``relative`` (``a`` or ``a/b``), each part made if missing and ``create``,
        each opened with ``O_NOFOLLOW`` relative to the one above: a link anywhere is refused."""
        parent, fd = self.path, os.dup(self.fd)
        try:
            for part in Path(relative).parts:
                name = self._name(part)
                if create:
                    try:
                        os.mkdir(name, 0o777, dir_fd=fd)
                    except FileExistsError:
                        pass
                try:
                    inner = os.open(name, _DIR_FLAGS | os.O_NOFOLLOW, dir_fd=fd)
                except OSError as exc:
                    if exc.errno in (errno.ELOOP, errno.ENOTDIR):
                        raise LinkRefused(
                            parent / name, "a link or a file stands there, not a folder: not used"
                        ) from None
                    raise
                os.close(fd)
                fd, parent = inner, parent / name
        except BaseException:
            os.close(fd)
            raise
        return Folder(fd, parent)

    def make_private(self, prefix: str) -> Folder:
        """A new sub-folder of a random name (mode 700) that nobody else can have prepared."""
        for _ in range(100):
            name = f".{prefix}{os.urandom(6).hex()}"
            try:
                os.mkdir(name, 0o700, dir_fd=self.fd)
            except FileExistsError:
                continue
            return self.child(name, create=False)
        raise FileExistsError(errno.EEXIST, "no free private folder name", str(self.path))

    # -- writing -------------------------------------------------------------------------------
    def create_fresh(self, name: str, mode: int = 0o644) -> int:
        """A descriptor of ``name`` opened for writing as a new regular file: whatever stood there
        (a link, an old file) is removed first, and it is created with ``O_EXCL | O_NOFOLLOW``."""
        self.remove(name)
        return os.open(self._name(name), _FRESH_FLAGS, mode, dir_fd=self.fd)

    def open_fresh(self, name: str, mode: int = 0o644) -> BinaryIO:
        return os.fdopen(self.create_fresh(name, mode), "wb")

    def write_bytes(self, name: str, data: bytes, fsync: bool = False, mode: int = 0o644) -> Path:
        """``data`` as the whole file ``name``, complete or not at all: written under a fresh name
        and renamed over ``name`` (replacing a link there, never following it)."""
        self._name(name)
        if self.is_dir(name):
            raise IsADirectoryError(errno.EISDIR, "a folder stands there", str(self.path / name))
        for _ in range(100):
            tmp = f".{name[:40]}.{os.urandom(6).hex()}.writing"
            try:
                fd = os.open(tmp, _FRESH_FLAGS, mode, dir_fd=self.fd)
            except FileExistsError:
                continue
            break
        else:
            raise FileExistsError(errno.EEXIST, "no free temporary name", str(self.path / name))
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                if fsync:
                    f.flush()
                    os.fsync(f.fileno())
            os.rename(tmp, name, src_dir_fd=self.fd, dst_dir_fd=self.fd)
        except BaseException:
            self.remove(tmp)
            raise
        return self.path / name

    def write_text(self, name: str, text: str, fsync: bool = False, mode: int = 0o644) -> Path:
        return self.write_bytes(name, text.encode("utf-8"), fsync, mode)

    @contextmanager
    def replacing(self, name: str) -> Iterator[Path]:
        """A fresh path (pinned to this folder's handle) for a library to write ``name`` at; when the
        block ends without an error, what was written is renamed over ``name``."""
        self._name(name)
        private = self.make_private(f"{name[:40]}.")
        try:
            yield private.pinned(name)
            if private.lstat(name) is not None:
                os.rename(name, name, src_dir_fd=private.fd, dst_dir_fd=self.fd)
        finally:
            private_name = private.path.name
            private.close()
            self.remove_tree(private_name)

    def open_append(self, name: str, mode: int = 0o644) -> BinaryIO:
        """``name`` opened to append to (created if missing). A link standing there is removed; a
        file with more than one hard link, or not a regular file, is replaced by a fresh copy of
        its content first, so nothing is appended to a file that is also somebody else's."""
        self._name(name)
        st = self.lstat(name)
        if st is not None and (stat.S_ISLNK(st.st_mode) or not stat.S_ISREG(st.st_mode)):
            self.remove(name)
        elif st is not None and st.st_nlink > 1:
            self.write_bytes(name, self.read_bytes(name, st.st_size))
        flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC
        fd = os.open(name, flags, mode, dir_fd=self.fd)
        after = os.fstat(fd)
        if after.st_nlink > 1 or not stat.S_ISREG(after.st_mode):  # linked again in between
            os.close(fd)
            raise LinkRefused(self.path / name, "a file linked elsewhere too: not appended to")
        return os.fdopen(fd, "ab")

    def rename(self, old: str, new: str) -> None:
        """``old`` renamed to ``new`` in this folder (replacing a link at ``new``, never following it)."""
        os.rename(self._name(old), self._name(new), src_dir_fd=self.fd, dst_dir_fd=self.fd)

    def remove(self, name: str) -> bool:
        """``name`` removed if it is a file or a link (a link's target is untouched); True if it was.
        A folder there is refused."""
        try:
            os.unlink(self._name(name), dir_fd=self.fd)
        except FileNotFoundError:
            return False
        except IsADirectoryError:
            raise IsADirectoryError(errno.EISDIR, "a folder stands there", str(self.path / name)) from None
        return True

    def remove_tree(self, name: str) -> None:
        """``name`` removed with everything below it, never following a link (a link there is
        removed as a link); nothing if it is missing."""
        st = self.lstat(name)
        if st is None:
            return
        if not stat.S_ISDIR(st.st_mode):
            self.remove(name)
            return
        shutil.rmtree(name, dir_fd=self.fd)

    # -- reading -------------------------------------------------------------------------------
    def read_bytes(self, name: str, max_bytes: int) -> bytes:
        """The bytes of the regular file ``name`` (not a link, a FIFO or a device), at most
        ``max_bytes``, read without blocking; an UnreadableFile names it otherwise."""
        shown = self.path / name
        try:
            fd = os.open(self._name(name), os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW | os.O_CLOEXEC, dir_fd=self.fd)
        except OSError as exc:
            why = "a symbolic link: not read" if exc.errno == errno.ELOOP else (exc.strerror or str(exc))
            raise UnreadableFile(f"{shown}: cannot read: {why}") from None
        return _bounded(fd, shown, max_bytes)


def _bounded(fd: int, shown: Path, max_bytes: int) -> bytes:
    """At most ``max_bytes`` of the open regular file ``fd`` (closed after); an UnreadableFile
    names ``shown`` for anything else, a read error too."""
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise UnreadableFile(f"{shown}: not a regular file (a device, a FIFO or a folder): not read")
        try:
            data = f.read(max_bytes + 1)
        except OSError as exc:
            raise UnreadableFile(f"{shown}: cannot read: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        raise UnreadableFile(f"{shown}: larger than the {max_bytes:,} bytes read here")
    return data
