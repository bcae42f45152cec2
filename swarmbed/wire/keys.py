"""Key expressions of one run. Everything lives under ``swarmbed/<run-id>/`` so runs never mix."""

from __future__ import annotations

from dataclasses import dataclass

from swarmbed.wire.errors import WireError

PREFIX = "swarmbed"


@dataclass(frozen=True)
class Keys:
    run_id: str

    @property
    def root(self) -> str:
        return f"{PREFIX}/{self.run_id}"

    # queryables on the coordinator: what each process needs of the run (JSON of wire.schema specs)
    @property
    def agent_config(self) -> str:
        return f"{self.root}/config/agent"

    @property
    def netem_config(self) -> str:
        return f"{self.root}/config/netem"

    # coordinator -> netem proxy: the run is over after the given tick
    @property
    def netem_stop(self) -> str:
        return f"{self.root}/netem/stop"

    # launcher (chaos) -> netem proxy: the radio's parameters changed from a tick on
    @property
    def netem_control(self) -> str:
        return f"{self.root}/netem/control"

    # coordinator -> agent i: one sample per tick (observation + inbox), or a stop order
    def agent_in(self, agent_id: int) -> str:
        return f"{self.root}/agent/{agent_id}/in"

    # coordinator -> the host daemon carrying some of the run's agents: one sample per tick holding
    # their inputs (swarmbed.wire.codec.encode_host_tick), which its relay hands out as ``agent_in``
    def host_in(self, host: str) -> str:
        return f"{self.root}/host/{host}/in"

    # agent i, started by host daemon ``host`` -> that host's relay, on the host's own router: its
    # output, gathered there with the other agents' of the host into one sample for the proxy
    def hosted_out(self, host: str, agent_id: int) -> str:
        return f"{self.root}/host/{host}/agent/{agent_id}/out"

    def hosted_out_all(self, host: str) -> str:
        return f"{self.root}/host/{host}/agent/*/out"

    # a host's relay -> netem proxy: the outputs of the host's agents, gathered
    def host_out(self, host: str) -> str:
        return f"{self.root}/host/{host}/out"

    @property
    def host_out_all(self) -> str:
        return f"{self.root}/host/*/out"

    # agent i -> netem proxy: one sample per tick (action + radio messages)
    def agent_out(self, agent_id: int) -> str:
        return f"{self.root}/agent/{agent_id}/out"

    @property
    def agent_out_all(self) -> str:
        return f"{self.root}/agent/*/out"

    # agent i -> coordinator: final report or fatal error
    def agent_report(self, agent_id: int) -> str:
        return f"{self.root}/agent/{agent_id}/report"

    @property
    def agent_report_all(self) -> str:
        return f"{self.root}/agent/*/report"

    # coordinator -> netem proxy: positions and membership of tick k
    @property
    def world(self) -> str:
        return f"{self.root}/world"

    # netem proxy -> coordinator: actions of tick k, inboxes of tick k+1, counters
    @property
    def netem_step(self) -> str:
        return f"{self.root}/netem/step"

    # coordinator -> anyone watching: progress a few times a second (swarmbed watch)
    @property
    def status(self) -> str:
        return f"{self.root}/status"

    # What operators may read. Every key below view/ (and status) is published with congestion
    # control DROP, so a watcher that stops reading loses samples instead of holding up the run;
    # the run's own keys (ticks, outputs, steps, the world) are BLOCK and no operator may read them.
    @property
    def view(self) -> str:
        return f"{self.root}/view/**"

    # netem proxy -> watchers: every agent's messages and payload bytes sent so far (wall-clock paced)
    @property
    def view_traffic(self) -> str:
        return f"{self.root}/view/traffic"

    # coordinator -> monitors (swarmbed groot): agent i's tree changes, as the agent handed them over
    def view_bt(self, agent_id: int) -> str:
        return f"{self.root}/view/agent/{agent_id}/bt"

    # netem proxy queryable: the agents whose answer to the tick in hand it still waits for (a stuck
    # run names them)
    @property
    def netem_awaiting(self) -> str:
        return f"{self.root}/netem/awaiting"

    # netem proxy -> coordinator: final totals once the ledger is on disk
    @property
    def netem_report(self) -> str:
        return f"{self.root}/netem/report"

    # liveliness tokens
    def alive_agent(self, agent_id: int, incarnation: int = 0) -> str:
        """An agent's token. A swap starts a new process (the next incarnation) before the old one
        leaves, so each process of an agent holds its own token."""
        return f"{self.root}/alive/agent/{agent_id}/{incarnation}"

    def alive_agent_any(self, agent_id: int) -> str:
        return f"{self.root}/alive/agent/{agent_id}/*"

    @property
    def alive_agents(self) -> str:
        return f"{self.root}/alive/agent/*/*"

    # agent -> coordinator (and operators): each tick's behavior tree status changes, when recorded
    def agent_bt(self, agent_id: int) -> str:
        return f"{self.root}/agent/{agent_id}/bt"

    @property
    def agent_bt_all(self) -> str:
        return f"{self.root}/agent/*/bt"

    # a monitor's liveliness token (swarmbed groot): while one is alive, the agent hands over its tree's changes
    def monitor(self, agent_id: int) -> str:
        return f"{self.root}/monitor/agent/{agent_id}"

    @property
    def monitor_all(self) -> str:
        return f"{self.root}/monitor/**"

    # coordinator queryable: an agent's snapshot, handed over by the old process during a swap
    # (query with payload) and fetched by the new one (query without)
    def agent_snapshot(self, agent_id: int) -> str:
        return f"{self.root}/agent/{agent_id}/snapshot"

    @property
    def agent_snapshot_all(self) -> str:
        return f"{self.root}/agent/*/snapshot"

    # coordinator queryable: swap requests (JSON {agent, to}) and their outcome (JSON {swap})
    @property
    def swap(self) -> str:
        return f"{self.root}/swap"

    @property
    def alive_netem(self) -> str:
        return f"{self.root}/alive/netem"

    def alive_netem_shard(self, shard: int) -> str:
        """The token of proxy ``shard`` of a radio split over proxies (one proxy holds ``alive_netem``)."""
        return f"{self.root}/alive/netem/{shard}"

    @property
    def alive_netem_shard_all(self) -> str:
        return f"{self.root}/alive/netem/*"

    def netem_tokens(self, shards: int) -> list[str]:
        """The tokens of a run's proxies: its one proxy's, or each proxy's of a split radio."""
        return [self.alive_netem] if shards == 1 else [self.alive_netem_shard(i) for i in range(shards)]

    @property
    def alive_coordinator(self) -> str:
        return f"{self.root}/alive/coordinator"

    @property
    def alive_all(self) -> str:
        return f"{self.root}/alive/**"


