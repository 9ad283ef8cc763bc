"""Run metrics from arrays (pure: no files, no clock).

Inputs are the ground-truth trajectory sampled every world tick, the applied commands,
and what the scenario fixes (starts, goals, radii, v_max, goal tolerance, time limit,
obstacles). Definitions (SI units; "run" of a robot = from t = 0 to its arrival, or to the
end of the trajectory if it never arrives):

- **arrival**: the first sample at which the robot's centre is within the goal tolerance
  of its goal, at t <= time limit (the world's rule). `time_to_goal_s` is that t. The
  tolerance is widened by `ARRIVAL_RECORD_EPS_M`: positions are recorded to 10 um, and a
  robot the world found exactly at the tolerance (arriving on the last tick of a run that
  ended as all arrived) was otherwise 7 um outside it in the record, a success counted as
  a miss.
- **contact**: two discs (robot-robot or robot-obstacle) overlapping by more than 1 mm
  (distance < r_i + r_j - 1 mm) at a sample. `contacts` counts contact *episodes*: a pair
  that comes into contact and stays in contact over consecutive samples counts once.
  Contact events logged by the world that no trajectory sample within one tick confirms
  (e.g. between samples) are added as episodes too.
- **success**: every robot arrived and there was no contact.
- **min gap**: the smallest distance - r_i - r_j over all robot-robot and robot-obstacle
  pairs and samples (negative: overlap); `min_gap_robots_m` over the robot-robot pairs
  only, `min_gap_obstacles_m` over the robot-obstacle pairs only (None without such pairs).
- **path length**: the polyline length of the robot's run, starting at its scenario start.
  `path_ratio` = path length / straight distance from the start to the point where the
  robot arrived (>= 1, exactly 1 for a straight run; None if it never arrived).
  `straight_m` is the start-goal distance.
- **time ratio**: time to goal / ideal time, ideal = straight distance / v_max.
- **oscillations** (reversals of turning direction): heading rate r_k = (unwrapped heading
  difference) / dt between consecutive samples. A *turn* is a maximal run of consecutive
  intervals whose rate has one sign with |r_k| >= 0.05 rad/s and whose accumulated heading
  change |sum r_k dt_k| is >= 0.1 rad. A *reversal* is a turn that follows the previous
  turn (runs that are not turns are skipped) of the opposite sign and starts within 3 s of
  that turn's end. Counted over the robot's run.
- **reversal causes** (`reversal_causes`; a diagnostic, not a target): each reversal is
  put in the first class that fits, from the speed at the start of the reversing turn and
  the plans in force (the last command applied at or before each turn's start):
  `slow` (speed below 0.5 m/s: turning nearly on the spot, in a crowd or while escaping);
  `escape` (either plan was an escape); `no_via_point` (either plan had no via-point:
  heading for the goal, or a planner that does not report one, such as ORCA);
  `side_flip` (the same threat, resolved on the other side); `threat_switch` (the first
  via-point resolves another threat); `same_via_point` (the same threat on the same side:
  the two halves of one swerve, turning towards the via-point and back, or the tracker
  settling). Without the `side` and `resolved` command columns every reversal that is
  not `slow` or `escape` is `unknown`. The counts of a robot sum to its oscillations.
- **side flips** (needs the optional `side` and `resolved` command columns): consecutive
  commands of one robot (by `seq`) that both resolve a threat (`resolved` present, `side`
  LEFT (+1) or RIGHT (-1)) with opposite sides. `side_flips_same_threat` additionally
  requires the same resolved id. Without the columns both are None.
- **encounters** (crossing encounters, `orchestrator.analysis.encounters`): the other robots
  that come closer than 2.5 m (centre to centre) to the robot at some sample, with headings
  more than 45 degrees apart at the sample of their closest approach. Counted over the whole
  trajectory, not only the robot's run. `reversals_per_encounter` = the run's oscillations /
  its encounters (None without encounters).
- **planning time**: `plan_ms` of the commands that planned, i.e. status neither
  `arrived` nor `stale`; p50 / p99 / max / mean pooled over robots.
- **latency**: (t_applied - pose_stamp) in ms over all commands; p50 / p99.
- **deadline miss**: consecutive commands of one robot (by `seq`) whose pose stamps differ
  by more than one control period + one world tick (+ 1 us for rounding); rate = misses /
  such consecutive pairs ("cycles").

Aggregate means (`path_ratio_mean`, `time_ratio_mean`, ...) are over the robots that
arrived; `oscillations_per_robot`, `side_flips_per_robot` and `encounters_per_robot` over
all robots; `oscillations_max` is the largest count of one robot (0 without robots).
Values that do not exist (no robot arrived, no commands) are None in JSON.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, TypedDict

import numpy as np

from agent.core.scenario import Scenario
from orchestrator.analysis.encounters import crossing_encounters
from orchestrator.analysis.turns import (
    REVERSAL_CAUSES,
    PlanInForce,
    oscillations,
    reversal_causes,
)

CONTACT_OVERLAP_M = 1.0e-3
NOT_PLANNING_STATUSES = frozenset({"arrived", "stale"})
_TIME_EPS_S = 1.0e-6
ARRIVAL_RECORD_EPS_M = 1.0e-5
"""Widening of the goal tolerance for arrival in a recorded trajectory [m]: more than the
rounding of a recorded position (half of 1e-5 m per axis, 7.1 um in all)."""
_CHUNK_TICKS = 2048


@dataclass(frozen=True)
class Trajectory:
    """Ground truth, one sample per world tick.

    Args:
        t_s: (T,) increasing sample times.
        robot_ids: (n,) robot ids, the column order of the other arrays.
        pose: (T, n, 3) x [m], y [m], heading [rad].
        applied: (T, n, 2) applied v [m/s], omega [rad/s].
    """

    t_s: np.ndarray
    robot_ids: np.ndarray
    pose: np.ndarray
    applied: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=float).reshape(-1)
        ids = np.asarray(self.robot_ids, dtype=np.int64).reshape(-1)
        pose = np.asarray(self.pose, dtype=float).reshape(t.size, ids.size, 3)
        applied = np.asarray(self.applied, dtype=float).reshape(t.size, ids.size, 2)
        if t.size > 1 and np.any(np.diff(t) <= 0.0):
            raise ValueError("t_s must be strictly increasing")
        for name, value in (("t_s", t), ("robot_ids", ids), ("pose", pose),
                            ("applied", applied)):
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class Commands:
    """Applied commands, one row each (any order).

    Args:
        t_applied_s, pose_stamp_s, v, omega, plan_ms: (C,) floats.
        robot, seq: (C,) ints.
        status: (C,) strings (`PlanStatus` values).
        side: (C,) ints (-1 RIGHT, 0 NONE, +1 LEFT) or None when not recorded.
        resolved: (C,) floats, the resolved threat id or NaN for none; None when not
            recorded.
    """

    t_applied_s: np.ndarray
    robot: np.ndarray
    seq: np.ndarray
    pose_stamp_s: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    plan_ms: np.ndarray
    status: np.ndarray
    side: np.ndarray | None = None
    resolved: np.ndarray | None = None

    def __post_init__(self) -> None:
        c = np.asarray(self.robot).reshape(-1).size
        for name in ("t_applied_s", "pose_stamp_s", "v", "omega", "plan_ms"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float)
                               .reshape(c))
        for name in ("robot", "seq"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.int64)
                               .reshape(c))
        object.__setattr__(self, "status", np.asarray(self.status, dtype=str).reshape(c))
        if self.side is not None:
            object.__setattr__(self, "side", np.asarray(self.side, dtype=np.int64).reshape(c))
        if self.resolved is not None:
            object.__setattr__(self, "resolved",
                               np.asarray(self.resolved, dtype=float).reshape(c))

    @staticmethod
    def empty() -> Commands:
        z = np.zeros(0)
        return Commands(z, z, z, z, z, z, z, np.zeros(0, dtype=str))


@dataclass(frozen=True)
class RunSpec:
    """What the scenario fixes for the metrics.

    Args:
        robot_ids: (n,); start_m, goal_m: (n, 2); radius_m, v_max_mps: (n,).
        goal_tolerance_m, time_limit_s: scalars.
        obstacle_ids: (m,); obstacle_center_m, obstacle_velocity_mps: (m, 2) (positions
            at t = 0, constant velocity); obstacle_radius_m: (m,).
    """

    robot_ids: np.ndarray
    start_m: np.ndarray
    goal_m: np.ndarray
    radius_m: np.ndarray
    v_max_mps: np.ndarray
    goal_tolerance_m: float
    time_limit_s: float
    obstacle_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    obstacle_center_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    obstacle_velocity_mps: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    obstacle_radius_m: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @staticmethod
    def from_scenario(scenario: Scenario) -> RunSpec:
        robots, obstacles = scenario.robots, scenario.obstacles
        return RunSpec(
            robot_ids=np.array([r.id for r in robots], dtype=np.int64),
            start_m=np.array([r.start[:2] for r in robots], dtype=float).reshape(-1, 2),
            goal_m=np.array([r.goal for r in robots], dtype=float).reshape(-1, 2),
            radius_m=np.array([r.radius_m for r in robots], dtype=float),
            v_max_mps=np.array([r.limits.v_max_mps for r in robots], dtype=float),
            goal_tolerance_m=scenario.goal_tolerance_m,
            time_limit_s=scenario.time_limit_s,
            obstacle_ids=np.array([o.id for o in obstacles], dtype=np.int64),
            obstacle_center_m=np.array([o.center for o in obstacles], dtype=float)
            .reshape(-1, 2),
            obstacle_velocity_mps=np.array([o.velocity for o in obstacles], dtype=float)
            .reshape(-1, 2),
            obstacle_radius_m=np.array([o.radius_m for o in obstacles], dtype=float),
        )


@dataclass(frozen=True)
class ContactEpisode:
    """A pair came into contact at t_s (ids; obstacles negative) with this overlap."""

    t_s: float
    id_a: int
    id_b: int
    overlap_m: float


@dataclass(frozen=True)
class RobotMetrics:
    """Per-robot results (None where not defined)."""

    id: int
    arrived: bool
    time_to_goal_s: float | None
    ideal_time_s: float
    time_ratio: float | None
    path_length_m: float
    straight_m: float
    path_ratio: float | None
    oscillations: int
    reversal_causes: dict[str, int]
    side_flips: int | None
    side_flips_same_threat: int | None
    encounters: int
    contacts: int
    min_gap_m: float | None
    plan_ms_mean: float | None
    plan_ms_p50: float | None
    plan_ms_p99: float | None
    plan_ms_max: float | None
    cycles: int
    deadline_misses: int


@dataclass(frozen=True)
class RunMetrics:
    """Whole-run results; `to_json_dict` gives the `metrics.json` content."""

    robots: int
    arrived: int
    success: bool
    contacts: int
    contact_pairs: list[list[int]]
    min_gap_m: float | None
    min_gap_robots_m: float | None
    min_gap_obstacles_m: float | None
    path_length_mean_m: float | None
    path_ratio_mean: float | None
    time_to_goal_mean_s: float | None
    time_ratio_mean: float | None
    makespan_s: float | None
    oscillations_per_robot: float
    oscillations_total: int
    oscillations_max: int
    reversal_causes_per_robot: dict[str, float]
    side_flips_per_robot: float | None
    encounters_per_robot: float
    reversals_per_encounter: float | None
    plan_ms_mean: float | None
    plan_ms_p50: float | None
    plan_ms_p99: float | None
    plan_ms_max: float | None
    plan_cycles: int
    sim_latency_ms_p50: float | None
    sim_latency_ms_p99: float | None
    deadline_misses: int
    deadline_miss_rate: float | None
    sim_time_s: float
    time_limit_s: float
    control_period_s: float
    world_dt_s: float
    per_robot: list[RobotMetrics]
    wall_latency_ms: dict[str, dict[str, float | None]] = field(default_factory=dict)
    wall_latency_ms_by_router: dict[str, dict[str, dict[str, float | None]]] = field(
        default_factory=dict)
    """`wall_latency_ms` of the robots behind each router (`latency.router_groups`): ``world`` for
    the world's own router, ``router-<name>`` for a relay; empty in a run without relays."""

    def to_json_dict(self) -> dict[str, Any]:
        """Plain JSON types; NaN and infinities become None."""
        plain: dict[str, Any] = _jsonable(asdict(self))
        return plain


