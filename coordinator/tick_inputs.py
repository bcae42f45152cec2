"""Where the coordinator puts the agents' inputs of a tick: one sample for each agent on the hub's
machine, one for all the agents of a host (whose relay hands each its own,
:mod:`swarmbed.hosts.relay`); in a radio split by region, each agent told which proxy reads its
answer (:mod:`swarmbed.wire.regions`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import zenoh

from swarmbed.schema.experiment import LOCAL, RadioSplit
from swarmbed.wire.codec import EMPTY_INBOX, WorldSample, encode_host_tick, encode_tick
from swarmbed.wire.keys import Keys
from swarmbed.wire.observation import Observation
from swarmbed.wire.regions import owners

BLOCK = zenoh.CongestionControl.BLOCK


class TickInputs:
    """The publishers of agents' and hosts' tick samples. ``split``: a radio split by region, else
    None. ``agent_pubs``, one per agent, are the coordinator's (it orders agents on them too)."""

    def __init__(self, session: zenoh.Session, keys: Keys, split: RadioSplit | None) -> None:
        self.session, self.keys, self.split = session, keys, split
        self.agent_pubs: Sequence[zenoh.Publisher] = ()
        self.host_pubs: dict[str, zenoh.Publisher] = {}

    def put(
        self,
        k: int,
        sample: WorldSample,
        observed: Mapping[int, Observation],
        inboxes: Mapping[int, bytes],
        decisions: Mapping[int, int],
        where: Mapping[int, str],
    ) -> None:
        """Every live agent's input of tick ``k``; ``where``: the host of each agent not on this machine."""
        shard: dict[int, int] = {}
        if self.split is not None:  # each agent's answer goes to the proxy that owns it at this tick
            shard = dict(zip(sample.ids, owners(sample.xs, self.split).tolist(), strict=True))
        carried: dict[str, list[int]] = {}
        for i, obs in observed.items():
            host = where.get(i, LOCAL)
            if host == LOCAL:
                data = encode_tick(k, obs.to_wire(), inboxes.get(i, EMPTY_INBOX), decisions.get(i), shard.get(i))
                self.agent_pubs[i].put(data)
            else:
                carried.setdefault(host, []).append(i)
        for host, ids in carried.items():  # one sample per host, the agents' inputs as columns
            obs_wire = [observed[i].to_wire() for i in ids]
            host_inboxes = [inboxes.get(i, EMPTY_INBOX) for i in ids]
            shards = [shard.get(i, 0) for i in ids] if shard else None
            data = encode_host_tick(k, ids, obs_wire, host_inboxes, [decisions.get(i) for i in ids], shards)
            self._host_pub(host).put(data)

    def _host_pub(self, host: str) -> zenoh.Publisher:
        pub = self.host_pubs.get(host)
        if pub is None:
            pub = self.host_pubs[host] = self.session.declare_publisher(
                self.keys.host_in(host), congestion_control=BLOCK
            )
        return pub

    def close(self) -> None:
        for pub in self.host_pubs.values():
            pub.undeclare()
        self.host_pubs = {}
