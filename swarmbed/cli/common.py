"""What the verbs share: argument types, the engine flag, an --out folder's check, a session to a running hub."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from swarmbed import config as cfg
from swarmbed.files import safefiles
from swarmbed.plugins import registry
from swarmbed.wire.validation import did_you_mean

if TYPE_CHECKING:
    Subparsers = argparse._SubParsersAction["Parser"]  # what add_subparsers returns


class Parser(argparse.ArgumentParser):
    """argparse's parser, its errors one line (argparse prints the whole usage block first) with a
    did-you-mean for an unknown option and where the usage is."""

    def error(self, message: str) -> NoReturn:
        if message.startswith("unrecognized arguments: "):
            options = [o for action in self._actions for o in action.option_strings]
            message += did_you_mean(message.split(": ", 1)[1].split()[0].split("=")[0], options)
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def keys_epilog() -> str:
    return (
        "Any key of the experiment can be overridden with --set KEY=VALUE (read as YAML).\n"
        "`swarmbed params` lists the run, agents and network keys; `swarmbed params NAME` the keys of a\n"
        f"scenario ({', '.join(registry.scenario_names())}) or an allocator "
        f"({', '.join(registry.names())})."
    )


def fmt(v) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:,.1f}"
    if isinstance(v, int):
        return f"{v:,}"
    return "-" if v is None else str(v)


def taken(out: Path, force: bool) -> str | None:
    """Why ``out`` cannot take a new run, or None. A folder that holds anything is refused (a finished
    run would be overwritten and its extra logs left beside the new ones) unless ``force``, which
    clears it whole first."""
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        return f"--out {out}: exists and is not a folder"
    if not out.exists() or not any(out.iterdir()):
        return None
    if not force:
        from swarmbed.records.run_folder import RunDir

        if RunDir(out).complete:
            what = "a finished run"
        elif (out / "config.yaml").exists() or any(out.glob("partial_*")) or any(out.glob("*.part")):
            what = "an interrupted run (no summary.json: it did not finish)"
        else:
            what = "files"
        return f"--out {out}: holds {what} already; give another --out, or --force to clear it first"
    safefiles.remove_tree(out)
    return None


def port_number(text: str) -> int:
    """A TCP port for argparse: 0 (a free one) to 65535; anything else is argparse's one-line error."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{port}: a port is 0 (any free one) to 65535")
    return port


def refusals(exp, engine: str) -> list[str]:
    """Why ``exp`` cannot run on ``engine`` from the command line (none: it can)."""
    from swarmbed.engine import refusals

    return refusals(exp, cfg.resolve_experiment(exp).allocator_cls.decision_source, engine)


def engine_prefix(engine: str) -> str:
    return "--engine inprocess: " if engine == "inprocess" else ""


def add_engine(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--engine",
        choices=["processes", "inprocess"],
        default="processes",
        help="processes (default): every agent its own OS process over Zenoh and the netem proxy; inprocess: "
        "every agent and the radio stepped in this process, the same result files byte for byte, faster for "
        "light allocators (lock-step, one machine, no ROS 2, no tree logs): develop and sweep in-process, "
        "validate in processes",
    )


def add_live_view(parser: argparse.ArgumentParser, what: str) -> None:
    """``--foxglove [PORT]`` and ``--view-clients N``, as every command that serves a live view
    declares them; ``what`` ends the --foxglove help: what the view shows."""
    parser.add_argument(
        "--foxglove",
        nargs="?",
        const=8765,
        type=port_number,
        metavar="PORT",
        help=f"serve the run live to Foxglove over its WebSocket protocol on 127.0.0.1:PORT (default 8765; {what})",
    )
    parser.add_argument(
        "--view-clients", type=positive, default=4, metavar="N", help="viewers --foxglove admits at once (default 4)"
    )


def positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not at least 1")
    return value


def client_session(args: argparse.Namespace, connect_timeout_s: float | None = None):
    """A client session from the shared zenoh flags, or None after printing why it cannot open
    (no route to the endpoint within ``connect_timeout_s``, refused credentials, an unreadable
    credentials file)."""
    import zenoh

    from swarmbed.wire.credentials import CredentialsError
    from swarmbed.wire.zenoh_session import connect_timeout, tls_from_args, zenoh_config

    try:
        return zenoh.open(
            zenoh_config(
                "client",
                args.connect,
                [],
                args.zenoh_config,
                args.credentials,
                tls_from_args(args),
                connect_timeout_s=connect_timeout(args, connect_timeout_s),
            )
        )
    except CredentialsError as exc:
        print(f"error: {exc}", file=sys.stderr)
    except zenoh.ZError as exc:
        hint = "" if args.credentials else " (a run's hub admits only processes with credentials: give --credentials)"
        print(
            f"error: cannot reach {', '.join(args.connect) or 'any endpoint (give --connect)'}: {exc}{hint}",
            file=sys.stderr,
        )
    return None
