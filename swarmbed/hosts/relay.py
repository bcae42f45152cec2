"""A host daemon's relay of one run: the hub's one tick sample for this host, handed out as each
agent's own; the agents' outputs, gathered into one sample for the proxy.

The coordinator puts one sample a tick on ``swarmbed/<run>/host/<name>/in`` for every host that
carries agents (:func:`~swarmbed.wire.codec.encode_host_tick`), instead of one per agent; the relay,
inside the host's router, encodes and puts each agent's tick sample on its ``agent/<i>/in``, where
the agent's process reads it as before. The agents a host daemon starts put their outputs on
``host/<name>/agent/<i>/out``, which only this router hears; the relay sends them on to the proxy
together (``host/<name>/out``) once every agent of the tick answered, or :data:`HOLD_S` after the
first it holds (an agent that died or is slow holds the others' up by no more; an answer after
that goes on at once, before its agent can do anything else). So the hub's puts,
and its router's routing of a tick both ways, grow with the hosts, not the agents, and the agents'
samples are byte for byte what the hub would have put and the proxy would have taken.

A relay puts only for the agents it was asked to start (a swap or a restart that brings an agent
here starts it here too); the inputs of any other agent a sample names are dropped, counted and
logged, never forwarded, and the rest go on. The
hub's access rules let no remote identity publish an agent's input, so the relay's puts reach the
agents on this router only.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable

import zenoh

from swarmbed.wire.codec import WireError, decode_host_tick, encode_host_out
from swarmbed.wire.keys import Keys, agent_id_of, out_shard_of

log = logging.getLogger("swarmbed.host")
BLOCK = zenoh.CongestionControl.BLOCK
#: the longest the relay holds an output while it waits for the rest of its host's (seconds)
HOLD_S = 0.005


class TickRelay:
    """Splits the hub's tick samples for host ``host`` of run ``keys`` into its agents' samples."""

    def __init__(self, session: zenoh.Session, keys: Keys, host: str) -> None:
        self.session, self.keys, self.host = session, keys, host
        self.lock = threading.Lock()
        self.publishers: dict[int, zenoh.Publisher] = {}  # the agents this host carries
        self.malformed = 0
        self.relayed = 0  # tick samples split
        self.gathered = 0  # output samples sent on
        self.entities: list = []
        # outputs held for the proxy, the number the last tick asked for, how many came, and when
        # the first held came
        self.held: list[tuple[int, int | None, bytes]] = []  # (agent, the proxy that reads it, output)
        self.expected = 0
        self.answers = 0
        self.held_since = 0.0
        self.waited_out = False  # the hold ran out this tick: what comes later goes on at once
        self.wake = threading.Condition(self.lock)
        self.closed = False

    def __enter__(self) -> TickRelay:
        return self.open()

    def open(self) -> TickRelay:
        """Subscribe to the hub's tick samples for this host."""
        s, k = self.session, self.keys
        self.out = s.declare_publisher(k.host_out(self.host), congestion_control=BLOCK)
        self.entities = [
            self.out,
            s.declare_subscriber(k.host_in(self.host), zenoh.handlers.Callback(self._on_sample, indirect=False)),
            *(  # an answer on its agent's key, or below it on the key of the proxy that reads it
                s.declare_subscriber(key, zenoh.handlers.Callback(self._on_output, indirect=False))
                for key in (k.hosted_out_all(self.host), f"{k.hosted_out_all(self.host)}/*")
            ),
        ]
        self.flusher = threading.Thread(target=self._flush_held, name=f"relay-{self.host}", daemon=True)
        self.flusher.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        with self.lock:
            entities = [*self.entities[::-1], *self.publishers.values()]
            self.entities, self.publishers, self.closed = [], {}, True
            self.wake.notify()
        for entity in entities:
            entity.undeclare()

    def carry(self, agents: Iterable[int]) -> None:
        """Relay the inputs of ``agents`` from now on (their processes start on this host)."""
        with self.lock:
            for agent in agents:
                if agent not in self.publishers:
                    self.publishers[agent] = self.session.declare_publisher(
                        self.keys.agent_in(agent), congestion_control=BLOCK
                    )

    def carried(self) -> list[int]:
        with self.lock:
            return sorted(self.publishers)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            tick = decode_host_tick(sample.payload.to_bytes())
        except WireError as exc:
            self._malformed(f"malformed tick sample on {sample.key_expr} dropped: {exc}")
            return
        with self.lock:
            publishers = [self.publishers.get(a) for a in tick.agents]
            self.expected = len(publishers) - publishers.count(None)
            self.answers, self.waited_out = 0, False
        for publisher, (_agent, data) in zip(publishers, tick.samples(), strict=True):
            if publisher is not None:
                publisher.put(data)
        self.relayed += 1
        strangers = [a for a, p in zip(tick.agents, publishers, strict=True) if p is None]
        if strangers:  # an agent whose process is not (or no longer) here: the others go on
            self._malformed(f"tick {tick.tick}: inputs of agents {strangers[:10]}, not carried here, dropped")

    def _malformed(self, what: str) -> None:
        self.malformed += 1
        if self.malformed <= 20:
            log.warning("host %s: %s", self.host, what)

    def _on_output(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            agent, shard = agent_id_of(key), out_shard_of(key)
            with self.lock:
                if agent not in self.publishers:
                    raise WireError(f"an output of agent {agent}, which this host does not carry")
                if not self.held:
                    self.held_since = time.monotonic()
                    self.wake.notify()
                self.held.append((agent, shard, sample.payload.to_bytes()))
                self.answers += 1
                # the last of the tick, or one after the hold ran out: sent on at once, before its
                # agent can do anything else (leave, say), as it would reach the proxy directly
                done = self.answers >= self.expected or self.waited_out
                held = self._take_held() if done else None
            if held:
                self._send(held)
        except WireError as exc:
            self._malformed(f"output on {key} dropped: {exc}")

    def _take_held(self) -> list[tuple[int, int | None, bytes]]:
        held, self.held = self.held, []
        return held

    def _send(self, held: list[tuple[int, int | None, bytes]]) -> None:
        """One sample per proxy the outputs go to (one, unless the radio is split by region)."""
        by_shard: dict[int | None, list[tuple[int, bytes]]] = {}
        for agent, shard, data in held:
            by_shard.setdefault(shard, []).append((agent, data))
        for shard, outputs in by_shard.items():
            data = encode_host_out([a for a, _ in outputs], [data for _, data in outputs])
            if shard is None:
                self.out.put(data)
            else:  # a put: no publisher to keep per proxy
                self.session.put(f"{self.keys.host_out(self.host)}/{shard}", data, congestion_control=BLOCK)
            self.gathered += 1

    def _flush_held(self) -> None:
        """Send on what has been held for :data:`HOLD_S` (the rest of its tick is slow or gone)."""
        while True:
            with self.lock:
                while not self.closed and not self.held:
                    self.wake.wait()
                if self.closed:
                    return
                wait = self.held_since + HOLD_S - time.monotonic()
                if wait > 0:
                    self.wake.wait(wait)
                    continue
                held = self._take_held()
                self.waited_out = True
            self._send(held)