# --------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------

def path_length_m(xy_m: np.ndarray) -> float:
    """Length of a (T, 2) polyline."""
    xy = np.asarray(xy_m, dtype=float).reshape(-1, 2)
    return float(np.hypot(*np.diff(xy, axis=0).T).sum()) if len(xy) > 1 else 0.0


def arrival_index(t_s: np.ndarray, xy_m: np.ndarray, goal_m: np.ndarray, tolerance_m: float,
                  time_limit_s: float) -> int | None:
    """First sample index within tolerance of the goal at t <= time limit, or None.

    Args:
        t_s: (T,); xy_m: (T, 2); goal_m: (2,).
    """
    dist = np.hypot(*(np.asarray(xy_m) - np.asarray(goal_m)).T)
    hit = np.flatnonzero((dist <= tolerance_m + ARRIVAL_RECORD_EPS_M)
                         & (np.asarray(t_s) <= time_limit_s + _TIME_EPS_S))
    return int(hit[0]) if hit.size else None


def side_flips(seq: np.ndarray, side: np.ndarray, resolved: np.ndarray) -> tuple[int, int]:
    """(flips, same-threat flips) of one robot's commands (see the module docstring).

    Args:
        seq, side, resolved: (C,) of one robot; resolved NaN = no threat resolved.
    """
    order = np.argsort(seq, kind="stable")
    side = np.asarray(side)[order]
    resolved = np.asarray(resolved, dtype=float)[order]
    active = (side != 0) & np.isfinite(resolved)
    both = active[1:] & active[:-1]
    flip = both & (side[1:] == -side[:-1])
    same = flip & (resolved[1:] == resolved[:-1])
    return int(flip.sum()), int(same.sum())


