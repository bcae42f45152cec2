"""``swarmbed watch`` and ``groot``: looking inside a run while it goes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from swarmbed.cli.common import add_live_view, client_session, port_number
from swarmbed.wire.zenoh_session import add_zenoh_args

if TYPE_CHECKING:
    from swarmbed.cli.common import Subparsers


def cmd_watch(args: argparse.Namespace) -> int:

    from swarmbed.results.watch import WatchError, watch

    session = client_session(args, connect_timeout_s=args.wait)  # the run may not be up yet
    if session is None:
        return 2
    live = None
    if args.foxglove is not None:
        from swarmbed.results.foxglove_live import StatusFoxglove
        from swarmbed.results.recording import RecordingError

        try:
            live = StatusFoxglove(args.foxglove, max_clients=args.view_clients)
        except RecordingError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        print(f"Foxglove: open connection {live.url}", file=sys.stderr, flush=True)
    with session:
        try:
            return watch(
                session, args.run, wait=args.wait, map_file=Path(args.map) if args.map else None, foxglove=live
            )
        except WatchError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        finally:
            if live is not None:
                live.close()


def register_watch(sub: Subparsers) -> None:
    """``swarmbed watch``: its arguments, run by :func:`cmd_watch`."""
    wat = sub.add_parser("watch", help="a live view of a running experiment (read-only)")
    wat.add_argument("--run", help="the run id (default: the one run visible from the endpoint)")
    wat.add_argument(
        "--wait", type=float, default=10.0, help="seconds to wait for the hub to listen and the run to answer"
    )
    wat.add_argument("--map", metavar="FILE.html", help="also keep a map of the run in FILE.html (reloads itself)")
    add_live_view(wat, "0: a free port; agents, poses and markers from the run's progress samples; the viewers extra")
    add_zenoh_args(wat)
    wat.set_defaults(func=cmd_watch)


def cmd_groot(args: argparse.Namespace) -> int:
    from swarmbed.results.groot import run_gateway
    from swarmbed.results.watch import WatchError

    try:
        import zmq  # noqa: F401
    except ImportError:
        print("error: swarmbed groot needs pyzmq: pip install 'swarmbed[viewers]'", file=sys.stderr)
        return 2
    session = client_session(args, connect_timeout_s=args.wait)  # the run may not be up yet
    if session is None:
        return 2
    with session:
        try:
            return run_gateway(session, args.run, args.agent, args.port, args.bind, wait=args.wait)
        except WatchError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2


def register_groot(sub: Subparsers) -> None:
    """``swarmbed groot``: its arguments, run by :func:`cmd_groot`."""
    gr = sub.add_parser("groot", help="watch an agent's behavior tree of a running run in Groot2, live")
    gr.add_argument("--run", help="the run id (default: the one run visible from the endpoint)")
    gr.add_argument("--agent", type=int, default=0, help="the agent to show first (type another id to switch)")
    gr.add_argument(
        "--port", type=port_number, default=1667, help="Groot2's port (and the next one), as BehaviorTree.CPP"
    )
    gr.add_argument("--bind", default="127.0.0.1", help="the address Groot2 connects to (default: this machine only)")
    gr.add_argument(
        "--wait", type=float, default=10.0, help="seconds to wait for the hub to listen and the run to answer"
    )
    add_zenoh_args(gr)
    gr.set_defaults(func=cmd_groot)
