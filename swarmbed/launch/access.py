"""Who may join a run and what each may do: per-run credentials and the hub's access-control rules.

Both are Zenoh's own mechanisms, enforced by the hub router (the coordinator's session), not by our
code: user/password authentication (``transport/auth/usrpwd``) refuses a session without valid
credentials at connect time, and access control (``access_control``, default deny) refuses every
message a subject is not allowed, before it reaches any subscriber.

Identities of one run (users in the hub's dictionary):

=============  =================================================================================
``netem``      the proxy: takes agents' outputs, the world and the stop order; publishes steps.
``netem-<i>``  proxy i of a radio split over proxies: as ``netem``, but holds only its own token
               and reads, of the outputs split by region, only those sent to it
``agent-<i>``  agent i: publishes only ``agent/<i>/out``, reports and snapshots only for itself,
               receives only ``agent/<i>/in``
operators      files made by ``swarmbed credentials --role operator`` and admitted with
               ``swarmbed run --admit``: read the run's progress, views and tokens (``swarmbed
               watch``, ``swarmbed groot``), all published with DROP, never a key the run blocks
               on; ask for swaps
hosts          files made with ``--role host``: a host daemon's router, bound to one host name
               (its credentials' ``host``, else its user name). It carries the traffic of the
               agents it may carry (placed on it, moved to it by a scripted swap, or listed in
               ``may_carry``) and nothing of any other
               agent, never an agent's input; it serves start/stop and holds a token only under
               its own ``swarmbed/hosts/<name>``, and takes the run's tick samples and sends its
               agents' gathered outputs under its own name only (``host/<name>/in`` and
               ``.../out``, :mod:`swarmbed.hosts.relay`)
=============  =================================================================================

The coordinator publishes the world, ticks and agent inputs from inside the hub, where no rule
applies; no remote identity may publish them.
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path

import psutil

from swarmbed.files import safefiles
from swarmbed.wire.child_process import process_alive
from swarmbed.wire.credentials import Identity, check_admitted, write_credentials, write_dictionary
from swarmbed.wire.keys import HOSTS, PREFIX, Keys, proxy_name
from swarmbed.wire.ros2_conventions import ADMIN_SPACE as ROS2_ADMIN_SPACE
from swarmbed.wire.ros2_conventions import NODE_PREFIX as ROS2_NODE_PREFIX

log = logging.getLogger("swarmbed.access")
OWNER = "owner.json"  # in a run's private folder: the launcher that made it (pid, start time)
MAX_OWNER_BYTES = 4096  # an owner record is about 60 bytes

EVERY_MESSAGE = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
]


def _allow(rule_id: str, messages: list[str], key_exprs: list[str], flow: str = "ingress") -> dict:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": key_exprs}


def agent_user(agent_id: int) -> str:
    return f"agent-{agent_id}"


def _agent_rules(k: Keys, user: str, ids: Iterable[int]) -> list[dict]:
    """What a subject that carries agents ``ids`` may send: their outputs and reports, their
    inputs to subscribe to, their spec and snapshots to fetch, their tokens; nothing of any other agent."""
    ids = sorted(ids)
    if not ids:
        return []
    return [
        # an output goes on its key, or below it on the key of the proxy that reads it (a radio split by region)
        _allow(
            f"{user}-put",
            ["put"],
            [key for i in ids for key in (k.agent_out(i), f"{k.agent_out(i)}/*", k.agent_bt(i))],
        ),
        _allow(f"{user}-subscribe", ["declare_subscriber"], [k.agent_in(i) for i in ids]),
        _allow(
            f"{user}-query",
            ["query"],
            [k.agent_config, *(key for i in ids for key in (k.agent_report(i), k.agent_snapshot(i)))],
        ),
        _allow(f"{user}-alive", ["liveliness_token"], [k.alive_agent_any(i) for i in ids]),
        _allow(f"{user}-monitored", ["declare_liveliness_subscriber", "liveliness_query"], [k.monitor(i) for i in ids]),
    ]


def access_rules(
    keys: Keys,
    agent_ids: Iterable[int],
    operators: Iterable[str],
    hosts: Mapping[str, tuple[str, Iterable[int]]],
    ros2_domain: int | None = None,
    commanders: Iterable[str] = (),
    proxies: int = 1,
) -> dict:
    """The hub's ``access_control`` section for one run (default deny). ``proxies``: the netem
    proxies of the run, each its own identity (:func:`~swarmbed.wire.keys.proxy_name`: ``netem``,
    ``netem-1``, ...) holding only its own token and reading only what goes to it. ``hosts``: each admitted
    host's user name -> (the host name it is bound to, the agents it may carry, as
    :func:`~swarmbed.schema.experiment.carriers` gives them). ``ros2_domain``: the ROS 2 domain the run
    publishes on, if it does; operators may then read its topics and join its graph (a ROS 2 node
    of theirs holds its own tokens), and publish on none of its topics. ``commanders``: operators
    who may also publish the robots' decisions (``/robot_<i>/cmd``, for the ``ros2`` allocator)."""
    k, root = keys, keys.root
    alive = f"{root}/alive/**"
    rules = [
        _allow("deliver", EVERY_MESSAGE, ["**"], flow="egress"),  # what a subject may send is held at ingress
        _allow("netem", ["put"], [k.netem_step, k.view_traffic]),
        _allow("netem-subscribe", ["declare_subscriber"], [k.world, k.netem_stop, k.netem_control]),
        _allow("netem-query", ["query"], [k.netem_config, k.netem_report]),
        _allow("netem-serve", ["declare_queryable", "reply"], [k.netem_awaiting]),
        _allow("watch-alive", ["declare_liveliness_subscriber", "liveliness_query"], [alive]),
        # operators read only what is published with DROP (progress, views): a reader that stops
        # reading must never hold up a key the run blocks on (ticks, outputs, steps, the world)
        _allow("operator-read", ["declare_subscriber"], [k.status, k.view]),
        _allow("operator-tokens", ["declare_liveliness_subscriber", "liveliness_query"], [alive, f"{HOSTS}/**"]),
        _allow("operator-ask", ["query"], [k.swap, f"{HOSTS}/*/info"]),
        _allow("operator-monitor", ["liveliness_token"], [k.monitor_all]),
        _allow("operator-find", ["liveliness_query"], [f"{PREFIX}/*/alive/coordinator"]),
        _allow("host-watch", ["declare_liveliness_subscriber", "liveliness_query"], [alive, f"{HOSTS}/**"]),
    ]
    operator_rules = ["operator-read", "operator-tokens", "operator-ask", "operator-find", "operator-monitor"]
    netem_ros2: list[str] = []
    if ros2_domain is not None:
        ros2, readers, netem_ros2 = _ros2_rules(ros2_domain)
        rules += ros2
        operator_rules += readers
    subjects: list[dict] = []
    policies: list[dict] = []
    tokens = k.netem_tokens(proxies)
    for shard in range(proxies):
        user = proxy_name(shard)
        own = [  # every output not split by region, and those below the keys of this proxy
            _allow(
                f"{user}-outputs",
                ["declare_subscriber"],
                [f"{key}{below}" for key in (k.agent_out_all, k.host_out_all) for below in ("", f"/{shard}")],
            ),
            _allow(f"{user}-alive", ["liveliness_token"], [tokens[shard]]),
        ]
        rules += own
        subjects.append({"id": user, "usernames": [user]})
        base = ["deliver", "netem", "netem-subscribe", "netem-query", "netem-serve", "watch-alive", *netem_ros2]
        policies.append({"subjects": [user], "rules": [*base, *(r["id"] for r in own)]})
    for i in agent_ids:
        user = agent_user(i)
        own = _agent_rules(k, user, [i])
        rules += own
        subjects.append({"id": user, "usernames": [user]})
        policies.append({"subjects": [user], "rules": ["deliver", "watch-alive", *(r["id"] for r in own)]})
    commanders = list(commanders) if ros2_domain is not None else []  # without ROS 2, operators like any
    if commanders:
        subjects.append({"id": "commanders", "usernames": commanders})
        policies.append({"subjects": ["commanders"], "rules": ["deliver", *operator_rules, "ros2-command"]})
    operators = [user for user in operators if user not in commanders]
    if operators:
        subjects.append({"id": "operators", "usernames": operators})
        policies.append({"subjects": ["operators"], "rules": ["deliver", *operator_rules]})
    for user, (host, ids) in sorted(hosts.items()):
        subject = f"host-{user}"
        own = _agent_rules(k, subject, ids)
        rules += own + [
            _allow(f"{subject}-serve", ["declare_queryable", "reply"], [f"{HOSTS}/{host}/*"]),
            _allow(f"{subject}-announce", ["liveliness_token"], [f"{HOSTS}/{host}"]),
            # its relay (swarmbed.hosts.relay) takes the run's tick samples for this host, no other's,
            # and sends on its agents' outputs (the proxy takes only those of agents it may carry)
            _allow(f"{subject}-ticks", ["declare_subscriber"], [k.host_in(host)]),
            _allow(f"{subject}-outputs", ["put"], [k.host_out(host), f"{k.host_out(host)}/*"]),
        ]
        subjects.append({"id": subject, "usernames": [user]})
        policies.append(
            {
                "subjects": [subject],
                "rules": [
                    "deliver",
                    "host-watch",
                    f"{subject}-serve",
                    f"{subject}-announce",
                    f"{subject}-ticks",
                    f"{subject}-outputs",
                    *(r["id"] for r in own),
                ],
            }
        )
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def _ros2_rules(domain: int) -> tuple[list[dict], list[str], list[str]]:
    """The rules of a run that publishes ROS 2 topics on ``domain``, and the ids of those an
    operator and the proxy get."""
    graph = f"{ROS2_ADMIN_SPACE}/{domain}/**"
    history = f"{domain}/**/@adv/**"
    rules = [
        _allow("ros2-read", ["declare_subscriber"], [f"{domain}/**"]),
        _allow("ros2-graph", ["declare_liveliness_subscriber", "liveliness_query", "liveliness_token"], [graph]),
        # `**` never matches an `@` chunk: the graph's tokens need their own way out
        _allow("ros2-deliver", EVERY_MESSAGE, [graph], flow="egress"),
        # a late subscription to a transient-local topic (/tasks) finds the advanced publisher's
        # token and asks its cache, below the topic's key under @adv
        _allow("ros2-history", ["declare_liveliness_subscriber", "liveliness_query", "query"], [history]),
        _allow("ros2-history-deliver", EVERY_MESSAGE, [history], flow="egress"),
    ]
    # ... but never a token of the run's own nodes (/swarmbed, /swarmbed_radio): a viewer declares
    # its own node's; one that dropped the hub's would tell every ROS 2 node the run had ended
    ours = f"{ROS2_ADMIN_SPACE}/{domain}/*/*/*/*/*/*/{ROS2_NODE_PREFIX}$*/**"
    rules.append({**_allow("ros2-not-ours", ["liveliness_token"], [ours]), "permission": "deny"})
    readers = ["ros2-read", "ros2-graph", "ros2-deliver", "ros2-history", "ros2-history-deliver", "ros2-not-ours"]
    rules.append(_allow("ros2-command", ["put"], [f"{domain}/robot_$*/cmd/**"]))
    rules += [  # the proxy's own ROS 2 node publishes what each robot sent
        _allow("netem-ros2", ["put"], [f"{domain}/robot_$*/radio/sent/**"]),
        _allow("netem-ros2-graph", ["liveliness_token"], [graph]),
    ]
    return rules, readers, ["netem-ros2", "netem-ros2-graph"]


