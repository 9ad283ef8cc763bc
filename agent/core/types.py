"""Typed inputs and outputs of the pure planning core.

An `Observation` is everything one robot knows when it plans: its own state, its goal and
limits, and what it *sensed* of the others (positions and radii, plus velocities and
path linearity *estimated* from their observed history; never their plans or goals).
A `PlanResult` is what every planner returns. Arrays are row-major; shapes are in the
docstrings. Construction validates shapes and finiteness and raises `ValueError`.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np

from agent.core.config import RobotLimits

_T = TypeVar("_T")


class Side(enum.IntEnum):
    """Side on which the robot passes the threat it resolves.

    LEFT is the tangent at alpha + theta (Eq. 11): the robot turns counter-clockwise and
    leaves the threat on its right. RIGHT is alpha - theta (Eq. 10).
    """

    RIGHT = -1
    NONE = 0
    LEFT = 1


class PlanStatus(enum.StrEnum):
    """Outcome of one planning cycle; sent on the wire as its string value."""

    OK = "ok"  # planned, and (eIFP-MPC) the QP solved
    ARRIVED = "arrived"  # within goal tolerance: commanding a stop
    ESCAPE = "escape"  # inside an inflated disc: steering straight out of it
    NO_FEASIBLE = "no_feasible"  # threats but no feasible via-point: slowing on the direct path
    SOLVER_INACCURATE = "solver_inaccurate"  # OSQP stopped short (cap, first command settled)
    SOLVER_FAILED = "solver_failed"  # OSQP failed: safe braking command
    STALE = "stale"  # set by the robot node when it brakes for lack of fresh poses
    YIELD = "yield"  # stuck: standing so a robot with a lower id can pass (liveness rule 2)
    STAND_CLEAR = "stand_clear"  # arrived, standing aside (goal_guard, make_way)


def _as_array(name: str, value: object, shape: tuple[int | None, ...]) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    # A finite sum proves every entry finite (the exact check only when it is not).
    if not math.isfinite(float(arr.sum())) and not np.isfinite(arr).all():
        raise ValueError(f"{name}: non-finite value")
    return arr


def _shallow_copy(obj: _T) -> _T:
    """`copy.copy` of a plain dataclass instance (fields in its `__dict__`), without the
    generic copy protocol: the planners' per-cycle `with_*` copies."""
    new = object.__new__(type(obj))
    new.__dict__.update(obj.__dict__)
    return new


def _check_finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name}: non-finite value {value!r}")
    return value


@dataclass(frozen=True)
class EgoState:
    """The robot's own state.

    Args:
        x_m, y_m: position.
        heading_rad: theta of Eq. (1).
        v_mps: current forward speed (the last commanded speed: odometry).
        omega_radps: current turn rate (the last commanded turn rate).
    """

    x_m: float
    y_m: float
    heading_rad: float
    v_mps: float = 0.0
    omega_radps: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "heading_rad", "v_mps", "omega_radps"):
            object.__setattr__(self, name, _check_finite(name, getattr(self, name)))

    @property
    def position_m(self) -> np.ndarray:
        """Position as a (2,) array."""
        return np.array([self.x_m, self.y_m])

    @property
    def velocity_mps(self) -> np.ndarray:
        """Velocity v_r as a (2,) array (Eq. 3)."""
        return self.v_mps * np.array([np.cos(self.heading_rad), np.sin(self.heading_rad)])


