"""The ``swarmbed`` command: its verbs (``VERBS``, one module of ``swarmbed.cli`` per group) and :func:`main`."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING

from swarmbed import __version__
from swarmbed import config as cfg
from swarmbed.bt import BTError
from swarmbed.cli.authoring import register_bt, register_check_allocator, register_check_scenario, register_params
from swarmbed.cli.campaigns import register_analyze, register_replay, register_report, register_sweep
from swarmbed.cli.common import Parser
from swarmbed.cli.hosts import (
    register_certs,
    register_credentials,
    register_host,
    register_hosts,
    register_slurm_lab,
    register_swap,
)
from swarmbed.cli.run import register_run, register_soak
from swarmbed.cli.views import register_groot, register_watch
from swarmbed.engine.run_errors import RunError
from swarmbed.plugins import registry

if TYPE_CHECKING:
    from swarmbed.cli.common import Subparsers

#: what Ctrl-C left, per command that starts a run (the others say only "interrupted")
INTERRUPTED = {
    "run": "interrupted: every process was stopped; no summary.json was written",
    "soak": "interrupted: every process was stopped; the soak's files so far are kept, no verdict was written",
}


#: every verb, in the order ``swarmbed --help`` lists them
VERBS: tuple[Callable[[Subparsers], None], ...] = (
    register_run,
    register_soak,
    register_credentials,
    register_certs,
    register_bt,
    register_params,
    register_sweep,
    register_analyze,
    register_report,
    register_replay,
    register_check_allocator,
    register_check_scenario,
    register_host,
    register_hosts,
    register_slurm_lab,
    register_watch,
    register_groot,
    register_swap,
)


#: the verbs that run allocators here: they say so in one line when the kernels are not compiled
RUNS_ALLOCATORS = frozenset({"run", "soak", "sweep", "host", "check-allocator"})


def main(argv: list[str] | None = None) -> int:
    ap = Parser(prog="swarmbed", description="Zenoh-networked MRTA emulation testbed")
    ap.add_argument("--version", action="version", version=f"swarmbed {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    for register in VERBS:
        register(sub)

    for name, module in (("agent", "swarmbed.agent_runtime.process"), ("netem", "swarmbed.netem.proxy")):
        p = sub.add_parser(name, help=f"start one {name} process by hand (e.g. on another host)", add_help=False)
        p.set_defaults(func=None, module=module)

    args, rest = ap.parse_known_args(argv)
    if args.command in ("agent", "netem"):
        import importlib

        return importlib.import_module(args.module).main(rest)
    if rest:  # the verb's own parser names its options, and the closest to a mistyped one
        sub.choices[args.command].error(f"unrecognized arguments: {' '.join(rest)}")
    stopped_by = [signal.SIGINT]

    def on_sigterm(signum: int, _frame: object) -> None:  # `kill`: stop as Ctrl-C stops, cleaning up
        stopped_by[0] = signal.SIGTERM
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_sigterm)
    if args.command in RUNS_ALLOCATORS:
        from swarmbed.kernels import fallback_notice

        if notice := fallback_notice():
            print(notice, file=sys.stderr)
    try:
        return args.func(args)
    except (cfg.ConfigError, BTError, registry.PluginError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RunError as exc:
        print(f"run failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        print(str(exc) or INTERRUPTED.get(args.command, "interrupted"), file=sys.stderr)
        return 128 + stopped_by[0]
    except BrokenPipeError:  # the reader of our output went away (e.g. `| head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as exc:  # a full disk, a folder that is not there: one line naming what and where
        where = f": {exc.filename}" if exc.filename else ""
        print(f"error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
