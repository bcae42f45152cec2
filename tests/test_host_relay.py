"""A host daemon's relay (swarmbed.hosts.relay) over real Zenoh sessions on loopback: the hub's one
tick sample for a host becomes, on the host's router, each carried agent's own sample, byte for
byte what the hub puts for an agent on its own machine; a crafted sample is dropped whole, the
input of an agent the host does not carry alone."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import zenoh

from swarmbed import config as cfg
from swarmbed.hosts.relay import TickRelay
from swarmbed.wire.codec import EMPTY_INBOX, decode_host_tick, encode_host_tick, encode_tick, pack
from swarmbed.wire.errors import WireError
from swarmbed.wire.keys import Keys
from swarmbed.wire.zenoh_session import free_loopback_endpoint, zenoh_config
from tests.test_tickdecode import SCENARIOS

KEYS = Keys("relaytest")


def _inputs(name: str) -> tuple[list[dict], list[bytes]]:
    """Six agents' observations of a scenario as the hub puts them, and inboxes of every kind."""
    path, sets = SCENARIOS[name]
    scenario = cfg.resolve_experiment(cfg.load(path, ["agents.count=6", *sets])).scenario()
    observed = scenario.make_world(np.random.default_rng(3)).observations()
    inboxes = [EMPTY_INBOX, pack([[1, 0, b"\x00\xff" * 40]]), b"", EMPTY_INBOX, pack([[2, 5, b"x"]] * 3), b"\x01"]
    return [observed[i].to_wire() for i in sorted(observed)], inboxes


@pytest.fixture
def host_router():
    """A router standing in for a host daemon's, and a client session of the hub's side."""
    endpoint = free_loopback_endpoint()
    router = zenoh.open(zenoh_config("router", listen=[endpoint]))
    with (
        router,
        zenoh.open(zenoh_config("client", [endpoint])) as hub,
        zenoh.open(zenoh_config("client", [endpoint])) as agents,
    ):
        yield router, hub, agents


def _listen(session: zenoh.Session, ids: range) -> tuple[dict[int, list[bytes]], list]:
    heard: dict[int, list[bytes]] = {i: [] for i in ids}
    subs = [
        session.declare_subscriber(KEYS.agent_in(i), lambda s, i=i: heard[i].append(s.payload.to_bytes())) for i in ids
    ]
    return heard, subs