def deadline_misses(seq: np.ndarray, pose_stamp_s: np.ndarray, control_period_s: float,
                    world_dt_s: float) -> tuple[int, int]:
    """(misses, cycles) of one robot: consecutive pose stamps more than period + tick apart."""
    order = np.argsort(seq, kind="stable")
    gaps = np.diff(np.asarray(pose_stamp_s, dtype=float)[order])
    late = gaps > control_period_s + world_dt_s + _TIME_EPS_S
    return int(late.sum()), int(gaps.size)


@dataclass(frozen=True)
class ContactScan:
    """What `contact_episodes` finds over a whole trajectory.

    Args:
        episodes: contact episodes in time order.
        robot_min_gap_m: (n,) each robot column's min gap to any other disc [m].
        robots_min_gap_m: the min gap between two robots [m].
        obstacles_min_gap_m: the min gap between a robot and an obstacle [m].
        (Each +inf without such pairs.)
    """

    episodes: list[ContactEpisode]
    robot_min_gap_m: np.ndarray
    robots_min_gap_m: float
    obstacles_min_gap_m: float


def contact_episodes(traj: Trajectory, spec: RunSpec) -> ContactScan:
    """Contact episodes and the min gaps: each robot's to any other disc (robot or
    obstacle), and the run's robot-robot and robot-obstacle ones."""
    n, m = traj.robot_ids.size, spec.obstacle_ids.size
    ids = np.concatenate([traj.robot_ids, spec.obstacle_ids])
    radius = np.concatenate([spec.radius_m, spec.obstacle_radius_m])
    i, j = np.triu_indices(n + m, k=1)
    keep = i < n  # obstacle-obstacle pairs are scenery
    i, j = i[keep], j[keep]
    sum_r = radius[i] + radius[j]
    episodes: list[ContactEpisode] = []
    pair_min = np.full(i.size, np.inf)
    prev = np.zeros(i.size, dtype=bool)
    for c0 in range(0, traj.t_s.size, _CHUNK_TICKS):
        t = traj.t_s[c0:c0 + _CHUNK_TICKS]
        centres = _centres(traj.pose[c0:c0 + _CHUNK_TICKS, :, :2], t, spec)  # (t, n+m, 2)
        d = centres[:, i, :] - centres[:, j, :]
        gap = np.hypot(d[..., 0], d[..., 1]) - sum_r  # (t, P)
        if gap.size:
            np.minimum(pair_min, gap.min(axis=0), out=pair_min)
        touching = gap < -CONTACT_OVERLAP_M
        # A new episode: touching now, not at the previous sample.
        new = touching & ~np.vstack([prev[None, :], touching[:-1]])
        for k, p in np.argwhere(new):
            episodes.append(ContactEpisode(float(t[k]), int(ids[i[p]]), int(ids[j[p]]),
                                           float(-gap[k, p])))
        if touching.shape[0]:
            prev = touching[-1]
    robot_min = np.full(n + m, np.inf)
    np.minimum.at(robot_min, i, pair_min)
    np.minimum.at(robot_min, j, pair_min)
    with_robot = j < n
    return ContactScan(
        episodes=episodes, robot_min_gap_m=robot_min[:n],
        robots_min_gap_m=float(pair_min[with_robot].min(initial=np.inf)),
        obstacles_min_gap_m=float(pair_min[~with_robot].min(initial=np.inf)))


