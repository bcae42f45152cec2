"""The run's hub: the coordinator's Zenoh router, and who may reach it.

Every run process connects to the hub. :class:`HubOptions` says where it listens beyond loopback (for
other hosts' routers), whether it checks credentials, whose besides the run's own it admits
(operators, host daemons) and with which certificates; :func:`open_hub` opens it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import zenoh

from swarmbed.engine.run_errors import RunError
from swarmbed.wire.child_process import tune_gc, tune_malloc
from swarmbed.wire.credentials import Identity
from swarmbed.wire.zenoh_session import free_loopback_endpoint, zenoh_config


@dataclass(frozen=True)
class HubOptions:
    """How a run's hub is reached. The default is a loopback-only hub that admits only the run's
    own processes, each held to its own keys.

    ``listen``: endpoints where the hub also listens, for the routers of the hosts a placement
    names. ``auth``: without it anyone who reaches the hub may do anything (trusted benches only).
    ``admit``: operators and host daemons let in beside the run's own processes. ``tls``: the hub's
    certificates (:func:`~swarmbed.wire.zenoh_session.tls_settings`) for ``tls/`` endpoints in ``listen``.
    ``remote_proxy``: for a radio split over proxies, the command that runs proxy ``shard`` elsewhere,
    from the arguments it would run with here (``--slurm``: a job step on one of the allocation's
    nodes, :class:`~swarmbed.launch.slurm_allocation.SlurmHosts`); None: every proxy runs here.
    """

    listen: Sequence[str] = ()
    auth: bool = True
    admit: Sequence[Identity] = ()
    tls: Mapping[str, object] | None = None
    remote_proxy: Callable[[int, list[str]], list[str]] | None = None

    def admitting(self, *more: Identity) -> HubOptions:
        """The same hub, letting ``more`` in as well."""
        return HubOptions(self.listen, self.auth, (*self.admit, *more), self.tls, self.remote_proxy)


LOOPBACK_ONLY = HubOptions()
"""The default: this machine's run processes only, each held to its own keys."""


def open_hub(
    listen: Sequence[str] = (), attempts: int = 5, settings: Mapping[str, object] | None = None
) -> tuple[zenoh.Session, str]:
    """A router session listening on a free loopback TCP port (the run's own processes connect
    there) and on ``listen`` (where other hosts' routers connect); ``settings``: e.g. the run's
    authentication and access control (:meth:`RunAccess.hub_settings`)."""
    tune_malloc()  # the hub handles every tick's messages for as long as the run goes
    tune_gc()
    last: Exception | None = None
    for _ in range(attempts):
        endpoint = free_loopback_endpoint()
        try:
            config = zenoh_config("router", listen=[endpoint, *listen], settings=dict(settings or {}))
            return zenoh.open(config), endpoint
        except zenoh.ZError as exc:  # the port was taken between probe and bind
            last = exc
    raise RunError(f"could not listen on a loopback port: {last}")
