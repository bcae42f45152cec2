"""Opening Zenoh sessions the swarmbed way, and the shared ``--mode/--connect/--listen/--config`` flags.

Multicast scouting is always off: processes find each other only through explicit endpoints, so
two runs (or two users) on one machine never discover each other.
"""

from __future__ import annotations

import argparse
import json
import socket
from collections.abc import Sequence

import zenoh


def zenoh_config(
    mode: str = "client",
    connect: Sequence[str] = (),
    listen: Sequence[str] = (),
    config_file: str | None = None,
) -> zenoh.Config:
    conf = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return conf


def add_zenoh_args(parser: argparse.ArgumentParser, default_mode: str = "client") -> None:
    """The flags every swarmbed process accepts, as zenoh-python's examples share them."""
    g = parser.add_argument_group("zenoh")
    g.add_argument("--mode", choices=["client", "peer", "router"], default=default_mode,
                   help=f"zenoh session mode (default: {default_mode})")
    g.add_argument("--connect", "-e", action="append", default=[], metavar="ENDPOINT",
                   help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    g.add_argument("--listen", "-l", action="append", default=[], metavar="ENDPOINT",
                   help="endpoint to listen on (repeatable)")
    g.add_argument("--config", dest="zenoh_config", metavar="FILE", help="a zenoh JSON5 configuration file")


def open_from_args(args: argparse.Namespace) -> zenoh.Session:
    return zenoh.open(zenoh_config(args.mode, args.connect, args.listen, args.zenoh_config))


def free_loopback_endpoint() -> str:
    """A TCP endpoint on a currently free loopback port (the caller retries if it is taken meanwhile)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"
