"""Talking to host daemons (:mod:`.daemon`): which hosts are up, what each runs, and asking one to
start or stop a run's agents. The launcher (``swarmbed run``) and the operators' commands
(``swarmbed hosts``) use it; requests and answers are JSON objects on the host's own keys.

    swarmbed hosts --connect tcp/192.0.2.10:7447
"""

from __future__ import annotations

import json
import time
from typing import Any

import zenoh

from swarmbed.wire.keys import HOSTS, HostKeys, host_name_of


class HostError(RuntimeError):
    """A host that cannot be reached or refuses a request; the message says which and why."""


def _get_json(session: zenoh.Session, key: str, payload: dict | None, timeout: float) -> dict | None:
    """The JSON object a host's queryable answers, or None after ``timeout``. A query that finds
    no queryable ends at once: just after a host's token is seen, its queryables may not have
    reached this session's routing yet, so such a query is asked again (a query that reached the
    host and went unanswered took the whole timeout, and is not)."""
    body = json.dumps(payload) if payload is not None else None
    deadline = time.monotonic() + timeout
    while True:
        for reply in session.get(key, payload=body, timeout=max(0.1, deadline - time.monotonic())):
            if reply.ok is not None:
                answer = json.loads(reply.ok.payload.to_bytes())
                return answer if isinstance(answer, dict) else None
        if time.monotonic() + 0.1 >= deadline:
            return None
        time.sleep(0.1)


def visible_hosts(session: zenoh.Session, timeout: float = 2.0) -> list[str]:
    """Names of the hosts whose liveliness token this session can see."""
    names = set()
    for reply in session.liveliness().get(f"{HOSTS}/*", timeout=timeout):
        if reply.ok is not None:
            names.add(host_name_of(str(reply.ok.key_expr)))
    return sorted(names)


def host_info(session: zenoh.Session, name: str, timeout: float = 5.0) -> dict | None:
    return _get_json(session, HostKeys(name).info, None, timeout)


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


def start_agents(
    session: zenoh.Session,
    host: str,
    run_id: str,
    agents: list[int],
    args: list[str] | None = None,
    timeout: float = 30.0,
) -> None:
    """Ask ``host`` to start ``agents`` of ``run_id`` (with ``args``: ``--incarnation N --restore``
    for a swap); a HostError says why it did not."""
    answer = _get_json(session, HostKeys(host).start, {"run_id": run_id, "agents": agents, "args": args or []}, timeout)
    if answer is None:
        raise HostError(f"host {host} did not answer the request to start agents {agents}")
    if "error" in answer:
        raise HostError(f"host {host} refused to start agents {agents}: {answer['error']}")


def stop_agents(
    session: zenoh.Session,
    host: str,
    run_id: str,
    agents: list[int] | None = None,
    incarnation: int = 0,
    timeout: float = 10.0,
) -> None:
    """Ask ``host`` to stop ``agents`` (every agent of the run where None) of ``run_id``."""
    request: dict[str, Any] = {"run_id": run_id, "incarnation": incarnation}
    if agents is not None:
        request["agents"] = agents
    _get_json(session, HostKeys(host).stop, request, timeout)
