"""Run metrics from arrays (pure: no files, no clock).

Inputs are the ground-truth trajectory sampled every world tick, the applied commands,
and what the scenario fixes (starts, goals, radii, v_max, goal tolerance, time limit,
obstacles). Definitions (SI units; "run" of a robot = from t = 0 to its arrival, or to the
end of the trajectory if it never arrives):

- **arrival**: the first sample at which the robot's centre is within the goal tolerance
  of its goal, at t <= time limit (the world's rule). `time_to_goal_s` is that t.
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
- **planning time**: `plan_ms` of the commands that planned, i.e. status neither
  `arrived` nor `stale`; p50 / p99 / max / mean pooled over robots.
- **latency**: (t_applied - pose_stamp) in ms over all commands; p50 / p99.
- **deadline miss**: consecutive commands of one robot (by `seq`) whose pose stamps differ
  by more than one control period + one world tick (+ 1 us for rounding); rate = misses /
  such consecutive pairs ("cycles").

Aggregate means (`path_ratio_mean`, `time_ratio_mean`, ...) are over the robots that
arrived; `oscillations_per_robot` and `side_flips_per_robot` over all robots;
`oscillations_max` is the largest count of one robot (0 without robots). Values that
do not exist (no robot arrived, no commands) are None in JSON.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from agent.core.scenario import Scenario
from eifp_wire import TIMING_COLUMNS

CONTACT_OVERLAP_M = 1.0e-3
TURN_RATE_MIN_RADPS = 0.05
TURN_ANGLE_MIN_RAD = 0.1
REVERSAL_WINDOW_S = 3.0
# Below this speed a reversal is `slow` (module docstring, reversal causes) [m/s].
SLOW_REVERSAL_MPS = 0.5
REVERSAL_CAUSES = ("slow", "escape", "no_via_point", "side_flip", "threat_switch",
                   "same_via_point", "unknown")
NOT_PLANNING_STATUSES = frozenset({"arrived", "stale"})
_TIME_EPS_S = 1.0e-6
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
class Turn:
    """One turn of the heading: sign (+1 counter-clockwise), span and heading change."""

    sign: int
    start_s: float
    end_s: float
    angle_rad: float


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
    """`wall_latency_ms` of the robots behind each router (`router_groups`): ``world`` for
    the world's own router, ``router-<name>`` for a relay; empty in a run without relays."""

    def to_json_dict(self) -> dict[str, Any]:
        """Plain JSON types; NaN and infinities become None."""
        return _jsonable(asdict(self))


# --------------------------------------------------------------------------------------
# Wall-clock latency by stage
# --------------------------------------------------------------------------------------

WALL_STAGES: tuple[tuple[str, str, str, bool], ...] = (
    ("pose_to_robot", "pose_pub_ns", "pose_rx_ns", True),
    ("robot_wait", "pose_rx_ns", "plan_start_ns", False),
    ("plan", "plan_start_ns", "plan_end_ns", False),
    ("send", "plan_end_ns", "cmd_pub_ns", False),
    ("cmd_to_world", "cmd_pub_ns", "cmd_rx_ns", True),
    ("world_wait", "cmd_rx_ns", "applied_ns", False),
    ("sense_to_act", "pose_pub_ns", "cmd_rx_ns", False),
    ("end_to_end", "pose_pub_ns", "applied_ns", False),
)
"""(stage, from stamp, to stamp, crosses clocks). ``sense_to_act``: the world published a
pose -> the world received the command planned on it; ``end_to_end``: ... and applied it.
Both ends of those are the world's clock, so they hold across hosts too. A stage that
crosses clocks (world <-> robot) is measured only for commands whose robot shares the
world's clock (one host)."""
TRANSPORT_STAGE = "transport"
"""``sense_to_act`` less the robot's own time (pose received -> command published): the
pose's way out plus the command's way back, through every router between. Each of its two
differences is taken on one clock (the world's, the robot's), so it holds across hosts
without synchronised clocks."""
DIRECT_ROUTER = "world"
"""`router_groups` name of the robots connected to the world's own router."""


def _percentiles(ms: np.ndarray) -> dict[str, float | None]:
    return {"p50": round(float(np.percentile(ms, 50)), 3),
            "p99": round(float(np.percentile(ms, 99)), 3),
            "max": round(float(ms.max()), 3), "n": int(ms.size)}