def _number(text: str) -> int:
    """A key chunk that is a number as we write them (``0``, ``17``), else WireError; ``int()``
    alone would take ``+1``, ``1_0`` or ``٣``."""
    if not (text.isascii() and text.isdigit()) or len(text) > 9 or (len(text) > 1 and text[0] == "0"):
        raise WireError(f"{text!r} is not a number")
    return int(text)


def incarnation_of(key: str) -> int:
    """The incarnation in ``.../alive/agent/<id>/<incarnation>``; a WireError if there is none."""
    try:
        return _number(str(key).rsplit("/", 1)[1])
    except (WireError, IndexError):
        raise WireError(f"no incarnation in key {key!r}") from None


def agent_id_of(key: str) -> int:
    """The agent id in ``.../agent/<id>/...`` or ``.../alive/agent/<id>``; a WireError (which
    receivers count as malformed) if there is none."""
    parts = str(key).split("/")
    try:
        return _number(parts[parts.index("agent") + 1])
    except (WireError, ValueError, IndexError):
        raise WireError(f"no agent id in key {key!r}") from None


def alive_agent_of(key: str, root: str, n_agents: int) -> tuple[int, int]:
    """(agent, incarnation) of a token key ``<root>/alive/agent/<id>/<incarnation>`` with
    ``0 <= id < n_agents``; anything else is a WireError."""
    parts = str(key).split("/")
    head = f"{root}/alive/agent".split("/")
    if len(parts) != len(head) + 2 or parts[: len(head)] != head:
        raise WireError(f"not an agent's token: {key!r}")
    agent, incarnation = agent_id_of(key), incarnation_of(key)
    if agent >= n_agents:
        raise WireError(f"token of agent {agent}, outside 0..{n_agents - 1}: {key!r}")
    return agent, incarnation


HOSTS = f"{PREFIX}/hosts"


@dataclass(frozen=True)
class HostKeys:
    """Keys of one host daemon; outside any run, since a host serves one run after another."""

    name: str

    # liveliness token: the host is up
    @property
    def alive(self) -> str:
        return f"{HOSTS}/{self.name}"

    # queryables: what the host is (JSON), and start/stop agents of a run (JSON request and answer)
    @property
    def info(self) -> str:
        return f"{HOSTS}/{self.name}/info"

    @property
    def start(self) -> str:
        return f"{HOSTS}/{self.name}/start"

    @property
    def stop(self) -> str:
        return f"{HOSTS}/{self.name}/stop"


def out_shard_of(key: str) -> int | None:
    """The proxy an output key names below ``.../out`` (a radio split by region), None for ``.../out``."""
    head, _, last = str(key).rpartition("/")
    if last == "out":
        return None
    if not head.endswith("/out"):
        raise WireError(f"not an output key: {key!r}")
    return _number(last)


def run_host_of(key: str, root: str) -> str:
    """The host name in ``<root>/host/<name>/...`` (a run's host keys); a WireError if there is none."""
    parts, head = str(key).split("/"), f"{root}/host".split("/")
    if len(parts) <= len(head) or parts[: len(head)] != head or not parts[len(head)]:
        raise WireError(f"no host name in key {key!r}")
    return parts[len(head)]


def host_name_of(key: str) -> str:
    """The host name in ``swarmbed/hosts/<name>[/...]``."""
    parts = str(key).split("/")
    if parts[:2] != HOSTS.split("/") or len(parts) < 3:
        raise WireError(f"no host name in key {key!r}")
    return parts[2]


def proxy_name(shard: int) -> str:
    """The process name (and log file) of proxy ``shard``: ``netem``, ``netem-1``, ``netem-2``, ..."""
    return "netem" if shard == 0 else f"netem-{shard}"
