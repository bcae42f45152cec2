"""``swarmbed credentials``, ``certs``, ``host``, ``hosts`` and ``swap``: machines, identities and moving agents."""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from swarmbed.cli.common import client_session, positive
from swarmbed.wire.zenoh_session import add_zenoh_args

if TYPE_CHECKING:
    from swarmbed.cli.common import Subparsers


def cmd_credentials(args: argparse.Namespace) -> int:
    from swarmbed.wire.credentials import CredentialsError, Identity, write_credentials

    try:
        if args.host and args.role != "host":
            raise CredentialsError("--host names the host of a host identity: give --role host too")
        path = write_credentials(
            Path(args.file), Identity.new(args.user, args.role, args.host or ""), replace=args.force
        )
    except CredentialsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{path}: {args.role} {args.user!r}; admit it with swarmbed run --admit {path}")
    return 0


def register_credentials(sub: Subparsers) -> None:
    """``swarmbed credentials``: its arguments, run by :func:`cmd_credentials`."""
    from swarmbed.wire.credentials import ROLES

    cr = sub.add_parser("credentials", help="make a credentials file for a host daemon or an operator (watch, swap)")
    cr.add_argument("file", help="the file to write (created with mode 600; an existing file only with --force)")
    cr.add_argument("--force", action="store_true", help="replace FILE if it exists")
    cr.add_argument("--user", required=True, help="the user name (letters, digits, no ':' or spaces)")
    cr.add_argument(
        "--role",
        choices=list(ROLES),
        default="operator",
        help="operator: watch a run and ask for swaps; host: a host daemon; commander: an operator that may "
        "also publish the robots' decisions on ROS 2 (allocator ros2, docs/ros2.md) (default: operator)",
    )
    cr.add_argument(
        "--host",
        help="role host: the host name the daemon runs as (swarmbed host --name); "
        "the hub lets this identity act as that host only (default: the user name)",
    )
    cr.set_defaults(func=cmd_credentials)


