"""Credentials files: who a process is when it connects to a run's hub.

A credentials file is a small JSON object ``{"user": ..., "password": ..., "role": ...}`` readable
only by its owner (like an ssh key, a file that others may read is refused). The password is sent
to the hub by Zenoh's own user/password authentication (``transport/auth/usrpwd``); swarmbed never
puts it on a command line, where ``ps`` would show it, and never writes it to a run directory.
"""

from __future__ import annotations

import errno
import json
import os
import re
import secrets
import stat
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path

from swarmbed.files import safefiles

# roles a credentials file made by ``swarmbed credentials`` may have; the processes a run spawns
# itself get their own identities (netem, agent-<id>) from the launcher
ROLES = ("operator", "host", "commander")  # commander: an operator that may publish ROS 2 decisions
#: every role an identity may hold: the admitted ones and those of the processes a run spawns
ALL_ROLES = (*ROLES, "netem", "agent")
#: user and host names: one line of the hub's ``user:password`` dictionary and one key chunk of
#: ``swarmbed/hosts/<name>`` each, so no ``:``, no line break, no wildcard, bounded
#: and no leading ``.`` or ``-`` (``..`` and ``-rf`` are not names: one would be a folder's parent,
#: the other an option on any command line it lands on)
NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.@-]{0,63}")
#: the user names a run or a host daemon gives its own processes (``netem``, ``agent-<i>``,
#: ``<host>-agents``): never an admitted identity's
RESERVED = re.compile(r"netem|agent-[0-9]+|.*-agents")
#: the longest host name: ``<host>-agents``, its agents' identity, must itself be a user name
MAX_HOST_NAME = 64 - len("-agents")
#: passwords: what ``secrets.token_urlsafe`` writes, or any printable ASCII without spaces or ``:``
PASSWORD = re.compile(r"[!-9;-~]{8,256}")
#: a credentials file is a few hundred bytes; anything far larger is not one (and is not read)
MAX_FILE_BYTES = 4096


class CredentialsError(ValueError):
    pass


@dataclass(frozen=True)
class Identity:
    user: str
    password: str
    role: str
    host: str = ""  # role host: the one host name this identity may act as (its user name if empty)

    def __post_init__(self) -> None:
        """Every field checked, whoever built the identity: a password with a line break would write a
        second ``user:password`` line into the hub's dictionary, a host of ``*`` would be given every
        host's keys."""
        for field in ("user", "password", "role", "host"):
            if not isinstance(getattr(self, field), str):
                raise CredentialsError(f"{field}: must be a string, not {type(getattr(self, field)).__name__}")
        if not NAME.fullmatch(self.user):
            raise CredentialsError(
                f"user name {self.user[:80]!r}: 1 to 64 letters, digits, _ . @ -, starting with a letter, digit or _"
            )
        if self.role in ROLES and RESERVED.fullmatch(self.user):
            raise CredentialsError(
                f"user name {self.user!r}: a name a run gives its own processes (netem, agent-<i>, <host>-agents)"
            )
        if not PASSWORD.fullmatch(self.password):
            raise CredentialsError("password: 8 to 256 printable characters, without spaces, ':' or line breaks")
        if self.role not in ALL_ROLES:
            raise CredentialsError(f"role {self.role[:80]!r}: one of {', '.join(ROLES)}")
        if self.host and self.role != "host":
            raise CredentialsError(f"host name {self.host[:80]!r}: only a host identity has one")
        if self.role == "host":
            check_host_name(self.host_name)

    @classmethod
    def new(cls, user: str, role: str, host: str = "") -> Identity:
        return cls(user, secrets.token_urlsafe(24), role, host if role == "host" else "")

    @property
    def host_name(self) -> str:
        """The host a host identity is bound to: its daemon must run under this ``--name``."""
        return self.host or self.user


def check_host_name(name: str) -> str:
    """``name`` if it can name a host (placements, ``swarmbed host --name``), else a CredentialsError."""
    if not (isinstance(name, str) and NAME.fullmatch(name) and "@" not in name and len(name) <= MAX_HOST_NAME):
        raise CredentialsError(
            f"host name {str(name)[:80]!r}: 1 to {MAX_HOST_NAME} letters, digits, _ . -, starting with a letter, "
            "digit or _"
        )
    return name


