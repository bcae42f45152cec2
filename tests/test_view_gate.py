"""A live view's gate (issue 82, item 12): at most ``max_clients`` viewers at once, each with the
run's token in its URL, their bytes relayed both ways; a viewer refused never reaches the server."""

import socket
import threading
import time

from swarmbed.results.view_gate import ViewGate


def _echo_server() -> tuple[socket.socket, list[bytes]]:
    """A server on a free loopback port that answers each connection's first bytes with 'OK ' + them."""
    listener = socket.create_server(("127.0.0.1", 0))
    seen: list[bytes] = []

    def serve() -> None:
        while True:
            try:
                conn, _ = listener.accept()
            except OSError:
                return
            data = conn.recv(4096)
            seen.append(data)
            conn.sendall(b"OK " + data)
            threading.Thread(target=lambda c=conn: (c.recv(1), c.close()), daemon=True).start()

    threading.Thread(target=serve, daemon=True).start()
    return listener, seen


def _ask(port: int, path: str) -> tuple[socket.socket, bytes]:
    conn = socket.create_connection(("127.0.0.1", port), timeout=5)
    conn.sendall(f"GET {path} HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n\r\n".encode())
    return conn, conn.recv(4096)


def test_the_token_is_needed_and_the_path_reaches_the_server_as_slash():
    backend, seen = _echo_server()
    gate = ViewGate(backend.getsockname()[1], "127.0.0.1", 0, max_clients=2)
    try:
        conn, answer = _ask(gate.port, "/wrong")
        assert answer.startswith(b"HTTP/1.1 403") and not seen
        conn.close()
        conn, answer = _ask(gate.port, f"/{gate.token}")
        assert answer.startswith(b"OK GET / HTTP/1.1") and gate.token.encode() not in seen[0]
        conn.close()
        assert gate.url == f"ws://127.0.0.1:{gate.port}/{gate.token}"
    finally:
        gate.close()
        backend.close()


def test_no_more_viewers_than_the_cap_at_once():
    backend, seen = _echo_server()
    gate = ViewGate(backend.getsockname()[1], "127.0.0.1", 0, max_clients=2)
    try:
        held = [_ask(gate.port, f"/{gate.token}") for _ in range(2)]
        assert all(answer.startswith(b"OK") for _, answer in held)
        extra, answer = _ask(gate.port, f"/{gate.token}")
        assert answer.startswith(b"HTTP/1.1 503") and len(seen) == 2
        extra.close()
        for conn, _ in held:
            conn.close()
        deadline = time.monotonic() + 5
        while gate.admitted and time.monotonic() < deadline:
            time.sleep(0.05)
        assert gate.admitted == 0  # those that left make room
        again, answer = _ask(gate.port, f"/{gate.token}")
        assert answer.startswith(b"OK")
        again.close()
    finally:
        gate.close()
        backend.close()
