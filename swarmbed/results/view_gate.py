"""The door of a live view (``--foxglove``): a TCP front of Foxglove's WebSocket server that admits
at most ``max_clients`` viewers at once, each only with the run's token in its URL
(``ws://127.0.0.1:PORT/TOKEN``), and relays their bytes to the server, which listens on a
loopback port of its own.

Why: the server takes anyone who reaches its port, and on a shared machine every local user
reaches 127.0.0.1; 40 slow and 300 idle clients stretched a 23.6 s run to 79.5 s. The token is
printed to whoever started the view; the cap bounds what viewers can cost the run.
"""

from __future__ import annotations

import secrets
import socket
import threading

#: the most viewers a live view admits at once (``--view-clients``)
MAX_CLIENTS = 4
#: the most bytes of a viewer's HTTP upgrade request read before it is refused, and how long it may take
MAX_REQUEST_BYTES, REQUEST_TIMEOUT_S = 16 << 10, 5.0


class ViewGate:
    """Admits viewers of ``backend_port`` (on 127.0.0.1) at ``host:port`` (0: a free one)."""

    def __init__(self, backend_port: int, host: str, port: int, max_clients: int = MAX_CLIENTS) -> None:
        self.backend_port, self.max_clients = backend_port, max_clients
        self.token = secrets.token_urlsafe(12)
        self.listener = socket.create_server((host, port))
        self.port = self.listener.getsockname()[1]
        self.url = f"ws://{host}:{self.port}/{self.token}"
        self.lock = threading.Lock()
        self.open: set[socket.socket] = set()
        self.admitted = 0
        self.refused = 0
        self.closed = False
        threading.Thread(target=self._accept, name="view-gate", daemon=True).start()

    def _accept(self) -> None:
        while not self.closed:
            try:
                viewer, _ = self.listener.accept()
            except OSError:
                return
            with self.lock:
                full = self.admitted >= self.max_clients
                if not full:
                    self.admitted += 1
            if full:
                self._refuse(viewer, "503 Service Unavailable", f"at most {self.max_clients} viewers at once")
                continue
            threading.Thread(target=self._serve, args=(viewer,), name="view-gate-viewer", daemon=True).start()

    def _refuse(self, viewer: socket.socket, status: str, why: str) -> None:
        with self.lock:
            self.refused += 1
        try:
            viewer.sendall(
                f"HTTP/1.1 {status}\r\nContent-Length: {len(why)}\r\nConnection: close\r\n\r\n{why}".encode()
            )
        except OSError:
            pass
        viewer.close()

    def _request(self, viewer: socket.socket) -> bytes | None:
        """The viewer's HTTP request head with its path rewritten to ``/``, or None if it does not
        name the token (or is too long or too slow)."""
        viewer.settimeout(REQUEST_TIMEOUT_S)
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = viewer.recv(4096)
            if not chunk or len(head) + len(chunk) > MAX_REQUEST_BYTES:
                return None
            head += chunk
        first, _, rest = head.partition(b"\r\n")
        parts = first.split(b" ")
        if len(parts) != 3 or not secrets.compare_digest(parts[1], f"/{self.token}".encode()):
            return None
        viewer.settimeout(None)
        return b" ".join([parts[0], b"/", parts[2]]) + b"\r\n" + rest

    def _serve(self, viewer: socket.socket) -> None:
        try:
            try:
                request = self._request(viewer)
            except OSError:
                request = None
            if request is None:
                self._refuse(viewer, "403 Forbidden", "a live view needs the run's token in its URL")
                return
            try:
                server = socket.create_connection(("127.0.0.1", self.backend_port), timeout=REQUEST_TIMEOUT_S)
            except OSError:
                viewer.close()
                return
            server.settimeout(None)
            with self.lock:
                self.open.update((viewer, server))
            server.sendall(request)
            back = threading.Thread(target=_pump, args=(server, viewer), daemon=True)
            back.start()
            _pump(viewer, server)
            back.join()
            with self.lock:
                self.open.difference_update((viewer, server))
        finally:
            with self.lock:
                self.admitted -= 1

    def close(self) -> None:
        self.closed = True
        try:
            self.listener.shutdown(socket.SHUT_RDWR)  # wakes the accept under way: closing alone leaves it listening
        except OSError:
            pass
        self.listener.close()
        with self.lock:
            for sock in self.open:
                try:
                    sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass


def _pump(source: socket.socket, sink: socket.socket) -> None:
    """Bytes from ``source`` to ``sink`` until either closes; then both are shut."""
    try:
        while data := source.recv(65536):
            sink.sendall(data)
    except OSError:
        pass
    for sock in (source, sink):
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