@dataclass(frozen=True)
class Others:
    """What the robot sensed of the K other discs (robots and obstacles) it plans against.

    Args:
        ids: (K,) int ids; robots use their robot id, obstacles negative ids.
        position_m: (K, 2) observed positions.
        velocity_mps: (K, 2) velocities estimated from the observed history.
        radius_m: (K,) disc radii.
        linearity: (K,) w_j in [0, 1], how straight the observed history is (Eq. 15).
        track_start_m: (K, 2) s_j, the oldest position of the observed window (ghost path start).
        is_robot: (K,) bool, False for scenario obstacles.
        heading_rad: (K,) the observed headings (the world publishes full poses); None
            means unknown (NaN: whoever reads it must assume any heading).
        recent_speed_mps: (K,) speed over the newest interval of the observed history (the
            last two samples the disc is in), NaN when unknown (seen once only); None: all
            unknown. Read by the braking guard (`agent.planning.safety.unseen_speed_up_mps`): it
            shows a speed change that the least-squares velocity still trails.
        recent_interval_s: (K,) the length of that interval (NaN when unknown).
        recent_turn_rate_radps: (K,) signed heading change over that interval per second
            (NaN when unknown). Read by the braking guard under a delayed link
            (`agent.planning.safety.unseen_turn_closing_mps`): a turn the estimate's
            direction trails.
    """

    ids: np.ndarray
    position_m: np.ndarray
    velocity_mps: np.ndarray
    radius_m: np.ndarray
    linearity: np.ndarray
    track_start_m: np.ndarray
    is_robot: np.ndarray
    heading_rad: np.ndarray | None = None
    recent_speed_mps: np.ndarray | None = None
    recent_interval_s: np.ndarray | None = None
    recent_turn_rate_radps: np.ndarray | None = None

    def __post_init__(self) -> None:
        ids = np.asarray(self.ids, dtype=np.int64).reshape(-1)
        k = ids.shape[0]
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "position_m", _as_array("position_m", self.position_m, (k, 2)))
        object.__setattr__(
            self, "velocity_mps", _as_array("velocity_mps", self.velocity_mps, (k, 2))
        )
        radius = _as_array("radius_m", self.radius_m, (k,))
        if np.any(radius < 0.0):
            raise ValueError("radius_m: negative radius")
        object.__setattr__(self, "radius_m", radius)
        lin = _as_array("linearity", self.linearity, (k,))
        object.__setattr__(self, "linearity", np.clip(lin, 0.0, 1.0))
        object.__setattr__(
            self, "track_start_m", _as_array("track_start_m", self.track_start_m, (k, 2))
        )
        object.__setattr__(self, "is_robot", np.asarray(self.is_robot, dtype=bool).reshape(k))
        heading = (np.full(k, np.nan) if self.heading_rad is None
                   else _as_array("heading_rad", self.heading_rad, (k,)))
        object.__setattr__(self, "heading_rad", heading)
        for name in ("recent_speed_mps", "recent_interval_s"):
            value = getattr(self, name)
            if value is None:
                arr = np.full(k, np.nan)
            else:
                arr = np.asarray(value, dtype=float).reshape(-1)
                if arr.shape != (k,):
                    raise ValueError(f"{name}: shape {arr.shape}, expected {(k,)}")
                if np.any(np.isinf(arr)) or np.any(arr < 0.0):
                    raise ValueError(f"{name}: expected NaN (unknown) or finite values >= 0")
            object.__setattr__(self, name, arr)
        if self.recent_turn_rate_radps is None:
            turn = np.full(k, np.nan)
        else:
            turn = np.asarray(self.recent_turn_rate_radps, dtype=float).reshape(-1)
            if turn.shape != (k,):
                raise ValueError(f"recent_turn_rate_radps: shape {turn.shape}, expected {(k,)}")
            if np.any(np.isinf(turn)):
                raise ValueError("recent_turn_rate_radps: expected NaN (unknown) or finite values")
        object.__setattr__(self, "recent_turn_rate_radps", turn)

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    @staticmethod
    def empty() -> Others:
        """No one in sight."""
        z2 = np.zeros((0, 2))
        return Others(
            ids=np.zeros(0, dtype=np.int64),
            position_m=z2,
            velocity_mps=z2,
            radius_m=np.zeros(0),
            linearity=np.zeros(0),
            track_start_m=z2,
            is_robot=np.zeros(0, dtype=bool),
            heading_rad=np.zeros(0),
            recent_speed_mps=np.zeros(0),
            recent_interval_s=np.zeros(0),
            recent_turn_rate_radps=np.zeros(0),
        )

    @classmethod
    def trusted(cls, ids: np.ndarray, position_m: np.ndarray, velocity_mps: np.ndarray,
                radius_m: np.ndarray, linearity: np.ndarray, track_start_m: np.ndarray,
                is_robot: np.ndarray, heading_rad: np.ndarray | None = None,
                recent_speed_mps: np.ndarray | None = None,
                recent_interval_s: np.ndarray | None = None,
                recent_turn_rate_radps: np.ndarray | None = None) -> Others:
        """Build from arrays derived from already validated ones, skipping validation.

        For the hot path only (subsets, time shifts, estimates from validated snapshots);
        anything from outside goes through the validating constructor.
        """
        obj = object.__new__(cls)
        for name, value in (("ids", ids), ("position_m", position_m),
                            ("velocity_mps", velocity_mps), ("radius_m", radius_m),
                            ("linearity", linearity), ("track_start_m", track_start_m),
                            ("is_robot", is_robot)):
            object.__setattr__(obj, name, value)
        k = ids.shape[0]
        # NaN (unknown) columns are made only when missing: the hot path passes them all.
        for name, column in (("heading_rad", heading_rad), ("recent_speed_mps", recent_speed_mps),
                             ("recent_interval_s", recent_interval_s),
                             ("recent_turn_rate_radps", recent_turn_rate_radps)):
            object.__setattr__(obj, name, np.full(k, np.nan) if column is None else column)
        return obj

    def with_radius(self, radius_m: np.ndarray) -> Others:
        """The same others with disc radii `radius_m` ((K,), finite, >= 0)."""
        radius = np.asarray(radius_m, dtype=float).reshape(-1)
        if radius.shape != self.radius_m.shape or not np.isfinite(radius).all() \
                or (radius < 0.0).any():
            raise ValueError(f"radius_m: expected {len(self)} finite radii >= 0")
        obj = _shallow_copy(self)
        object.__setattr__(obj, "radius_m", radius)
        return obj

    def subset(self, index: np.ndarray) -> Others:
        """The others selected by an index or boolean mask, in that order."""
        # __post_init__ and `trusted` fill the optional columns (NaN where unknown)
        assert self.heading_rad is not None and self.recent_speed_mps is not None
        assert self.recent_interval_s is not None and self.recent_turn_rate_radps is not None
        return Others.trusted(
            ids=self.ids[index],
            position_m=self.position_m[index],
            velocity_mps=self.velocity_mps[index],
            radius_m=self.radius_m[index],
            linearity=self.linearity[index],
            track_start_m=self.track_start_m[index],
            is_robot=self.is_robot[index],
            heading_rad=self.heading_rad[index],
            recent_speed_mps=self.recent_speed_mps[index],
            recent_interval_s=self.recent_interval_s[index],
            recent_turn_rate_radps=self.recent_turn_rate_radps[index],
        )


