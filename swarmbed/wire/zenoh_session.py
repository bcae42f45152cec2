"""Opening Zenoh sessions the swarmbed way, and the shared ``--mode/--connect/--listen/--config`` flags.

Multicast scouting is always off: processes find each other only through explicit endpoints, so
two runs (or two users) on one machine never discover each other.

Zenoh's shared-memory transport is off unless a ``--config`` file says otherwise. With it on, a
session's first message over 3 KB (a checkpoint, a large consensus message) makes it a 16 MB pool
in ``/dev/shm``, and every session it reaches maps that pool: the hub held 16 MB per agent (1 GB
at 50 agents) and kept a dead session's pool mapped, so each restarted agent added 16 MB and two
file descriptors for good. Between a few hundred processes on one machine the copy it saves is a
few KB per message, and a container's default 64 MB ``/dev/shm`` would fill at four agents.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import socket
from collections.abc import Sequence
from pathlib import Path

import zenoh

from swarmbed.wire.credentials import CredentialsError, read_credentials

#: ZENOH_RUNTIME for ``run.zenoh_threads: single``: every Zenoh runtime handed over to one worker
#: thread, so a sample in and a sample out wake one thread instead of several
SINGLE_WORKER = (
    "(app: (handover: rx), acc: (handover: rx), tx: (handover: rx), net: (handover: rx), rx: (worker_threads: 1))"
)


#: ZENOH_RUNTIME for ``run.zenoh_threads: default``: as the single worker, but Zenoh's transmit runtime
#: on a worker of its own, so keep-alives go out while a tick runs on the receiving worker (a client
#: keeps Zenoh's 10 s lease: a cut-off host is noticed as soon as with Zenoh's own layout)
SPLIT_WORKERS = (
    "(app: (handover: rx), acc: (handover: rx), net: (handover: rx), rx: (worker_threads: 1), tx: (worker_threads: 1))"
)

#: the ZENOH_RUNTIME of each ``run.zenoh_threads`` value (``zenoh``, Zenoh's own layout: none)
RUNTIMES = {"default": SPLIT_WORKERS, "single": SINGLE_WORKER}


#: A client on the single worker answers ticks on Zenoh's only thread, which sends no keep-alive
#: while a tick runs: its lease (how long its router waits before giving it up) is a minute, not
#: Zenoh's 10 s, so that a long tick does not cost the agent its session
SINGLE_WORKER_LEASE_MS = 60_000


def single_worker() -> bool:
    """Whether this process's Zenoh runs on the single worker (``run.zenoh_threads: single``, or
    the same ``ZENOH_RUNTIME`` given by hand on another host)."""
    return os.environ.get("ZENOH_RUNTIME") == SINGLE_WORKER


def one_receiving_worker() -> bool:
    """Whether this process's Zenoh receives on one worker that may answer inside its callbacks
    (``run.zenoh_threads: default`` or ``single``)."""
    return os.environ.get("ZENOH_RUNTIME") in (SINGLE_WORKER, SPLIT_WORKERS)


def zenoh_config(
    mode: str = "client",
    connect: Sequence[str] = (),
    listen: Sequence[str] = (),
    config_file: str | None = None,
    credentials: str | None = None,
    settings: dict[str, object] | None = None,
    connect_timeout_s: float | None = None,
) -> zenoh.Config:
    """A session configuration. ``credentials``: a credentials file (see
    :mod:`swarmbed.wire.credentials`) whose user and password the session presents to the router it
    connects to; ``settings``: further configuration entries, by their path (e.g. ``access_control``);
    ``connect_timeout_s``: keep trying to connect that long (by default one attempt)."""
    conf = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if not config_file:
        conf.insert_json5("transport/shared_memory/enabled", "false")
    if single_worker() and mode == "client":
        conf.insert_json5("transport/link/tx/lease", json.dumps(SINGLE_WORKER_LEASE_MS))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
        if connect_timeout_s is not None:
            conf.insert_json5("connect/timeout_ms", json.dumps(int(connect_timeout_s * 1000)))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if credentials:
        identity = read_credentials(credentials)
        conf.insert_json5("transport/auth/usrpwd", json.dumps({"user": identity.user, "password": identity.password}))
    for path, value in (settings or {}).items():
        conf.insert_json5(path, json.dumps(value))
    return conf


def tls_settings(folder: str | Path, name: str) -> dict[str, object]:
    """Configuration entries for machine ``name``'s TLS links (``tls/HOST:PORT`` endpoints), as
    ``swarmbed certs`` lays them out in ``folder``: both ends of every link present a certificate of
    the folder's CA (mutual authentication), and a connecting end checks the name it dialled."""
    folder = Path(folder)
    needed = [folder / "ca.pem", folder / f"{name}.pem", folder / f"{name}.key"]
    missing = [str(p) for p in needed if not p.exists()]
    if missing:
        raise CredentialsError(
            f"TLS files missing: {', '.join(missing)} (swarmbed certs {folder} {name}=ADDRESS makes them)"
        )
    ca, cert, key = (str(p.resolve()) for p in needed)
    return {
        "transport/link/tls": {
            "root_ca_certificate": ca,
            "enable_mtls": True,
            "verify_name_on_connect": True,
            "listen_certificate": cert,
            "listen_private_key": key,
            "connect_certificate": cert,
            "connect_private_key": key,
        }
    }


