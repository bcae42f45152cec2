"""Key expressions of one run. Everything lives under ``swarmbed/<run-id>/`` so runs never mix."""

from __future__ import annotations

from dataclasses import dataclass

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

    # coordinator -> agent i: one sample per tick (observation + inbox), or a stop order
    def agent_in(self, agent_id: int) -> str:
        return f"{self.root}/agent/{agent_id}/in"

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

    # netem proxy -> coordinator: final totals once the ledger is on disk
    @property
    def netem_report(self) -> str:
        return f"{self.root}/netem/report"

    # liveliness tokens
    def alive_agent(self, agent_id: int) -> str:
        return f"{self.root}/alive/agent/{agent_id}"

    @property
    def alive_agents(self) -> str:
        return f"{self.root}/alive/agent/*"

    @property
    def alive_netem(self) -> str:
        return f"{self.root}/alive/netem"

    @property
    def alive_coordinator(self) -> str:
        return f"{self.root}/alive/coordinator"

    @property
    def alive_all(self) -> str:
        return f"{self.root}/alive/**"


def agent_id_of(key: str) -> int:
    """The agent id in ``.../agent/<id>/...`` or ``.../alive/agent/<id>``."""
    parts = str(key).split("/")
    try:
        return int(parts[parts.index("agent") + 1])
    except (ValueError, IndexError) as exc:
        raise ValueError(f"no agent id in key {key!r}") from exc
