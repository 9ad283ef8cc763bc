"""The one deterministic in-process loop: the world and every robot's controller, in one process.

Same `world.sim.dynamics.WorldSim` and `agent.planning.controller.RobotController` as the
distributed processes; only the transport is replaced by in-process links. Each world tick:

1. process faults (kill, stop, restart) and the world's view of them (liveliness, lease);
2. the tick's snapshot enters the pose link of every robot whose pose slot it is on (as the
   world publishes tick t on ``poses/<t mod K>`` and a robot subscribes to its slot,
   `world.sim.schedule.plan_pose_slot`; every tick for a robot whose plans do not keep one slot);
3. each robot observes what its link releases and, on its planning ticks, plans on the true
   sim time (so it sees the poses' real age) and sends its command into its command link,
   ``plan_delay_ms`` late for a slow robot;
4. the world applies what the command links release (the newest ``seq`` per robot only),
   steps the dynamics and the sink records the tick.

Without faults every link delivers at once and every robot plans on tick 0 mod K: all robots
see the same snapshot, plan, and their commands apply before the world steps. Process faults
are emulated: ``kill`` takes a robot offline for good (the world brakes it; it stays as an
obstacle); ``stop`` freezes its controller and the world takes it offline after the
transport lease (`world.sim.schedule.LINK_LEASE_MS`), back when it resumes; ``restart`` is a kill
followed, `RESTART_DELAY_S` later, by a fresh controller with the same id.

Pure: no files, no clock. Deterministic for a given scenario, fault plan and seed (only the
recorded planning times vary between runs).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from agent.core.scenario import RobotSpec, Scenario
from agent.planning.controller import RobotController
from agent.planning.routing import StaticMap
from world.sim.dynamics import WorldSim
from world.sim.faults import FaultPlan
from world.sim.link import LINK_COMMANDS, LINK_POSES, FaultyLink, link_rng
from world.sim.schedule import LINK_LEASE_MS, plan_pose_slot, pose_slot_count, pose_slot_of_tick

CMD_TIMEOUT_S = 0.5
"""Sim time without a command after which the world brakes a robot."""
RESTART_DELAY_S = 2.0
"""Sim time a restarted robot is away (a new process starting, as in distributed runs)."""
PROGRESS_EVERY_S = 1.0
"""Sim time between two `on_progress` calls."""
EPS_S = 1e-9


class RunSink(Protocol):
    """Where the loop records a run (`world.recorder.RunRecorder` writes the run directory)."""

    def record_tick(self, t_s: float, robot_ids: Any, pose: Any, applied: Any) -> None: ...

    def record_command(self, t_s: float, robot_id: int, seq: int, pose_stamp_s: float,
                       v_mps: float, omega_radps: float, plan_ms: float, status: str, *,
                       side: int = 0, resolved: int | None = None) -> None: ...

    def event(self, kind: str, t_s: float, **fields: Any) -> None: ...

    # Optional: a sink with `record_plan(t_s, robot_id, debug, *, v_mps, omega_radps,
    # status)` also gets every plan's `PlanDebug` (`world.recorder.RunRecorder` has it).


@dataclass(frozen=True)
class SimProgress:
    """What the loop reports to `on_progress` about every sim second."""

    sim_t_s: float
    n_robots: int
    arrived: frozenset[int]
    contacts: int
    lost: frozenset[int] = field(default_factory=frozenset)


@dataclass(frozen=True)
class LockstepResult:
    """How a lockstep run ended.

    Args:
        reason: "all_arrived", "arrived_or_lost" (every robot arrived or was killed for
            good: a lost robot does not hold the run to its time limit) or "time_limit".
        all_arrived: every robot arrived.
        contacts: contact episodes counted by the world.
        sim_time_s: sim time at the end.
        ticks: world ticks run.
        lost: robots offline at the end (killed and not restarted).
    """

    reason: str
    all_arrived: bool
    contacts: int
    sim_time_s: float
    ticks: int
    lost: tuple[int, ...] = ()


@dataclass
class _Robot:
    """One robot of the loop: its controller, links, schedule and process state."""

    spec: RobotSpec
    ctrl: RobotController
    pose_link: FaultyLink
    cmd_link: FaultyLink
    ticks_per_cycle: int
    phase_ticks: int
    pose_slot: int | None
    plan_delay_s: float
    seq: int = 0
    state: str = "up"  # "up" | "stopped" | "down"
    resume_s: float = math.inf
    lease_s: float = math.inf
    back_s: float = math.inf

    def plans_on(self, tick: int) -> bool:
        return (tick >= self.phase_ticks
                and (tick - self.phase_ticks) % self.ticks_per_cycle == 0)


def _ticks_per(world_rate_hz: float, rate_hz: float) -> int:
    ratio = world_rate_hz / rate_hz
    n = round(ratio)
    if n < 1 or abs(ratio - n) > 1e-9:
        raise ValueError(f"control rate {rate_hz} Hz must divide the world rate "
                         f"{world_rate_hz} Hz")
    return n


def run_lockstep(scenario: Scenario, sink: RunSink, *, world_rate_hz: float = 50.0,
                 control_rate_hz: float = 10.0, faults: FaultPlan | None = None,
                 on_progress: Callable[[SimProgress], None] | None = None) -> LockstepResult:
    """Run `scenario` to its end, recording into `sink`.

    Args:
        scenario: the resolved scenario.
        sink: receives every tick, command and event.
        world_rate_hz: world ticks per sim second.
        control_rate_hz: planning cycles per sim second; must divide world_rate_hz.
        faults: injected link and process faults, and per-robot timing; None: none.
        on_progress: called about every sim second.

    Raises:
        ValueError: rates that are not positive or do not divide, or a fault plan naming
            robots the scenario does not have.
    """
    if not (world_rate_hz > 0 and control_rate_hz > 0):
        raise ValueError("world_rate_hz and control_rate_hz must be positive")
    _ticks_per(world_rate_hz, control_rate_hz)
    plan = faults if faults is not None else FaultPlan()
    plan.check([r.id for r in scenario.robots])
    dt_s = 1.0 / world_rate_hz
    slots = pose_slot_count(world_rate_hz, control_rate_hz)

    static_map = StaticMap.of_obstacles(scenario.obstacles)

    def controller(spec: RobotSpec) -> RobotController:
        rate_hz = plan.timing_of(spec.id).control_rate_hz or control_rate_hz
        return RobotController(spec, scenario.planner_config, scenario.goal_tolerance_m,
                               compensate_latency=plan.compensate_latency,
                               control_period_s=1.0 / rate_hz, static_map=static_map)

    robots = []
    for spec in scenario.robots:
        timing = plan.timing_of(spec.id)
        rate_hz = timing.control_rate_hz or control_rate_hz
        robots.append(_Robot(
            spec=spec, ctrl=controller(spec),
            pose_link=FaultyLink(plan.links, link_rng(plan.seed, LINK_POSES, spec.id)),
            cmd_link=FaultyLink(plan.links, link_rng(plan.seed, LINK_COMMANDS, spec.id)),
            ticks_per_cycle=_ticks_per(world_rate_hz, rate_hz),
            phase_ticks=round(timing.phase_s * world_rate_hz),
            pose_slot=plan_pose_slot(1.0 / rate_hz, timing.phase_s, dt_s, slots),
            plan_delay_s=timing.plan_delay_ms * 1e-3))
    by_id = {r.spec.id: r for r in robots}
    pending = sorted(plan.process, key=lambda f: f.at_s)
    lease_s = LINK_LEASE_MS * 1e-3
    world = WorldSim(scenario, cmd_timeout_s=CMD_TIMEOUT_S)
    last_seq: dict[int, int] = {}
    record_plan = getattr(sink, "record_plan", None)
    max_ticks = math.ceil(scenario.time_limit_s * world_rate_hz - 1e-9)
    progress_ticks = max(1, round(PROGRESS_EVERY_S * world_rate_hz))
    ego_err_sum, ego_err_max, plans, stale_cmds = 0.0, 0.0, 0, 0

    def progress() -> SimProgress:
        return SimProgress(sim_t_s=float(world.t_s), n_robots=len(robots),
                           arrived=frozenset(int(r) for r in world.robot_ids[world.arrived]),
                           contacts=int(world.contact_count),
                           lost=frozenset(r.spec.id for r in robots if r.state == "down"))

    start: dict[str, Any] = {"mode": "lockstep", "n_robots": len(robots),
                             "world_rate_hz": world_rate_hz, "control_rate_hz": control_rate_hz}
    if plan.active:
        start["faults"] = plan.to_json()
    sink.event("start", 0.0, **start)
    sink.record_tick(world.t_s, world.robot_ids, world.pose, world.applied)
    for rid in world.robot_ids[world.arrived].tolist():
        sink.event("arrived", world.t_s, robot=rid)
    reason = "time_limit"
    while True:
        if world.all_arrived():
            reason = "all_arrived"
            break
        # A killed robot that will not come back no longer holds the run open.
        gone = np.array([r.state == "down" and r.back_s == math.inf for r in robots])
        if gone.any() and bool(np.all(world.arrived | gone)):
            reason = "arrived_or_lost"
            break
        if world.tick >= max_ticks:
            break
        t, tick = world.t_s, world.tick
        # 1. Process faults and the world's view of them (liveliness, lease).
        while pending and pending[0].at_s <= t + EPS_S:
            f = pending.pop(0)
            r = by_id[f.robot_id]
            sink.event("fault", t, fault=f.kind, robot=f.robot_id, duration_s=f.duration_s)
            if f.kind == "stop" and r.state == "up":
                r.state, r.resume_s, r.lease_s = "stopped", t + f.duration_s, t + lease_s
            elif f.kind in ("kill", "restart") and r.state != "down":
                r.state, r.resume_s, r.lease_s = "down", math.inf, math.inf
                r.back_s = t + RESTART_DELAY_S if f.kind == "restart" else math.inf
                if not world.offline[world.index_of(r.spec.id)]:
                    world.set_offline(r.spec.id, True)
                    sink.event("robot_lost", t, robot=r.spec.id)
        for r in robots:
            rid = r.spec.id
            offline = bool(world.offline[world.index_of(rid)])
            if r.state == "stopped" and t + EPS_S >= r.lease_s and not offline:
                world.set_offline(rid, True)
                sink.event("robot_lost", t, robot=rid)
            if r.state == "stopped" and t + EPS_S >= r.resume_s:
                r.state = "up"
                if world.offline[world.index_of(rid)]:
                    world.set_offline(rid, False)
                    last_seq.pop(rid, None)
                    sink.event("robot_rejoined", t, robot=rid)
            if r.state == "down" and t + EPS_S >= r.back_s:
                r.state, r.back_s, r.seq = "up", math.inf, 0
                r.ctrl = controller(r.spec)
                r.pose_link.clear()
                r.cmd_link.clear()
                world.set_offline(rid, False)
                last_seq.pop(rid, None)
                sink.event("robot_rejoined", t, robot=rid)
        # 2-3. Sense through the pose links (the robot's slot), plan on the planning ticks.
        snapshot = world.snapshot()
        slot = pose_slot_of_tick(tick, slots)
        for k, r in enumerate(robots):
            if r.pose_slot is None or r.pose_slot == slot:
                r.pose_link.send(t, snapshot)
            if r.state == "stopped":
                continue
            for snap in r.pose_link.receive(t):
                if r.state == "up":
                    r.ctrl.observe(snap)
            if r.state != "up" or not r.plans_on(tick):
                continue
            res = r.ctrl.plan(t)
            if record_plan is not None and res.debug is not None:
                record_plan(t, r.spec.id, res.debug, v_mps=res.v_mps,
                            omega_radps=res.omega_radps, status=str(res.status.value))
            obs = r.ctrl.last_observation
            if obs is not None:
                err = math.hypot(obs.ego.x_m - world.pose[k, 0], obs.ego.y_m - world.pose[k, 1])
                ego_err_sum += err
                ego_err_max = max(ego_err_max, err)
                plans += 1
            stamp = r.ctrl.snapshot.stamp_s if r.ctrl.snapshot is not None else t
            r.cmd_link.send(t + r.plan_delay_s, (r.seq, stamp, res))
            r.seq += 1
        # 4. The world applies what its command links release (the newest seq only).
        for r in robots:
            rid = r.spec.id
            for seq, stamp, res in r.cmd_link.receive(t):
                if seq <= last_seq.get(rid, -1):
                    stale_cmds += 1
                    continue
                last_seq[rid] = seq
                world.set_command(rid, res.v_mps, res.omega_radps, r.ctrl.command_hold_s)
                sink.record_command(t, rid, seq, stamp, res.v_mps, res.omega_radps,
                                    res.times.total_ms, str(res.status.value),
                                    side=int(res.side), resolved=res.resolved_id)
        events = world.step(dt_s)
        sink.record_tick(world.t_s, world.robot_ids, world.pose, world.applied)
        for rid in events.arrivals:
            sink.event("arrived", world.t_s, robot=rid)
        for a, b, overlap in events.new_contacts:
            sink.event("contact", world.t_s, a=a, b=b, overlap_m=round(overlap, 6))
        for rid in events.timeouts:
            sink.event("cmd_timeout", world.t_s, robot=rid)
        if on_progress is not None and world.tick % progress_ticks == 0:
            on_progress(progress())
    lost = tuple(sorted(r.spec.id for r in robots if r.state == "down"))
    all_arrived = bool(world.all_arrived())
    link_counts = {
        link: {name: sum(getattr(getattr(r, link).counts, name) for r in robots)
               for name in ("dropped", "duplicated", "reordered")}
        for link in ("pose_link", "cmd_link")}
    sink.event("end", world.t_s, reason=reason,
               success=all_arrived and world.contact_count == 0, all_arrived=all_arrived,
               arrived=[int(r) for r in world.robot_ids[world.arrived]],
               contacts=world.contact_count, ticks=world.tick,
               min_gap_m=round(world.min_gap_m, 6) if math.isfinite(world.min_gap_m) else None,
               lost=list(lost), cmd_timeouts=world.timeout_count,
               cmd_hold_expiries=world.hold_expiry_count, stale=stale_cmds,
               stale_poses=sum(r.ctrl.rejected_stale for r in robots), **link_counts,
               ego_error_m_mean=round(ego_err_sum / plans, 6) if plans else None,
               ego_error_m_max=round(ego_err_max, 6))
    if on_progress is not None:
        on_progress(progress())
    return LockstepResult(reason=reason, all_arrived=all_arrived,
                          contacts=int(world.contact_count), sim_time_s=float(world.t_s),
                          ticks=int(world.tick), lost=lost)
