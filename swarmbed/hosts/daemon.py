"""``swarmbed host``: the daemon of one machine that takes part in runs.

It runs the machine's Zenoh router (the rmw_zenoh convention: one router per host, the host's own
processes connect to it, routers connect to each other), announces itself with a liveliness token
(``swarmbed/hosts/<name>``; its queryable ``.../info`` answers with its cores, free memory and
agents), and starts or stops agent processes when a run's launcher asks (``.../start``,
``.../stop``: JSON in, JSON out, typed in :mod:`swarmbed.wire.control`; the answer says what
started or why not).

Agents it starts are its children: they connect to its router, log to ``<logs>/<run-id>/``, and die
with it (the kernel's parent-death signal), so a host that dies takes its agents with it and the
run sees agent loss. Ctrl-C or SIGTERM stops its agents and leaves no orphan.

    swarmbed host --name labpc2 --connect tcp/192.0.2.10:7447

The launcher's and the operators' side of the conversation is :mod:`.client`.
"""

from __future__ import annotations

import ipaddress
import logging
import os
import signal
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import psutil
import zenoh

from swarmbed.files import safefiles
from swarmbed.hosts.relay import TickRelay
from swarmbed.launch.access import EVERY_MESSAGE
from swarmbed.launch.host_client import HostError
from swarmbed.launch.launcher import AGENT_MODULE, Children, ForkServerError
from swarmbed.wire.child_process import process_name, tune_malloc
from swarmbed.wire.control import HostAnswer, HostInfo, StartAgents, StopAgents, decode_start, decode_stop, encode_json
from swarmbed.wire.credentials import (
    Identity,
    check_host_name,
    read_credentials,
    write_credentials,
    write_dictionary,
)
from swarmbed.wire.errors import WireError
from swarmbed.wire.keys import HOSTS, HostKeys, Keys
from swarmbed.wire.membership import is_alive
from swarmbed.wire.zenoh_session import free_loopback_endpoint, undeclare_all, zenoh_config

log = logging.getLogger("swarmbed.host")


def _agent_of(name: str) -> int:
    return int(name.split("_")[1].split(".")[0])