def _centres(xy: np.ndarray, t_s: np.ndarray, spec: RunSpec) -> np.ndarray:
    """(T, n+m, 2) robot and obstacle centres at the sample times."""
    ob = spec.obstacle_center_m[None] + spec.obstacle_velocity_mps[None] * t_s[:, None, None]
    return np.concatenate([xy, ob], axis=1)


def _confirmed(traj: Trajectory, spec: RunSpec, t_s: float, id_a: int, id_b: int,
               window_s: float) -> bool:
    """Whether the trajectory shows pair (a, b) in contact within window_s of t_s."""
    near = np.flatnonzero(np.abs(traj.t_s - t_s) <= window_s + _TIME_EPS_S)
    if near.size == 0:
        return False
    ids = np.concatenate([traj.robot_ids, spec.obstacle_ids])
    radius = np.concatenate([spec.radius_m, spec.obstacle_radius_m])
    col = {int(x): k for k, x in enumerate(ids)}
    if id_a not in col or id_b not in col:
        return False
    c = _centres(traj.pose[near, :, :2], traj.t_s[near], spec)
    a, b = col[id_a], col[id_b]
    gap = np.hypot(*(c[:, a] - c[:, b]).T) - radius[a] - radius[b]
    return bool(np.any(gap < -CONTACT_OVERLAP_M))


