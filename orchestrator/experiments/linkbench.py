"""What mutual TLS and the access control cost per message: robot <-> world ping-pong.

    python -m orchestrator.experiments.linkbench [--rounds 2000] [--repeat 3] [--robots 64]

A world-like router process (the run's `eifp_wire.transport.session_settings`, with TLS its
`eifp_wire.access.access_control` for ``--robots`` robots) echoes every command it gets on
``cmd/0`` back on ``poses/0`` from a router-local subscriber, as the world answers a robot;
this process, a client with robot 0's certificate, sends a `PAYLOAD_BYTES` payload and waits
for the echo: two hops per round trip. Modes: ``tcp`` (plain, what ``--insecure`` runs) and
``tls`` (mutual TLS + access control, the default). Declared, express publishers on both
sides. Prints p50 / p99 / mean round-trip times per mode and repeat, and the median p50
difference. Pin it to a core (``taskset -c 1``) on a busy machine: p99 is other tenants.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUN = "linkbench"
WARMUP = 200
PAYLOAD_BYTES = 496
"""Size of each ping (opaque bytes, only echoed: nothing decodes them), about a pose message
of a dozen robots."""


def _settings(mode: str, role: str, port: int, tls_dir: Path, robots: int) -> dict[str, str]:
    from eifp_wire import TlsFiles, access_control, robot_cn, session_settings

    proto = "tls" if mode == "tls" else "tcp"
    ep = f"{proto}/127.0.0.1:{port}"
    if role == "router":
        tls = TlsFiles.in_dir(tls_dir, "world") if mode == "tls" else None
        acl = access_control(RUN, range(robots)) if mode == "tls" else None
        return session_settings(mode="router", listen=[ep], tls=tls, acl=acl)
    tls = TlsFiles.in_dir(tls_dir, robot_cn(0)) if mode == "tls" else None
    return session_settings(mode="client", connect=[ep], connect_timeout_ms=10_000, tls=tls)


def serve(mode: str, port: int, tls_dir: Path, robots: int) -> None:
    """The router: echo cmd/0 -> poses/0 until stdin closes."""
    import zenoh

    from agent.process import open_session
    from eifp_wire import RunKeys

    keys = RunKeys(RUN)
    session = open_session(_settings(mode, "router", port, tls_dir, robots))
    pub = session.declare_publisher(keys.poses_slot(0), express=True,
                                    congestion_control=zenoh.CongestionControl.DROP)
    sub = session.declare_subscriber(keys.cmd(0), lambda s: pub.put(s.payload))
    print("ready", flush=True)
    sys.stdin.read()
    sub.undeclare()
    session.close()


def ping(mode: str, port: int, tls_dir: Path, rounds: int) -> list[float]:
    """Round-trip times [ms] of `rounds` pings (after `WARMUP`)."""
    import threading

    import zenoh

    from agent.process import open_session
    from eifp_wire import RunKeys

    keys = RunKeys(RUN)
    session = open_session(_settings(mode, "client", port, tls_dir, 0),
                           deadline=time.monotonic() + 10.0)
    got = threading.Event()
    sub = session.declare_subscriber(keys.poses_slot(0), lambda s: got.set())
    pub = session.declare_publisher(keys.cmd(0), express=True,
                                    congestion_control=zenoh.CongestionControl.DROP)
    deadline = time.monotonic() + 10.0
    # zenoh's stub types matching_status as bool; it is a MatchingStatus
    while not pub.matching_status.matching:  # type: ignore[attr-defined]
        if time.monotonic() > deadline:
            raise RuntimeError("the publisher never matched the router's subscriber")
        time.sleep(0.01)
    payload = bytes(PAYLOAD_BYTES)
    out = []
    for k in range(WARMUP + rounds):
        got.clear()
        t0 = time.perf_counter()
        pub.put(payload)
        if not got.wait(1.0):
            continue  # a lost echo (DROP): not timed
        if k >= WARMUP:
            out.append((time.perf_counter() - t0) * 1e3)
    sub.undeclare()
    session.close()
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m orchestrator.experiments.linkbench",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--robots", type=int, default=64, help="robots in the ACL")
    parser.add_argument("--serve", nargs=4, metavar=("MODE", "PORT", "DIR", "ROBOTS"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        serve(args.serve[0], int(args.serve[1]), Path(args.serve[2]), int(args.serve[3]))
        return 0
    from agent.security import make_run_pki
    from orchestrator.experiments.distributed import free_tcp_endpoint

    p50: dict[str, list[float]] = {"tcp": [], "tls": []}
    with tempfile.TemporaryDirectory() as tmp:
        tls_dir = Path(tmp) / "tls"
        make_run_pki(tls_dir, RUN, range(args.robots))
        print(f"{'mode':5} {'rep':>3} {'n':>5} {'p50 ms':>8} {'p99 ms':>8} {'mean ms':>8}")
        for rep in range(args.repeat):
            for mode in ("tcp", "tls"):
                port = int(free_tcp_endpoint().rsplit(":", 1)[1])
                router = subprocess.Popen(
                    [sys.executable, "-m", "orchestrator.experiments.linkbench", "--serve",
                     mode, str(port), str(tls_dir), str(args.robots)],
                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
                try:
                    assert router.stdout is not None and router.stdin is not None
                    if router.stdout.readline().strip() != "ready":
                        raise RuntimeError("the router did not start")
                    rtt = sorted(ping(mode, port, tls_dir, args.rounds))
                finally:
                    if router.stdin:
                        router.stdin.close()
                    try:
                        router.wait(10.0)
                    except subprocess.TimeoutExpired:
                        router.kill()
                        router.wait()
                q50 = rtt[len(rtt) // 2]
                q99 = rtt[min(len(rtt) - 1, int(0.99 * len(rtt)))]
                p50[mode].append(q50)
                print(f"{mode:5} {rep:>3} {len(rtt):>5} {q50:8.3f} {q99:8.3f} "
                      f"{statistics.fmean(rtt):8.3f}", flush=True)
    d = statistics.median(p50["tls"]) - statistics.median(p50["tcp"])
    print(f"median p50: tcp {statistics.median(p50['tcp']):.3f} ms, tls+acl "
          f"{statistics.median(p50['tls']):.3f} ms: TLS adds {d * 1e3:+.1f} us per round trip "
          "(2 hops)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
