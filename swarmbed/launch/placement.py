"""Where a run's agent processes start and stop: this machine's fork server (or fresh interpreters)
for agents placed here, a host daemon's for agents placed on another machine.

:class:`AgentPlacement` is what the launcher hands the coordinator as its
:class:`~swarmbed.coordinator.process_control.Placement`: the coordinator decides when an agent needs a
process (the first one, a swap, a restart) and this class knows how to start one there.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import zenoh

from swarmbed.launch.access import agent_user
from swarmbed.launch.host_client import start_agents, stop_agents, wait_for_hosts
from swarmbed.launch.launcher import Children
from swarmbed.schema.experiment import LOCAL
from swarmbed.wire.child_process import process_name
from swarmbed.wire.control import StartAgents, StopAgents
from swarmbed.wire.keys import Keys


@dataclass
class AgentPlacement:
    """Starts agents as the run's children or on its hosts. ``common``: every child's arguments
    (run id, hub endpoint, log rotation); ``identity(user)``: the credentials arguments of a
    process (none without access control); ``hub``: the endpoint hosts' routers connect to."""

    children: Children
    session: zenoh.Session
    keys: Keys
    common: Sequence[str]
    log_rotation: tuple[int, int]  # (MB per file, backups kept), for agents started on hosts
    identity: Callable[[str], list[str]]
    hub: str
    auth: bool
    join_timeout: float
    started: list[str] = field(default_factory=list)  # hosts this run started agents on

    def first(self, agent: int) -> None:
        """The first process of ``agent`` on this machine (hosts start theirs through :meth:`on_host`)."""
        self.children.spawn(
            f"agent_{agent}",
            "swarmbed.agent_runtime",
            [*self.common, *self.identity(agent_user(agent)), "--id", str(agent)],
        )

    def on_host(self, host: str, agents: list[int]) -> None:
        """The first processes of ``agents`` on ``host`` (waited for and introduced already)."""
        start_agents(self.session, host, self._start(agents))
        if host not in self.started:
            self.started.append(host)

    def _start(self, agents: list[int], incarnation: int = 0, restore: bool = False) -> StartAgents:
        max_mb, backups = self.log_rotation
        return StartAgents(
            run_id=self.keys.run_id,
            agents=agents,
            incarnation=incarnation,
            restore=restore,
            log_max_mb=max_mb,
            log_backups=backups,
        )

    def place(self, agent: int, host: str, incarnation: int, restore: bool = True) -> None:
        if host == LOCAL:
            args = ["--id", str(agent), "--incarnation", str(incarnation), *(["--restore"] if restore else [])]
            self.children.spawn(
                process_name(agent, incarnation),
                "swarmbed.agent_runtime",
                [*self.common, *self.identity(agent_user(agent)), *args],
            )
            return
        wait_for_hosts(self.session, [host], min(5.0, self.join_timeout), self.hub, auth=self.auth)
        start_agents(self.session, host, self._start([agent], incarnation, restore))
        if host not in self.started:
            self.started.append(host)

    def unplace(self, agent: int, host: str, incarnation: int) -> None:
        if host == LOCAL:
            proc = self.children.procs.get(process_name(agent, incarnation))
            if proc is not None and proc.poll() is None:
                proc.kill()
        else:
            stop_agents(
                self.session, host, StopAgents(run_id=self.keys.run_id, agents=[agent], incarnation=incarnation)
            )

    def exit_status(self, process: str) -> str:
        return self.children.exit_status(process)

    def stop_all(self) -> None:
        """Agents still running on the hosts after a failure."""
        for host in self.started:
            stop_agents(self.session, host, StopAgents(run_id=self.keys.run_id))