class RunAccess:
    """One run's identities: a private folder (mode 700, removed by :meth:`close`) holding the hub's
    dictionary and one credentials file per process the launcher spawns."""

    def __init__(
        self,
        keys: Keys,
        agent_ids: Iterable[int],
        admitted: Iterable[Identity] = (),
        carriers: Mapping[str, Iterable[int]] | None = None,
        ros2_domain: int | None = None,
        proxies: int = 1,
    ) -> None:
        self.keys = keys
        self.proxies = proxies
        self.ros2_domain = ros2_domain
        self.agent_ids = sorted(agent_ids)
        self.admitted = check_admitted(admitted)
        self.carriers = {host: sorted(ids) for host, ids in (carriers or {}).items()}  # host -> agents it may carry
        proxy_users = [proxy_name(shard) for shard in range(proxies)]
        taken = {*proxy_users, *map(agent_user, self.agent_ids)}
        for identity in self.admitted:
            if identity.user in taken:
                raise ValueError(f"admitted user {identity.user!r} clashes with a name the run gives its own processes")
        remove_orphaned_folders()
        self.folder = Path(tempfile.mkdtemp(prefix=f"swarmbed-{keys.run_id}-"))  # mode 700
        claim_folder(self.folder)
        own = [Identity.new(user, "netem") for user in proxy_users]
        own += [Identity.new(agent_user(i), "agent") for i in self.agent_ids]
        self.files = {
            identity.user: write_credentials(self.folder / f"{identity.user}.json", identity) for identity in own
        }
        self.dictionary = write_dictionary(self.folder / "hub.dictionary", own + self.admitted)

    def credentials(self, process: str) -> str:
        """The credentials file of a proxy (``netem``, ``netem-<i>``) or an agent (``agent-<i>``)."""
        return str(self.files[process])

    def hub_settings(self) -> dict[str, object]:
        return {
            "transport/auth/usrpwd": {"dictionary_file": str(self.dictionary)},
            "access_control": access_rules(
                self.keys,
                self.agent_ids,
                operators=[i.user for i in self.admitted if i.role != "host"],
                commanders=[i.user for i in self.admitted if i.role == "commander"],
                hosts={
                    i.user: (i.host_name, self.carriers.get(i.host_name, [])) for i in self.admitted if i.role == "host"
                },
                ros2_domain=self.ros2_domain,
                proxies=self.proxies,
            ),
        }

    def close(self) -> None:
        safefiles.remove_tree(self.folder)