def wall_latency_ms(stamps: np.ndarray) -> dict[str, dict[str, float | None]]:
    """p50, p99 and max [ms] and the count of every `WALL_STAGES` stage and of
    `TRANSPORT_STAGE`.

    Args:
        stamps: (K, 9) int64, one row per applied command, columns `TIMING_COLUMNS`
            (0: not stamped).

    Returns:
        stage -> {"p50", "p99", "max", "n"}; stages with no measurable command are left out.
    """
    stamps = np.asarray(stamps, dtype=np.int64).reshape(-1, len(TIMING_COLUMNS))
    col = {name: stamps[:, k] for k, name in enumerate(TIMING_COLUMNS)}
    same_clock = (col["robot_clock"] == col["world_clock"]) & (col["robot_clock"] != 0)
    out: dict[str, dict[str, float | None]] = {}
    for stage, start, end, crosses in WALL_STAGES:
        ok = (col[start] > 0) & (col[end] > 0)
        if crosses:
            ok &= same_clock
        ms = (col[end][ok] - col[start][ok]) / 1e6
        if ms.size:
            out[stage] = _percentiles(ms)
    ends = ("pose_pub_ns", "pose_rx_ns", "cmd_pub_ns", "cmd_rx_ns")
    ok = np.all([col[name] > 0 for name in ends], axis=0)
    world_ns = col["cmd_rx_ns"][ok] - col["pose_pub_ns"][ok]
    robot_ns = col["cmd_pub_ns"][ok] - col["pose_rx_ns"][ok]
    if world_ns.size:
        out[TRANSPORT_STAGE] = _percentiles((world_ns - robot_ns) / 1e6)
    return out


def router_groups(robot_ids: Iterable[int], relays: Mapping[str, Iterable[int]]
                  ) -> dict[str, list[int]]:
    """Router name -> the robots connected to it: each relay's robots (`relays`, the world's
    ``--relay`` list by certificate name), and `DIRECT_ROUTER` for the rest (those that
    dial the world's router). Empty without relays."""
    if not relays:
        return {}
    behind = {name: sorted(int(i) for i in ids) for name, ids in relays.items()}
    relayed = {i for ids in behind.values() for i in ids}
    direct = sorted(int(i) for i in robot_ids if int(i) not in relayed)
    return {DIRECT_ROUTER: direct, **behind} if direct else behind


def wall_latency_ms_by_group(robot: np.ndarray, stamps: np.ndarray,
                             groups: Mapping[str, Iterable[int]]
                             ) -> dict[str, dict[str, dict[str, float | None]]]:
    """`wall_latency_ms` of the commands of each group of robots.

    Args:
        robot: (K,) the robot id of each row of `stamps`.
        stamps: (K, 9) as `wall_latency_ms`.
        groups: group name -> its robot ids (e.g. `router_groups`).
    """
    robot = np.asarray(robot, dtype=np.int64).reshape(-1)
    stamps = np.asarray(stamps, dtype=np.int64).reshape(-1, len(TIMING_COLUMNS))
    if robot.size != stamps.shape[0]:
        raise ValueError(f"{robot.size} robot ids for {stamps.shape[0]} rows of stamps")
    return {name: wall_latency_ms(stamps[np.isin(robot, np.fromiter(ids, dtype=np.int64))])
            for name, ids in groups.items()}


# --------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------

def find_turns(t_s: np.ndarray, heading_rad: np.ndarray, *,
               min_rate_radps: float = TURN_RATE_MIN_RADPS,
               min_angle_rad: float = TURN_ANGLE_MIN_RAD) -> list[Turn]:
    """The turns of one heading history (see the module docstring).

    Args:
        t_s: (T,) increasing times.
        heading_rad: (T,) headings, wrapped or not.
    """
    t = np.asarray(t_s, dtype=float)
    if t.size < 2:
        return []
    dtheta = np.diff(np.unwrap(np.asarray(heading_rad, dtype=float)))
    rate = dtheta / np.diff(t)
    sign = np.where(rate >= min_rate_radps, 1, np.where(rate <= -min_rate_radps, -1, 0))
    # Run boundaries: where the sign changes (interval indices).
    edges = np.flatnonzero(np.diff(sign)) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [sign.size]])  # exclusive
    turns = []
    for i0, i1 in zip(starts.tolist(), ends.tolist()):
        s = int(sign[i0])
        if s == 0:
            continue
        angle = abs(float(dtheta[i0:i1].sum()))
        if angle >= min_angle_rad:
            turns.append(Turn(sign=s, start_s=float(t[i0]), end_s=float(t[i1]),
                              angle_rad=angle))
    return turns