@dataclass(frozen=True)
class Observation:
    """Everything one robot knows at one planning instant.

    Args:
        robot_id: this robot's id.
        ego: own state.
        goal_m: (2,) goal position.
        radius_m: own radius.
        limits: actuation limits.
        goal_tolerance_m: the robot stops when this close to its goal.
        others: the sensed others (already limited to the sensing radius / neighbour cap
            or not: planners apply `ThreatConfig.sensing_radius_m` and `max_neighbors`).
        pose_age_s: how old the poses were when the robot planned, after it predicted them
            forward to now (0: fresh poses, as in an undisturbed lockstep run) [s].
        goal_distance_m: how far the robot still has to go when `goal_m` is an intermediate
            goal on a route (`with_goal`); None: straight to `goal_m` [m].
    """

    robot_id: int
    ego: EgoState
    goal_m: np.ndarray
    radius_m: float
    limits: RobotLimits = field(default_factory=RobotLimits)
    goal_tolerance_m: float = 0.25
    others: Others = field(default_factory=Others.empty)
    pose_age_s: float = 0.0
    goal_distance_m: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "goal_m", _as_array("goal_m", self.goal_m, (2,)))
        age = _check_finite("pose_age_s", self.pose_age_s)
        if age < 0.0:
            raise ValueError("pose_age_s: must not be negative")
        object.__setattr__(self, "pose_age_s", age)
        radius = _check_finite("radius_m", self.radius_m)
        if radius <= 0.0:
            raise ValueError("radius_m: must be positive")
        object.__setattr__(self, "radius_m", radius)
        tol = _check_finite("goal_tolerance_m", self.goal_tolerance_m)
        if tol <= 0.0:
            raise ValueError("goal_tolerance_m: must be positive")
        object.__setattr__(self, "goal_tolerance_m", tol)

    def with_goal(self, goal_m: np.ndarray, goal_distance_m: float) -> Observation:
        """The same observation heading for `goal_m` (a route's intermediate goal) with
        `goal_distance_m` still to go along the route, skipping validation: the planner
        computed both (a finite (2,) point and a finite distance)."""
        obj = _shallow_copy(self)
        object.__setattr__(obj, "goal_m", goal_m)
        object.__setattr__(obj, "goal_distance_m", float(goal_distance_m))
        return obj

    def with_others(self, others: Others) -> Observation:
        """The same observation with `others` replaced, skipping validation: for the hot
        path, where `others` is a subset of this observation's (already validated) others."""
        obj = _shallow_copy(self)
        object.__setattr__(obj, "others", others)
        return obj


@dataclass(frozen=True)
class Threat:
    """One collision threat of Eq. (6)."""

    other_id: int
    tcpa_s: float
    dcpa_m: float


@dataclass(frozen=True)
class StageTimes:
    """Wall time spent per planning stage, in milliseconds (the only non-deterministic field)."""

    threats_ms: float = 0.0
    viapoints_ms: float = 0.0
    spline_ms: float = 0.0
    control_ms: float = 0.0
    total_ms: float = 0.0