def _settle(heard: dict[int, list[bytes]], want: int, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while sum(map(len, heard.values())) < want and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(0.2)  # anything more that was going to come


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_a_host_tick_sample_becomes_each_agents_own_sample_byte_for_byte(host_router, scenario):
    router, hub, agents = host_router
    obs, inboxes = _inputs(scenario)
    carried = [5, 0, 3]  # out of order: the sample's order is the hub's, not the ids'
    decisions = [None, 7, -(2**31)]
    heard, subs = _listen(agents, range(6))
    with TickRelay(router, KEYS, "h1") as relay:
        relay.carry(carried)
        time.sleep(0.3)
        hub.put(
            KEYS.host_in("h1"),
            encode_host_tick(41, carried, [obs[i] for i in carried], [inboxes[i] for i in carried], decisions),
        )
        _settle(heard, len(carried))
        assert relay.relayed == 1 and relay.malformed == 0
    for sub in subs:
        sub.undeclare()
    for agent, decision in zip(carried, decisions, strict=True):
        assert heard[agent] == [encode_tick(41, obs[agent], inboxes[agent], decision)], agent
    assert not any(heard[i] for i in range(6) if i not in carried)


CRAFTED = {
    "not msgpack": b"\xc1",
    "not a list": pack({"tick": 1}),
    "four fields": pack([1, [0], [{}], [b""]]),
    "negative tick": pack([-1, [0], [{}], [b""], [None]]),
    "a bool for a tick": pack([True, [0], [{}], [b""], [None]]),
    "columns of two lengths": pack([1, [0, 1], [{}], [b"", b""], [None, None]]),
    "an agent twice": pack([1, [0, 0], [{}, {}], [b"", b""], [None, None]]),
    "a negative agent": pack([1, [-1], [{}], [b""], [None]]),
    "an obs that is not a map": pack([1, [0], [[1, 2]], [b""], [None]]),
    "an inbox that is text": pack([1, [0], [{}], ["x"], [None]]),
    "a decision past 32 bits": pack([1, [0], [{}], [b""], [2**31]]),
}


def test_a_crafted_host_sample_is_dropped_whole_and_counted(host_router):
    router, hub, agents = host_router
    heard, subs = _listen(agents, range(6))
    with TickRelay(router, KEYS, "h1") as relay:
        relay.carry([0, 1])
        time.sleep(0.3)
        for data in CRAFTED.values():
            hub.put(KEYS.host_in("h1"), data)
        hub.put(KEYS.host_in("h2"), encode_host_tick(1, [0], [{}], [b""], [None]))  # another host's
        _settle(heard, 1, timeout=1.0)
        assert (relay.malformed, relay.relayed) == (len(CRAFTED), 0)
    for sub in subs:
        sub.undeclare()
    assert not any(heard.values())


@pytest.mark.parametrize("name", sorted(CRAFTED))
def test_each_crafted_host_sample_is_refused_with_what_is_wrong(name):
    with pytest.raises(WireError):
        decode_host_tick(CRAFTED[name])


def test_the_input_of_an_agent_not_carried_here_is_dropped_and_the_others_go_on(host_router):
    """An agent whose process is not on this host (one being restarted elsewhere, or a crafted
    name): its input is dropped and counted, the carried agents get theirs, and the answers are
    gathered for the carried ones only."""
    router, hub, agents = host_router
    heard, subs = _listen(agents, range(6))
    with TickRelay(router, KEYS, "h1") as relay:
        relay.carry([0, 1])
        time.sleep(0.3)
        hub.put(KEYS.host_in("h1"), encode_host_tick(3, [4, 0, 1], [{}] * 3, [b""] * 3, [None] * 3))
        _settle(heard, 2)
        assert (relay.malformed, relay.relayed, relay.expected) == (1, 1, 2)
    for sub in subs:
        sub.undeclare()
    assert heard[0] == [encode_tick(3, {}, b"")] and heard[1] == [encode_tick(3, {}, b"")] and not heard[4]


def test_agents_carried_while_samples_arrive_are_relayed_from_their_first_tick(host_router):
    """The daemon starts agents for a run while the relay already relays others' ticks (a swap or a
    restart brings one here mid-run)."""
    router, hub, agents = host_router
    heard, subs = _listen(agents, range(4))
    stop = threading.Event()
    with TickRelay(router, KEYS, "h1") as relay:
        relay.carry([0])
        time.sleep(0.3)

        def tick() -> None:
            k = 0
            while not stop.is_set():
                ids = [0, 1] if 1 in relay.carried() else [0]
                n = len(ids)
                hub.put(KEYS.host_in("h1"), encode_host_tick(k, ids, [{}] * n, [b""] * n, [None] * n))
                k += 1
                time.sleep(0.005)

        thread = threading.Thread(target=tick)
        thread.start()
        time.sleep(0.2)
        relay.carry([1])
        time.sleep(0.3)
        stop.set()
        thread.join()
        time.sleep(0.2)
    for sub in subs:
        sub.undeclare()
    assert heard[0] and heard[1] and not heard[2] and not heard[3]
    assert relay.malformed == 0


def test_the_proxy_takes_a_hosts_gathered_outputs_only_for_agents_that_host_may_carry(tmp_path):
    """The proxy's own handler of ``host/<name>/out``, over a real Zenoh put: in a run with access
    control (carriers known) an output of an agent the host may not carry is refused, whole
    sample; the others arrive as if each agent had put its own, under the host's key."""
    from swarmbed.netem.proxy import Proxy
    from swarmbed.schema.experiment import netem_spec
    from swarmbed.wire.codec import encode_agent_out, encode_host_out
    from tests.conftest import experiment

    spec = netem_spec(experiment("agents.count=6"), {"h1": [1, 2], "h2": [3]})
    endpoint = free_loopback_endpoint()
    router = zenoh.open(zenoh_config("router", listen=[endpoint]))
    host = zenoh.open(zenoh_config("client", [endpoint]))
    with router, host:
        proxy = Proxy(spec, KEYS, router, tmp_path)
        sub = router.declare_subscriber(KEYS.host_out_all, zenoh.handlers.Callback(proxy._on_host_out, indirect=False))
        time.sleep(0.3)
        outs = {i: encode_agent_out(0, i, ["stop"], []) for i in range(6)}
        host.put(KEYS.host_out("h1"), encode_host_out([2, 1], [outs[2], outs[1]]))
        host.put(KEYS.host_out("h1"), encode_host_out([1, 3], [outs[1], outs[3]]))  # 3 is h2's
        host.put(KEYS.host_out("h9"), encode_host_out([4], [outs[4]]))  # no host of this run
        host.put(KEYS.host_out("h2"), b"\xc1")
        time.sleep(0.5)
        sub.undeclare()
    events = []
    while not proxy.events.empty():
        events.append(proxy.events.get())
    assert proxy.arrived == [(KEYS.hosted_out("h1", 2), outs[2]), (KEYS.hosted_out("h1", 1), outs[1])]
    refused = sorted(str(exc) for what, (_key, exc) in ((w, d) for w, d in events if w == "malformed"))
    assert len(refused) == 3, refused
    assert "h1 may not carry agents [3]" in refused[0] and "h9 may not carry agents [4]" in refused[1], refused
    assert "not msgpack" in refused[2], refused
    # without access control any host may send any agent's output: the proxy checks each as it does
    # an agent's own (its key's agent, its tick)
    open_spec = netem_spec(experiment("agents.count=6"))
    assert open_spec.carriers is None


def test_gathered_outputs_go_one_sample_per_proxy_that_reads_them(host_router):
    """A radio split by region: the agents answer below their output key on the key of the proxy
    that owns them at the tick; the relay sends each proxy its own, once all answered."""
    from swarmbed.wire.codec import decode_host_out

    router, hub, agents = host_router
    got: list[tuple[str, list]] = []
    subs = [
        hub.declare_subscriber(key, lambda s: got.append((str(s.key_expr), decode_host_out(s.payload.to_bytes()))))
        for key in (KEYS.host_out_all, f"{KEYS.host_out_all}/*")
    ]
    with TickRelay(router, KEYS, "h1") as relay:
        relay.carry([0, 1, 2])
        time.sleep(0.3)
        hub.put(KEYS.host_in("h1"), encode_host_tick(0, [0, 1, 2], [{}] * 3, [b""] * 3, [None] * 3, [2, 0, 2]))
        time.sleep(0.2)
        for agent, shard in ((0, 2), (1, 0), (2, 2)):
            agents.put(f"{KEYS.hosted_out('h1', agent)}/{shard}", bytes([agent]))
        agents.put(f"{KEYS.hosted_out('h1', 5)}/0", b"not carried")
        deadline = time.monotonic() + 5
        while len(got) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(0.2)
        assert relay.malformed == 1
    for sub in subs:
        sub.undeclare()
    assert sorted(got) == [
        (f"{KEYS.host_out('h1')}/0", [(1, b"\x01")]),
        (f"{KEYS.host_out('h1')}/2", [(0, b"\x00"), (2, b"\x02")]),
    ]
