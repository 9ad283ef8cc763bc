"""The transport's floor: what a robot process costs per control cycle before its own code.

`orchestrator bench --floor --robots N` runs one router that publishes an
`eifp_wire.poses.PosesMsg` of N discs every world tick (50 Hz) on the pose slots, as the
world does, and N client processes that do a robot's I/O and nothing else: each subscribes
to one pose slot, takes every pose off the queue Zenoh's thread puts it on, copies its
payload out (``payload.to_bytes()``) and publishes a command-sized payload, with Zenoh on
one thread: the loop of `agent.node.RobotNode` with nothing in it. No decoding, sensing,
planning or encoding. Each client reports its CPU per cycle: its main thread (waking, taking
the pose, publishing) and Zenoh's threads (receiving, queueing, sending, the lease).
`orchestrator bench --process` minus this is what the robot's own code costs.

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
"""About the size of an encoded `eifp_wire.messages.CommandMsg`."""
STARTUP_TIMEOUT_S = 60.0
RUN_ID = "transport-floor"
"""The floor's own run id: its keys are a run's (`eifp_wire.keys.RunKeys`)."""


@dataclass(frozen=True)
class FloorRow:
    """One floor run: mean CPU per cycle of the N clients [ms], by part.

    Args:
        robots: client processes (and discs in each pose message).
        cycles: mean poses a client received (one cycle each).
        main_ms: the main thread: woken by the pose, its payload copied out, the command
            put.
        zenoh_ms: Zenoh's threads: receiving, queueing, sending, the lease.
        total_ms: their sum.
        pose_bytes: size of one pose message.
    """

    robots: int
    cycles: float
    main_ms: float
    zenoh_ms: float
    total_ms: float
    pose_bytes: int


def pose_payload(n: int) -> bytes:
    """A pose message of `n` robots spread on a circle (the bytes the world sends)."""
    import numpy as np

    from agent.core.types import PoseSnapshot
    from eifp_wire import PosesMsg

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
    main = statistics.fmean(r["main_ms"] for r in reports)
    zenoh_ = statistics.fmean(r["zenoh_ms"] for r in reports)
    return FloorRow(robots=n, cycles=statistics.fmean(r["cycles"] for r in reports),
                    main_ms=main, zenoh_ms=zenoh_, total_ms=main + zenoh_,
                    pose_bytes=pose_bytes)


def format_floor_row(row: FloorRow) -> str:
    """The row as the benchmark prints it."""
    return (f"transport floor, {row.robots} clients, {row.cycles:.0f} cycles each, "
            f"{row.pose_bytes}-byte poses (plain TCP):\n"
            f"  CPU ms per cycle: main thread (take the pose, put the command) "
            f"{row.main_ms:.3f}  Zenoh threads {row.zenoh_ms:.3f} = {row.total_ms:.3f}")


def _settings(mode: str, endpoint: str) -> dict[str, str]:
    from eifp_wire import session_settings

    if mode == "router":
        return session_settings(mode="router", listen=[endpoint])
    return session_settings(mode="client", connect=[endpoint])


def _router(endpoint: str, n: int, seconds: float) -> int:
    import zenoh

    from agent.process import close_session, open_session
    from eifp_wire import ControlMsg, RunKeys

    keys = RunKeys(RUN_ID)
    payload = pose_payload(n)
    session = open_session(_settings("router", endpoint))
    assert session is not None
    try:
        pubs = [session.declare_publisher(keys.poses_slot(k),
                                          congestion_control=zenoh.CongestionControl.DROP,
                                          express=True) for k in range(POSE_SLOTS)]
        ready: queue.SimpleQueue[zenoh.Sample] = queue.SimpleQueue()
        sink = session.declare_subscriber(keys.cmd_all, lambda sample: None)
        alive = session.liveliness().declare_subscriber(keys.alive_robot_all, ready.put,
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
        session.put(keys.control, ControlMsg("end", tick * TICK_S, "time_limit").encode())
        time.sleep(1.0)
        alive.undeclare()
        sink.undeclare()
        print(json.dumps({"ticks": tick, "pose_bytes": len(payload)}))
    finally:
        close_session(session)
    return 0


def _client(endpoint: str, index: int) -> int:
    import zenoh

    from agent.node import MAX_NAP_S
    from agent.process import (
        close_session,
        enqueue_on_receive,
        open_session,
        use_one_zenoh_thread,
    )
    from eifp_wire import RunKeys

    keys = RunKeys(RUN_ID)
    use_one_zenoh_thread()
    session = open_session(_settings("client", endpoint),
                           deadline=time.monotonic() + STARTUP_TIMEOUT_S)
    assert session is not None
    command = bytes(COMMAND_BYTES)
    try:
        pub = session.declare_publisher(keys.cmd(index),
                                        congestion_control=zenoh.CongestionControl.DROP,
                                        express=True)
        # As a robot: Zenoh's thread puts each pose sample on a queue the main thread
        # blocks on, at most a nap at a time.
        poses: queue.SimpleQueue[zenoh.Sample] = queue.SimpleQueue()
        pose_sub = session.declare_subscriber(keys.poses_slot(index % POSE_SLOTS),
                                              enqueue_on_receive(poses.put))
        end = session.declare_subscriber(keys.control)
        token = session.liveliness().declare_token(keys.alive_robot(index))
        cycles, start, main_start = 0, 0.0, 0.0
        while end.try_recv() is None:
            try:
                sample = poses.get(timeout=MAX_NAP_S)
            except queue.Empty:
                continue
            if not cycles:
                start, main_start = time.process_time(), time.thread_time()
            sample.payload.to_bytes()
            pub.put(command)
            cycles += 1
        if not cycles:
            raise RuntimeError(f"floor client {index}: no pose arrived")
        main_s = time.thread_time() - main_start
        process_s = time.process_time() - start
        print(json.dumps({"cycles": cycles, "main_ms": main_s * 1e3 / cycles,
                          "zenoh_ms": max(0.0, process_s - main_s) * 1e3 / cycles}))
        token.undeclare()
        pose_sub.undeclare()
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
