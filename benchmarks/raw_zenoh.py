"""The raw Zenoh baseline's processes: a client (ticked by the bench, relays one message, replies)
and the relay; with ``--fanout 0`` the bare barrier (a client replies to each tick at once, no
relay). Started by ``benchmarks/lockstep.py``; not part of swarmbed."""

import argparse
import queue
import struct

import zenoh

from swarmbed.wire.session import zenoh_config

BLOCK = zenoh.CongestionControl.BLOCK


def client(s: zenoh.Session, ns: str, i: int, fanout: int) -> None:
    events: queue.SimpleQueue = queue.SimpleQueue()
    subs = [
        s.declare_subscriber(f"{ns}/c/{i}/tick", lambda x: events.put(("tick", x.payload.to_bytes()))),
        s.declare_subscriber(f"{ns}/c/{i}/relay", lambda x: events.put(("relay", x.payload.to_bytes()))),
    ]
    to_relay = s.declare_publisher(f"{ns}/relay", congestion_control=BLOCK)
    done = s.declare_publisher(f"{ns}/done", congestion_control=BLOCK)
    token = s.liveliness().declare_token(f"{ns}/alive/{i}")
    relayed: dict[int, int] = {}
    waiting: int | None = None
    while True:
        what, data = events.get()
        if what == "tick":
            (k,) = struct.unpack("<q", data)
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


FANOUT = 5

if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("role", choices=["client", "relay"])
    ap.add_argument("--ns", required=True)
    ap.add_argument("--connect", required=True)
    ap.add_argument("--id", type=int, default=0)
    ap.add_argument("--n", type=int, default=0)
    ap.add_argument("--fanout", type=int, default=FANOUT, help="messages each client waits for per tick (0: none)")
    a = ap.parse_args()
    with zenoh.open(zenoh_config("client", connect=[a.connect])) as session:
        client(session, a.ns, a.id, a.fanout) if a.role == "client" else relay(session, a.ns, a.n)