def find_reversals(turns: Sequence[Turn], window_s: float = REVERSAL_WINDOW_S
                   ) -> list[tuple[Turn, Turn]]:
    """(previous turn, reversing turn) for every turn that follows a turn of the opposite
    sign and starts within window_s of its end."""
    return [
        (prev, cur) for prev, cur in zip(turns, turns[1:])
        if cur.sign == -prev.sign and cur.start_s - prev.end_s <= window_s + _TIME_EPS_S
    ]


def count_reversals(turns: Sequence[Turn], window_s: float = REVERSAL_WINDOW_S) -> int:
    """Turns that follow a turn of the opposite sign and start within window_s of its end."""
    return len(find_reversals(turns, window_s))


@dataclass(frozen=True)
class PlanInForce:
    """One robot's applied commands as a step function of time, for `reversal_causes`.

    Args:
        t_applied_s: (C,) increasing application times.
        status: (C,) `PlanStatus` values.
        side: (C,) -1 RIGHT, 0 NONE, +1 LEFT, or None when not recorded.
        resolved: (C,) resolved threat id, NaN for none, or None when not recorded.
    """

    t_applied_s: np.ndarray
    status: np.ndarray
    side: np.ndarray | None
    resolved: np.ndarray | None

    def at(self, t_s: float) -> tuple[str, int, float] | None:
        """(status, side, resolved id) of the last command applied at or before t_s."""
        i = int(np.searchsorted(self.t_applied_s, t_s + _TIME_EPS_S, side="right")) - 1
        if i < 0:
            return None
        side = int(self.side[i]) if self.side is not None else 0
        resolved = float(self.resolved[i]) if self.resolved is not None else math.nan
        return str(self.status[i]), side, resolved


def reversal_causes(t_s: np.ndarray, heading_rad: np.ndarray, speed_mps: np.ndarray,
                    plans: PlanInForce) -> dict[str, int]:
    """The reversals of one heading history by cause (module docstring).

    Args:
        t_s, heading_rad, speed_mps: (T,) the robot's run.
        plans: its applied commands.

    Returns:
        {cause: count} over `REVERSAL_CAUSES`; the counts sum to `oscillations`.
    """
    counts = dict.fromkeys(REVERSAL_CAUSES, 0)
    t = np.asarray(t_s, dtype=float)
    speed = np.asarray(speed_mps, dtype=float)
    known = plans.side is not None and plans.resolved is not None
    for prev, cur in find_reversals(find_turns(t, heading_rad)):
        i = min(int(np.searchsorted(t, cur.start_s - _TIME_EPS_S)), t.size - 1)
        a, b = plans.at(prev.start_s), plans.at(cur.start_s)
        if abs(float(speed[i])) < SLOW_REVERSAL_MPS:
            cause = "slow"
        elif a is None or b is None:
            cause = "unknown"
        elif "escape" in (a[0], b[0]):
            cause = "escape"
        elif not known:
            cause = "unknown"
        elif math.isnan(a[2]) or math.isnan(b[2]) or 0 in (a[1], b[1]):
            cause = "no_via_point"
        elif a[2] != b[2]:
            cause = "threat_switch"
        else:
            cause = "side_flip" if a[1] != b[1] else "same_via_point"
        counts[cause] += 1
    return counts


