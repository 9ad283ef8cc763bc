"""The deterministic in-process runner: the distributed mode's world and planners, one process.

Same `world.dynamics.WorldSim`, same `agent.controller.RobotController` and planners, same
`world.recorder.RunRecorder` files as a distributed run; only the transport is gone. Every
control period (`world_rate_hz / control_rate_hz` world ticks, an integer) all robots
observe the same snapshot of the world, then plan; their commands are applied at once
(zero latency) and held until the next period. The run stops when every robot has
arrived or at the time limit. Decisions are deterministic (the planners' inputs do not
depend on wall time); only the recorded `plan_ms` timings vary between runs.

With a `FaultPlan` (`run_lockstep(..., faults=)`), the runner streams like the real
processes instead: every world tick's snapshot enters each robot's pose link
(`agent.link.FaultyLink`, sim-time delays, seeded per link), each robot observes what its
link releases and plans at its own rate and phase on the true sim time (so the planner
sees the poses' real age), and its commands reach the world through its command link,
``plan_delay_ms`` late for a slow robot; the world keeps the newest ``seq`` per robot.
Process faults are emulated: ``kill`` takes the robot offline for good (the world brakes
it; it stays as an obstacle); ``stop`` freezes its controller, the world takes it offline
after the transport lease (`protocol.LINK_LEASE_MS`) and back when it resumes;
``restart`` is a kill followed, `RESTART_DELAY_S` later, by a fresh controller with the
same id. This path is deterministic too, for a given plan and seed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from orchestrator.faults import FaultPlan
from orchestrator.metrics import RunMetrics
from orchestrator.rundir import metrics_from_run_dir, write_metrics
from world.scenario import Scenario

if TYPE_CHECKING:
    from world.dynamics import WorldSim
    from world.recorder import RunRecorder

CMD_TIMEOUT_S = 0.5
RESTART_DELAY_S = 2.0
"""Sim time a restarted robot is away (a new process starting, as in distributed runs)."""
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


def _step_and_record(world: WorldSim, rec: RunRecorder, dt_s: float) -> None:
    """Step the world by dt_s and record the tick and its events (both loops share it)."""
    events = world.step(dt_s)
    rec.record_tick(world.t_s, world.robot_ids, world.pose, world.applied)
    for rid in events.arrivals:
        rec.event("arrived", world.t_s, robot=rid)
    for a, b, overlap in events.new_contacts:
        rec.event("contact", world.t_s, a=a, b=b, overlap_m=round(overlap, 6))
    for rid in events.timeouts:
        rec.event("cmd_timeout", world.t_s, robot=rid)


def run_lockstep(scenario: Scenario, out_dir: Path, *, world_rate_hz: float = 50.0,
                 control_rate_hz: float = 10.0,
                 on_progress: Callable[[LockstepProgress], None] | None = None,
                 faults: FaultPlan | None = None) -> LockstepOutcome:
    """Run `scenario` in lockstep and write the run directory and `metrics.json`.

    Args:
        scenario: the resolved scenario.
        out_dir: run directory (created).
        world_rate_hz: world ticks per sim second.
        control_rate_hz: planning cycles per sim second; must divide world_rate_hz.
        on_progress: called about every sim second with a `LockstepProgress`.
        faults: if given, run the streaming, fault-injected loop (`_run_faulty`).
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
    if faults is not None:
        return _run_faulty(scenario, Path(out_dir), world_rate_hz, control_rate_hz, faults,
                           on_progress)
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
                    world.set_command(ctrl.spec.id, res.v_mps, res.omega_radps,
                                      ctrl.command_hold_s)
                    rec.record_command(world.t_s, ctrl.spec.id, seq[k], snapshot.stamp_s,
                                       res.v_mps, res.omega_radps, res.times.total_ms,
                                       str(res.status.value), side=int(res.side),
                                       resolved=res.resolved_id)
                    seq[k] += 1
            _step_and_record(world, rec, dt_s)
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


@dataclass
class _FaultyRobot:
    """One robot of a fault-injected lockstep run: its controller, links and state."""

    spec: object
    ctrl: object
    pose_link: object
    cmd_link: object
    ticks_per_cycle: int
    phase_ticks: int
    plan_delay_s: float
    seq: int = 0
    state: str = "up"  # "up" | "stopped" | "down"
    resume_s: float = math.inf
    lease_s: float = math.inf
    back_s: float = math.inf


