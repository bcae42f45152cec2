"""The raw Zenoh floors' processes, started by ``benchmarks/lockstep.py``; not part of swarmbed.

- ``client``: ticked by the bench; replies at once (``--fanout 0``, the bare barrier) or relays one
  message and replies once the ``--fanout`` it is owed have arrived (the retired relay baseline);
  ``--direct`` answers inside the subscriber's own callback (``indirect=False``: no Python thread
  in between), the B1 floor's client.
- ``relay``: forwards each client's message to the next ``FANOUT`` clients (relay baseline).
- ``agent`` and ``proxy``: swarmbed's skeleton with no Python work (B2): an agent answers a tick
  with one output on its own key; the proxy, its own process, counts a tick's outputs and sends
  the coordinator one step sample when the last arrives.
"""

import argparse
import queue
import struct
import threading

import zenoh

from swarmbed.wire.zenoh_session import zenoh_config

BLOCK = zenoh.CongestionControl.BLOCK
FANOUT = 5


def _direct(fn):  # a handler that runs in Zenoh's own thread, with no Python thread hop
    return zenoh.handlers.Callback(fn, indirect=False)


def _answer_ticks(s: zenoh.Session, ns: str, i: int, answer: zenoh.Publisher, size: int) -> None:
    """Answer each tick with ``size`` bytes on ``answer``, put from the callback that received it,
    until a negative tick."""
    finished = threading.Event()

    def on_tick(x: zenoh.Sample) -> None:
        (k,) = struct.unpack("<q", x.payload.to_bytes()[:8])
        if k < 0:
            finished.set()
        else:
            answer.put(struct.pack("<qq", k, i) + b"\0" * max(0, size - 16))

    sub = s.declare_subscriber(f"{ns}/c/{i}/tick", _direct(on_tick))
    token = s.liveliness().declare_token(f"{ns}/alive/{i}")
    finished.wait()
    token.undeclare()
    sub.undeclare()


def client(s: zenoh.Session, ns: str, i: int, fanout: int, direct: bool) -> None:
    done = s.declare_publisher(f"{ns}/done", congestion_control=BLOCK)
    if direct:  # B1: the reply is put from the callback that received the tick
        _answer_ticks(s, ns, i, done, 16)
        return
    events: queue.SimpleQueue = queue.SimpleQueue()
    subs = [
        s.declare_subscriber(f"{ns}/c/{i}/tick", lambda x: events.put(("tick", x.payload.to_bytes()))),
        s.declare_subscriber(f"{ns}/c/{i}/relay", lambda x: events.put(("relay", x.payload.to_bytes()))),
    ]
    to_relay = s.declare_publisher(f"{ns}/relay", congestion_control=BLOCK)
    token = s.liveliness().declare_token(f"{ns}/alive/{i}")
    relayed: dict[int, int] = {}
    waiting: int | None = None
    while True:
        what, data = events.get()
        if what == "tick":
            (k,) = struct.unpack("<q", data[:8])
            if k < 0:
                break
            if fanout:
                to_relay.put(struct.pack("<qq", k, i) + b"\0" * 16)
            waiting = k
        else:
            k = struct.unpack("<q", data[:8])[0]
            relayed[k] = relayed.get(k, 0) + 1
        if waiting is not None and relayed.get(waiting, 0) >= fanout:
            relayed.pop(waiting, None)
            done.put(struct.pack("<qq", waiting, i))
            waiting = None
    token.undeclare()
    for x in subs:
        x.undeclare()


def relay(s: zenoh.Session, ns: str, n: int) -> None:
    pubs = [s.declare_publisher(f"{ns}/c/{j}/relay", congestion_control=BLOCK) for j in range(n)]
    stop: queue.SimpleQueue = queue.SimpleQueue()

    def forward(sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        k, i = struct.unpack("<qq", data[:16])
        if k < 0:
            stop.put(None)
            return
        for d in range(1, FANOUT + 1):
            pubs[(i + d) % n].put(data)

    sub = s.declare_subscriber(f"{ns}/relay", forward)
    token = s.liveliness().declare_token(f"{ns}/alive/relay")
    stop.get()
    token.undeclare()
    sub.undeclare()


def agent(s: zenoh.Session, ns: str, i: int, out_bytes: int) -> None:
    """B2's agent: one output of ``out_bytes`` per tick, on its own key."""
    _answer_ticks(s, ns, i, s.declare_publisher(f"{ns}/out/{i}", congestion_control=BLOCK), out_bytes)


def proxy(s: zenoh.Session, ns: str, n: int, out_bytes: int) -> None:
    """B2's proxy: a counter, not a scan; the step goes out from the callback of the last output."""
    step = s.declare_publisher(f"{ns}/step", congestion_control=BLOCK)
    finished = threading.Event()
    got = [0]

    def on_out(x: zenoh.Sample) -> None:
        data = x.payload.to_bytes()
        (k,) = struct.unpack("<q", data[:8])
        got[0] += 1
        if got[0] == n:
            got[0] = 0
            step.put(struct.pack("<q", k) + b"\0" * max(0, out_bytes - 8))

    def on_stop(x: zenoh.Sample) -> None:
        finished.set()

    subs = [
        s.declare_subscriber(f"{ns}/out/*", _direct(on_out)),
        s.declare_subscriber(f"{ns}/stop", _direct(on_stop)),
    ]
    token = s.liveliness().declare_token(f"{ns}/alive/proxy")
    finished.wait()
    token.undeclare()
    for x in subs:
        x.undeclare()


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("role", choices=["client", "relay", "agent", "proxy"])
    ap.add_argument("--ns", required=True)
    ap.add_argument("--connect", required=True)
    ap.add_argument("--id", type=int, default=0)
    ap.add_argument("--n", type=int, default=0)
    ap.add_argument("--fanout", type=int, default=FANOUT, help="messages each client waits for per tick (0: none)")
    ap.add_argument("--direct", action="store_true", help="client: reply inside a direct callback")
    ap.add_argument("--bytes", type=int, default=200, help="agent and proxy: bytes of each output")
    a = ap.parse_args()
    with zenoh.open(zenoh_config("client", connect=[a.connect])) as session:
        if a.role == "client":
            client(session, a.ns, a.id, a.fanout, a.direct)
        elif a.role == "relay":
            relay(session, a.ns, a.n)
        elif a.role == "agent":
            agent(session, a.ns, a.id, a.bytes)
        else:
            proxy(session, a.ns, a.n, a.bytes)
