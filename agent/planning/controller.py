"""One robot's sense -> estimate -> plan cycle, shared by the robot process and lockstep runs.

The controller holds what a robot knows: the newest pose snapshot it accepted, the history
of the others' poses (`NeighborTracker`), its planner's memory and the command it sent
last (its odometry for its own speed). It has no transport and no clock: the robot
process and the lockstep runner feed it snapshots and the current sim time.

Latency compensation (on by default): a snapshot stamped `stamp_s` is `age = now_s -
stamp_s` old when the robot plans at `now_s`. Before planning, the robot forward-predicts
its own pose with the command it has been applying (the unicycle arc of Eq. 1) and the
others' positions with their estimated velocities, both over `age` (capped at
`MAX_COMPENSATED_AGE_S`). With ``compensate_latency=False`` the robot plans on the poses as
they were when stamped. The clock behind `now_s` is the world's sim time: in lockstep the
true sim time, in the robot process a sim clock kept in step with the world (see
`agent.node`), so the age includes any injected delay.
"""

from __future__ import annotations

import numpy as np

from agent.core.config import PlannerConfig
from agent.core.scenario import RobotSpec
from agent.core.types import EgoState, Observation, Others, PlanResult, PlanStatus, PoseSnapshot
from agent.planning.estimation import ESTIMATION_MARGIN_M as ESTIMATION_MARGIN_M  # re-exported
from agent.planning.estimation import ESTIMATION_WINDOW_S, NeighborTracker
from agent.planning.make_way import LINGER_VIEW_M, PRESS_VIEW_M, VIEW_SLACK_M
from agent.planning.mechanisms import Mechanisms
from agent.planning.mpc_qp import MpcTuning
from agent.planning.planners import CONTROL_PERIOD_S, at_goal, make_planner
from agent.planning.routing import StaticMap

CLOSE_SLACK_M = VIEW_SLACK_M
"""How much farther than the press or linger gap a robot may be for a parked robot to
estimate the others (`Controller._robot_close`; `make_way.VIEW_SLACK_M`): the snapshot's raw
positions, not yet moved on by the pose age, so a robot closing in is seen as pressing a
cycle early rather than late [m]."""

MAX_COMPENSATED_AGE_S = 1.0
"""Poses older than this are not extrapolated further (the prediction would be fiction)."""
COMMAND_HOLD_PERIODS = 1.5
"""Each command tells the world to apply it for at most this many control periods
(`eifp_wire.messages.CommandMsg.hold_s`): one period plus half a period of jitter between two
commands; a command that is not followed in time (lost or late on the link) then gives way
to braking instead of acting until the world's time-out."""