def _run_faulty(scenario: Scenario, out_dir: Path, world_rate_hz: float,
                control_rate_hz: float, faults: FaultPlan,
                on_progress: Callable[[LockstepProgress], None] | None) -> LockstepOutcome:
    """The streaming lockstep loop with a `FaultPlan` (see the module docstring)."""
    from agent.controller import RobotController
    from agent.link import LINK_COMMANDS, LINK_POSES, FaultyLink, link_rng
    from protocol import LINK_LEASE_MS
    from world.dynamics import WorldSim
    from world.recorder import RunRecorder

    faults.check([r.id for r in scenario.robots])
    dt_s = 1.0 / world_rate_hz
    eps = 1e-9

    def ticks_of(rate_hz: float) -> int:
        ratio = world_rate_hz / rate_hz
        n = round(ratio)
        if n < 1 or abs(ratio - n) > 1e-9:
            raise ValueError(f"control rate {rate_hz} Hz must divide the world rate "
                             f"{world_rate_hz} Hz")
        return n

    def controller(spec: object) -> RobotController:
        timing = faults.timing_of(spec.id)  # type: ignore[attr-defined]
        return RobotController(spec, scenario.planner_config,  # type: ignore[arg-type]
                               scenario.goal_tolerance_m,
                               compensate_latency=faults.compensate_latency,
                               control_period_s=1.0 / (timing.control_rate_hz
                                                       or control_rate_hz))

    robots = []
    for spec in scenario.robots:
        timing = faults.timing_of(spec.id)
        robots.append(_FaultyRobot(
            spec=spec, ctrl=controller(spec),
            pose_link=FaultyLink(faults.links, link_rng(faults.seed, LINK_POSES, spec.id)),
            cmd_link=FaultyLink(faults.links, link_rng(faults.seed, LINK_COMMANDS, spec.id)),
            ticks_per_cycle=ticks_of(timing.control_rate_hz or control_rate_hz),
            phase_ticks=round(timing.phase_s * world_rate_hz),
            plan_delay_s=timing.plan_delay_ms * 1e-3))
    by_id = {r.spec.id: r for r in robots}
    pending = sorted(faults.process, key=lambda f: f.at_s)
    lease_s = LINK_LEASE_MS * 1e-3
    world = WorldSim(scenario, cmd_timeout_s=CMD_TIMEOUT_S)
    last_seq: dict[int, int] = {}
    max_ticks = math.ceil(scenario.time_limit_s * world_rate_hz - 1e-9)
    progress_ticks = max(1, round(PROGRESS_EVERY_S * world_rate_hz))
    ego_err_sum, ego_err_max, plans, stale_cmds = 0.0, 0.0, 0, 0

    wall0 = time.perf_counter()
    reason = "time_limit"
    with RunRecorder(out_dir, scenario) as rec:
        rec.event("start", 0.0, mode="lockstep", n_robots=len(robots),
                  world_rate_hz=world_rate_hz, control_rate_hz=control_rate_hz,
                  faults=faults.to_json())
        rec.record_tick(world.t_s, world.robot_ids, world.pose, world.applied)
        for rid in world.robot_ids[world.arrived].tolist():
            rec.event("arrived", world.t_s, robot=rid)
        while True:
            if world.all_arrived():
                reason = "all_arrived"
                break
            if world.tick >= max_ticks:
                break
            t, tick = world.t_s, world.tick
            # Process faults and the world's view of them (liveliness, lease).
            while pending and pending[0].at_s <= t + eps:
                f = pending.pop(0)
                r = by_id[f.robot_id]
                rec.event("fault", t, fault=f.kind, robot=f.robot_id, duration_s=f.duration_s)
                if f.kind == "stop" and r.state == "up":
                    r.state, r.resume_s, r.lease_s = "stopped", t + f.duration_s, t + lease_s
                elif f.kind in ("kill", "restart") and r.state != "down":
                    r.state, r.resume_s, r.lease_s = "down", math.inf, math.inf
                    r.back_s = t + RESTART_DELAY_S if f.kind == "restart" else math.inf
                    if not world.offline[world.index_of(r.spec.id)]:
                        world.set_offline(r.spec.id, True)
                        rec.event("robot_lost", t, robot=r.spec.id)
            for r in robots:
                rid = r.spec.id
                offline = bool(world.offline[world.index_of(rid)])
                if r.state == "stopped" and t + eps >= r.lease_s and not offline:
                    world.set_offline(rid, True)
                    rec.event("robot_lost", t, robot=rid)
                if r.state == "stopped" and t + eps >= r.resume_s:
                    r.state = "up"
                    if world.offline[world.index_of(rid)]:
                        world.set_offline(rid, False)
                        last_seq.pop(rid, None)
                        rec.event("robot_rejoined", t, robot=rid)
                if r.state == "down" and t + eps >= r.back_s:
                    r.state, r.back_s, r.seq = "up", math.inf, 0
                    r.ctrl = controller(r.spec)
                    r.pose_link.clear()
                    r.cmd_link.clear()
                    world.set_offline(rid, False)
                    last_seq.pop(rid, None)
                    rec.event("robot_rejoined", t, robot=rid)
            # Sense through the pose links, plan at each robot's own slots.
            snapshot = world.snapshot()
            for k, r in enumerate(robots):
                r.pose_link.send(t, snapshot)
                if r.state == "stopped":
                    continue
                for snap in r.pose_link.receive(t):
                    if r.state == "up":
                        r.ctrl.observe(snap)
                if (r.state != "up" or tick < r.phase_ticks
                        or (tick - r.phase_ticks) % r.ticks_per_cycle):
                    continue
                res = r.ctrl.plan(t)
                obs = r.ctrl.last_observation
                if obs is not None:
                    err = math.hypot(obs.ego.x_m - world.pose[k, 0],
                                     obs.ego.y_m - world.pose[k, 1])
                    ego_err_sum += err
                    ego_err_max = max(ego_err_max, err)
                    plans += 1
                stamp = r.ctrl.snapshot.stamp_s if r.ctrl.snapshot is not None else t
                r.cmd_link.send(t + r.plan_delay_s, (r.seq, stamp, res))
                r.seq += 1
            # The world applies what its command links release (newest seq only).
            for r in robots:
                rid = r.spec.id
                for seq, stamp, res in r.cmd_link.receive(t):
                    if seq <= last_seq.get(rid, -1):
                        stale_cmds += 1
                        continue
                    last_seq[rid] = seq
                    world.set_command(rid, res.v_mps, res.omega_radps, r.ctrl.command_hold_s)
                    rec.record_command(t, rid, seq, stamp, res.v_mps, res.omega_radps,
                                       res.times.total_ms, str(res.status.value),
                                       side=int(res.side), resolved=res.resolved_id)
            _step_and_record(world, rec, dt_s)
            if on_progress is not None and world.tick % progress_ticks == 0:
                on_progress(_progress(world, wall0))
        success = world.all_arrived() and world.contact_count == 0
        links = {name: sum(getattr(r.pose_link.counts, name) for r in robots)
                 for name in ("dropped", "duplicated", "reordered")}
        cmd_links = {name: sum(getattr(r.cmd_link.counts, name) for r in robots)
                     for name in ("dropped", "duplicated", "reordered")}
        rec.event("end", world.t_s, reason=reason, success=success,
                  arrived=[int(r) for r in world.robot_ids[world.arrived]],
                  contacts=world.contact_count, ticks=world.tick,
                  min_gap_m=round(world.min_gap_m, 6) if math.isfinite(world.min_gap_m)
                  else None,
                  lost=sorted(r.spec.id for r in robots if r.state == "down"),
                  cmd_timeouts=world.timeout_count,
                  cmd_hold_expiries=world.hold_expiry_count, stale=stale_cmds,
                  stale_poses=sum(r.ctrl.rejected_stale for r in robots),
                  pose_link=links, cmd_link=cmd_links,
                  ego_error_m_mean=round(ego_err_sum / plans, 6) if plans else None,
                  ego_error_m_max=round(ego_err_max, 6))
    wall_s = time.perf_counter() - wall0
    if on_progress is not None:
        on_progress(_progress(world, wall0))
    metrics = metrics_from_run_dir(out_dir, control_period_s=1.0 / control_rate_hz,
                                   world_dt_s=dt_s)
    write_metrics(out_dir, metrics)
    return LockstepOutcome(out_dir=out_dir, reason=reason, success=metrics.success,
                           sim_time_s=world.t_s, ticks=world.tick, wall_s=wall_s,
                           metrics=metrics)