def oscillations(t_s: np.ndarray, heading_rad: np.ndarray) -> int:
    """Reversals of turning direction of one heading history."""
    return count_reversals(find_turns(t_s, heading_rad))


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
    hit = np.flatnonzero((dist <= tolerance_m) & (np.asarray(t_s) <= time_limit_s + _TIME_EPS_S))
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
    episodes, robot_min_gap = scan.episodes, scan.robot_min_gap_m
    min_gap = float(robot_min_gap.min()) if robot_min_gap.size else math.inf
    for t_ev, a, b in contact_events:
        if not _confirmed(traj, spec, float(t_ev), int(a), int(b), world_dt_s):
            episodes.append(ContactEpisode(float(t_ev), int(a), int(b), math.nan))
    has_side = commands.side is not None and commands.resolved is not None
    planned = ~np.isin(commands.status, list(NOT_PLANNING_STATUSES))

    per_robot: list[RobotMetrics] = []
    for k, rid in enumerate(spec.robot_ids.tolist()):
        t, xy, heading = _robot_run(traj, k, spec)
        idx = arrival_index(t, xy, spec.goal_m[k], spec.goal_tolerance_m, spec.time_limit_s)
        end = idx + 1 if idx is not None else t.size
        straight = float(np.hypot(*(spec.goal_m[k] - spec.start_m[k])))
        ideal = straight / float(spec.v_max_mps[k])
        length = path_length_m(xy[:end])
        reach = float(np.hypot(*(xy[idx] - xy[0]))) if idx is not None else 0.0
        t_goal = float(t[idx]) if idx is not None else None
        mine = commands.robot == rid
        flips: tuple[int | None, int | None] = (None, None)
        if has_side:
            assert commands.side is not None and commands.resolved is not None
            flips = side_flips(commands.seq[mine], commands.side[mine],
                               commands.resolved[mine])
        misses, cycles = deadline_misses(commands.seq[mine], commands.pose_stamp_s[mine],
                                         control_period_s, world_dt_s)
        plan = commands.plan_ms[mine & planned]
        order = np.argsort(commands.t_applied_s[mine], kind="stable")
        in_force = PlanInForce(
            commands.t_applied_s[mine][order], commands.status[mine][order],
            commands.side[mine][order] if has_side and commands.side is not None else None,
            (commands.resolved[mine][order]
             if has_side and commands.resolved is not None else None),
        )
        speed = _run_speed(traj, k, t.size)
        gap_k = float(robot_min_gap[k])
        per_robot.append(RobotMetrics(
            id=int(rid),
            arrived=idx is not None,
            time_to_goal_s=t_goal,
            ideal_time_s=ideal,
            time_ratio=(t_goal / ideal if t_goal is not None and ideal > 0 else None),
            path_length_m=length,
            straight_m=straight,
            path_ratio=(length / reach if idx is not None and reach > 0 else None),
            oscillations=oscillations(t[:end], heading[:end]),
            reversal_causes=reversal_causes(t[:end], heading[:end], speed[:end], in_force),
            side_flips=flips[0],
            side_flips_same_threat=flips[1],
            contacts=sum(1 for e in episodes if rid in (e.id_a, e.id_b)),
            min_gap_m=_finite(gap_k),
            plan_ms_mean=float(plan.mean()) if plan.size else None,
            plan_ms_p50=_pct(plan, 50),
            plan_ms_p99=_pct(plan, 99),
            plan_ms_max=float(plan.max()) if plan.size else None,
            cycles=cycles,
            deadline_misses=misses,
        ))

    arrived = [r for r in per_robot if r.arrived]
    plan_all = commands.plan_ms[planned]
    latency = (commands.t_applied_s - commands.pose_stamp_s) * 1000.0
    cycles_total = sum(r.cycles for r in per_robot)
    misses_total = sum(r.deadline_misses for r in per_robot)
    n = len(per_robot)
    pairs = sorted({tuple(sorted((e.id_a, e.id_b))) for e in episodes})
    return RunMetrics(
        robots=n,
        arrived=len(arrived),
        success=bool(n > 0 and len(arrived) == n and not episodes),
        contacts=len(episodes),
        contact_pairs=[list(p) for p in pairs],
        min_gap_m=_finite(min_gap),
        min_gap_robots_m=_finite(scan.robots_min_gap_m),
        min_gap_obstacles_m=_finite(scan.obstacles_min_gap_m),
        path_length_mean_m=_mean(r.path_length_m for r in arrived),
        path_ratio_mean=_mean(r.path_ratio for r in arrived),
        time_to_goal_mean_s=_mean(r.time_to_goal_s for r in arrived),
        time_ratio_mean=_mean(r.time_ratio for r in arrived),
        makespan_s=(max(r.time_to_goal_s or 0.0 for r in arrived)
                    if arrived and len(arrived) == n else None),
        oscillations_per_robot=float(np.mean([r.oscillations for r in per_robot])) if n else 0.0,
        oscillations_total=sum(r.oscillations for r in per_robot),
        oscillations_max=max((r.oscillations for r in per_robot), default=0),
        reversal_causes_per_robot={
            c: (float(np.mean([r.reversal_causes[c] for r in per_robot])) if n else 0.0)
            for c in REVERSAL_CAUSES
        },
        side_flips_per_robot=(float(np.mean([r.side_flips or 0 for r in per_robot]))
                              if has_side and n else None),
        plan_ms_mean=float(plan_all.mean()) if plan_all.size else None,
        plan_ms_p50=_pct(plan_all, 50),
        plan_ms_p99=_pct(plan_all, 99),
        plan_ms_max=float(plan_all.max()) if plan_all.size else None,
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
