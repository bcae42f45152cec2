"""What a crowd of viewers costs a run with a live view: its wall time with no viewer, and with
slow viewers (a WebSocket each that never reads) plus idle connections (a TCP connection that
never sends), in the same run of this script, alternating.

    python benchmarks/view_flood.py                          # 40 slow + 300 idle, 2 pairs
    python benchmarks/view_flood.py --slow 40 --idle 300 --view-clients 4 --pairs 3

Each run is ``swarmbed run experiments/space_mtsr.yaml --foxglove 0`` (20 agents, 3,000 simulated
s, lock-step: about 25 s on a 2-core machine); the crowd connects as soon as the run prints its
view's URL. Before the view's gate (``swarmbed/results/view_gate.py``), 40 slow and 300 idle
clients stretched a 23.6 s run to 79.5 s; with it, at most ``--view-clients`` viewers are admitted
and the others are refused (``--view-clients 400`` shows what admitting them all costs).
"""

from __future__ import annotations

import argparse
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
URL = re.compile(r"Foxglove: open connection (ws://127\.0\.0\.1:(\d+)/(\S+))")


def slow_viewer(port: int, token: str, held: list[socket.socket]) -> None:
    """A viewer that completes the WebSocket upgrade and then never reads what it is sent."""
    try:
        conn = socket.create_connection(("127.0.0.1", port), timeout=10)
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        conn.sendall(
            f"GET /{token} HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
            "Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n".encode()
        )
        held.append(conn)
    except OSError:
        pass


def one_run(slow: int, idle: int, view_clients: int, agents: int, duration: float) -> tuple[float, int]:
    """(wall seconds of the run, connections the crowd held open to the view's port)."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [
            sys.executable,
            "-m",
            "swarmbed",
            "run",
            str(ROOT / "experiments" / "space_mtsr.yaml"),
            "--foxglove",
            "0",
            "--view-clients",
            str(view_clients),
            "--no-progress",
            "--out",
            f"{tmp}/run",
            "--set",
            f"agents.count={agents}",
            "--set",
            f"run.duration={duration}",
        ]
        t0 = time.monotonic()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp)
        held: list[socket.socket] = []
        assert proc.stderr is not None
        for line in proc.stderr:
            found = URL.search(line)
            if found:
                port, token = int(found.group(2)), found.group(3)
                for _ in range(idle):
                    try:
                        held.append(socket.create_connection(("127.0.0.1", port), timeout=10))
                    except OSError:
                        break
                threads = [threading.Thread(target=slow_viewer, args=(port, token, held)) for _ in range(slow)]
                for t in threads:
                    t.start()
                break
        proc.communicate()
        wall = time.monotonic() - t0
        for conn in held:
            conn.close()
        if proc.returncode != 0:
            raise SystemExit(f"the run failed ({proc.returncode})")
        return wall, len(held)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slow", type=int, default=40)
    ap.add_argument("--idle", type=int, default=300)
    ap.add_argument("--view-clients", type=int, default=4)
    ap.add_argument("--agents", type=int, default=20)
    ap.add_argument("--duration", type=float, default=3000.0)
    ap.add_argument("--pairs", type=int, default=2)
    args = ap.parse_args()
    walls: dict[str, list[float]] = {"no viewer": [], "crowd": []}
    connected = []
    for _ in range(args.pairs):
        walls["no viewer"].append(one_run(0, 0, args.view_clients, args.agents, args.duration)[0])
        wall, held = one_run(args.slow, args.idle, args.view_clients, args.agents, args.duration)
        walls["crowd"].append(wall)
        connected.append(held)
    for name, values in walls.items():
        print(
            f"{name:<10} {statistics.median(values):6.1f} s wall (median of {len(values)}: "
            f"{', '.join(f'{v:.1f}' for v in values)})"
        )
    print(
        f"crowd / no viewer: x{statistics.median(walls['crowd']) / statistics.median(walls['no viewer']):.2f} "
        f"({args.slow} slow + {args.idle} idle clients, --view-clients {args.view_clients}; "
        f"connections held open: {connected})"
    )


if __name__ == "__main__":
    main()
