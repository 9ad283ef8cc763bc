"""The world's per-tick cost against N, in-process (``orchestrator scale --world-bench``).

    orchestrator scale --world-bench --agents 16,32,64,128,256,512,1024 --ticks 200 --out DIR

Per tick, as `world.node.WorldNode.tick` does it: decode and apply the commands that arrive
in one tick (N / 5: every robot sends one per 0.1 s), step the dynamics (integration,
arrivals, contacts), cut the poses into one message per published cell of the pose grid
(`world.world_cycle.WorldCycle.pose_cells`), write the trajectory rows. No transport.

Besides the stage times it reports what the pose grid sends: the bytes of all cell
messages of a tick, how many cells, and what one robot receives per tick (the mean over
the robots of the bytes and messages of the cells it holds, `world.sim.cells`), the figure
that should stay flat in N at a fixed density (the `circles` family tiles 8-robot circles).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

WORLD_STAGES = ("step", "poses", "record", "commands")
"""Stages of a world tick, timed separately."""


def world_tick_costs(n: int, ticks: int, out_dir: Path) -> dict[str, Any]:
    """Time the world's work per tick for n robots of the `circles` family.

    Robots drive straight at their goals (a constant command). Returns median microseconds
    per stage, the pose messages' sizes and what a robot receives per tick.
    """
    import numpy as np

    from eifp_wire import CommandMsg
    from orchestrator.experiments.families import circles
    from world.recorder import RunRecorder
    from world.world_cycle import WorldCycle

    scenario = circles(n)
    cycle = WorldCycle(scenario, "world-bench", cmd_timeout_s=1e6)
    sim, rule = cycle.sim, cycle.cell_rule
    ids = [int(r) for r in sim.robot_ids]
    known = frozenset(ids)
    per_tick = max(1, n // 5)
    payloads = [CommandMsg(rid, 0, 0.0, 0.5, 0.0, 1.0, "ok").encode() for rid in ids]
    times: dict[str, list[float]] = {k: [] for k in WORLD_STAGES}
    cells: list[tuple[tuple[int, int], bytes]] = []
    with RunRecorder(out_dir, scenario) as recorder:
        for tick in range(ticks):
            t0 = time.perf_counter()
            for k in range(per_tick):
                j = (tick * per_tick + k) % n
                msg = CommandMsg.decode(payloads[j], known_ids=known, expected_robot_id=ids[j])
                sim.set_command(msg.robot_id, msg.v_mps, msg.omega_radps)
                recorder.record_command(sim.t_s, msg.robot_id, tick, 0.0, msg.v_mps,
                                        msg.omega_radps, msg.plan_ms, msg.status)
            t1 = time.perf_counter()
            sim.step(0.02)
            t2 = time.perf_counter()
            cells = cycle.pose_cells()
            t3 = time.perf_counter()
            recorder.record_tick(sim.t_s, sim.robot_ids, sim.pose, sim.applied)
            t4 = time.perf_counter()
            for key, dt in zip(WORLD_STAGES, (t2 - t1, t3 - t2, t4 - t3, t1 - t0)):
                times[key].append(dt * 1e6)
    size = dict(cells)
    held = [rule.needed(float(x), float(y)) for x, y in sim.pose[:, :2]]
    rx_bytes = [sum(len(size.get(c, b"")) for c in h) for h in held]
    row: dict[str, Any] = {
        "agents": n, "ticks": ticks, "poses_bytes": sum(len(p) for p in size.values()),
        "cells": len(size), "rx_bytes_per_robot": float(np.mean(rx_bytes)),
        "rx_msgs_per_robot": float(np.mean([len(h & size.keys()) for h in held])),
    }
    row["poses_bytes_per_robot"] = row["poses_bytes"] / n
    total = np.sum([times[k] for k in WORLD_STAGES], axis=0)
    row["tick_us_p50"] = float(np.percentile(total, 50))
    row["tick_us_per_robot"] = row["tick_us_p50"] / n
    for key in WORLD_STAGES:
        row[f"{key}_us_p50"] = float(np.percentile(times[key], 50))
    return row


def format_world_rows(rows: Sequence[dict[str, Any]]) -> str:
    """The world benchmark's table."""
    head = ["N", "tick us p50", "us/robot", *(f"{k} us" for k in WORLD_STAGES), "cells",
            "poses B", "B/robot", "robot rx B/tick", "robot rx msgs/tick"]
    body = [[str(r["agents"]), f"{r['tick_us_p50']:.0f}", f"{r['tick_us_per_robot']:.2f}",
             *(f"{r[f'{k}_us_p50']:.0f}" for k in WORLD_STAGES), str(r["cells"]),
             str(r["poses_bytes"]), f"{r['poses_bytes_per_robot']:.1f}",
             f"{r['rx_bytes_per_robot']:.0f}", f"{r['rx_msgs_per_robot']:.1f}"] for r in rows]
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths)),
             "  ".join("-" * w for w in widths)]
    lines += ["  ".join(c.ljust(w) for c, w in zip(b, widths)) for b in body]
    return "\n".join(lines)