def write_private(path: str | Path, data: bytes, replace: bool = True) -> Path:
    """``data`` as the whole file ``path``, readable by its owner only (mode 600 from its creation):
    written under a fresh name and renamed over ``path``, so a link or a hard link standing there is
    replaced, never written through or truncated. ``replace=False``: a FileExistsError if anything
    stands at ``path``."""
    if not replace and os.path.lexists(path):
        raise FileExistsError(errno.EEXIST, "exists", str(path))
    return safefiles.write_bytes(path, data, mode=0o600)


def write_credentials(path: Path, identity: Identity, replace: bool = True) -> Path:
    """Write ``identity`` to ``path``, created readable and writable by its owner only. ``replace=False``:
    a CredentialsError if ``path`` exists (a user's file is never replaced without asking)."""
    try:
        write_private(path, json.dumps(asdict(identity)).encode(), replace=replace)
    except FileExistsError:
        raise CredentialsError(f"{path}: exists; give --force to replace it with new credentials") from None
    except OSError as exc:
        raise CredentialsError(f"{path}: {exc.strerror or exc}") from None
    return Path(path)


def read_credentials(path: str | Path) -> Identity:
    """The identity in ``path``; a CredentialsError names the file and what is wrong with it."""
    path = Path(path)
    try:
        st = path.stat()
    except OSError as exc:
        raise CredentialsError(f"credentials file {path}: {exc.strerror}") from None
    # type, size and mode before a byte is read: /dev/zero or a FIFO would never end
    if not stat.S_ISREG(st.st_mode):
        raise CredentialsError(f"credentials file {path}: not a regular file")
    if st.st_size > MAX_FILE_BYTES:
        raise CredentialsError(f"credentials file {path}: {st.st_size} bytes, more than a credentials file holds")
    if st.st_mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise CredentialsError(
            f"credentials file {path}: readable by others (mode {stat.S_IMODE(st.st_mode):o}); run chmod 600 {path}"
        )
    try:
        with open(path, "rb") as f:
            raw = f.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise CredentialsError(f"credentials file {path}: {exc.strerror}") from None
    try:
        data = json.loads(raw)
    except (ValueError, RecursionError):  # nested brackets overflow json's recursion
        raise CredentialsError(f"credentials file {path}: not JSON") from None
    if not isinstance(data, dict) or not {"user", "password"} <= data.keys():
        raise CredentialsError(f"credentials file {path}: not a JSON object with user and password")
    unknown = sorted(str(k) for k in data.keys() - {"user", "password", "role", "host"})
    if unknown:
        raise CredentialsError(f"credentials file {path}: unknown field {unknown[0][:40]!r}")
    try:
        return Identity(data["user"], data["password"], data.get("role", "operator"), data.get("host", ""))
    except CredentialsError as exc:
        raise CredentialsError(f"credentials file {path}: {exc}") from None


def check_admitted(identities: Iterable[Identity]) -> list[Identity]:
    """The identities a hub is asked to admit, refused unless each is an operator or a host and no two
    share a user name or are bound to one host name (the later would take the earlier's keys)."""
    out: list[Identity] = []
    users: set[str] = set()
    hosts: set[str] = set()
    for identity in identities:
        if identity.role not in ROLES:
            raise CredentialsError(f"user {identity.user!r}: role {identity.role!r} cannot be admitted (only {ROLES})")
        if identity.user in users:
            raise CredentialsError(f"two admitted credentials files are both user {identity.user!r}")
        users.add(identity.user)
        if identity.role == "host":
            if identity.host_name in hosts:
                raise CredentialsError(f"two admitted credentials files are both bound to host {identity.host_name!r}")
            hosts.add(identity.host_name)
        out.append(identity)
    return out


def write_dictionary(path: Path, identities: Iterable[Identity]) -> Path:
    """A Zenoh usrpwd dictionary file (``user:password`` lines) admitting ``identities``, created
    readable by its owner only."""
    return write_private(path, "".join(f"{i.user}:{i.password}\n" for i in identities).encode())
