"""The one deterministic in-process loop: the world and every robot's controller, in one process.

Same `world.sim.dynamics.WorldSim` and `agent.planning.controller.RobotController` as the
distributed processes; only the transport is replaced by in-process links. Each world tick:

1. process faults (kill, stop, restart) and the world's view of them (liveliness, lease);
2. the tick's snapshot is cut into the cells of the pose grid (`world.sim.cells.split_cells`,
   as the world publishes one message per cell), and each robot whose pose slot the tick is
   on (as the world publishes tick t on ``poses/<t mod K>/...`` and a robot subscribes to
   its slot, `world.sim.schedule.plan_pose_slot`; every tick for a robot whose plans do not
   keep one slot) gets the view of the cells it holds (`world.sim.cells.merge_parts`, the
   same merge a robot process makes of its cells' messages) into its pose link;
3. each robot observes what its link releases, moves its cells with its own position in it
   (`world.sim.cells.CellSubscription`, as the robot process does) and, on its planning
   ticks, plans on the true sim time (so it sees the poses' real age) and sends its command
   into its command link, ``plan_delay_ms`` late for a slow robot;
4. the world applies what the command links release (the newest ``seq`` per robot only),
   steps the dynamics and the sink records the tick.

Without faults every link delivers at once and every robot plans on tick 0 mod K: all robots
see the same tick (each the discs of its cells), plan, and their commands apply before the
world steps. Process faults
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
from agent.core.types import PlanResult, PoseSnapshot
from agent.planning.controller import COMMAND_HOLD_PERIODS, RobotController
from agent.planning.routing import StaticMap
from world.sim.cells import Cell, CellChange, CellRule, CellSubscription, merge_parts, split_cells
from world.sim.dynamics import WorldSim
from world.sim.faults import FaultPlan
from world.sim.lifecycle import EPS_S, ProcessState, RobotLifecycle, Transition
from world.sim.link import LINK_COMMANDS, LINK_POSES, FaultyLink, link_rng
from world.sim.schedule import LINK_LEASE_MS, plan_pose_slot, pose_slot_count, pose_slot_of_tick

CMD_TIMEOUT_S = 0.5
"""Sim time without a command after which the world brakes a robot."""
RESTART_DELAY_S = 2.0
"""Sim time a restarted robot is away (a new process starting, as in distributed runs)."""
PROGRESS_EVERY_S = 1.0
"""Sim time between two `on_progress` calls."""


class RunSink(Protocol):
    """Where the loop records a run (`world.recorder.RunRecorder` writes the run directory)."""

    def record_tick(self, t_s: float, robot_ids: np.ndarray, pose: np.ndarray,
                    applied: np.ndarray) -> None: ...

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
    """One robot of the loop: its controller, links, schedule and process lifecycle."""

    spec: RobotSpec
    ctrl: RobotController
    pose_link: FaultyLink[PoseSnapshot]
    cmd_link: FaultyLink[tuple[int, float, PlanResult]]  # (seq, pose stamp [s], plan)
    ticks_per_cycle: int
    phase_ticks: int
    pose_slot: int | None
    plan_delay_s: float
    cells: CellSubscription
    seq: int = 0
    life: RobotLifecycle = field(default_factory=RobotLifecycle)

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


@dataclass
class _EgoError:
    """How far each planning robot's own estimate was from the truth [m], summed."""

    sum_m: float = 0.0
    max_m: float = 0.0
    plans: int = 0

    def add(self, err_m: float) -> None:
        self.sum_m += err_m
        self.max_m = max(self.max_m, err_m)
        self.plans += 1


