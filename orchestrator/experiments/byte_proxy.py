"""A TCP forwarding proxy that counts the bytes crossing it, each way, over time.

It stands for the network link between two hosts: a relay router dials the proxy's address
instead of the world's, and every byte between them passes here (with TLS: the encrypted
records, as a link would carry them). The counts are what crossed the link, not what Zenoh
meant to send: framing, batching, TLS records, keep-alives and declarations included.

    with CountingProxy(("127.0.0.1", world_port)) as proxy:
        ...  # the relay dials tcp/127.0.0.1:<proxy.port>
        down = proxy.counter.between("downstream", t0_wall, t1_wall)

Each accepted connection gets two threads (one per direction) that copy with blocking
``recv``/``sendall``; a closed side closes the other. ``upstream`` is what the dialling
side (the relay) sends towards the target (the world), ``downstream`` the reverse.
"""

from __future__ import annotations

import contextlib
import math
import socket
import threading
import time
from collections.abc import Callable
from types import TracebackType

DIRECTIONS = ("upstream", "downstream")
"""``upstream``: from the side that dials the proxy to the target; ``downstream``: back."""
BUCKET_S = 0.1
"""Width of the wall-time buckets the bytes are counted in."""
CHUNK_B = 1 << 16


class ByteCounter:
    """Bytes per direction in wall-time buckets of `bucket_s` (thread-safe).

    Args:
        bucket_s: bucket width [s]; a window's sum is exact to within one bucket at each end.
        clock: wall clock [s] (``time.time``: the world's events carry the same clock).
    """

    def __init__(self, bucket_s: float = BUCKET_S,
                 clock: Callable[[], float] = time.time) -> None:
        if not bucket_s > 0.0:
            raise ValueError(f"bucket_s must be > 0, got {bucket_s}")
        self.bucket_s = bucket_s
        self.clock = clock
        self._lock = threading.Lock()
        self._buckets: dict[str, dict[int, int]] = {d: {} for d in DIRECTIONS}

    def add(self, direction: str, n_bytes: int, at_s: float | None = None) -> None:
        """Count `n_bytes` in `direction` at wall time `at_s` (None: now)."""
        k = math.floor((self.clock() if at_s is None else at_s) / self.bucket_s)
        with self._lock:
            buckets = self._buckets[direction]
            buckets[k] = buckets.get(k, 0) + int(n_bytes)

    def total(self, direction: str) -> int:
        """Every byte counted in `direction`."""
        with self._lock:
            return sum(self._buckets[direction].values())

    def between(self, direction: str, t0_s: float, t1_s: float) -> int:
        """Bytes in `direction` in the buckets that start in [t0_s, t1_s) (wall seconds)."""
        lo, hi = math.ceil(t0_s / self.bucket_s), math.ceil(t1_s / self.bucket_s)
        with self._lock:
            return sum(n for k, n in self._buckets[direction].items() if lo <= k < hi)


class CountingProxy:
    """Listens on `listen_host` (a free port) and forwards every connection to `target`.

    Args:
        target: (host, port) every accepted connection is forwarded to.
        listen_host: address to listen on.
        counter: where the bytes are counted (a new `ByteCounter` by default).
    """

    def __init__(self, target: tuple[str, int], listen_host: str = "127.0.0.1",
                 counter: ByteCounter | None = None) -> None:
        self.target = target
        self.counter = counter or ByteCounter()
        self.connections = 0
        self._server = socket.create_server((listen_host, 0))
        self.host, self.port = self._server.getsockname()[:2]
        self._sockets: list[socket.socket] = []
        self._lock = threading.Lock()
        self._closed = threading.Event()
        self._acceptor = threading.Thread(target=self._accept, name="proxy-accept", daemon=True)

    def start(self) -> CountingProxy:
        self._acceptor.start()
        return self

    def __enter__(self) -> CountingProxy:
        return self.start()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    @property
    def endpoint(self) -> str:
        """The proxy's address as a Zenoh TCP endpoint (``tcp/<host>:<port>``)."""
        return f"tcp/{self.host}:{self.port}"

    def close(self) -> None:
        """Stop accepting and cut every forwarded connection."""
        self._closed.set()
        _close(self._server)
        with self._lock:
            sockets, self._sockets = self._sockets, []
        for sock in sockets:
            _close(sock)
        if self._acceptor.is_alive():
            self._acceptor.join(timeout=5.0)

    def _accept(self) -> None:
        while not self._closed.is_set():
            try:
                near, _ = self._server.accept()
            except OSError:
                return  # closed
            try:
                far = socket.create_connection(self.target, timeout=5.0)
            except OSError:
                _close(near)
                continue
            far.settimeout(None)
            for sock in (near, far):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                if self._closed.is_set():
                    _close(near)
                    _close(far)
                    return
                self._sockets += [near, far]
                self.connections += 1
            for src, dst, direction in ((near, far, "upstream"), (far, near, "downstream")):
                threading.Thread(target=self._pump, args=(src, dst, direction),
                                 name=f"proxy-{direction}", daemon=True).start()

    def _pump(self, src: socket.socket, dst: socket.socket, direction: str) -> None:
        """Copy `src` to `dst` until either side closes, counting each chunk as it is
        passed on (before the other side can have it)."""
        try:
            while data := src.recv(CHUNK_B):
                self.counter.add(direction, len(data))
                dst.sendall(data)
        except OSError:
            pass
        finally:
            _close(src)
            _close(dst)


def _close(sock: socket.socket) -> None:
    with contextlib.suppress(OSError):  # not connected, or closed already
        sock.shutdown(socket.SHUT_RDWR)
    sock.close()