class Host:
    def __init__(
        self, name: str, session: zenoh.Session, endpoint: str, logs: Path, agent_credentials: str | None = None
    ) -> None:
        self.name = name
        self.agent_credentials = agent_credentials  # what its agents present to its router, if it asks
        self.keys = HostKeys(name)
        self.session = session
        self.endpoint = endpoint  # where this host's agents connect: its own router
        self.logs = logs
        self.runs: dict[str, Children] = {}
        self.relays: dict[str, TickRelay] = {}  # per run: the hub's tick samples, handed to its agents here
        self.lock = threading.Lock()
        self._entities: list[Any] = []

    def info(self) -> HostInfo:
        with self.lock:
            agents = {
                run: sorted(_agent_of(n) for n, p in ch.procs.items() if p.poll() is None)
                for run, ch in self.runs.items()
            }
        return HostInfo(
            name=self.name,
            cores=os.cpu_count(),
            mem_free_mb=psutil.virtual_memory().available // 2**20,
            pid=os.getpid(),
            endpoint=self.endpoint,
            agents={r: a for r, a in agents.items() if a},
        )

    def start_agents(self, request: StartAgents) -> HostAnswer:
        run_id, ids, incarnation = request.run_id, request.agents, request.incarnation
        if not is_alive(self.session, Keys(run_id).alive_coordinator):
            # the hub's access rules let only the hub ask; a run that is not there is not its run
            return HostAnswer(error=f"start: run {run_id} has no coordinator reachable from host {self.name}")
        with self.lock:
            children = self.runs.get(run_id)
            if children is None:
                log_dir = self.logs / run_id
                try:
                    safefiles.make_folder(log_dir)
                except OSError as exc:
                    return HostAnswer(error=f"cannot write logs to {log_dir}: {exc.strerror}")
                try:
                    children = self.runs[run_id] = Children(log_dir, fork_agents=True)
                except ForkServerError as exc:
                    return HostAnswer(error=str(exc))
            busy = [
                i
                for i in ids
                if (p := children.procs.get(process_name(i, incarnation))) is not None and p.poll() is None
            ]
            if busy:
                return HostAnswer(error=f"agents {busy} of run {run_id} already run on host {self.name}")
            relay = self.relays.get(run_id)
            if relay is None:
                relay = self.relays[run_id] = TickRelay(self.session, Keys(run_id), self.name).open()
            relay.carry(ids)  # before the agents start: the hub ticks once every agent holds its token
            identity = ["--credentials", self.agent_credentials] if self.agent_credentials else []
            for i in ids:
                children.spawn(
                    process_name(i, incarnation),
                    AGENT_MODULE,
                    ["--run-id", run_id, "--connect", self.endpoint, *identity, "--id", str(i), "--host", self.name]
                    + request.agent_args(),
                )
        log.info("host %s: started agents %s of run %s", self.name, ids, run_id)
        return HostAnswer(started=ids, logs=str(self.logs / run_id))

    def stop_agents(self, request: StopAgents) -> HostAnswer:
        with self.lock:
            children = self.runs.get(request.run_id)
            if children is None:
                return HostAnswer()
            if request.agents is not None:
                names = [process_name(i, request.incarnation) for i in request.agents]
            else:
                names = list(children.procs)
            procs = [children.procs[n] for n in names if n in children.procs]
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=5)
            except Exception:
                p.kill()
        return HostAnswer(stopped=[_agent_of(n) for n in names])

    def _serve(self, key: str, answer: Callable[[bytes | None], str]) -> Callable[[zenoh.Query], None]:
        """Answer queries on ``key`` with ``answer(request bytes)``, replying on ``key`` itself: a
        query on ``swarmbed/hosts/*/info`` gets its answer under this host's own name, the only one
        the hub lets this host reply on. A request that does not decode is answered with why."""

        def on_query(query: zenoh.Query) -> None:
            data = query.payload.to_bytes() if query.payload is not None else None
            try:
                text = answer(data)
            except WireError as exc:
                text = encode_json(HostAnswer(error=str(exc)))
            query.reply(key, text)

        return on_query

    def declare(self) -> None:
        s, k = self.session, self.keys
        self._entities += [
            s.declare_queryable(k.info, self._serve(k.info, lambda _data: encode_json(self.info()))),
            s.declare_queryable(
                k.start, self._serve(k.start, lambda data: encode_json(self.start_agents(decode_start(data))))
            ),
            s.declare_queryable(
                k.stop, self._serve(k.stop, lambda data: encode_json(self.stop_agents(decode_stop(data))))
            ),
            s.liveliness().declare_token(k.alive),
        ]

    def reap(self) -> None:
        """Forget runs whose agents have all exited."""
        with self.lock:
            for run_id in [r for r, ch in self.runs.items() if all(p.poll() is not None for p in ch.procs.values())]:
                self.runs.pop(run_id).kill_all()  # nothing left to kill but the run's fork server
                relay = self.relays.pop(run_id, None)
                if relay is not None:
                    relay.close()

    def close(self) -> None:
        undeclare_all(self._entities)
        with self.lock:
            runs = list(self.runs.values())
            relays, self.relays = list(self.relays.values()), {}
        for relay in relays:
            relay.close()
        for children in runs:
            children.kill_all()


def _on_loopback(endpoint: str) -> bool:
    """Whether a Zenoh endpoint (``tcp/127.0.0.1:7447``, ``tcp/[::1]:7447``, ``tcp/localhost:7447``)
    names this machine's loopback only."""
    address = endpoint.split("/", 1)[-1].split("#")[0]
    hostname = address.rsplit(":", 1)[0].strip("[]")
    if hostname == "localhost":
        return True
    try:
        return ipaddress.ip_address(hostname).is_loopback
    except ValueError:
        return False


def host_router_rules(agents_user: str) -> dict:
    """The host router's own ``access_control``: the agents it starts (one local identity) may not
    query, serve or announce anything under ``swarmbed/hosts`` (an agent must not ask its host to
    start or stop agents); what else they send, the hub holds to the agents this host may carry."""
    return {
        "enabled": True,
        "default_permission": "allow",
        "rules": [
            {
                "id": "no-host-orders",
                "permission": "deny",
                "flows": ["ingress"],
                "messages": EVERY_MESSAGE,
                "key_exprs": [HOSTS, f"{HOSTS}/**"],
            }
        ],
        "subjects": [{"id": "agents", "usernames": [agents_user]}],
        "policies": [{"subjects": ["agents"], "rules": ["no-host-orders"]}],
    }