def _pct(values: np.ndarray, q: float) -> float | None:
    return float(np.percentile(values, q)) if values.size else None


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _mean(values: Iterable[float | None]) -> float | None:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(vals)) if vals else None


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.bool_ | bool):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    return obj


# --------------------------------------------------------------------------------------
# The whole run
# --------------------------------------------------------------------------------------

def compute_metrics(traj: Trajectory, commands: Commands, spec: RunSpec, *,
                    control_period_s: float, world_dt_s: float,
                    contact_events: Sequence[tuple[float, int, int]] = ()) -> RunMetrics:
    """Every metric of one run (definitions in the module docstring).

    Args:
        traj: ground truth; its robot columns must be spec.robot_ids in order.
        commands: applied commands.
        spec: what the scenario fixes.
        control_period_s: the robots' planning period.
        world_dt_s: the world tick.
        contact_events: (t_s, id_a, id_b) contacts the world logged.
    """
    if not np.array_equal(traj.robot_ids, spec.robot_ids):
        raise ValueError("trajectory robot columns must match the scenario's robot ids")
    scan = contact_episodes(traj, spec)
    for t_ev, a, b in contact_events:
        if not _confirmed(traj, spec, float(t_ev), int(a), int(b), world_dt_s):
            scan.episodes.append(ContactEpisode(float(t_ev), int(a), int(b), math.nan))
    planned = ~np.isin(commands.status, list(NOT_PLANNING_STATUSES))
    encounters = crossing_encounters(traj.pose[:, :, :2], traj.pose[:, :, 2])
    per_robot = [
        _robot_metrics(traj, spec, k, scan,
                       _robot_commands(commands, int(rid), planned, control_period_s,
                                       world_dt_s), int(encounters[k]))
        for k, rid in enumerate(spec.robot_ids.tolist())]
    return _run_metrics(per_robot, traj, commands, spec, scan, planned,
                        control_period_s=control_period_s, world_dt_s=world_dt_s)


class _PlanMs(TypedDict):
    """The planning-time fields of `RobotMetrics` and `RunMetrics` [ms]."""

    plan_ms_mean: float | None
    plan_ms_p50: float | None
    plan_ms_p99: float | None
    plan_ms_max: float | None


def _plan_ms(plan_ms: np.ndarray) -> _PlanMs:
    """Mean, p50, p99 and largest planning time [ms] (None without plans)."""
    return {"plan_ms_mean": float(plan_ms.mean()) if plan_ms.size else None,
            "plan_ms_p50": _pct(plan_ms, 50), "plan_ms_p99": _pct(plan_ms, 99),
            "plan_ms_max": float(plan_ms.max()) if plan_ms.size else None}