@dataclass(frozen=True)
class PlanDebug:
    """A planner's internals for one cycle, for viewing only (never read by a decision).

    Filled from arrays the planner computed anyway; empty arrays where a planner has no such
    stage (ORCA has no via-points, ifp and eifp no MPC prediction).

    Args:
        ego: (3,) x [m], y [m], heading [rad] the robot planned from (its own estimate,
            forward-predicted by the pose age).
        threat_ids: ids of the threats of Eq. (6), ranked as the planner ranked them.
        via_points_m: (K, 2) the via-points between the robot and its goal.
        reference_m: (M, 2) samples of the reference path the tracker follows.
        predicted_m: (N, 2) the MPC's predicted positions over its horizon (eIFP-MPC).
    """

    ego: np.ndarray
    threat_ids: tuple[int, ...] = ()
    via_points_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    reference_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    predicted_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @classmethod
    def trusted(cls, ego: np.ndarray, threat_ids: tuple[int, ...], via_points_m: np.ndarray,
                reference_m: np.ndarray, predicted_m: np.ndarray) -> PlanDebug:
        """Built by a planner from its own finite arrays of the documented shapes (float),
        or by `eifp_wire.messages.PlanDebugMsg.decode` from arrays it has checked: the ids
        are made ints, nothing else is checked (`PlanDebugMsg` checks every value before
        one is sent)."""
        debug = object.__new__(cls)
        debug.__dict__.update(ego=ego, threat_ids=tuple(int(i) for i in threat_ids),
                              via_points_m=via_points_m, reference_m=reference_m,
                              predicted_m=predicted_m)
        return debug

    def __post_init__(self) -> None:
        object.__setattr__(self, "ego", _as_array("ego", self.ego, (3,)))
        object.__setattr__(self, "threat_ids", tuple(int(i) for i in self.threat_ids))
        for name in ("via_points_m", "reference_m", "predicted_m"):
            value = np.asarray(getattr(self, name), dtype=float).reshape(-1, 2)
            object.__setattr__(self, name, _as_array(name, value, (None, 2)))


@dataclass(frozen=True)
class PlanResult:
    """What a planner decided in one cycle.

    Args:
        v_mps, omega_radps: the command, within the robot's limits.
        status: outcome of the cycle.
        waypoints_m: (M, 2) waypoints from the robot's position to its goal (M >= 2).
        via_point_m: (2,) the chosen via-point, or None when no threat needed one.
        side: side of the chosen via-point relative to the threat it resolves.
        resolved_id: id of the threat that via-point resolves, or None.
        threats: the threats of Eq. (6), ranked by TCPA (Eq. 7).
        times: per-stage timings.
        solver_iterations: OSQP iterations (eIFP-MPC), else 0.
        debug: the planner's internals for viewing (`PlanDebug`), or None; not part of
            `decision`.
    """

    v_mps: float
    omega_radps: float
    status: PlanStatus
    waypoints_m: np.ndarray
    via_point_m: np.ndarray | None = None
    side: Side = Side.NONE
    resolved_id: int | None = None
    threats: tuple[Threat, ...] = ()
    times: StageTimes = field(default_factory=StageTimes)
    solver_iterations: int = 0
    debug: PlanDebug | None = None

    def decision(self) -> tuple[object, ...]:
        """Everything but the timings, for determinism checks."""
        via = None if self.via_point_m is None else tuple(np.round(self.via_point_m, 12))
        return (
            round(self.v_mps, 12),
            round(self.omega_radps, 12),
            self.status,
            tuple(map(tuple, np.round(self.waypoints_m, 12))),
            via,
            self.side,
            self.resolved_id,
            self.threats,
            self.solver_iterations,
        )


@dataclass(frozen=True)
class PoseSnapshot:
    """What a robot's sensor sees at one instant: every disc's pose, nothing else.

    Args:
        stamp_s: sim time at which the poses were true.
        tick: the world tick that produced them (orders snapshots).
        ids: (n,) int ids; robots >= 0, scenario obstacles < 0.
        pose: (n, 3) x [m], y [m], heading [rad] (heading 0 for obstacles).
        radius_m: (n,) disc radii.
    """

    stamp_s: float
    tick: int
    ids: np.ndarray
    pose: np.ndarray
    radius_m: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "stamp_s", _check_finite("stamp_s", self.stamp_s))
        ids = np.asarray(self.ids, dtype=np.int64).reshape(-1)
        n = ids.shape[0]
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "pose", _as_array("pose", self.pose, (n, 3)))
        object.__setattr__(self, "radius_m", _as_array("radius_m", self.radius_m, (n,)))

    @classmethod
    def trusted(cls, stamp_s: float, tick: int, ids: np.ndarray, pose: np.ndarray,
                radius_m: np.ndarray) -> PoseSnapshot:
        """A snapshot of arrays that were validated already (a decoded `eifp_wire.poses.PosesMsg`:
        int64 ids, finite (n, 3) poses and (n,) radii): nothing is converted or checked."""
        snapshot = object.__new__(cls)
        snapshot.__dict__.update(stamp_s=stamp_s, tick=tick, ids=ids, pose=pose,
                                 radius_m=radius_m)
        return snapshot

    @property
    def is_robot(self) -> np.ndarray:
        """(n,) bool: robots have non-negative ids."""
        return self.ids >= 0