def claim_folder(folder: Path) -> None:
    """Record this process as the owner of the temporary ``folder`` (``swarmbed-<what>-...``), so that
    :func:`remove_orphaned_folders` removes it once this process is gone, however it ended."""
    safefiles.write_text(folder / OWNER, json.dumps({"pid": os.getpid(), "started": psutil.Process().create_time()}))


def remove_orphaned_folders(tmp: Path | None = None) -> list[Path]:
    """Remove the private folders of runs whose launcher is gone (killed before :meth:`RunAccess.close`
    ran); returns them. Only this user's folders that are not links are looked at, their owner
    record read bounded and without blocking; one without a readable record is left alone."""
    removed = []
    for folder in safefiles.own_folders(Path(tmp or tempfile.gettempdir()), "swarmbed-*-*"):
        try:  # another local user may have planted owner.json as a FIFO or a link to /dev/zero
            owner = json.loads(safefiles.read_file(folder / OWNER, MAX_OWNER_BYTES))
            orphaned = not process_alive(int(owner["pid"]), float(owner["started"]))
        except (OSError, ValueError, KeyError, TypeError, RecursionError):
            continue
        if orphaned:
            safefiles.remove_tree(folder)
            removed.append(folder)
    if removed:
        log.info("removed %d private folders of runs whose launcher is gone", len(removed))
    return removed
