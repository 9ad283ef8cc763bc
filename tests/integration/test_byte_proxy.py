"""The link proxy over loopback sockets: it forwards both ways unchanged and counts each
byte once, in the direction it went (`orchestrator.experiments.byte_proxy`)."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator

import pytest

from orchestrator.experiments.byte_proxy import CountingProxy

pytestmark = pytest.mark.timeout(30)


@pytest.fixture
def echo_server() -> Iterator[tuple[str, int]]:
    """A server that answers every chunk with the chunk doubled."""
    server = socket.create_server(("127.0.0.1", 0))

    def answer(conn: socket.socket) -> None:
        with conn:
            while data := conn.recv(65536):
                conn.sendall(data * 2)

    def serve() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            threading.Thread(target=answer, args=(conn,), daemon=True).start()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield server.getsockname()[:2]
    server.shutdown(socket.SHUT_RDWR)  # wakes the blocked accept (Linux)
    server.close()
    thread.join(timeout=5.0)


def recv_exactly(sock: socket.socket, n: int) -> bytes:
    out = b""
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        assert chunk, "closed early"
        out += chunk
    return out


def test_bytes_are_forwarded_and_counted_each_way(echo_server: tuple[str, int]) -> None:
    with CountingProxy(echo_server) as proxy:
        t0 = time.time()
        with socket.create_connection((proxy.host, proxy.port), timeout=5.0) as a, \
                socket.create_connection((proxy.host, proxy.port), timeout=5.0) as b:
            payload = bytes(range(256)) * 40  # 10 240 bytes
            a.sendall(payload)
            assert recv_exactly(a, 2 * len(payload)) == payload * 2
            b.sendall(b"xyz")
            assert recv_exactly(b, 6) == b"xyzxyz"
        t1 = time.time() + proxy.counter.bucket_s
        assert proxy.connections == 2
        assert proxy.endpoint == f"tcp/127.0.0.1:{proxy.port}"
        # Everything sent has been received through the proxy, so it has been counted.
        assert proxy.counter.total("upstream") == len(payload) + 3
        assert proxy.counter.total("downstream") == 2 * (len(payload) + 3)
        assert proxy.counter.between("upstream", t0 - 1.0, t1) == len(payload) + 3


def test_close_cuts_forwarded_connections(echo_server: tuple[str, int]) -> None:
    proxy = CountingProxy(echo_server).start()
    with socket.create_connection((proxy.host, proxy.port), timeout=5.0) as a:
        a.sendall(b"ping")
        assert recv_exactly(a, 8) == b"pingping"
        proxy.close()
        assert a.recv(1) == b""  # the proxy closed its side
    with pytest.raises(OSError):
        socket.create_connection((proxy.host, proxy.port), timeout=1.0)


def test_a_target_that_refuses_closes_the_dialler() -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        dead = probe.getsockname()[:2]  # bound, not listening: connections are refused
        with CountingProxy(dead) as proxy, \
                socket.create_connection((proxy.host, proxy.port), timeout=5.0) as a:
            assert a.recv(1) == b""
            assert proxy.connections == 0
