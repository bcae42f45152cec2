"""What really crossed the wire: the kernel's TCP counters of this process's own sockets.

The installed zenoh-python wheel exposes no transport statistics, so a process reads the Linux
``tcp_info`` of every TCP socket it holds (Zenoh's links among them), as ``ss -ti`` shows it:
``bytes_acked`` (payload bytes the peer acknowledged, i.e. sent and arrived) and
``bytes_received``, plus segment counts. These are TCP payload bytes: Zenoh's framing, its
keep-alives and every sample of the session, radio and control alike, but not the IP and TCP
headers (``segments`` gives their count: 52 bytes each over IPv4 with timestamps).

A socket closed before the reading (a link that dropped and reconnected) is not counted; a run's
processes hold their links from start to end.
"""

from __future__ import annotations

import os
import socket
import struct
import sys

# offsets in struct tcp_info (linux/tcp.h): tcpi_bytes_acked and tcpi_bytes_received are u64 at
# 120 and 128, tcpi_segs_out and tcpi_segs_in u32 at 136 and 140 (kernels 4.2 and later)
_TCP_INFO_LEN = 144
_COUNTERS = struct.Struct("=QQII")
_COUNTERS_AT = 120


def tcp_counters() -> dict[str, int] | None:
    """Sums over this process's TCP sockets: ``sent``, ``received``, ``segments_out``,
    ``segments_in``, ``sockets``; None where the kernel's counters cannot be read (not Linux)."""
    if sys.platform != "linux":
        return None
    try:
        fds = os.listdir("/proc/self/fd")
    except OSError:
        return None
    total = {"sent": 0, "received": 0, "segments_out": 0, "segments_in": 0, "sockets": 0}
    for name in fds:
        fd = int(name)
        try:
            if not os.readlink(f"/proc/self/fd/{fd}").startswith("socket:"):
                continue
            dup = os.dup(fd)
        except OSError:
            continue  # closed meanwhile (the listing's own fd among them)
        with socket.socket(fileno=dup) as sock:
            if sock.type != socket.SOCK_STREAM or sock.family not in (socket.AF_INET, socket.AF_INET6):
                continue
            try:
                info = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, _TCP_INFO_LEN)
            except OSError:
                continue
        if len(info) < _COUNTERS_AT + _COUNTERS.size:
            return None  # a kernel older than these counters
        acked, received, segs_out, segs_in = _COUNTERS.unpack_from(info, _COUNTERS_AT)
        total["sent"] += acked
        total["received"] += received
        total["segments_out"] += segs_out
        total["segments_in"] += segs_in
        total["sockets"] += 1
    return total
