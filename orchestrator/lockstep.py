"""The deterministic in-process runner: the distributed mode's world and planners, one process.

Same `world.dynamics.WorldSim`, same `agent.controller.RobotController` and planners, same
`world.recorder.RunRecorder` files as a distributed run; only the transport is gone. Every
control period (`world_rate_hz / control_rate_hz` world ticks, an integer) all robots
observe the same snapshot of the world, then plan; their commands are applied at once
(zero latency) and held until the next period. The run stops when every robot has
arrived or at the time limit. Decisions are deterministic (the planners' inputs do not
depend on wall time); only the recorded `plan_ms` timings vary between runs.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from orchestrator.metrics import RunMetrics
from orchestrator.rundir import metrics_from_run_dir, write_metrics
from world.scenario import Scenario

CMD_TIMEOUT_S = 0.5
PROGRESS_EVERY_S = 1.0
"""Sim time between two `on_progress` calls."""


@dataclass(frozen=True)
class LockstepProgress:
    """What `run_lockstep` reports to `on_progress` (field names as `DistributedProgress`)."""

    wall_s: float
    sim_t_s: float
    n_robots: int
    arrived: frozenset[int]
    contacts: int
    started: bool = True
    lost: frozenset[int] = field(default_factory=frozenset)


@dataclass(frozen=True)
class LockstepOutcome:
    """How a lockstep run ended.

    Args:
        out_dir: the run directory.
        reason: "all_arrived" or "time_limit".
        success: every robot arrived and no contact (as `metrics.success`).
        sim_time_s: sim time at the end.
        ticks: world ticks run.
        wall_s: wall time of the run (without the metrics).
        metrics: the run's metrics (also in `metrics.json`).
    """

    out_dir: Path
    reason: str
    success: bool
    sim_time_s: float
    ticks: int
    wall_s: float
    metrics: RunMetrics


def run_lockstep(scenario: Scenario, out_dir: Path, *, world_rate_hz: float = 50.0,
                 control_rate_hz: float = 10.0,
                 on_progress: Callable[[LockstepProgress], None] | None = None
                 ) -> LockstepOutcome:
    """Run `scenario` in lockstep and write the run directory and `metrics.json`.

    Args:
        scenario: the resolved scenario.
        out_dir: run directory (created).
        world_rate_hz: world ticks per sim second.
        control_rate_hz: planning cycles per sim second; must divide world_rate_hz.
        on_progress: called about every sim second with a `LockstepProgress`.
    """
    from agent.controller import RobotController
    from world.dynamics import WorldSim
    from world.recorder import RunRecorder

    if not (world_rate_hz > 0 and control_rate_hz > 0):
        raise ValueError("world_rate_hz and control_rate_hz must be positive")
    ratio = world_rate_hz / control_rate_hz
    ticks_per_cycle = round(ratio)
    if ticks_per_cycle < 1 or abs(ratio - ticks_per_cycle) > 1e-9:
        raise ValueError(f"control rate {control_rate_hz} Hz must divide the world rate "
                         f"{world_rate_hz} Hz")
    dt_s = 1.0 / world_rate_hz
    period_s = 1.0 / control_rate_hz
    max_ticks = math.ceil(scenario.time_limit_s * world_rate_hz - 1e-9)
    progress_ticks = max(1, round(PROGRESS_EVERY_S * world_rate_hz))

    world = WorldSim(scenario, cmd_timeout_s=CMD_TIMEOUT_S)
    controllers = [
        RobotController(spec, scenario.planner_config, scenario.goal_tolerance_m,
                        control_period_s=period_s)
        for spec in scenario.robots
    ]
    seq = [0] * len(controllers)
    n = len(controllers)

    out_dir = Path(out_dir)
    wall0 = time.perf_counter()
    reason = "time_limit"
    with RunRecorder(out_dir, scenario) as rec:
        rec.event("start", 0.0, mode="lockstep", n_robots=n, world_rate_hz=world_rate_hz,
                  control_rate_hz=control_rate_hz)
        rec.record_tick(world.t_s, world.robot_ids, world.pose, world.applied)
        for rid in world.robot_ids[world.arrived].tolist():
            rec.event("arrived", world.t_s, robot=rid)
        while True:
            if world.all_arrived():
                reason = "all_arrived"
                break
            if world.tick >= max_ticks:
                break
            if world.tick % ticks_per_cycle == 0:
                # One snapshot for everyone, then everyone plans, then the commands apply.
                snapshot = world.snapshot()
                results = []
                for ctrl in controllers:
                    ctrl.observe(snapshot)
                    results.append(ctrl.plan(world.t_s))
                for k, (ctrl, res) in enumerate(zip(controllers, results)):
                    world.set_command(ctrl.spec.id, res.v_mps, res.omega_radps)
                    rec.record_command(world.t_s, ctrl.spec.id, seq[k], snapshot.stamp_s,
                                       res.v_mps, res.omega_radps, res.times.total_ms,
                                       str(res.status.value), side=int(res.side),
                                       resolved=res.resolved_id)
                    seq[k] += 1
            events = world.step(dt_s)
            rec.record_tick(world.t_s, world.robot_ids, world.pose, world.applied)
            for rid in events.arrivals:
                rec.event("arrived", world.t_s, robot=rid)
            for a, b, overlap in events.new_contacts:
                rec.event("contact", world.t_s, a=a, b=b, overlap_m=round(overlap, 6))
            for rid in events.timeouts:
                rec.event("cmd_timeout", world.t_s, robot=rid)
            if on_progress is not None and world.tick % progress_ticks == 0:
                on_progress(_progress(world, wall0))
        success = world.all_arrived() and world.contact_count == 0
        rec.event("end", world.t_s, reason=reason, success=success,
                  arrived=[int(r) for r in world.robot_ids[world.arrived]],
                  contacts=world.contact_count, ticks=world.tick,
                  min_gap_m=round(world.min_gap_m, 6) if math.isfinite(world.min_gap_m)
                  else None)
    wall_s = time.perf_counter() - wall0
    if on_progress is not None:
        on_progress(_progress(world, wall0))
    metrics = metrics_from_run_dir(out_dir, control_period_s=period_s, world_dt_s=dt_s)
    write_metrics(out_dir, metrics)
    return LockstepOutcome(out_dir=out_dir, reason=reason, success=metrics.success,
                           sim_time_s=world.t_s, ticks=world.tick, wall_s=wall_s,
                           metrics=metrics)


def _progress(world: object, wall0: float) -> LockstepProgress:
    ids = world.robot_ids  # type: ignore[attr-defined]
    return LockstepProgress(
        wall_s=time.perf_counter() - wall0,
        sim_t_s=float(world.t_s),  # type: ignore[attr-defined]
        n_robots=int(ids.size),
        arrived=frozenset(int(r) for r in ids[world.arrived]),  # type: ignore[attr-defined]
        contacts=int(world.contact_count),  # type: ignore[attr-defined]
    )