class RobotController:
    """Sense, estimate and plan for one robot.

    Args:
        spec: the robot (id, goal, radius, limits, planner name).
        config: planner settings.
        goal_tolerance_m: the robot stops when this close to its goal.
        compensate_latency: forward-predict by the snapshot's age before planning.
        control_period_s: the robot's planning period; the planner's rate limits (and
            ORCA's time step) use it.
        static_map: the scenario's static obstacles, known in advance
            (`agent.planning.routing`); None: no map.
        mechanisms: the via-point planner's mechanisms instead of those the planner's name
            and `config` give (`agent.planning.planners.make_planner`).
        tuning: eIFP-MPC's tracker weights and OSQP settings instead of those of `config`'s
            profile (`agent.planning.planners.make_planner`).
        command_hold_periods: how many control periods the world may apply one of this
            robot's commands before it brakes (`COMMAND_HOLD_PERIODS`).

    Attributes:
        command_hold_s: `command_hold_periods` control periods; sent with each command.
    """

    def __init__(self, spec: RobotSpec, config: PlannerConfig, goal_tolerance_m: float,
                 *, compensate_latency: bool = True,
                 control_period_s: float = CONTROL_PERIOD_S,
                 static_map: StaticMap | None = None,
                 mechanisms: Mechanisms | None = None,
                 tuning: MpcTuning | None = None,
                 command_hold_periods: float = COMMAND_HOLD_PERIODS) -> None:
        if not (np.isfinite(control_period_s) and control_period_s > 0.0):
            raise ValueError(f"control_period_s must be positive, got {control_period_s!r}")
        if not (np.isfinite(command_hold_periods) and command_hold_periods > 0.0):
            raise ValueError(f"command_hold_periods must be positive, got {command_hold_periods!r}")
        self.spec = spec
        self.config = config
        self.goal_tolerance_m = float(goal_tolerance_m)
        self.compensate_latency = compensate_latency
        self.control_period_s = float(control_period_s)
        self.command_hold_s = float(command_hold_periods) * self.control_period_s
        # one window: the others' estimates are fitted over it, and the braking guard
        # allows for their lag
        self.planner = make_planner(spec.planner, config, control_period_s=self.control_period_s,
                                    static_map=static_map, mechanisms=mechanisms,
                                    tuning=tuning, estimation_window_s=ESTIMATION_WINDOW_S)
        guide = getattr(self.planner, "guide", None)
        if guide is not None:  # route graphs built before the run, not on its first cycle
            guide.prepare(spec.radius_m)
        prepare_tracker = getattr(self.planner, "prepare_tracker", None)
        if prepare_tracker is not None:  # likewise the MPC's QP
            prepare_tracker(spec.limits)
        self.tracker = NeighborTracker(spec.id, ESTIMATION_WINDOW_S)
        self.snapshot: PoseSnapshot | None = None
        self.command = (0.0, 0.0)
        self.rejected_stale = 0
        self.last_observation: Observation | None = None
        self._row = -1
        self._row_ids: np.ndarray | None = None  # the read-only ids `_row` was found in
        self._goal = np.asarray(spec.goal, dtype=float)
        # obstacle ids that do not move (the scenario's map): any other obstacle id in a
        # snapshot is a moving one, which a parked robot keeps watching (`goal_guard`)
        ids = static_map.ids if static_map is not None else None
        self._static_ids = frozenset(ids.tolist() if ids is not None else ())
        self.movers_in_view = False
        mech = getattr(self.planner, "mech", None)
        self._watch_robots = bool(getattr(mech, "make_way", False))
        # the linger rule needs static discs (`make_way.closes_passage`): without any, a
        # parked robot looks only as far as the press rules see
        self._view_m = (max(PRESS_VIEW_M, LINGER_VIEW_M)
                        if static_map is not None and len(static_map) else PRESS_VIEW_M)

    def observe(self, snapshot: PoseSnapshot) -> bool:
        """Accept a snapshot if it is newer than the last one and shows this robot.

        Returns:
            False (and counts it) for a stale, duplicated or out-of-order snapshot, or one
            in which this robot does not appear.
        """
        last = self.snapshot
        if last is not None and (snapshot.tick <= last.tick or snapshot.stamp_s < last.stamp_s):
            self.rejected_stale += 1
            return False
        ids = snapshot.ids
        if ids is self._row_ids:  # the same read-only ids as last time (`PoseDecoder`)
            row = self._row
        else:
            rows = np.flatnonzero(ids == self.spec.id)
            if rows.size == 0:
                self.rejected_stale += 1
                return False
            row = int(rows[0])
            self._row_ids = None if ids.flags.writeable else ids
            # a set test: about 4 us with 25 obstacles in view, np.isin about 19 us
            self.movers_in_view = not self._static_ids.issuperset(ids[ids < 0].tolist())
        self.tracker.update(snapshot)
        self.snapshot = snapshot
        self._row = row  # this robot's row in `snapshot`
        return True

    def observation(self, now_s: float, *, with_others: bool | None = True) -> Observation:
        """What the robot knows at `now_s`, forward-predicted by the snapshot's age.

        Args:
            now_s: sim time of planning.
            with_others: False leaves the others out (empty): no estimates are made; None
                leaves them out only when the robot is parked at its goal
                (`agent.planning.planners.at_goal`), no moving obstacle is in view
                (a parked robot watches those, `agent.planning.goal_guard`) and, with
                `Mechanisms.make_way`, no robot is near enough to press on it
                (`_robot_close`), as `plan` does.
        """
        snap = self.snapshot
        if snap is None:
            raise RuntimeError("no snapshot observed yet")
        row = self._row
        x, y, heading = snap.pose[row].tolist()
        v, omega = self.command
        age = min(max(float(now_s - snap.stamp_s), 0.0), MAX_COMPENSATED_AGE_S)
        if self.compensate_latency and age > 0.0:
            x, y, heading = _predict_unicycle(x, y, heading, v, omega, age)
        if with_others is None:
            with_others = (self.movers_in_view
                           or not at_goal(x, y, self._goal, self.goal_tolerance_m)
                           or (self._watch_robots and self._robot_close(snap, row)))
        return Observation(
            robot_id=self.spec.id,
            ego=EgoState(x_m=x, y_m=y, heading_rad=heading, v_mps=v, omega_radps=omega),
            goal_m=self._goal,
            radius_m=self.spec.radius_m,
            limits=self.spec.limits,
            goal_tolerance_m=self.goal_tolerance_m,
            others=self._others(snap.pose[row, :2], age) if with_others else Others.empty(),
            pose_age_s=age,
        )

    def _robot_close(self, snap: PoseSnapshot, row: int) -> bool:
        """Whether another robot is within `make_way`'s press or linger gap (the larger,
        plus `CLOSE_SLACK_M`; the press gap alone on a map with no static discs, where no
        passage is closed and nobody lingers) of this one, from the snapshot's raw
        positions: a parked robot with `make_way` estimates the others only then (a few
        microseconds against the estimates' 0.25 ms)."""
        ids, pose = snap.ids, snap.pose
        gap = (np.hypot(pose[:, 0] - pose[row, 0], pose[:, 1] - pose[row, 1])
               - snap.radius_m - snap.radius_m[row])
        close = (ids >= 0) & (gap <= self._view_m)
        close[row] = False
        return bool(close.any())

    def _others(self, here_m: np.ndarray, age_s: float) -> Others:
        """The others' estimates near `here_m`, moved on by `age_s` if compensating."""
        others = self.tracker.others(
            near_m=here_m, within_m=self.config.threats.sensing_radius_m + ESTIMATION_MARGIN_M)
        if self.compensate_latency and age_s > 0.0:
            others = _advance(others, age_s)
        return others

    def plan(self, now_s: float) -> PlanResult:
        """Plan on the newest snapshot; without any snapshot, brake (status STALE).

        A robot at its goal gets the planners' ARRIVED stop, which they decide on the ego
        state alone (`agent.planning.planners.at_goal`) before looking at anyone: the others
        are then not estimated (its `last_observation` has none), which makes a parked
        robot's cycle about 0.25 ms cheaper with 128 robots in the poses; unless a moving
        obstacle is in view, which a parked robot watches (`agent.planning.goal_guard`), or
        a robot is close enough to press on it (`agent.planning.make_way`).
        """
        if self.snapshot is None:
            return self.brake()
        observation = self.observation(now_s, with_others=None)
        self.last_observation = observation
        result = self.planner.plan(observation, now_s)
        self.command = (result.v_mps, result.omega_radps)
        return result

    def brake(self) -> PlanResult:
        """Stop command used when the robot cannot plan (no fresh poses)."""
        self.command = (0.0, 0.0)
        here = np.zeros((2, 2))
        if self.snapshot is not None:
            here[:] = self.snapshot.pose[self._row, :2]
        return PlanResult(v_mps=0.0, omega_radps=0.0, status=PlanStatus.STALE, waypoints_m=here)


