"""Talking to host daemons (:mod:`.daemon`): which hosts are up, what each runs, and asking one to
start or stop a run's agents. The launcher (``swarmbed run``) and the operators' commands
(``swarmbed hosts``) use it; requests and answers are JSON objects on the host's own keys, typed
in :mod:`swarmbed.wire.control`.

    swarmbed hosts --connect tcp/192.0.2.10:7447
"""

from __future__ import annotations

import logging
import time

import zenoh

from swarmbed.wire.control import (
    HostAnswer,
    HostInfo,
    StartAgents,
    StopAgents,
    decode_host_answer,
    decode_host_info,
    encode_json,
)
from swarmbed.wire.errors import WireError
from swarmbed.wire.keys import HOSTS, HostKeys, host_name_of

log = logging.getLogger("swarmbed.hosts")


class HostError(RuntimeError):
    """A host that cannot be reached or refuses a request; the message says which and why."""


def _ask(session: zenoh.Session, key: str, body: str | None, timeout: float) -> bytes | None:
    """The bytes a host's queryable answers, or None after ``timeout``. A query that finds no
    queryable ends at once: just after a host's token is seen, its queryables may not have reached
    this session's routing yet, so such a query is asked again (a query that reached the host and
    went unanswered took the whole timeout, and is not)."""
    deadline = time.monotonic() + timeout
    while True:
        for reply in session.get(key, payload=body, timeout=max(0.1, deadline - time.monotonic())):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
        if time.monotonic() + 0.1 >= deadline:
            return None
        time.sleep(0.1)


def _request(
    session: zenoh.Session, host: str, key: str, request: StartAgents | StopAgents, timeout: float
) -> HostAnswer | None:
    data = _ask(session, key, encode_json(request), timeout)
    if data is None:
        return None
    try:
        return decode_host_answer(data)
    except WireError as exc:
        raise HostError(f"host {host} answered nonsense: {exc}") from None


def visible_hosts(session: zenoh.Session, timeout: float = 2.0) -> list[str]:
    """Names of the hosts whose liveliness token this session can see."""
    names = set()
    for reply in session.liveliness().get(f"{HOSTS}/*", timeout=timeout):
        if reply.ok is not None:
            names.add(host_name_of(str(reply.ok.key_expr)))
    return sorted(names)


def host_info(session: zenoh.Session, name: str, timeout: float = 5.0) -> HostInfo | None:
    """What host ``name`` says of itself (cores, free memory, its agents), for people and the
    deployment file; None if it does not answer, or answers other than a host's information (the
    reason logged)."""
    data = _ask(session, HostKeys(name).info, None, timeout)
    if data is None:
        return None
    try:
        return decode_host_info(data)
    except WireError as exc:
        log.warning("host %s: %s", name, exc)
        return None


def wait_for_hosts(
    session: zenoh.Session, names: list[str], timeout: float, endpoint_hint: str, auth: bool = True
) -> None:
    """Until every named host holds its token; else a HostError naming the missing ones and the
    command that starts each (``auth``: with the credentials a hub that requires them admits)."""
    deadline = time.monotonic() + timeout
    missing = sorted(set(names))
    while missing:
        missing = sorted(set(names) - set(visible_hosts(session, timeout=1.0)))
        if missing and time.monotonic() > deadline:
            creds = " --credentials FILE" if auth else ""
            commands = "\n".join(f"    swarmbed host --name {h} --connect {endpoint_hint}{creds}" for h in missing)
            admit = (
                (
                    "\nwhere FILE is a host credentials file (swarmbed credentials FILE --user NAME --role host) "
                    "this run admits (swarmbed run --admit FILE)"
                )
                if auth
                else ""
            )
            raise HostError(
                f"hosts not reachable after {timeout:.0f} s: {', '.join(missing)}; start each on its "
                f"machine with:\n{commands}{admit}"
            )


def start_agents(session: zenoh.Session, host: str, request: StartAgents, timeout: float = 30.0) -> None:
    """Ask ``host`` to start agents; a HostError says why it did not."""
    answer = _request(session, host, HostKeys(host).start, request, timeout)
    if answer is None:
        raise HostError(f"host {host} did not answer the request to start agents {request.agents}")
    if answer.error is not None:
        raise HostError(f"host {host} refused to start agents {request.agents}: {answer.error}")


def stop_agents(session: zenoh.Session, host: str, request: StopAgents, timeout: float = 10.0) -> None:
    """Ask ``host`` to stop agents of a run (best effort: a host that is gone has stopped them)."""
    _request(session, host, HostKeys(host).stop, request, timeout)
