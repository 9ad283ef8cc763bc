"""The transport's floor: what a robot process costs per control cycle before its own code.

`orchestrator bench --floor --robots N` runs one router that publishes a `protocol.PosesMsg`
of N discs every world tick (50 Hz) on the pose slots, as the world does, and N client
processes that do a robot's I/O and nothing else: each subscribes to one pose slot, takes
every pose out of Zenoh on Zenoh's thread (``payload.to_bytes()``, as `agent.node.RobotNode`
does) and publishes a command-sized payload, with Zenoh on one thread and its Python thread
state kept, as a robot. No decoding, sensing, planning or encoding. Each client reports its
process CPU per cycle, split into the Python handler (taking the payload, publishing) and
the rest (Zenoh's runtime receiving, sending and keeping the lease; the main thread's
naps). `orchestrator bench --process` minus this is what the robot's own code costs.

Plain TCP on loopback (TLS made no measurable difference to `bench --process`).
"""

from __future__ import annotations

import json
import os
import queue
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass

TICK_S = 0.02
"""The world's tick (50 Hz)."""
POSE_SLOTS = 5
"""Pose slots: a client receives every fifth pose, 10 per second, as a robot does."""
COMMAND_BYTES = 200
"""About the size of an encoded `protocol.CommandMsg`."""
STARTUP_TIMEOUT_S = 60.0
_KEY = "eifp-floor"


@dataclass(frozen=True)
class FloorRow:
    """One floor run: mean CPU per cycle of the N clients [ms], by part.

    Args:
        robots: client processes (and discs in each pose message).
        cycles: mean poses a client received (one cycle each).
        handler_ms: the Python handler on Zenoh's thread: the payload taken out, the
            command put.
        zenoh_ms: the rest of the process: Zenoh's runtime (receiving, entering Python,
            sending, the lease) and the main thread's naps.
        total_ms: their sum.
        pose_bytes: size of one pose message.
    """

    robots: int
    cycles: float
    handler_ms: float
    zenoh_ms: float
    total_ms: float
    pose_bytes: int


def pose_payload(n: int) -> bytes:
    """A pose message of `n` robots spread on a circle (the bytes the world sends)."""
    import numpy as np

    from agent.core.types import PoseSnapshot
    from protocol import PosesMsg

    angle = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    pose = np.column_stack([10.0 * np.cos(angle), 10.0 * np.sin(angle), angle + np.pi])
    snapshot = PoseSnapshot(stamp_s=1.0, tick=50, ids=np.arange(n), pose=pose,
                            radius_m=np.full(n, 0.2))
    return PosesMsg.from_snapshot(snapshot, pub_ns=time.monotonic_ns(), clock_id=1).encode()


