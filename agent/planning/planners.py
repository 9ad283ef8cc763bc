"""One interface for the four planners: `ifp`, `eifp`, `eifp-mpc` and `orca`.

`make_planner(name, config)` returns an object with `plan(observation, now_s) -> PlanResult`.

- `ifp`: the baseline IFP (`agent.planning.ifp`): earliest feasible via-point, iterated; the spline
  is followed by the unicycle tracking law (`agent.planning.unicycle.track_reference`).
- `eifp`: eIFP (`agent.planning.eifp`): TCPA ranking and the cost of Eqs. (15)-(17) with side
  memory; the spline followed by the same tracking law, as the paper's eIFP (no MPC).
- `eifp-mpc`: eIFP whose spline is tracked by the OSQP LTV-MPC (`agent.planning.mpc`), with the
  neighbours' constant-velocity predictions as soft half-plane constraints. Not in the
  paper: with stale poses (`Observation.pose_age_s` > 0, i.e. a delayed link) each
  half-plane keeps `LATENCY_CLEARANCE_FACTOR` x age x |v_j - v_r| more clearance, the
  distance the pair can close before a command planned now takes effect; with fresh poses
  (an undisturbed lockstep run) nothing changes. Last, the braking guard
  (`agent.planning.safety`; not in the ``paper`` profile) caps the command's speed so the
  robot can still stop its own approach to every disc it faces.
- `orca`: ORCA through `pyrvo` (`agent.planning.orca`) plus a heading controller.

Every planner stops (status ARRIVED) once its centre is within half the goal tolerance of
the goal: half, so that the world, which judges arrival on ground truth at the full
tolerance, agrees even when the robot's own pose estimate is slightly off.

Which of this project's additions a planner runs follows from its name and the
configuration's profile (`agent.planning.mechanisms.mechanisms`), and eIFP-MPC's tracker
weights and solver settings from the profile too (`agent.planning.mpc_qp.profile_tuning`);
both are inputs of `make_planner` (`mechanisms`, `tuning`), which the profile only
defaults: an ablation or a test builds a planner with other ones. Planners keep only the memory
the method needs (side per threat and the threats resolved last cycle for eIFP, the MPC's
warm start); for the same sequence of inputs they return the same decisions. Stage timings are
wall time from an injected `timer` (default `time.perf_counter`); they are the only
non-deterministic output and never influence a decision.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Protocol

import numpy as np

from agent.core.config import PLANNER_NAMES, PlannerConfig, RobotLimits
from agent.core.types import (
    Observation,
    Others,
    PlanDebug,
    PlanResult,
    PlanStatus,
    Side,
    StageTimes,
)
from agent.planning.estimation import ESTIMATION_WINDOW_S
from agent.planning.goal_guard import WATCH_FROM_M, refuge_point
from agent.planning.guidance import RouteGuide
from agent.planning.liveness import Strategy, squeezed
from agent.planning.make_way import MakeWay
from agent.planning.mechanisms import Mechanisms
from agent.planning.mechanisms import mechanisms as mechanisms_of
from agent.planning.mpc_qp import MpcTuning, profile_tuning
from agent.planning.routing import StaticMap
from agent.planning.safety import (
    braking_speed_limit,
    heading_sweep_rad,
    unseen_speed_up_mps,
    unseen_turn_closing_mps,
)
from agent.planning.spline import START_RADIUS_M, build_reference
from agent.planning.threats import nearby_others
from agent.planning.turning import Turn, start_turn, turn_command
from agent.planning.unicycle import HEADING_GAIN, LOOKAHEAD_S, track_reference

if TYPE_CHECKING:  # imported on first use (osqp, scipy, pyrvo load slowly)
    from agent.planning.mpc import MpcTracker
    from agent.planning.orca import OrcaController

Timer = Callable[[], float]

ARRIVAL_FRACTION = 0.5
"""A planner stops when closer to its goal than this fraction of the goal tolerance."""

CLAMP_MIN_SPEED_MPS = 0.2
"""Below this speed the reference spline starts natural and the lines-and-arcs path has no
start arc: a robot that (nearly) stands can turn on the spot, and a reference forced along
its heading would send it the wrong way."""

CONTROL_PERIOD_S = 0.1
"""Default command period: the rate limits of the tracking laws use it."""

PASSAGE_GUARD_ROOM_M = 0.03
"""Against a passage's discs the MPC keeps at least the braking guard's gap plus this [m]:
a plan that runs along a wall exactly at the guard's gap is one the guard stops, since
any heading a little towards the wall closes a gap that is already spent (`rooms_lane_4`,
seed 1: a robot stood in the corridor 0.05 m from a corner disc for the rest of the run)."""
PASSAGE_SLACK_M = 0.0
"""Against a passage's discs the MPC asks at most the robot's present distance less this
[m] (`_predictions`): with nothing less, a robot at the guard's gap from a corner plans a
way that does not close on it (5 mm less let it plan along the corner, which the guard
then stopped: `lane_bend`, seed 2)."""

LATENCY_CLEARANCE_FACTOR = 2.0
"""eIFP-MPC's half-planes keep this many pose ages of relative motion on top of their
clearance (pose link plus the command link, assumed as slow); 0 with fresh poses."""

RECENT_SPEED_MAX_AGE_S = 0.05
"""The braking guard reads the others' recent speeds (`Others.recent_speed_mps`) only from
poses at most this old; from older ones it keeps the blind bound. The recent-speed bound
assumes every robot changes speed at most at accel_max, which holds while links are
healthy; on a slow or lossy link the world brakes a robot whose command outlived its hold
and resumes its next command at once (`world.sim.dynamics`), so its speed can jump. Poses
are fresh (age 0) in an undisturbed lockstep run and a few ms old in a healthy
distributed one.