def cmd_certs(args: argparse.Namespace) -> int:
    from swarmbed.launch.certs import CertError, make_certs

    try:
        written = make_certs(Path(args.folder), args.machines, args.days)
    except (CertError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path in written:
        print(path)
    print("copy ca.pem and a machine's NAME.pem and NAME.key to it (never ca.key); see docs/machines.md (TLS)")
    return 0


def register_certs(sub: Subparsers) -> None:
    """``swarmbed certs``: its arguments, run by :func:`cmd_certs`."""
    ce = sub.add_parser("certs", help="a certificate authority and per-machine certificates for TLS between machines")
    ce.add_argument("folder", help="where the CA (ca.pem, ca.key) and the certificates go; the CA is reused")
    ce.add_argument(
        "machines",
        nargs="+",
        metavar="NAME[=ADDR,...]",
        help="a machine and the addresses others reach it by, e.g. hub=192.0.2.10 labpc2=labpc2.lab",
    )
    ce.add_argument("--days", type=positive, default=365, help="validity (default 365 days)")
    ce.set_defaults(func=cmd_certs)


def cmd_host(args: argparse.Namespace) -> int:
    from swarmbed.hosts.daemon import serve
    from swarmbed.launch.host_client import HostError
    from swarmbed.wire.credentials import CredentialsError
    from swarmbed.wire.logs import LOG_FORMAT
    from swarmbed.wire.zenoh_session import tls_from_args

    logging.basicConfig(level=logging.INFO, format=LOG_FORMAT)
    logs = Path(args.logs) if args.logs else Path("runs") / "hosts" / args.name
    try:
        return serve(
            args.name,
            args.connect,
            args.listen,
            logs,
            args.zenoh_config,
            args.mode,
            args.credentials,
            tls_from_args(args),
            insecure=args.insecure,
        )
    except (CredentialsError, HostError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def register_host(sub: Subparsers) -> None:
    """``swarmbed host``: its arguments, run by :func:`cmd_host`."""
    host = sub.add_parser("host", help="run this machine's host daemon: a Zenoh router that starts agents for runs")
    host.add_argument("--name", required=True, help="this host's name in placements (letters, digits, _ . -)")
    host.add_argument("--logs", help="where its agents log (default: runs/hosts/<name>)")
    host.add_argument(
        "--insecure",
        action="store_true",
        help="run without --credentials: no authentication, anyone who reaches the router may start "
        "agents (their code included); allowed with loopback endpoints only",
    )
    add_zenoh_args(host, default_mode="router", retries=False)
    host.set_defaults(func=cmd_host)


def cmd_slurm_lab(args: argparse.Namespace) -> int:
    """A Slurm cluster on this machine until Ctrl-C: slurmctld, and one slurmd per network namespace."""
    import signal
    import threading

    from swarmbed.hosts.netns import LabError, make_lab
    from swarmbed.hosts.slurm_lab import make_slurm_lab

    folder = Path(args.folder).resolve()
    try:
        lab = make_lab(folder / "logs")
    except LabError as exc:
        print(f"error: slurm-lab: {exc}", file=sys.stderr)
        return 2
    try:
        cluster = make_slurm_lab(lab, folder, args.nodes)
    except LabError as exc:
        lab.close()
        print(f"error: slurm-lab: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    print(
        f"slurm-lab: {args.nodes} nodes n1..n{args.nodes} up (logs in {folder}); in another terminal:\n"
        f"  export SLURM_CONF={folder / 'slurm.conf'}\n"
        f"  salloc --nodes={args.nodes} swarmbed run experiments/quickstart.yaml --slurm\n"
        "Ctrl-C here stops the cluster and removes its namespaces.",
        flush=True,
    )
    try:
        while not stop.wait(1.0):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not leave namespaces behind
        cluster.close()
        lab.close()
    print("slurm-lab: stopped", flush=True)
    return 0


def register_slurm_lab(sub: Subparsers) -> None:
    """``swarmbed slurm-lab``: its arguments, run by :func:`cmd_slurm_lab`."""
    lab = sub.add_parser(
        "slurm-lab",
        help="a Slurm cluster on this machine (root, slurm-wlm): one node per network namespace, to try run --slurm",
    )
    lab.add_argument("--nodes", type=positive, default=3, help="how many nodes (default 3)")
    lab.add_argument("--folder", default="runs/slurm-lab", help="its slurm.conf, state and logs")
    lab.set_defaults(func=cmd_slurm_lab)


def cmd_hosts(args: argparse.Namespace) -> int:
    from swarmbed.launch.host_client import host_info, visible_hosts

    session = client_session(args)
    if session is None:
        return 2
    with session:
        names = visible_hosts(session, timeout=args.timeout)
        if not names:
            print(f"no host visible from {', '.join(args.connect)}")
            return 1
        for name in names:
            info = host_info(session, name)
            if info is None:
                print(f"{name}  (no answer, or not a host's information)")
                continue
            agents = ", ".join(f"{run}: {len(ids)}" for run, ids in info.agents.items()) or "none"
            print(
                f"{name}  cores {info.cores or '?'}  free {info.mem_free_mb} MB  "
                f"router {info.endpoint}  agents {agents}"
            )
    return 0


def register_hosts(sub: Subparsers) -> None:
    """``swarmbed hosts``: its arguments, run by :func:`cmd_hosts`."""
    hosts = sub.add_parser("hosts", help="list the hosts visible from an endpoint")
    hosts.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for answers")
    add_zenoh_args(hosts)
    hosts.set_defaults(func=cmd_hosts)


def cmd_swap(args: argparse.Namespace) -> int:
    """Ask a running run to move one agent to another host before its next tick; wait for the outcome."""

    from swarmbed.results.watch import running_runs
    from swarmbed.wire.control import SwapAnswer, SwapQueued, SwapRecord, SwapRefused, decode_swap_answer
    from swarmbed.wire.credentials import CredentialsError, read_credentials
    from swarmbed.wire.errors import WireError
    from swarmbed.wire.keys import Keys

    if args.credentials:
        try:
            role = read_credentials(args.credentials).role
        except CredentialsError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        if role not in ("operator", "commander"):
            print(
                f"error: {args.credentials} is a {role}'s credentials: swaps are asked by an operator "
                "(swarmbed credentials FILE --user NAME, admitted with swarmbed run --admit FILE)",
                file=sys.stderr,
            )
            return 2

    def ask(request: dict) -> SwapAnswer | None:
        for reply in session.get(key, payload=json.dumps(request), timeout=5.0):
            if reply.ok is not None:
                try:
                    return decode_swap_answer(reply.ok.payload.to_bytes())
                except WireError as exc:
                    return SwapRefused(error=f"the coordinator's answer is malformed: {exc}")
        return None

    session = client_session(args)
    if session is None:
        return 2
    with session:
        if args.run is None:  # the only run visible from here, as swarmbed watch picks it
            runs = running_runs(session)
            if len(runs) != 1:
                print(
                    f"error: {len(runs)} runs are visible ({', '.join(runs) or 'none'}): name one with --run",
                    file=sys.stderr,
                )
                return 2
            args.run = runs[0]
        key = Keys(args.run).swap
        answer = ask({"agent": args.agent, "to": args.to})
        if not isinstance(answer, SwapQueued):
            why = answer.error if isinstance(answer, SwapRefused) else "no coordinator answered"
            print(f"error: run {args.run}: {why}", file=sys.stderr)
            return 2
        print(f"swap {answer.queued} of agent {args.agent} to {args.to} queued; waiting for its outcome", flush=True)
        deadline = time.monotonic() + args.wait
        while time.monotonic() < deadline:
            record = ask({"swap": answer.queued})
            if isinstance(record, SwapRefused):
                print(f"error: run {args.run}: {record.error}", file=sys.stderr)
                return 2
            if isinstance(record, SwapRecord):
                print(
                    f"swap of agent {record.agent} from {record.from_host} to {record.to} before tick "
                    f"{record.tick}: {record.outcome}"
                    + (
                        f" ({record.reason})"
                        if record.reason
                        else f", {record.snapshot_bytes} bytes, paused {record.pause_ms:.0f} ms"
                    )
                )
                return 0 if record.outcome == "ok" else 1
            time.sleep(0.1)
    print(f"error: the swap was queued but not done within {args.wait:.0f} s", file=sys.stderr)
    return 1


def register_swap(sub: Subparsers) -> None:
    """``swarmbed swap``: its arguments, run by :func:`cmd_swap`."""
    swap = sub.add_parser("swap", help="move a running agent to another host, with its state")
    swap.add_argument("--run", help="the run id (deployment.json names it; default: the only run visible)")
    swap.add_argument("--agent", type=int, required=True, help="the agent to move")
    swap.add_argument("--to", required=True, help="the host to move it to ('local': the launching machine)")
    swap.add_argument("--wait", type=float, default=60.0, help="seconds to wait for the outcome")
    add_zenoh_args(swap)
    swap.set_defaults(func=cmd_swap)