@dataclass(frozen=True)
class _RobotCommands:
    """What one robot's applied commands give its metrics.

    Args:
        flips: `side_flips` (None, None without the side columns).
        misses, cycles: `deadline_misses`.
        plan_ms: (P,) planning times of the commands that planned.
        in_force: its commands as a step function of time.
    """

    flips: tuple[int | None, int | None]
    misses: int
    cycles: int
    plan_ms: np.ndarray
    in_force: PlanInForce


def _robot_commands(commands: Commands, rid: int, planned: np.ndarray,
                    control_period_s: float, world_dt_s: float) -> _RobotCommands:
    mine = commands.robot == rid
    order = np.argsort(commands.t_applied_s[mine], kind="stable")
    side = resolved = None
    flips: tuple[int | None, int | None] = (None, None)
    if commands.side is not None and commands.resolved is not None:
        side, resolved = commands.side[mine], commands.resolved[mine]
        flips = side_flips(commands.seq[mine], side, resolved)
        side, resolved = side[order], resolved[order]
    misses, cycles = deadline_misses(commands.seq[mine], commands.pose_stamp_s[mine],
                                     control_period_s, world_dt_s)
    in_force = PlanInForce(commands.t_applied_s[mine][order], commands.status[mine][order],
                           side, resolved)
    return _RobotCommands(flips, misses, cycles, commands.plan_ms[mine & planned], in_force)


def _robot_metrics(traj: Trajectory, spec: RunSpec, k: int, scan: ContactScan,
                   mine: _RobotCommands, encounters: int) -> RobotMetrics:
    """The metrics of robot column k, which had `encounters` crossing encounters."""
    rid = int(spec.robot_ids[k])
    t, xy, heading = _robot_run(traj, k, spec)
    idx = arrival_index(t, xy, spec.goal_m[k], spec.goal_tolerance_m, spec.time_limit_s)
    end = idx + 1 if idx is not None else t.size
    straight = float(np.hypot(*(spec.goal_m[k] - spec.start_m[k])))
    ideal = straight / float(spec.v_max_mps[k])
    length = path_length_m(xy[:end])
    reach = float(np.hypot(*(xy[idx] - xy[0]))) if idx is not None else 0.0
    t_goal = float(t[idx]) if idx is not None else None
    speed = _run_speed(traj, k, t.size)
    return RobotMetrics(
        id=rid,
        arrived=idx is not None,
        time_to_goal_s=t_goal,
        ideal_time_s=ideal,
        time_ratio=(t_goal / ideal if t_goal is not None and ideal > 0 else None),
        path_length_m=length,
        straight_m=straight,
        path_ratio=(length / reach if idx is not None and reach > 0 else None),
        oscillations=oscillations(t[:end], heading[:end]),
        reversal_causes=reversal_causes(t[:end], heading[:end], speed[:end], mine.in_force),
        side_flips=mine.flips[0],
        side_flips_same_threat=mine.flips[1],
        encounters=encounters,
        contacts=sum(1 for e in scan.episodes if rid in (e.id_a, e.id_b)),
        min_gap_m=_finite(float(scan.robot_min_gap_m[k])),
        **_plan_ms(mine.plan_ms),
        cycles=mine.cycles,
        deadline_misses=mine.misses,
    )


def _run_metrics(per_robot: list[RobotMetrics], traj: Trajectory, commands: Commands,
                 spec: RunSpec, scan: ContactScan, planned: np.ndarray, *,
                 control_period_s: float, world_dt_s: float) -> RunMetrics:
    """The whole run's metrics from its robots'."""
    episodes = scan.episodes
    n = len(per_robot)
    arrived = sum(r.arrived for r in per_robot)
    plan_all = commands.plan_ms[planned]
    latency = (commands.t_applied_s - commands.pose_stamp_s) * 1000.0
    cycles_total = sum(r.cycles for r in per_robot)
    misses_total = sum(r.deadline_misses for r in per_robot)
    robot_gaps = scan.robot_min_gap_m
    return RunMetrics(
        robots=n,
        arrived=arrived,
        success=bool(n > 0 and arrived == n and not episodes),
        contacts=len(episodes),
        contact_pairs=[list(p) for p in sorted({tuple(sorted((e.id_a, e.id_b)))
                                                for e in episodes})],
        min_gap_m=_finite(float(robot_gaps.min()) if robot_gaps.size else math.inf),
        min_gap_robots_m=_finite(scan.robots_min_gap_m),
        min_gap_obstacles_m=_finite(scan.obstacles_min_gap_m),
        **_arrival_means(per_robot),
        **_turning(per_robot, has_side=commands.side is not None
                   and commands.resolved is not None),
        **_plan_ms(plan_all),
        plan_cycles=int(plan_all.size),
        sim_latency_ms_p50=_pct(latency, 50),
        sim_latency_ms_p99=_pct(latency, 99),
        deadline_misses=misses_total,
        deadline_miss_rate=misses_total / cycles_total if cycles_total else None,
        sim_time_s=float(traj.t_s[-1]) if traj.t_s.size else 0.0,
        time_limit_s=float(spec.time_limit_s),
        control_period_s=float(control_period_s),
        world_dt_s=float(world_dt_s),
        per_robot=per_robot,
    )