The same age switches the guard's turn allowances on: from poses older than this the
robot's own heading is swept on through its stop, not only over the reaction time, and an
other turning towards the robot counts as closing as much faster than its estimate shows
as its observed turn rate makes it (`agent.planning.safety.unseen_turn_closing_mps`). With
fresh poses the estimates are current and both are left out: they only slow the robot in
crowds where nothing is hidden by delay."""


class Planner(Protocol):
    """A collision-avoidance planner for one robot."""

    name: str

    def plan(self, observation: Observation, now_s: float) -> PlanResult:
        """Decide the command for this cycle from what the robot observed at `now_s`."""
        ...

    def reset(self) -> None:
        """Forget all memory (side choices, warm starts)."""
        ...


def at_goal(x_m: float, y_m: float, goal_m: np.ndarray, goal_tolerance_m: float) -> bool:
    """Whether a robot at (x, y) is parked: within `ARRIVAL_FRACTION` of the tolerance."""
    gap = math.hypot(float(goal_m[0]) - x_m, float(goal_m[1]) - y_m)
    return gap <= ARRIVAL_FRACTION * goal_tolerance_m


def braking_speed_mps(observation: Observation, period_s: float) -> float:
    """The speed a stopping robot commands: its own, less the most it may brake in one
    command period (`RobotLimits.accel_max_mps2`), down to 0.

    A stop commanded at once (v = 0 from 0.9 m/s) is one no robot can make, and the others
    plan on that: the braking guard (`agent.planning.safety`) assumes every robot changes
    speed at most at accel_max, so a robot close behind one that arrives at its goal, or
    starts to yield, could not stop its own approach in time."""
    ego, limits = observation.ego, observation.limits
    return max(ego.v_mps - limits.accel_max_mps2 * period_s, 0.0)


def arrived_result(observation: Observation, period_s: float) -> PlanResult | None:
    """The stop result when the robot is at its goal, else None (ego state and goal only:
    every planner returns it before looking at the others); the robot brakes at its limit
    (`braking_speed_mps`)."""
    ego = observation.ego
    if not at_goal(ego.x_m, ego.y_m, observation.goal_m, observation.goal_tolerance_m):
        return None
    here = np.array([[ego.x_m, ego.y_m], observation.goal_m])
    return PlanResult(v_mps=braking_speed_mps(observation, period_s), omega_radps=0.0,
                      status=PlanStatus.ARRIVED, waypoints_m=here,
                      debug=PlanDebug(ego=np.array([ego.x_m, ego.y_m, ego.heading_rad]),
                                      reference_m=here))


def _inside_any(observation: Observation, config: PlannerConfig) -> bool:
    """Whether the robot is inside some other's inflated disc (Eq. 8): then it escapes
    instead of yielding."""
    others = observation.others
    if len(others) == 0:
        return False
    gap = np.hypot(*(others.position_m - (observation.ego.x_m, observation.ego.y_m)).T)
    return bool((gap <= others.radius_m + observation.radius_m
                 + config.safety.d_safety_m).any())


def _shrunk(others: Others, ids: frozenset[int], shrink_m: float) -> Others:
    """`others` with the discs of `ids` smaller by `shrink_m` (not below 0): a planner
    that inflates them by d_safety (Eq. 8) keeps d_safety - shrink_m from them."""
    if shrink_m <= 0.0 or len(others) == 0:
        return others
    bound = np.fromiter((int(i) in ids for i in others.ids), bool, len(others))
    if not bound.any():
        return others
    return others.with_radius(np.where(bound, np.maximum(others.radius_m - shrink_m, 0.0),
                                       others.radius_m))


def _yield_result(observation: Observation, elapsed_s: float, period_s: float) -> PlanResult:
    """A stop while yielding (`agent.planning.liveness`, rule 2), braking at the robot's
    limit (`braking_speed_mps`)."""
    ego = observation.ego
    here = np.array([[ego.x_m, ego.y_m], observation.goal_m])
    return PlanResult(v_mps=braking_speed_mps(observation, period_s), omega_radps=0.0,
                      status=PlanStatus.YIELD, waypoints_m=here,
                      times=StageTimes(total_ms=elapsed_s * 1e3),
                      debug=PlanDebug(ego=np.array([ego.x_m, ego.y_m, ego.heading_rad]),
                                      reference_m=here))


def _xy(x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    """(n, 2) [x, y] from two (n,) arrays: `numpy.column_stack`'s result, without its
    generic set-up (a few us a cycle)."""
    xy = np.empty((x_m.shape[0], 2))
    xy[:, 0] = x_m
    xy[:, 1] = y_m
    return xy


class ViaPointPlanner:
    """IFP, eIFP and eIFP-MPC: via-points -> cubic spline -> tracker.

    Args:
        name: `ifp`, `eifp` or `eifp-mpc`.
        config: planner parameters.
        control_period_s: the command period (rate limits of the tracking law).
        timer: wall clock for stage timings only.
        static_map: the scenario's static obstacles (`make_planner`).
        mechanisms: the mechanisms to run instead of `name`'s under `config`.
        tuning: eIFP-MPC's tracker weights and OSQP settings instead of those of
            `config`'s profile (`profile_tuning`); ifp and eifp run no tracker.
        estimation_window_s: the window the others' velocity estimates are fitted over
            (`agent.planning.estimation.NeighborTracker`); the braking guard allows for
            their lag, half of it [s].
    """

    def __init__(self, name: str, config: PlannerConfig, *,
                 control_period_s: float = CONTROL_PERIOD_S,
                 timer: Timer = time.perf_counter,
                 static_map: StaticMap | None = None,
                 mechanisms: Mechanisms | None = None,
                 tuning: MpcTuning | None = None,
                 estimation_window_s: float = ESTIMATION_WINDOW_S) -> None:
        from agent.planning.eifp import EifpSelector
        from agent.planning.ifp import plan_ifp

        if name not in ("ifp", "eifp", "eifp-mpc"):
            raise ValueError(f"not a via-point planner: {name!r}")
        self.name = name
        self.config = config
        self.control_period_s = control_period_s
        self._timer = timer
        self.mech = mechanisms if mechanisms is not None else mechanisms_of(name, config)
        self.tuning = tuning if tuning is not None else profile_tuning(config)
        self.estimation_window_s = estimation_window_s
        self._selector = EifpSelector(config, self.mech) if name != "ifp" else None
        self._plan_ifp = plan_ifp
        self._trackers: dict[RobotLimits, MpcTracker] = {}
        self.guide: RouteGuide | None = None
        self._turn: Turn | None = None  # a committed turn on the spot (`turning`)
        self.turns = 0
        self._static = static_map
        self._parked = False  # reached its goal once: `goal_guard` watches it from then
        self.make_way = MakeWay()  # press clocks once parked (`Mechanisms.make_way`)
        if self.mech.routing or self.mech.liveness is not None:
            self.guide = RouteGuide(
                static_map if static_map is not None else StaticMap.empty(),
                config.safety.d_safety_m, routes=self.mech.routing,
                liveness=self.mech.liveness, passages=self.mech.passages,
                lanes=self.mech.lanes)
        self._passage: tuple[frozenset[int], float] = (frozenset(), math.inf)

    def reset(self) -> None:
        """Forget side memory, MPC warm starts, the route and the liveness state."""
        if self._selector is not None:
            self._selector.reset()
        if self.guide is not None:
            self.guide.reset()
        for tracker in self._trackers.values():
            tracker.reset()
        self._turn = None
        self._parked = False
        self.make_way.reset()

    def prepare_tracker(self, limits: RobotLimits) -> None:
        """Set up eIFP-MPC's tracker for these limits now rather than on the first cycle
        that needs it (the QP's matrices, scaling and OSQP set-up: about 2 ms, a cost that
        otherwise lands on every robot's first plan at once when a fleet starts). The
        tracker is the one that cycle would have built, so nothing planned changes."""
        if self.name == "eifp-mpc":
            self._tracker(limits)

    def _tracker(self, limits: RobotLimits) -> MpcTracker:
        from agent.planning.mpc import MpcTracker

        tracker = self._trackers.get(limits)
        if tracker is None:
            tracker = MpcTracker(limits, self.config.mpc, self.tuning)
            self._trackers[limits] = tracker
        return tracker

    def _mpc(self, observation: Observation) -> MpcTracker:
        return self._tracker(observation.limits)

    def plan(self, observation: Observation, now_s: float) -> PlanResult:
        """One cycle: threats and via-points, spline, then MPC or the tracking law."""
        clock = self._timer
        t0 = clock()
        cfg = self.config
        done = arrived_result(observation, self.control_period_s)
        self._parked |= done is not None
        refuge = self._refuge(observation, now_s, done is not None)
        if refuge is not None:  # step aside (`goal_guard`, `make_way`)
            observation = replace(observation, goal_m=refuge, goal_distance_m=None)
            done = arrived_result(observation, self.control_period_s)
            if done is not None:
                done = replace(done, status=PlanStatus.STAND_CLEAR)
        if done is not None:
            return replace(done, times=StageTimes(total_ms=(clock() - t0) * 1e3))
        ego = observation.ego
        limits = observation.limits
        # Bound the work: the others within the sensing radius, at most max_neighbors,
        # selected once per cycle for the via-points and the MPC alike.
        everyone = observation.others
        near = nearby_others(np.array([ego.x_m, ego.y_m]), everyone,
                             cfg.threats.sensing_radius_m, cfg.threats.max_neighbors)
        if near is not observation.others:
            observation = observation.with_others(near)
        sensed = observation  # true radii, for the tracker and the braking guard
        guided = self._guide(observation, now_s, everyone)
        if guided is None:
            return _yield_result(observation, clock() - t0, self.control_period_s)
        observation, tail, stuck = guided
        if self._selector is None:
            via = self._plan_ifp(observation, cfg, clock)
        else:
            via = self._selector.select(observation, clock)
        if tail is not None:
            # the route goes on past the intermediate goal: so does the reference
            via = replace(via, waypoints_m=np.concatenate((via.waypoints_m, tail)))
        t1 = clock()
        mpc_cfg, mech = cfg.mpc, self.mech
        moving = ego.v_mps >= CLAMP_MIN_SPEED_MPS
        ref = build_reference(
            via.waypoints_m, ego.heading_rad, limits.v_max_mps, limits.accel_max_mps2,
            mpc_cfg.dt_s, mpc_cfg.horizon_steps, v_start_mps=ego.v_mps,
            clamp_heading=mech.clamp_heading and moving,
            lines_arcs=mech.lines_arcs,
            corner_radius_m=cfg.reference.corner_radius_m,
            start_radius_m=START_RADIUS_M if moving else 0.0,
        )
        t2 = clock()
        last = np.array([ego.v_mps, ego.omega_radps])
        iterations = 0
        status = via.status
        predicted = None
        if self.name == "eifp-mpc":
            # the tracker keeps its own margin from every disc's true radius, squeeze or not
            preds, clearance = self._predictions(sensed, ref.t_s)
            res = self._mpc(observation).solve(
                np.array([ego.x_m, ego.y_m, ego.heading_rad]), last, ref, preds, clearance
            )
            v, omega, iterations = res.v_mps, res.omega_radps, res.iterations
            predicted = res
            if res.status != PlanStatus.OK:
                status = res.status
            if mech.turn_when_stuck:
                v, omega = self._turning(sensed, ref.x_m, ref.y_m, v, omega, stuck, now_s)
            if mech.braking_guard and len(sensed.others):
                v, omega = self._braking_guard(sensed, v, omega)
        else:
            v, omega = track_reference(
                ego.x_m, ego.y_m, ego.heading_rad, ref.x_m, ref.y_m,
                float(ref.v_mps[min(1, ref.n_steps)]),
                max(LOOKAHEAD_S * limits.v_max_mps, 0.3), limits, HEADING_GAIN,
                last_command=last, dt_s=self.control_period_s,
            )
        if refuge is not None and status == PlanStatus.OK:
            status = PlanStatus.STAND_CLEAR
        t3 = clock()
        times = StageTimes(
            threats_ms=via.threats_s * 1e3,
            viapoints_ms=(t1 - t0 - via.threats_s) * 1e3,
            spline_ms=(t2 - t1) * 1e3,
            control_ms=(t3 - t2) * 1e3,
            total_ms=(t3 - t0) * 1e3,
        )
        # For viewing only, after the timings: arrays the cycle computed anyway (the MPC's
        # prediction is one vectorised rollout of its planned inputs, about 10 us).
        debug = PlanDebug.trusted(
            ego=np.array([ego.x_m, ego.y_m, ego.heading_rad]),
            threat_ids=tuple(t.other_id for t in via.threats),
            via_points_m=via.waypoints_m[1:-1],
            reference_m=_xy(ref.x_m, ref.y_m),
            predicted_m=(predicted.predicted_states[:, :2] if predicted is not None
                         else np.zeros((0, 2))),
        )
        return PlanResult(
            v_mps=float(v), omega_radps=float(omega), status=status,
            waypoints_m=via.waypoints_m, via_point_m=via.via_point_m, side=via.side,
            resolved_id=via.resolved_id, threats=via.threats, times=times,
            solver_iterations=int(iterations), debug=debug,
        )

    def _refuge(self, observation: Observation, now_s: float, at_goal: bool
                ) -> np.ndarray | None:
        """Where a robot that has arrived, or is about to, stands instead of its goal: clear
        of a moving obstacle (`Mechanisms.goal_guard`, `agent.planning.goal_guard`), else
        aside for a robot pressed against it (`Mechanisms.make_way`,
        `agent.planning.make_way`); None: at its goal."""
        ego, goal, cfg = observation.ego, observation.goal_m, self.config
        # make_way sees every parked cycle, also with nobody in view (a parked robot is
        # given the others only while a robot is close): its arrival is the first one
        if self.mech.goal_guard and len(observation.others) and (self._parked or math.hypot(
                ego.x_m - goal[0], ego.y_m - goal[1]) <= WATCH_FROM_M):
            refuge = refuge_point(goal, observation.radius_m, observation.others,
                                  cfg.safety.d_safety_m, cfg.threats.t_max_s, self._static)
            if refuge is not None:
                return refuge
        if not (self.mech.make_way and self._parked):
            return None
        return self.make_way.refuge(now_s, goal, observation.radius_m,
                                    np.array([ego.x_m, ego.y_m]), at_goal,
                                    observation.others, cfg.safety.d_safety_m, self._static)

    def _guide(self, observation: Observation, now_s: float, everyone: Others
               ) -> tuple[Observation, np.ndarray | None, bool] | None:
        """Routes and liveness (`agent.planning.guidance`): None when the robot yields this
        cycle, else the observation eIFP plans on (heading for the route's intermediate
        goal; still discs shrunk while squeezing, `liveness.squeezed`), the route's
        waypoints after that goal (None: the goal is the final one), and whether the
        progress monitor found the robot stuck this cycle. Near a narrow passage its
        discs are shrunk to the passage's margin (`agent.planning.passages`); the MPC
        keeps that margin from them too (`_predictions`)."""
        self._passage = (frozenset(), math.inf)
        if self.guide is None:
            return observation, None, False
        cfg = self.config
        guided = self.guide.guide(observation, now_s, everyone)
        if guided.strategy is Strategy.YIELD and (guided.hold
                                                   or not _inside_any(observation, cfg)):
            return None
        tail = None
        if guided.tail_m.shape[0]:
            observation = observation.with_goal(guided.goal_m, guided.left_m)
            tail = guided.tail_m
        elif guided.hold:  # to a waiting spot before a one-lane passage
            observation = observation.with_goal(guided.goal_m, guided.left_m)
        live = self.mech.liveness
        if guided.squeeze and live is not None:
            observation = observation.with_others(squeezed(
                observation.others, cfg.safety.d_safety_m, live.squeeze_margin_m,
                live.slow_mps))
        if guided.passage_ids:
            self._passage = (guided.passage_ids, guided.passage_margin_m)
            observation = observation.with_others(_shrunk(
                observation.others, guided.passage_ids,
                cfg.safety.d_safety_m - guided.passage_margin_m))
        return observation, tail, guided.stuck

    def _turning(self, observation: Observation, ref_x_m: np.ndarray, ref_y_m: np.ndarray,
                 v_mps: float, omega_radps: float, stuck: bool, now_s: float
                 ) -> tuple[float, float]:
        """The tracker's (v, omega), or a committed turn on the spot
        (`agent.planning.turning`): one starts when the robot is found stuck this cycle."""
        ego = observation.ego
        if stuck and self._turn is None:
            self._turn = start_turn(ego.x_m, ego.y_m, ego.heading_rad, ego.v_mps,
                                    ego.omega_radps, v_mps, ref_x_m, ref_y_m, now_s)
            if self._turn is not None:
                self.turns += 1
        if self._turn is None:
            return v_mps, omega_radps
        command = turn_command(self._turn, ego.heading_rad, ego.omega_radps,
                               observation.limits, self.control_period_s, now_s)
        if command is None:
            self._turn = None
            return v_mps, omega_radps
        return command

    def _braking_guard(self, observation: Observation, v_mps: float,
                       omega_radps: float) -> tuple[float, float]:
        """(v, omega): `v_mps` capped by `agent.planning.safety.braking_speed_limit`, braking
        no harder than the rate limit allows, and, where even the hardest braking cannot
        meet the cap under the commanded turn, the reachable turn rate that allows the
        highest speed (`_safest_turn`).

        The robot brakes along the arc it was commanded (the world holds omega while it
        brakes, `world.sim.dynamics`), so the headings checked are those swept at omega
        from now until the robot stands: a robot turning while it brakes faces discs it
        does not face now (`pillar_circle` 40, evaluation seed 6: two robots escaping
        each other at 1 m/s turned into each other while braking).

        Two passes with one result: first with every other's unseen speed-up at its bound
        `accel_max x lag` (a scalar: no per-disc trigonometry); the speed limit falls as the
        speed-up grows, so when that pass lets `v_mps` through, the exact one would too. Only
        a command the bound limits pays for `unseen_speed_up_mps`, which reads the others'
        recent speeds from fresh poses only (`RECENT_SPEED_MAX_AGE_S`). From older poses
        the others' turns count too (`unseen_turn_closing_mps`, the larger of the two per
        other); the first pass's bound is then at least the largest turn term."""
        ego, limits, others = observation.ego, observation.limits, observation.others
        # `Others` fills its optional columns on construction (NaN where unknown)
        assert others.heading_rad is not None and others.recent_turn_rate_radps is not None
        assert others.recent_interval_s is not None
        reaction_s = observation.pose_age_s + self.control_period_s
        # how much an other robot's velocity estimate may trail its velocity now
        lag_s = 0.5 * self.estimation_window_s + observation.pose_age_s
        fresh = observation.pose_age_s <= RECENT_SPEED_MAX_AGE_S
        # the headings the robot sweeps before it stands
        turning_s = reaction_s + max(v_mps, 0.0) / limits.accel_max_mps2

        def limit(unseen_dv: np.ndarray | float, omega: float = omega_radps) -> float:
            return braking_speed_limit(
                (ego.x_m, ego.y_m), ego.heading_rad, observation.radius_m,
                others.position_m, others.velocity_mps, others.radius_m,
                reaction_s=reaction_s, decel_mps2=limits.accel_max_mps2,
                margin_m=self.config.safety.braking_margin_m,
                sweep_rad=heading_sweep_rad(omega, turning_s), up_to_mps=v_mps,
                unseen_dv_mps=unseen_dv,
            )

        turning = None
        if not fresh:
            turning = unseen_turn_closing_mps(
                (ego.x_m, ego.y_m), others.position_m, others.velocity_mps, others.heading_rad,
                others.recent_turn_rate_radps, others.is_robot,
                turn_rate_max_radps=limits.omega_max_radps, age_s=observation.pose_age_s,
                reaction_s=reaction_s)
        bound = limits.accel_max_mps2 * lag_s
        if turning is not None and len(turning):
            bound = max(bound, float(turning.max()))
        if v_mps <= limit(bound):
            return v_mps, omega_radps
        unseen = unseen_speed_up_mps(
            (ego.x_m, ego.y_m), others.position_m, others.heading_rad, others.is_robot,
            accel_mps2=limits.accel_max_mps2, turn_rate_radps=limits.omega_max_radps,
            lag_s=lag_s, others_speed_mps=np.hypot(*others.velocity_mps.T),
            v_max_mps=limits.v_max_mps,
            recent_speed_mps=others.recent_speed_mps if fresh else None,
            recent_lag_s=0.5 * others.recent_interval_s + observation.pose_age_s)
        if turning is not None:
            unseen = np.maximum(unseen, turning)
        v_safe = limit(unseen)
        if v_mps <= v_safe:
            return v_mps, omega_radps
        hardest = max(ego.v_mps - limits.accel_max_mps2 * self.control_period_s,
                      limits.v_min_mps)
        if v_safe < hardest:
            omega_radps, v_safe = self._safest_turn(observation, omega_radps, v_safe,
                                                   lambda w: limit(unseen, w))
        return min(v_mps, max(v_safe, hardest)), omega_radps

    def _safest_turn(self, observation: Observation, omega_radps: float, v_safe_mps: float,
                     cap: Callable[[float], float]) -> tuple[float, float]:
        """(omega, its speed cap): of the commanded turn rate, the last one (whose arc the
        last cycle's guard covered) and the two ends of the turn rates reachable in one
        period, the one whose braking arc allows the highest speed; the commanded one on
        ties."""
        ego, limits = observation.ego, observation.limits
        step = limits.alpha_max_radps2 * self.control_period_s
        lo = max(-limits.omega_max_radps, ego.omega_radps - step)
        hi = min(limits.omega_max_radps, ego.omega_radps + step)
        best = (v_safe_mps, omega_radps)
        for omega in (ego.omega_radps, lo, hi):
            if lo <= omega <= hi:
                best = max(best, (cap(omega), omega), key=lambda c: c[0])
        return best[1], best[0]

    def _predictions(self, observation: Observation,
                     t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Constant-velocity predictions (K, N+1, 2) of the sensed others and clearances (K,)."""
        cfg = self.config
        near = observation.others
        preds = near.position_m[:, None, :] + near.velocity_mps[:, None, :] * t_s[None, :, None]
        clearance = observation.radius_m + near.radius_m + cfg.mpc.clearance_margin_m
        ids, margin = self._passage
        if ids and len(near):
            # a narrow passage's walls: the margin it leaves, at least the guard's gap
            # and some room, and never more than the robot has now (from a corner it
            # brushed, the QP then plans away from it instead of finding its own start
            # infeasible)
            bound = np.fromiter((int(i) in ids for i in near.ids), bool, len(near))
            ego = observation.ego
            now = np.hypot(near.position_m[:, 0] - ego.x_m, near.position_m[:, 1] - ego.y_m)
            keep = np.minimum(observation.radius_m + near.radius_m
                              + max(min(margin, cfg.mpc.clearance_margin_m),
                                    cfg.safety.braking_margin_m + PASSAGE_GUARD_ROOM_M),
                              now - PASSAGE_SLACK_M)
            clearance = np.where(bound, keep, clearance)
        if observation.pose_age_s > 0.0 and len(near):
            # Loop delay: the poses are pose_age_s old and the command reaches the wheels
            # about as late again (links are assumed symmetric), so the pair can close by
            # up to 2 * age * |v_j - v_r| before our command takes effect.
            ego = observation.ego
            v_r = ego.v_mps * np.array([np.cos(ego.heading_rad), np.sin(ego.heading_rad)])
            rel = np.hypot(*(near.velocity_mps - v_r).T)
            clearance = clearance + LATENCY_CLEARANCE_FACTOR * observation.pose_age_s * rel
        return preds, clearance


class OrcaPlanner:
    """ORCA (RVO2 via `pyrvo`) with a heading controller; the same interface as the others.

    Args:
        config: planner parameters.
        control_period_s: the command period (ORCA's time step and the rate limits).
        timer: wall clock for stage timings only.
    """

    name = "orca"

    def __init__(self, config: PlannerConfig, *, control_period_s: float = CONTROL_PERIOD_S,
                 timer: Timer = time.perf_counter) -> None:
        self.config = config
        self.control_period_s = control_period_s
        self._timer = timer
        self._controllers: dict[RobotLimits, OrcaController] = {}

    def reset(self) -> None:
        """ORCA keeps no memory between cycles."""

    def plan(self, observation: Observation, now_s: float) -> PlanResult:
        """One ORCA cycle."""
        from agent.planning.orca import OrcaController

        t0 = self._timer()
        done = arrived_result(observation, self.control_period_s)
        if done is not None:
            return replace(done, times=StageTimes(total_ms=(self._timer() - t0) * 1e3))
        controller = self._controllers.get(observation.limits)
        if controller is None:
            controller = OrcaController(observation.limits, self.config, self.control_period_s)
            self._controllers[observation.limits] = controller
        ego = observation.ego
        position = np.array([ego.x_m, ego.y_m])
        cmd = controller.command(
            position, ego.heading_rad, ego.velocity_mps, observation.goal_m,
            observation.radius_m, observation.others,
            last_command=np.array([ego.v_mps, ego.omega_radps]),
        )
        elapsed_ms = (self._timer() - t0) * 1e3
        waypoints = np.array([position, observation.goal_m])
        return PlanResult(
            v_mps=float(cmd.v_mps), omega_radps=float(cmd.omega_radps), status=PlanStatus.OK,
            waypoints_m=waypoints, side=Side.NONE,
            times=StageTimes(control_ms=elapsed_ms, total_ms=elapsed_ms),
            debug=PlanDebug(ego=np.array([ego.x_m, ego.y_m, ego.heading_rad]),
                            reference_m=waypoints),
        )


def make_planner(name: str, config: PlannerConfig, *,
                 control_period_s: float = CONTROL_PERIOD_S,
                 timer: Timer = time.perf_counter,
                 static_map: StaticMap | None = None,
                 mechanisms: Mechanisms | None = None,
                 tuning: MpcTuning | None = None,
                 estimation_window_s: float = ESTIMATION_WINDOW_S) -> Planner:
    """The planner called `name` (one of `PLANNER_NAMES`).

    Args:
        static_map: the scenario's static obstacles, known in advance; eIFP-MPC routes
            round them (`agent.planning.routing`). ORCA, IFP and eIFP ignore it.
        mechanisms: the via-point planners' mechanisms, instead of those `name` and
            `config` give (`agent.planning.mechanisms.mechanisms`); ORCA ignores it.
        tuning: eIFP-MPC's tracker weights and OSQP settings, instead of those of
            `config`'s profile (`agent.planning.mpc_qp.profile_tuning`); the other
            planners ignore it.
        estimation_window_s: the window of the others' velocity estimates, whose lag
            eIFP-MPC's braking guard allows for (`ViaPointPlanner`) [s].
    """
    if name == "orca":
        return OrcaPlanner(config, control_period_s=control_period_s, timer=timer)
    if name in PLANNER_NAMES:
        return ViaPointPlanner(name, config, control_period_s=control_period_s, timer=timer,
                               static_map=static_map, mechanisms=mechanisms, tuning=tuning,
                               estimation_window_s=estimation_window_s)
    raise ValueError(f"unknown planner {name!r}; expected one of {', '.join(PLANNER_NAMES)}")
