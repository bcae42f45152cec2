"""Credentials files: who a process is when it connects to a run's hub.

A credentials file is a small JSON object ``{"user": ..., "password": ..., "role": ...}`` readable
only by its owner (like an ssh key, a file that others may read is refused). The password is sent
to the hub by Zenoh's own user/password authentication (``transport/auth/usrpwd``); swarmbed never
puts it on a command line, where ``ps`` would show it, and never writes it to a run directory.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import stat
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import IO

# roles a credentials file made by ``swarmbed credentials`` may have; the processes a run spawns
# itself get their own identities (netem, agent-<id>) from the launcher
ROLES = ("operator", "host")


class CredentialsError(ValueError):
    pass


@dataclass(frozen=True)
class Identity:
    user: str
    password: str
    role: str
    host: str = ""  # role host: the one host name this identity may act as (its user name if empty)

    @classmethod
    def new(cls, user: str, role: str, host: str = "") -> Identity:
        if not user or ":" in user or any(c.isspace() for c in user):
            raise CredentialsError(f"user name {user!r}: must be non-empty, without ':' or spaces")
        if host and not re.fullmatch(r"[A-Za-z0-9_.-]+", host):
            raise CredentialsError(f"host name {host!r}: letters, digits, _ . - only")
        return cls(user, secrets.token_urlsafe(24), role, host if role == "host" else "")

    @property
    def host_name(self) -> str:
        """The host a host identity is bound to: its daemon must run under this ``--name``."""
        return self.host or self.user


def open_private(path: str | Path, mode: str = "w") -> IO:
    """``path`` opened for writing (``"w"`` or ``"wb"``), emptied and readable by its owner only
    (mode 600, also when it existed before)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    f = os.fdopen(fd, mode)
    os.fchmod(fd, 0o600)  # an existing file keeps its mode through O_CREAT
    return f


def write_credentials(path: Path, identity: Identity) -> Path:
    """Write ``identity`` to ``path``, created readable and writable by its owner only."""
    with open_private(path) as f:
        json.dump(asdict(identity), f)
    return Path(path)


def read_credentials(path: str | Path) -> Identity:
    """The identity in ``path``; a CredentialsError names the file and what is wrong with it."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
        text = path.read_text()
    except OSError as exc:
        raise CredentialsError(f"credentials file {path}: {exc.strerror}") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise CredentialsError(
            f"credentials file {path}: readable by others (mode {stat.S_IMODE(mode):o}); run chmod 600 {path}"
        )
    try:
        data = json.loads(text)
        identity = Identity(
            str(data["user"]), str(data["password"]), str(data.get("role", "operator")), str(data.get("host", ""))
        )
    except (ValueError, KeyError, TypeError):
        raise CredentialsError(f"credentials file {path}: not a JSON object with user and password") from None
    return identity


def write_dictionary(path: Path, identities: Iterable[Identity]) -> Path:
    """A Zenoh usrpwd dictionary file (``user:password`` lines) admitting ``identities``, created
    readable by its owner only."""
    with open_private(path) as f:
        f.writelines(f"{i.user}:{i.password}\n" for i in identities)
    return Path(path)