class _ArrivalMeans(TypedDict):
    """The arrival fields of `RunMetrics`."""

    path_length_mean_m: float | None
    path_ratio_mean: float | None
    time_to_goal_mean_s: float | None
    time_ratio_mean: float | None
    makespan_s: float | None


def _arrival_means(per_robot: list[RobotMetrics]) -> _ArrivalMeans:
    """Means over the robots that arrived, and the makespan if every robot did."""
    arrived = [r for r in per_robot if r.arrived]
    return {
        "path_length_mean_m": _mean(r.path_length_m for r in arrived),
        "path_ratio_mean": _mean(r.path_ratio for r in arrived),
        "time_to_goal_mean_s": _mean(r.time_to_goal_s for r in arrived),
        "time_ratio_mean": _mean(r.time_ratio for r in arrived),
        "makespan_s": (max(r.time_to_goal_s or 0.0 for r in arrived)
                       if arrived and len(arrived) == len(per_robot) else None),
    }


class _Turning(TypedDict):
    """The oscillation, side-flip and encounter fields of `RunMetrics`."""

    oscillations_per_robot: float
    oscillations_total: int
    oscillations_max: int
    reversal_causes_per_robot: dict[str, float]
    side_flips_per_robot: float | None
    encounters_per_robot: float
    reversals_per_encounter: float | None


def _turning(per_robot: list[RobotMetrics], *, has_side: bool) -> _Turning:
    """Oscillations (per robot, total, largest), their causes per robot, the side flips
    per robot (None without the side columns) and the crossing encounters."""
    n = len(per_robot)
    counts = [r.oscillations for r in per_robot]
    encounters = sum(r.encounters for r in per_robot)
    return {
        "oscillations_per_robot": float(np.mean(counts)) if n else 0.0,
        "oscillations_total": sum(counts),
        "oscillations_max": max(counts, default=0),
        "reversal_causes_per_robot": {
            c: (float(np.mean([r.reversal_causes[c] for r in per_robot])) if n else 0.0)
            for c in REVERSAL_CAUSES},
        "side_flips_per_robot": (float(np.mean([r.side_flips or 0 for r in per_robot]))
                                 if has_side and n else None),
        "encounters_per_robot": encounters / n if n else 0.0,
        "reversals_per_encounter": sum(counts) / encounters if encounters else None,
    }


def _run_speed(traj: Trajectory, k: int, size: int) -> np.ndarray:
    """(size,) applied speed of robot column k on the samples of `_robot_run` (which may
    have prepended a t = 0 sample: it gets speed 0)."""
    v = traj.applied[:, k, 0]
    return np.concatenate([np.zeros(size - v.size), v]) if size > v.size else v


def _robot_run(traj: Trajectory, k: int, spec: RunSpec
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (T',), xy (T', 2), heading (T',)) of robot column k, from its scenario start."""
    t, xy, heading = traj.t_s, traj.pose[:, k, :2], traj.pose[:, k, 2]
    if t.size == 0 or t[0] > _TIME_EPS_S:
        # No t = 0 sample: the run starts at the scenario start (heading of the first sample).
        h0 = heading[:1] if t.size else np.zeros(1)
        t = np.concatenate([[0.0], t])
        xy = np.concatenate([spec.start_m[k][None], xy])
        heading = np.concatenate([h0, heading])
    return t, xy, heading