class _Loop:
    """One lockstep run: the world, the robots and what the ``end`` event tallies.

    Each `tick` runs the steps of the module docstring in order; the world's state is read
    once per step, so no robot's result depends on another's order.
    """

    def __init__(self, scenario: Scenario, sink: RunSink, plan: FaultPlan, *,
                 world_rate_hz: float, control_rate_hz: float) -> None:
        self.scenario, self.sink, self.plan = scenario, sink, plan
        self.world_rate_hz, self.control_rate_hz = world_rate_hz, control_rate_hz
        self.dt_s = 1.0 / world_rate_hz
        self.slots = pose_slot_count(world_rate_hz, control_rate_hz)
        self.cell_rule = CellRule.of_config(scenario.planner_config)
        self.static_map = StaticMap.of_obstacles(scenario.obstacles)
        self.robots = [self._robot(spec) for spec in scenario.robots]
        self.by_id = {r.spec.id: r for r in self.robots}
        self.pending = sorted(plan.process, key=lambda f: f.at_s)
        self.world = WorldSim(scenario, cmd_timeout_s=CMD_TIMEOUT_S)
        self.last_seq: dict[int, int] = {}
        self.record_plan = getattr(sink, "record_plan", None)
        self.ego = _EgoError()
        self.stale_cmds = 0

    def controller(self, spec: RobotSpec) -> RobotController:
        rate_hz = self.plan.timing_of(spec.id).control_rate_hz or self.control_rate_hz
        hold = self.plan.command_hold_periods
        return RobotController(spec, self.scenario.planner_config,
                               self.scenario.goal_tolerance_m,
                               compensate_latency=self.plan.compensate_latency,
                               control_period_s=1.0 / rate_hz, static_map=self.static_map,
                               command_hold_periods=(COMMAND_HOLD_PERIODS if hold is None
                                                     else hold))

    def _robot(self, spec: RobotSpec) -> _Robot:
        plan, world_rate_hz = self.plan, self.world_rate_hz
        timing = plan.timing_of(spec.id)
        rate_hz = timing.control_rate_hz or self.control_rate_hz
        return _Robot(
            spec=spec, ctrl=self.controller(spec),
            pose_link=FaultyLink(plan.links, link_rng(plan.seed, LINK_POSES, spec.id)),
            cmd_link=FaultyLink(plan.links, link_rng(plan.seed, LINK_COMMANDS, spec.id)),
            ticks_per_cycle=_ticks_per(world_rate_hz, rate_hz),
            phase_ticks=round(timing.phase_s * world_rate_hz),
            pose_slot=plan_pose_slot(1.0 / rate_hz, timing.phase_s, self.dt_s, self.slots),
            plan_delay_s=timing.plan_delay_ms * 1e-3,
            cells=CellSubscription(self.cell_rule, spec.start[:2]))

    def progress(self) -> SimProgress:
        world = self.world
        return SimProgress(sim_t_s=float(world.t_s), n_robots=len(self.robots),
                           arrived=frozenset(int(r) for r in world.robot_ids[world.arrived]),
                           contacts=int(world.contact_count),
                           lost=frozenset(r.spec.id for r in self.robots if r.life.down))

    def start(self) -> None:
        """The ``start`` event, tick 0 and the robots that start at their goals."""
        world, plan = self.world, self.plan
        start: dict[str, Any] = {"mode": "lockstep", "n_robots": len(self.robots),
                                 "world_rate_hz": self.world_rate_hz,
                                 "control_rate_hz": self.control_rate_hz}
        if plan.active:
            start["faults"] = plan.to_json()
        self.sink.event("start", 0.0, **start)
        self.sink.record_tick(world.t_s, world.robot_ids, world.pose, world.applied)
        for rid in world.robot_ids[world.arrived].tolist():
            self.sink.event("arrived", world.t_s, robot=rid)

    def end_reason(self, max_ticks: int) -> str | None:
        """Why the run ends before the next tick, or None to go on."""
        world = self.world
        if world.all_arrived():
            return "all_arrived"
        # A killed robot that will not come back no longer holds the run open.
        gone = np.array([r.life.gone_for_good for r in self.robots])
        if gone.any() and bool(np.all(world.arrived | gone)):
            return "arrived_or_lost"
        if world.tick >= max_ticks:
            return "time_limit"
        return None

    def _set_offline(self, rid: int, offline: bool, t: float) -> None:
        """Take a robot offline (``robot_lost``) or bring it back (``robot_rejoined``: its
        command numbering starts over)."""
        self.world.set_offline(rid, offline)
        if not offline:
            self.last_seq.pop(rid, None)
        self.sink.event("robot_lost" if offline else "robot_rejoined", t, robot=rid)

    def _offline(self, rid: int) -> bool:
        return bool(self.world.offline[self.world.index_of(rid)])

    def apply_faults(self, t: float) -> None:
        """1a. The process faults due by `t`."""
        while self.pending and self.pending[0].at_s <= t + EPS_S:
            f = self.pending.pop(0)
            r = self.by_id[f.robot_id]
            self.sink.event("fault", t, fault=f.kind, robot=f.robot_id, duration_s=f.duration_s)
            died = r.life.fault(f.kind, t, f.duration_s, lease_s=LINK_LEASE_MS * 1e-3,
                                restart_delay_s=RESTART_DELAY_S)
            if died and not self._offline(r.spec.id):
                self._set_offline(r.spec.id, True, t)

    def advance_lifecycles(self, t: float) -> None:
        """1b. The world's view of the processes: leases, resumptions, restarts."""
        for r in self.robots:
            rid = r.spec.id
            for change in r.life.advance(t):
                if change is Transition.LEASE_EXPIRED and not self._offline(rid):
                    self._set_offline(rid, True, t)
                elif change is Transition.RESUMED and self._offline(rid):
                    self._set_offline(rid, False, t)
                elif change is Transition.RESTARTED:
                    r.seq, r.ctrl = 0, self.controller(r.spec)
                    r.cells = CellSubscription(self.cell_rule, r.spec.start[:2])
                    r.pose_link.clear()
                    r.cmd_link.clear()
                    self._set_offline(rid, False, t)

    def sense_and_plan(self, t: float, tick: int) -> None:
        """2-3. Sense through the pose links (the robot's slot and cells), plan on the
        planning ticks."""
        snapshot = self.world.snapshot()
        parts = split_cells(snapshot, self.cell_rule.size_m)
        views: dict[frozenset[Cell] | None, PoseSnapshot] = {}  # robots holding the same cells
        slot = pose_slot_of_tick(tick, self.slots)
        for k, r in enumerate(self.robots):
            if r.pose_slot is None or r.pose_slot == slot:
                held = r.cells.cells
                view = views.get(held)
                if view is None:
                    view = views[held] = merge_parts(parts, held, snapshot.stamp_s,
                                                     snapshot.tick)
                r.pose_link.send(t, view)
            if r.life.state is ProcessState.STOPPED:
                continue
            for snap in r.pose_link.receive(t):
                if r.life.up:
                    _observe(r, snap)
            if r.life.up and r.plans_on(tick):
                self._plan(k, r, t)

    def _plan(self, k: int, r: _Robot, t: float) -> None:
        res = r.ctrl.plan(t)
        if self.record_plan is not None and res.debug is not None:
            self.record_plan(t, r.spec.id, res.debug, v_mps=res.v_mps,
                             omega_radps=res.omega_radps, status=str(res.status.value))
        obs = r.ctrl.last_observation
        if obs is not None:
            pose = self.world.pose
            self.ego.add(math.hypot(obs.ego.x_m - pose[k, 0], obs.ego.y_m - pose[k, 1]))
        stamp = r.ctrl.snapshot.stamp_s if r.ctrl.snapshot is not None else t
        r.cmd_link.send(t + r.plan_delay_s, (r.seq, stamp, res))
        r.seq += 1

    def apply_commands(self, t: float) -> None:
        """4a. The world applies what its command links release (the newest seq only)."""
        for r in self.robots:
            rid = r.spec.id
            for seq, stamp, res in r.cmd_link.receive(t):
                if seq <= self.last_seq.get(rid, -1):
                    self.stale_cmds += 1
                    continue
                self.last_seq[rid] = seq
                self.world.set_command(rid, res.v_mps, res.omega_radps, r.ctrl.command_hold_s)
                self.sink.record_command(t, rid, seq, stamp, res.v_mps, res.omega_radps,
                                         res.times.total_ms, str(res.status.value),
                                         side=int(res.side), resolved=res.resolved_id)

    def step(self) -> None:
        """4b. Step the dynamics; record the tick and what happened in it."""
        world, sink = self.world, self.sink
        events = world.step(self.dt_s)
        sink.record_tick(world.t_s, world.robot_ids, world.pose, world.applied)
        for rid in events.arrivals:
            sink.event("arrived", world.t_s, robot=rid)
        for a, b, overlap in events.new_contacts:
            sink.event("contact", world.t_s, a=a, b=b, overlap_m=round(overlap, 6))
        for rid in events.timeouts:
            sink.event("cmd_timeout", world.t_s, robot=rid)

    def tick(self) -> None:
        """One world tick: steps 1-4 of the module docstring."""
        t, tick = self.world.t_s, self.world.tick
        self.apply_faults(t)
        self.advance_lifecycles(t)
        self.sense_and_plan(t, tick)
        self.apply_commands(t)
        self.step()

    def finish(self, reason: str) -> LockstepResult:
        """The ``end`` event and the result."""
        world, robots, ego = self.world, self.robots, self.ego
        lost = tuple(sorted(r.spec.id for r in robots if r.life.down))
        all_arrived = bool(world.all_arrived())
        link_counts = {
            link: {name: sum(getattr(getattr(r, link).counts, name) for r in robots)
                   for name in ("dropped", "duplicated", "reordered")}
            for link in ("pose_link", "cmd_link")}
        self.sink.event(
            "end", world.t_s, reason=reason,
            success=all_arrived and world.contact_count == 0, all_arrived=all_arrived,
            arrived=[int(r) for r in world.robot_ids[world.arrived]],
            contacts=world.contact_count, ticks=world.tick,
            min_gap_m=round(world.min_gap_m, 6) if math.isfinite(world.min_gap_m) else None,
            lost=list(lost), cmd_timeouts=world.timeout_count,
            cmd_hold_expiries=world.hold_expiry_count, stale=self.stale_cmds,
            stale_poses=sum(r.ctrl.rejected_stale for r in robots), **link_counts,
            ego_error_m_mean=round(ego.sum_m / ego.plans, 6) if ego.plans else None,
            ego_error_m_max=round(ego.max_m, 6))
        return LockstepResult(reason=reason, all_arrived=all_arrived,
                              contacts=int(world.contact_count), sim_time_s=float(world.t_s),
                              ticks=int(world.tick), lost=lost)


def _observe(r: _Robot, snapshot: PoseSnapshot) -> CellChange:
    """The robot observes a view and moves its cells, as `agent.robot_cycle.RobotCycle`
    does."""
    if not r.ctrl.observe(snapshot):
        if not bool((snapshot.ids == r.spec.id).any()):
            return r.cells.missed_self()
        return CellChange()
    row = int(np.flatnonzero(snapshot.ids == r.spec.id)[0])
    x, y = snapshot.pose[row, :2].tolist()
    return r.cells.follow(x, y)


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
    loop = _Loop(scenario, sink, plan, world_rate_hz=world_rate_hz,
                 control_rate_hz=control_rate_hz)
    max_ticks = math.ceil(scenario.time_limit_s * world_rate_hz - 1e-9)
    progress_ticks = max(1, round(PROGRESS_EVERY_S * world_rate_hz))
    loop.start()
    while (reason := loop.end_reason(max_ticks)) is None:
        loop.tick()
        if on_progress is not None and loop.world.tick % progress_ticks == 0:
            on_progress(loop.progress())
    result = loop.finish(reason)
    if on_progress is not None:
        on_progress(loop.progress())
    return result
