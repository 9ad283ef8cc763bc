"""Costs of run.mcap and the live view (docs/visualisation.md). Not part of the package.

    .venv/bin/python scripts/measure_viz.py lockstep [N]       # lockstep setup G: MCAP off / on
    .venv/bin/python scripts/measure_viz.py world [N ...]      # in-process world tick: off / on
    .venv/bin/python scripts/measure_viz.py live OUT [SIM_S]   # distributed setup G, 16 robots:
                                                               # no live / live idle / a client
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import struct
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

import numpy as np


def lockstep(n: int) -> None:
    from orchestrator.experiments.families import resolve
    from world.recorder import RunRecorder
    from world.sim.lockstep import run_lockstep

    sc = resolve("setup_g", agents=n)
    for mcap in (False, True, False, True):
        d = Path(tempfile.mkdtemp())
        t0 = time.perf_counter()
        with RunRecorder(d, sc, mcap=mcap) as rec:
            res = run_lockstep(sc, rec)
        wall = time.perf_counter() - t0
        size = (d / "run.mcap").stat().st_size if mcap else 0
        print(json.dumps({"n": n, "mcap": mcap, "wall_s": round(wall, 2), "ticks": res.ticks,
                          "ms_per_tick": round(wall / res.ticks * 1e3, 3),
                          "mcap_MB_per_sim_min": round(size / 1e6 / res.sim_time_s * 60, 2)}),
              flush=True)


def world(n: int, ticks: int = 1500) -> None:
    """As `world.node.WorldNode.tick`: decode and record n/5 commands and n/5 plan-debug
    messages (synthetic: 21-point reference and prediction), step, encode the poses, record
    the tick."""
    from agent.core.types import PlanDebug
    from eifp_wire import CommandMsg, PlanDebugMsg, PosesMsg
    from orchestrator.experiments.families import circles
    from world.recorder import RunRecorder
    from world.sim.dynamics import WorldSim

    for mcap in (False, True, False, True):
        sc = circles(n)
        sim = WorldSim(sc)
        ids = [int(r) for r in sim.robot_ids]
        known = frozenset(ids)
        per = max(1, n // 5)
        rng = np.random.default_rng(0)
        cmds = [CommandMsg(r, 0, 0.0, 0.5, 0.0, 1.0, "ok").encode() for r in ids]
        dbg = [PlanDebugMsg(r, 0, 0.0, 0.5, 0.0, "ok", PlanDebug(
            ego=np.zeros(3), threat_ids=tuple(ids[(k + 1) % n:(k + 1) % n + 2]),
            via_points_m=rng.normal(size=(1, 2)), reference_m=rng.normal(size=(21, 2)),
            predicted_m=rng.normal(size=(21, 2)))).encode() for k, r in enumerate(ids)]
        out = Path(tempfile.mkdtemp())
        ts = []
        with RunRecorder(out, sc, mcap=mcap) as rec:
            for tick in range(ticks):
                t0 = time.perf_counter()
                for k in range(per):
                    j = (tick * per + k) % n
                    m = CommandMsg.decode(cmds[j], known_ids=known, expected_robot_id=ids[j])
                    sim.set_command(m.robot_id, m.v_mps, m.omega_radps)
                    rec.record_command(sim.t_s, m.robot_id, tick, 0.0, m.v_mps, m.omega_radps,
                                       m.plan_ms, m.status)
                    d = PlanDebugMsg.decode(dbg[j], known_ids=known, expected_robot_id=ids[j])
                    rec.record_plan(sim.t_s, ids[j], d.debug, v_mps=d.v_mps,
                                    omega_radps=d.omega_radps, status=d.status)
                sim.step(0.02)
                PosesMsg.from_snapshot(sim.snapshot()).encode()
                rec.record_tick(sim.t_s, sim.robot_ids, sim.pose, sim.applied)
                ts.append(time.perf_counter() - t0)
        ms = np.array(ts) * 1e3
        print(json.dumps({"n": n, "mcap": mcap, "tick_ms_p50": round(float(np.median(ms)), 3),
                          "tick_ms_mean": round(float(ms.mean()), 3),
                          "tick_ms_p99": round(float(np.percentile(ms, 99)), 3)}), flush=True)


def _watch(port: int, stop: threading.Event, got: dict) -> None:
    """A Foxglove WebSocket client subscribed to every topic, counting what arrives."""
    import websockets

    async def run() -> None:
        async with websockets.connect(f"ws://127.0.0.1:{port}",
                                      subprotocols=["foxglove.sdk.v1"]) as ws:
            while not stop.is_set():
                try:
                    frame = await asyncio.wait_for(ws.recv(), 0.2)
                except TimeoutError:
                    continue
                if isinstance(frame, bytes):
                    if frame[0] == 0x01:
                        struct.unpack_from("<IQ", frame, 1)
                        got["msgs"] = got.get("msgs", 0) + 1
                        got["bytes"] = got.get("bytes", 0) + len(frame)
                    continue
                msg = json.loads(frame)
                if msg["op"] == "advertise":
                    subs = [{"id": c["id"], "channelId": c["id"]} for c in msg["channels"]]
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    asyncio.run(run())


def live(root: Path, sim_s: float) -> None:
    """World tick times (the end event's tick_ms) of a distributed setup G run, 16 robots:
    without --live, with the live bridge but no client, with a client on every topic."""
    import psutil

    from orchestrator.experiments.distributed import run_distributed
    from orchestrator.experiments.families import resolve
    from world.mcap_log import LiveView
    from world.scenario_file import dump_scenario

    root.mkdir(parents=True, exist_ok=True)
    for mode in ("none", "idle", "client"):
        sc = dataclasses.replace(resolve("setup_g", agents=16), time_limit_s=sim_s)
        path = root / f"{mode}.yaml"
        dump_scenario(sc, path)
        out = root / mode
        view, got, stop, client = None, {}, threading.Event(), None
        if mode != "none":
            view = LiveView("127.0.0.1", 0, robot_ids=[r.id for r in sc.robots])
            if mode == "client":
                client = threading.Thread(target=_watch, args=(view.port, stop, got),
                                          daemon=True)
                client.start()
        me = psutil.Process()
        cpu0 = sum(me.cpu_times()[:2])
        run_distributed(path, out, f"m-{mode}-{uuid.uuid4().hex[:6]}", time_scale=1.0,
                        startup_timeout_s=120, live=view)
        launcher_cpu = sum(me.cpu_times()[:2]) - cpu0
        stop.set()
        if client is not None:
            client.join(5)
        if view is not None:
            view.stop()
        end = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()
               if '"end"' in line][-1]
        size = (out / "run.mcap").stat().st_size
        print(json.dumps({"mode": mode, "tick_ms": end.get("tick_ms"),
                          "overruns": end["overruns"], "ticks": end["ticks"],
                          "plans": end.get("plans"), "launcher_cpu_s": round(launcher_cpu, 2),
                          "client_msgs": got.get("msgs"),
                          "client_MB": round(got.get("bytes", 0) / 1e6, 2),
                          "mcap_MB_per_sim_min": round(size / 1e6 / end["t"] * 60, 2)}),
              flush=True)


if __name__ == "__main__":
    what, rest = sys.argv[1], sys.argv[2:]
    if what == "lockstep":
        lockstep(int(rest[0]) if rest else 16)
    elif what == "world":
        for n in [int(a) for a in rest] or [16]:
            world(n)
    elif what == "live":
        live(Path(rest[0]), float(rest[1]) if len(rest) > 1 else 20.0)
    else:
        sys.exit(__doc__)