CHILD_CONNECT_TIMEOUT_S = 20.0  # a child process keeps trying to reach the hub this long, unless told


def _seconds(text: str) -> float:
    value = float(text)
    if not value >= 0:  # also NaN
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds >= 0")
    return value


def connect_timeout(args: argparse.Namespace, default: float | None) -> float | None:
    """How long to keep trying to connect: ``--connect-timeout`` if given, else ``default``."""
    given = getattr(args, "connect_timeout", None)
    return default if given is None else given


def add_zenoh_args(parser: argparse.ArgumentParser, default_mode: str = "client", retries: bool = True) -> None:
    """The flags every swarmbed process accepts, as zenoh-python's examples share them
    (``--connect-timeout`` unless ``retries`` is False: a router keeps trying on its own)."""
    g = parser.add_argument_group("zenoh")
    g.add_argument(
        "--mode",
        choices=["client", "peer", "router"],
        default=default_mode,
        help=f"zenoh session mode (default: {default_mode})",
    )
    g.add_argument(
        "--connect",
        "-e",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)",
    )
    g.add_argument(
        "--listen", "-l", action="append", default=[], metavar="ENDPOINT", help="endpoint to listen on (repeatable)"
    )
    g.add_argument("--config", dest="zenoh_config", metavar="FILE", help="a zenoh JSON5 configuration file")
    g.add_argument(
        "--credentials",
        metavar="FILE",
        help="a credentials file (user and password, mode 600) for a hub that requires them",
    )
    g.add_argument("--tls", metavar="DIR", help="certificates made by swarmbed certs, for tls/HOST:PORT endpoints")
    if retries:
        g.add_argument(
            "--connect-timeout",
            type=_seconds,
            default=None,
            metavar="SECONDS",
            help=f"how long to keep trying to reach --connect before giving up (default: "
            f"{CHILD_CONNECT_TIMEOUT_S:.0f} for a run's processes, --wait where a command has it, else one try)",
        )
    g.add_argument(
        "--tls-name",
        metavar="NAME",
        help="whose certificate in --tls DIR this process presents (default: the host's --name, else "
        "this machine's host name)",
    )


def open_from_args(args: argparse.Namespace) -> zenoh.Session:
    """A child process's session from its flags. One that cannot open (nothing listens there, the
    hub refuses the credentials, the credentials file is unreadable) ends the process with exit
    code 2 and a message that says where and why."""
    try:
        # a hub that hundreds of agents reach at once refuses some connections for a moment: retry
        return zenoh.open(
            zenoh_config(
                args.mode,
                args.connect,
                args.listen,
                args.zenoh_config,
                args.credentials,
                tls_from_args(args),
                connect_timeout_s=connect_timeout(args, CHILD_CONNECT_TIMEOUT_S),
            )
        )
    except CredentialsError as exc:
        logging.getLogger("swarmbed").error("%s", exc)
    except zenoh.ZError as exc:
        who = f"credentials of {args.credentials}" if args.credentials else "no credentials"
        logging.getLogger("swarmbed").error(
            "cannot open a session to %s with %s: %s",
            ", ".join(args.connect) or "any endpoint",
            who,
            str(exc).split("  at ")[0],
        )
    raise SystemExit(2)


def tls_from_args(args: argparse.Namespace) -> dict[str, object] | None:
    """:func:`tls_settings` for ``--tls DIR [--tls-name NAME]``, or None without ``--tls``."""
    if not getattr(args, "tls", None):
        return None
    name = args.tls_name or getattr(args, "name", None) or socket.gethostname()
    return tls_settings(args.tls, name)


def free_port(address: str) -> int:
    """A TCP port currently free on ``address`` (the caller retries if it is taken meanwhile)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((address, 0))
        return int(s.getsockname()[1])


def free_loopback_endpoint() -> str:
    """A TCP endpoint on a currently free loopback port (the caller retries if it is taken meanwhile)."""
    return f"tcp/127.0.0.1:{free_port('127.0.0.1')}"


def undeclare_all(entities: list) -> None:
    """Undeclare Zenoh entities (publishers, subscribers, queryables, tokens) in reverse order of
    declaration, each on its own: one already gone with its session does not keep the others
    declared. Empties ``entities``."""
    for entity in reversed(entities):
        try:
            entity.undeclare()
        except Exception:
            pass
    entities.clear()