class HubLink:
    """Says, once each time it changes, whether the daemon's router reached a hub it connects to:
    a hub that is up but does not admit this host's credentials refuses it at the handshake, and
    from here that looks like silence, so after :data:`SILENT_S` the daemon names both causes."""

    SILENT_S = 10.0

    def __init__(self, name: str, connect: list[str], session: zenoh.Session) -> None:
        self.name, self.connect, self.session = name, connect, session
        self.since = time.monotonic()
        self.linked: bool | None = None  # None: nothing said yet

    def check(self) -> None:
        if not self.connect:
            return
        linked = bool(self.session.info.routers_zid())
        if linked and self.linked is not True:
            print(f"host {self.name}: connected to {', '.join(self.connect)}", flush=True)
            self.linked = True
        elif not linked and self.linked is None and time.monotonic() - self.since >= self.SILENT_S:
            print(
                f"host {self.name}: not connected to {', '.join(self.connect)} after {self.SILENT_S:.0f} s: the hub "
                "is not up yet, or it does not admit this host's credentials (swarmbed run --admit FILE)",
                flush=True,
            )
            self.linked = False
        elif not linked and self.linked:  # lost: said again if it stays away
            self.linked, self.since = None, time.monotonic()


def serve(
    name: str,
    connect: list[str],
    listen: list[str],
    logs: Path,
    zenoh_config_file: str | None = None,
    mode: str = "router",
    credentials: str | None = None,
    tls: dict[str, object] | None = None,
    insecure: bool = False,
) -> int:
    """Run the host daemon until SIGINT or SIGTERM: a router (or peer) for this machine.

    ``credentials``: a host credentials file the hubs it connects to admit (``swarmbed run --admit``).
    With it, the router also requires credentials of whoever connects to it: the daemon makes one
    identity for the agents it starts (in a private folder, gone when it stops), so that a stray
    process on this machine cannot reach a hub through it. ``tls``: :func:`~swarmbed.wire.zenoh_session.tls_settings`
    for ``tls/`` endpoints. Without credentials it refuses to start unless ``insecure`` and every
    endpoint it listens on or connects to is on loopback: an unauthenticated host daemon runs
    whatever anyone who reaches it names."""
    check_host_name(name)
    if not credentials and not insecure:
        raise HostError(
            f"host {name}: no --credentials: a host daemon without them lets anyone who reaches it start "
            "agents, which run code; make them with swarmbed credentials FILE --user NAME --role host "
            "(and admit the file with swarmbed run --admit), or pass --insecure on loopback"
        )
    if not credentials and not all(map(_on_loopback, [*connect, *listen])):
        raise HostError(
            f"host {name}: --insecure is allowed with loopback endpoints only, got "
            f"{', '.join(e for e in [*connect, *listen] if not _on_loopback(e))}"
        )
    listen = listen or [free_loopback_endpoint()]
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    # its agents connect all at once (forked by the hundred): take that many handshakes at a time
    settings: dict[str, object] = {"transport/unicast/accept_pending": 1024, **(tls or {})}
    private: Path | None = None
    agent_credentials = None
    if credentials:
        mine, local = read_credentials(credentials), Identity.new(f"{name}-agents", "agent")
        if mine.role != "host" or mine.host_name != name:
            raise HostError(
                f"host {name}: credentials file {credentials} is for {mine.role} "
                f"{mine.host_name if mine.role == 'host' else mine.user!r}, not for host {name!r} "
                f"(make one with swarmbed credentials FILE --user USER --role host --host {name})"
            )
        private = Path(tempfile.mkdtemp(prefix=f"swarmbed-host-{name}-"))
        agent_credentials = str(write_credentials(private / "agents.json", local))
        dictionary = write_dictionary(private / "router.dictionary", [local])
        settings["transport/auth/usrpwd"] = {
            "user": mine.user,
            "password": mine.password,
            "dictionary_file": str(dictionary),
        }
        settings["access_control"] = host_router_rules(local.user)
    tune_malloc()  # a daemon meant to stay up for days
    try:
        session = zenoh.open(zenoh_config(mode, connect, listen, zenoh_config_file, settings=settings))
    except zenoh.ZError as exc:  # a --listen port another process holds, an endpoint that cannot be
        if private:
            safefiles.remove_tree(private)
        raise HostError(
            f"host {name}: cannot open its router on {', '.join(listen)} ({str(exc).splitlines()[0][:160]}); "
            "is the port in use? give another --listen"
        ) from None
    except BaseException:
        if private:
            safefiles.remove_tree(private)
        raise
    with session:
        host = Host(name, session, listen[0], logs, agent_credentials)
        host.declare()
        log.info(
            "host %s: router on %s, connecting to %s; agents log to %s",
            name,
            ", ".join(listen),
            ", ".join(connect) or "nothing",
            logs,
        )
        print(f"host {name} up: router on {', '.join(listen)}", flush=True)
        link = HubLink(name, connect, session)
        try:
            while not stop.wait(1.0):
                host.reap()
                link.check()
        finally:
            host.close()
            if private:
                safefiles.remove_tree(private)
    log.info("host %s: stopped", name)
    return 0