def run_floor(n: int, seconds: float) -> FloorRow:
    """Run the router and `n` clients for `seconds` of publishing; returns the means.

    Raises:
        RuntimeError: a client did not start or report (its stderr is in the message).
    """
    from orchestrator.experiments.distributed import free_tcp_endpoint

    endpoint = free_tcp_endpoint()
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "orchestrator.experiments.transport_floor"]
    router = subprocess.Popen([*cmd, "router", endpoint, str(n), str(seconds)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    clients = [subprocess.Popen([*cmd, "client", endpoint, str(i)], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
               for i in range(n)]
    timeout_s = STARTUP_TIMEOUT_S + seconds + 30.0
    reports = []
    try:
        for proc in clients:
            out, err = proc.communicate(timeout=timeout_s)
            lines = [line for line in out.splitlines() if line.startswith("{")]
            if proc.returncode != 0 or not lines:
                raise RuntimeError(f"floor client exited {proc.returncode}: {err[-2000:]}")
            reports.append(json.loads(lines[-1]))
        out, err = router.communicate(timeout=30.0)
        if router.returncode != 0:
            raise RuntimeError(f"floor router exited {router.returncode}: {err[-2000:]}")
    finally:
        for proc in (*clients, router):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    pose_bytes = json.loads(out.splitlines()[-1])["pose_bytes"]
    handler = statistics.fmean(r["handler_ms"] for r in reports)
    rest = statistics.fmean(r["zenoh_ms"] for r in reports)
    return FloorRow(robots=n, cycles=statistics.fmean(r["cycles"] for r in reports),
                    handler_ms=handler, zenoh_ms=rest, total_ms=handler + rest,
                    pose_bytes=pose_bytes)


def format_floor_row(row: FloorRow) -> str:
    """The row as the benchmark prints it."""
    return (f"transport floor, {row.robots} clients, {row.cycles:.0f} cycles each, "
            f"{row.pose_bytes}-byte poses (plain TCP):\n"
            f"  CPU ms per cycle: handler (take the pose, put the command) "
            f"{row.handler_ms:.3f}  Zenoh and the rest {row.zenoh_ms:.3f} = {row.total_ms:.3f}")


def _settings(mode: str, endpoint: str) -> dict[str, str]:
    from protocol import session_settings

    if mode == "router":
        return session_settings(mode="router", listen=[endpoint])
    return session_settings(mode="client", connect=[endpoint])


def _router(endpoint: str, n: int, seconds: float) -> int:
    import zenoh

    from agent.process import close_session, open_session

    payload = pose_payload(n)
    session = open_session(_settings("router", endpoint))
    assert session is not None
    try:
        pubs = [session.declare_publisher(f"{_KEY}/poses/{k}",
                                          congestion_control=zenoh.CongestionControl.DROP,
                                          express=True) for k in range(POSE_SLOTS)]
        ready: queue.SimpleQueue = queue.SimpleQueue()
        sink = session.declare_subscriber(f"{_KEY}/cmd/*", lambda sample: None)
        alive = session.liveliness().declare_subscriber(f"{_KEY}/alive/*", ready.put,
                                                        history=True)
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        seen = 0
        while seen < n:
            ready.get(timeout=max(0.0, deadline - time.monotonic()))
            seen += 1
        start = time.monotonic()
        tick = 0
        while time.monotonic() - start < seconds:
            pubs[tick % POSE_SLOTS].put(payload)
            tick += 1
            time.sleep(max(0.0, start + tick * TICK_S - time.monotonic()))
        session.put(f"{_KEY}/end", b"end")
        time.sleep(1.0)
        alive.undeclare()
        sink.undeclare()
        print(json.dumps({"ticks": tick, "pose_bytes": len(payload)}))
    finally:
        close_session(session)
    return 0


def _client(endpoint: str, index: int) -> int:
    import threading

    import zenoh

    from agent.process import (
        call_on_receive,
        close_session,
        keep_thread_state,
        open_session,
        use_one_zenoh_thread,
    )

    use_one_zenoh_thread()
    session = open_session(_settings("client", endpoint),
                           deadline=time.monotonic() + STARTUP_TIMEOUT_S)
    assert session is not None
    command = bytes(COMMAND_BYTES)
    state = {"cycles": 0, "cpu_s": 0.0, "start": None}
    done = threading.Event()
    try:
        pub = session.declare_publisher(f"{_KEY}/cmd/{index}",
                                        congestion_control=zenoh.CongestionControl.DROP,
                                        express=True)

        def on_pose(sample: zenoh.Sample) -> None:  # a robot's cycle without its work
            cpu0 = time.thread_time()
            keep_thread_state()
            if state["start"] is None:
                state["start"] = time.process_time()
            sample.payload.to_bytes()
            pub.put(command)
            state["cycles"] += 1
            state["cpu_s"] += time.thread_time() - cpu0

        poses = session.declare_subscriber(f"{_KEY}/poses/{index % POSE_SLOTS}",
                                           call_on_receive(on_pose))
        end = session.declare_subscriber(f"{_KEY}/end", call_on_receive(lambda s: done.set()))
        token = session.liveliness().declare_token(f"{_KEY}/alive/{index}")
        while not done.wait(0.25):  # the robot's loop naps as long
            pass
        if not state["cycles"]:
            raise RuntimeError(f"floor client {index}: no pose arrived")
        process_s = time.process_time() - state["start"]
        cycles = state["cycles"]
        print(json.dumps({"cycles": cycles, "handler_ms": state["cpu_s"] * 1e3 / cycles,
                          "zenoh_ms": max(0.0, process_s - state["cpu_s"]) * 1e3 / cycles}))
        token.undeclare()
        poses.undeclare()
        end.undeclare()
    finally:
        close_session(session)
    return 0


def main(argv: list[str]) -> int:
    """``python -m orchestrator.experiments.transport_floor router|client ...``."""
    if argv[:1] == ["router"] and len(argv) == 4:
        return _router(argv[1], int(argv[2]), float(argv[3]))
    if argv[:1] == ["client"] and len(argv) == 3:
        return _client(argv[1], int(argv[2]))
    print("usage: router ENDPOINT N SECONDS | client ENDPOINT INDEX", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
