"""The world's per-tick cost against N, in-process (``orchestrator scale --world-bench``).

    orchestrator scale --world-bench --agents 16,32,64,128,256,512,1024 --ticks 200 --out DIR

Per tick, as `world.node.WorldNode.tick` does it: decode and apply the commands that arrive
in one tick (N / 5: every robot sends one per 0.1 s), step the dynamics (integration,
arrivals, contacts), cut the poses into one message per published cell of the pose grid
(`world.world_cycle.WorldCycle.pose_cells`), write the trajectory rows (and `run.mcap`'s
scene every other tick), and decode and record the plan internals that arrive in one tick
(N / 5, each of the size `BENCH_PLAN_POINTS`). No transport.

Besides the stage times it reports what the pose grid sends: the bytes of all cell
messages of a tick, how many cells, and what one robot receives per tick (the mean over
the robots of the bytes and messages of the cells it holds, `world.sim.cells`), the figure
that should stay flat in N at a fixed density (the `circles` family tiles 8-robot circles).
A robot takes one tick in `pose_slot_count` (its pose slot), `CONTROL_RATE_HZ` a second, so
per second is per tick times that.

Written to DIR: ``world_bench.json`` (rows and the command line) and ``world_bench.png``
(`plot_world_bench`: the per-robot columns against N). Figures only: nothing here asserts a
time budget.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from orchestrator.analysis.panels import Panel

WORLD_STAGES = ("step", "poses", "record", "commands", "plans")
"""Stages of a world tick, timed separately."""
WORLD_TICK_S = 0.02
"""The world's tick [s] (50 Hz, as `world.node`'s default)."""
BENCH_PLAN_POINTS = (2, 21, 21)
"""Via-points, reference samples and MPC prediction of each recorded plan, with
`BENCH_PLAN_THREATS` threats: the largest of a lockstep run of `circles` 16 (2400 plans:
via-points median 1, at most 2; 21 reference samples and 21 predicted points in every
plan; threats median 1, at most 2)."""
BENCH_PLAN_THREATS = 2
CONTROL_RATE_HZ = 10.0
"""A robot plans, sends a command and takes its slot's cells this often [Hz]."""
WORLD_PLOTTED = (
    Panel("a robot receives [pose kB/s]", ("rx_bytes_per_robot_s",), factor=1e-3),
    Panel("a robot receives [pose messages/s]", ("rx_msgs_per_robot_s",)),
    Panel("world tick per robot [us, p50]", ("tick_us_per_robot",)),
    Panel("world tick stages per robot [us, p50]",
          tuple(f"{k}_us_per_robot" for k in WORLD_STAGES), labels=WORLD_STAGES),
)
"""The panels of world_bench.png, the per-robot columns."""


def world_tick_costs(n: int, ticks: int, out_dir: Path) -> dict[str, Any]:
    """Time the world's work per tick for n robots of the `circles` family.

    Robots drive straight at their goals (a constant command). Returns median microseconds
    per stage, the pose messages' sizes and what a robot receives per tick.
    """
    import numpy as np

    from agent.core.types import PlanDebug
    from eifp_wire import CommandMsg, PlanDebugMsg
    from orchestrator.experiments.families import circles
    from world.recorder import RunRecorder
    from world.sim.schedule import pose_slot_count
    from world.world_cycle import WorldCycle

    scenario = circles(n)
    cycle = WorldCycle(scenario, "world-bench", cmd_timeout_s=1e6)
    sim, rule = cycle.sim, cycle.cell_rule
    ids = [int(r) for r in sim.robot_ids]
    known = frozenset(ids)
    per_tick = max(1, n // pose_slot_count(1.0 / WORLD_TICK_S, CONTROL_RATE_HZ))
    payloads = [CommandMsg(rid, 0, 0.0, 0.5, 0.0, 1.0, "ok").encode() for rid in ids]
    rng = np.random.default_rng(0)
    plans = [(str(cycle.keys.debug(rid)), PlanDebugMsg(rid, 0, 0.0, 0.5, 0.0, "ok", PlanDebug(
        ego=np.zeros(3),
        threat_ids=tuple(ids[(j + 1 + k) % n] for k in range(BENCH_PLAN_THREATS)),
        via_points_m=rng.uniform(-5.0, 5.0, (BENCH_PLAN_POINTS[0], 2)),
        reference_m=rng.uniform(-5.0, 5.0, (BENCH_PLAN_POINTS[1], 2)),
        predicted_m=rng.uniform(-5.0, 5.0, (BENCH_PLAN_POINTS[2], 2)))).encode())
        for j, rid in enumerate(ids)]
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
            sim.step(WORLD_TICK_S)
            t2 = time.perf_counter()
            cells = cycle.pose_cells()
            t3 = time.perf_counter()
            recorder.record_tick(sim.t_s, sim.robot_ids, sim.pose, sim.applied)
            t4 = time.perf_counter()
            for k in range(per_tick):
                got = cycle.plan_debug(*plans[(tick * per_tick + k) % n])
                if got is None:
                    raise RuntimeError("the world rejected a bench plan")
                recorder.record_plan(sim.t_s, got[0], got[1].debug, v_mps=got[1].v_mps,
                                     omega_radps=got[1].omega_radps, status=got[1].status)
            t5 = time.perf_counter()
            for key, dt in zip(WORLD_STAGES, (t2 - t1, t3 - t2, t4 - t3, t1 - t0, t5 - t4)):
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
    row["rx_bytes_per_robot_s"] = row["rx_bytes_per_robot"] * CONTROL_RATE_HZ
    row["rx_msgs_per_robot_s"] = row["rx_msgs_per_robot"] * CONTROL_RATE_HZ
    total = np.sum([times[k] for k in WORLD_STAGES], axis=0)
    row["tick_us_p50"] = float(np.percentile(total, 50))
    row["tick_us_per_robot"] = row["tick_us_p50"] / n
    for key in WORLD_STAGES:
        row[f"{key}_us_p50"] = float(np.percentile(times[key], 50))
        row[f"{key}_us_per_robot"] = row[f"{key}_us_p50"] / n
    return row


def plot_world_bench(rows: Sequence[dict[str, Any]], path: Path) -> Path:
    """The per-robot columns of `WORLD_PLOTTED` against N, one panel each.

    Raises:
        ValueError: no rows.
    """
    from orchestrator.analysis.plots import plot_against_n

    return plot_against_n(rows, WORLD_PLOTTED, path, ncols=2,
                          title="orchestrator scale --world-bench (circles, in-process)")


def write_world_outputs(rows: Sequence[dict[str, Any]], out_root: Path, argv: Sequence[str]
                        ) -> list[Path]:
    """world_bench.json and world_bench.png in out_root."""
    from orchestrator.analysis.rundir import write_json

    json_path = write_json(out_root / "world_bench.json", {"argv": list(argv), "rows": list(rows)})
    return [json_path, plot_world_bench(rows, out_root / "world_bench.png")]


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