def _predict_unicycle(x: float, y: float, heading: float, v: float, omega: float,
                      age_s: float) -> tuple[float, float, float]:
    """Constant-(v, omega) arc over age_s."""
    dtheta = omega * age_s
    if abs(dtheta) < 1e-9:
        return x + v * age_s * np.cos(heading), y + v * age_s * np.sin(heading), heading
    r = v / omega
    new_heading = heading + dtheta
    return (
        x + r * (np.sin(new_heading) - np.sin(heading)),
        y - r * (np.cos(new_heading) - np.cos(heading)),
        float(np.angle(np.exp(1j * new_heading))),
    )


def _advance(others: Others, age_s: float) -> Others:
    """The others moved on for age_s at their estimated velocities."""
    if len(others) == 0:
        return others
    shift = others.velocity_mps * age_s
    return Others.trusted(
        ids=others.ids,
        position_m=others.position_m + shift,
        velocity_mps=others.velocity_mps,
        radius_m=others.radius_m,
        linearity=others.linearity,
        track_start_m=others.track_start_m,
        is_robot=others.is_robot,
        heading_rad=others.heading_rad,  # a heading's drift over the age is not predicted
        recent_speed_mps=others.recent_speed_mps,
        recent_interval_s=others.recent_interval_s,
        recent_turn_rate_radps=others.recent_turn_rate_radps,
    )
