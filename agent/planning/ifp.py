"""Iterative Forecast Planner (IFP): the baseline via-point planner.

One planning cycle, as `plan_ifp` runs it:

1. Neighbours: the others inside the sensing radius, at most `max_neighbors`.
2. Escape: if the robot is inside an inflated disc (Q <= L, Eq. 8) the plan is
   [P, escape point, goal], status ESCAPE (the deepest disc wins, ties by id); for a robot
   standing (below `ESCAPE_STANDING_MPS`) just [P, escape point] (see there).
3. Threats of Eq. (6) at the robot's measured velocity, ranked by TCPA (Eq. 7). If there
   are any, the nearest one is resolved from P: its RIGHT/LEFT candidates (Eqs. 9-14) are
   built and the selector picks one (IFP: the earliest, smallest lambda*). If neither
   survives the plan is [P, goal], status NO_FEASIBLE.
4. Iteration (up to `max_depth` via-points in all): every leg of the waypoint list, from
   the robot outwards, is re-checked with `threats.legs_threats` at top speed, starting at
   the time the robot reaches the leg's start. The most imminent resolvable threat on a
   leg gets a via-point, inserted into that leg, built from the leg's start with the
   others advanced to that time; the shortened leg is then checked again. A leg whose
   threats all lack candidates is left as it is.

Choices the paper leaves open (documented here, tested in
tests/unit/agent/planning/test_ifp.py):

- Step 3 uses the measured velocity v_r as in Eq. (3). A robot that stands still (v_r = 0)
  sees no static obstacle as a threat under Eq. (6), so when Eq. (6) finds nothing the
  direct leg P -> goal still goes through the leg check of step 4
  (`Mechanisms.direct_leg_check`; not in the paper, off in its profile: then a cycle whose
  Eq. (6) finds nothing plans [P, goal]).
- The leg check counts other j as a threat when the closest approach on the leg is below
  its inflated radius L_j (not D_thresh, which is a detection radius): the plan must clear
  the inflated discs. Grazing within `LEG_GRAZE_TOL_M` is not a threat, so a leg that is
  tangent to a disc by construction is not flagged by rounding.
- The leg from a via-point's predecessor to the via-point is tangent to the disc it
  resolves, so that disc is excluded on that leg; it is checked on every other leg.
- Via-points are pushed radially `VIA_MARGIN_M` out of the moving disc they resolve
  (`viapoints.candidate_pair(margin_m=...)`). On the boundary itself a via-point
  would have no tangent to the same disc, and a next leg that cuts back into it (the
  usual case when the goal lies behind the obstacle) could not be fixed; from outside it
  gets a further tangent, so the iteration wraps the disc with a short polygon. The leg
  into a pushed via-point still clears the disc (it runs outside the tangent line).
- A candidate is only built from a leg start outside the disc by more than
  `ON_DISC_REL_TOL` of L.
- Step 3 drops threats whose TCPA is more than `GOAL_TCPA_MARGIN_S` past the time the
  robot needs to reach its goal at top speed (`Mechanisms.goal_tcpa_filter`; not in the
  paper, off in its profile): near the goal the measured velocity of an
  overshoot points at whoever stands beyond it, and resolving that sends the robot round
  its goal. Such others still count on the legs of step 4.
- With `Mechanisms.keep_plan` (eifp-mpc's default), the plan built in step 4 gives way to
  last cycle's via-points while those still hold (`kept_plan.kept_waypoints`).
- `ViaPlan.via_point_m` is the first via-point after P (where the robot heads now), with
  the side and the id of the threat that via-point resolves.

`Mechanisms` holds this project's additions to this cycle (`mechanisms` picks them by
planner and profile; `PAPER_MECHANISMS`, every one off, is the paper's cycle). Their
reasons are documented on the class and in docs/method.md.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from agent.core.config import PlannerConfig
from agent.core.types import Observation, Others, PlanStatus, Side, Threat
from agent.planning.kept_plan import kept_waypoints
from agent.planning.mechanisms import PAPER_MECHANISMS, Mechanisms, mechanisms
from agent.planning.threats import (
    as_complex,
    legs_threats,
    nearby_others,
    rank_threats,
    ranked,
    require_finite,
    threat_records,
)
from agent.planning.viapoints import (
    SIDES,
    candidate_pair,
    escape_point,
    escape_point_many,
    inflated_radius,
)

ESCAPE_STANDING_MPS = 0.05
"""Below this speed an escaping robot's plan ends at the escape point, without the goal.
The escape point lies a few cm outside the disc, straight away from its centre; when the
goal lies back past the disc, the cubic spline through [P, escape point, goal] leaves by a
few cm and turns back through the disc, and an MPC linearised about standing still (at
v = 0 a turn does not move the position to first order) finds standing best, so two robots
inside each other's inflated discs, each goal behind the other, would stand. The short
plan makes the reference turn
to the escape direction and leave; the next cycle, outside, plans round the disc. A moving
robot keeps the goal in its escape plan (the reference then continues where it goes)."""

# Closest approaches this close to L still clear the disc [m] (tangent legs, rounding).
LEG_GRAZE_TOL_M = 1.0e-6

# Eq. (6) threats whose TCPA exceeds the time to the goal at top speed by more than this
# are not resolved [s].
GOAL_TCPA_MARGIN_S = 0.5

# A leg start within L * (1 + this) of a disc centre is on the disc: no tangent from it.
ON_DISC_REL_TOL = 1.0e-6

HEAD_ON_MAX_DEG = 45.0
"""A threat whose course lies within this angle of the reciprocal of the robot's heading is
head-on (`is_head_on`)."""

HEAD_ON_MIN_SPEED_MPS = 0.2
"""Below this speed (the robot's or the other's) a course has no direction: not head-on."""

_HEAD_ON_COS = math.cos(math.radians(HEAD_ON_MAX_DEG))

def is_head_on(heading_rad: float, speed_mps: float, other_velocity_mps: np.ndarray) -> bool:
    """Whether an other's course lies within `HEAD_ON_MAX_DEG` of the reciprocal of the
    robot's heading, both moving at least `HEAD_ON_MIN_SPEED_MPS`."""
    vx, vy = float(other_velocity_mps[0]), float(other_velocity_mps[1])
    other_speed = math.hypot(vx, vy)
    if speed_mps < HEAD_ON_MIN_SPEED_MPS or other_speed < HEAD_ON_MIN_SPEED_MPS:
        return False
    towards = -(vx * math.cos(heading_rad) + vy * math.sin(heading_rad)) / other_speed
    return towards >= _HEAD_ON_COS

# select(k, points, times, leg_start, leg_end) -> index into SIDES of the chosen candidate
# of other k, or None if none is acceptable. points: the (RIGHT, LEFT) via-points as
# complex numbers x + iy [m]; times: their lambda* [s], inf where infeasible; leg_start,
# leg_end: the leg A -> B being split, complex [m].
CandidateSelector = Callable[
    [int, tuple[complex, complex], tuple[float, float], complex, complex], "int | None"
]


@dataclass(frozen=True)
class ViaPlan:
    """The waypoint plan of one IFP/eIFP cycle.

    Args:
        status: OK, ESCAPE or NO_FEASIBLE.
        waypoints_m: (M, 2) robot position, via-points in travel order, goal (M >= 2).
        via_point_m: (2,) the first via-point after the robot's position, or None.
        side: side of `via_point_m` relative to the threat it resolves (NONE for escape).
        resolved_id: id of the other `via_point_m` resolves, or None.
        threats: the threats of Eq. (6) at the measured velocity, ranked by TCPA.
        resolved_sides: (other id, side) for every via-point, in travel order.
        threats_s: wall time of the threat assessment, when a timer was given (else 0).
    """

    status: PlanStatus
    waypoints_m: np.ndarray
    via_point_m: np.ndarray | None = None
    side: Side = Side.NONE
    resolved_id: int | None = None
    threats: tuple[Threat, ...] = ()
    resolved_sides: tuple[tuple[int, Side], ...] = ()
    threats_s: float = 0.0


def select_earliest(
    k: int,
    points: tuple[complex, complex],
    times: tuple[float, float],
    leg_start: complex,
    leg_end: complex,
) -> int | None:
    """IFP's rule: the feasible candidate reached first (smallest lambda*); ties -> RIGHT.

    Args:
        k: index of the other being resolved (unused).
        points: the (RIGHT, LEFT) candidates, complex [m] (unused).
        times: their lambda* [s], inf if infeasible.
        leg_start, leg_end: the leg being split (unused).

    Returns:
        Index into `SIDES`, or None if neither is feasible.
    """
    right, left = times
    if right == math.inf and left == math.inf:
        return None
    return 1 if left < right else 0  # equal times: RIGHT


def validate_inputs(observation: Observation, config: PlannerConfig) -> None:
    """Raise `ValueError` on non-finite or meaningless planning inputs.

    `Observation`, `EgoState` and `Others` reject non-finite values when constructed, so
    their arrays are not scanned again here; this checks the scalars the planner reads.
    `PlannerConfig` refuses out-of-range and non-finite fields when it is built
    (`agent.core.config.field_range_error`), so the configuration needs no check here.
    """
    ego = observation.ego
    require_finite(
        "observation",
        ego.x_m,
        ego.y_m,
        ego.heading_rad,
        ego.v_mps,
        float(observation.goal_m[0]),
        float(observation.goal_m[1]),
        observation.radius_m,
        observation.limits.v_max_mps,
    )
    if not observation.limits.v_max_mps > 0.0:
        raise ValueError("limits.v_max_mps: must be positive")


def plan_ifp(
    observation: Observation, config: PlannerConfig, timer: Callable[[], float] | None = None
) -> ViaPlan:
    """One IFP cycle: earliest-feasible via-points, iterated up to `max_depth`, with ifp's
    mechanisms under `config.profile` (`mechanisms`).

    Args:
        observation: what the robot knows now.
        config: planner settings (d_safety, T_max, sensing, max_depth, profile).

    Returns:
        The waypoint plan; feed `waypoints_m` to `spline.build_reference`.

    Raises:
        ValueError: on non-finite inputs or configuration.
    """
    return plan_via_points(observation, config, lambda _others: select_earliest, timer=timer,
                           mech=mechanisms("ifp", config))


@dataclass(frozen=True)
class Decisions:
    """What earlier cycles and eIFP's encounter rules decided, passed explicitly into a cycle.

    Args:
        ignored_ids: others the robot leaves to themselves (eIFP's stand-on encounters,
            `agent.planning.encounters`): never resolved, on no leg; still escaped from if
            the robot is inside their inflated disc, and still listed in `ViaPlan.threats`.
        committed_ids: others the robot is already giving way to (eIFP's encounter rules):
            they stay threats while still approaching (0 < TCPA < 2 T_max), even when the
            robot's own swerve has pushed their DCPA past the threshold.
        primary_id: the other the previous cycle's first via-point resolved: with
            `Mechanisms.commitment`, a head-on one is resolved first again unless another
            one's TCPA is more than `Mechanisms.primary_hold_s` smaller.
        escape_id: the other the previous cycle escaped from, if it did
            (`Mechanisms.escape_band_m`).
        previous: the previous cycle's plan, if it was OK (`Mechanisms.keep_plan`).
    """

    ignored_ids: frozenset[int] = frozenset()
    committed_ids: frozenset[int] = frozenset()
    primary_id: int | None = None
    escape_id: int | None = None
    previous: ViaPlan | None = None


@dataclass(frozen=True)
class Assessment:
    """Step 1 and Eqs. (3)-(7) of one cycle: the neighbours and their threat ranking.

    Args:
        position_m: (2,) the robot's position P [m].
        others: the neighbours (sensing radius and cap applied), K of them.
        radius_m: (K,) their inflated radii L (Eq. 8) [m].
        index: indices of Eq. (6)'s threats, ranked by TCPA (Eq. 7).
        tcpa_s, dcpa_m: (K,) Eqs. (4)-(5) at the measured velocity.
        speed_mps: the robot's top speed, the speed of the velocity cone [m/s].
    """

    position_m: np.ndarray
    others: Others
    radius_m: np.ndarray
    index: np.ndarray
    tcpa_s: np.ndarray
    dcpa_m: np.ndarray
    speed_mps: float


def assess_threats(observation: Observation, config: PlannerConfig,
                   mech: Mechanisms = PAPER_MECHANISMS) -> Assessment:
    """Steps 1 and 3: the neighbours, and Eq. (6)'s threats at the measured velocity.

    Raises:
        ValueError: on non-finite inputs or configuration.
    """
    validate_inputs(observation, config)
    ego = observation.ego
    p = np.array([ego.x_m, ego.y_m])
    threats_cfg = config.threats
    others = nearby_others(p, observation.others, threats_cfg.sensing_radius_m,
                           threats_cfg.max_neighbors)
    radius = inflated_radius(observation.radius_m, others.radius_m, config.safety.d_safety_m)
    v_r = ego.v_mps * np.array([math.cos(ego.heading_rad), math.sin(ego.heading_rad)])
    d_thresh: float | np.ndarray = config.dcpa_threshold_m(observation.radius_m)
    if mech.inflated_threats:
        d_thresh = radius
    index, tcpa, dcpa = rank_threats(p, v_r, others, d_thresh, threats_cfg.t_max_s)
    return Assessment(position_m=p, others=others, radius_m=radius,
                      index=index, tcpa_s=tcpa, dcpa_m=dcpa,
                      speed_mps=float(observation.limits.v_max_mps))


def plan_via_points(
    observation: Observation,
    config: PlannerConfig,
    make_selector: Callable[[Others], CandidateSelector],
    decisions: Decisions = Decisions(),
    timer: Callable[[], float] | None = None,
    mech: Mechanisms = PAPER_MECHANISMS,
) -> ViaPlan:
    """The IFP cycle (module docstring) with a pluggable candidate selector.

    Args:
        observation: what the robot knows now.
        config: planner parameters.
        make_selector: given the neighbours the cycle plans against (after the sensing
            radius and neighbour cap), returns the rule that picks one candidate of a
            threat; IFP's is `select_earliest`, eIFP's cost rule is in `agent.planning.eifp`.
        decisions: what earlier cycles decided (`Decisions`).
        timer: a wall clock, only to time the threat assessment (`ViaPlan.threats_s`);
            it never influences the plan.
        mech: the mechanisms of the cycle (`Mechanisms`); the paper's by default.

    Raises:
        ValueError: on non-finite inputs or configuration.
    """
    t_start = timer() if timer is not None else 0.0
    assessment = assess_threats(observation, config, mech)
    select = make_selector(assessment.others)
    threats_s = timer() - t_start if timer is not None else 0.0
    return plan_cycle(observation, config, assessment, select, decisions, mech, threats_s)


def plan_cycle(
    observation: Observation,
    config: PlannerConfig,
    assessment: Assessment,
    select: CandidateSelector,
    decisions: Decisions,
    mech: Mechanisms,
    threats_s: float = 0.0,
) -> ViaPlan:
    """Steps 2-4 after the assessment: escape, resolve the first threat, iterate the legs.

    Args:
        observation: what the robot knows now.
        config: planner parameters.
        assessment: the cycle's `assess_threats`.
        select: the candidate selector for the cycle's neighbours.
        decisions: what earlier cycles and the encounter rules decided (`Decisions`).
        mech: the mechanisms of the cycle.
        threats_s: wall time the assessment took (reported in `ViaPlan.threats_s`).
    """
    others, p, goal = assessment.others, assessment.position_m, observation.goal_m
    t_max_s = config.threats.t_max_s
    index = resolution_order(observation, assessment, decisions, mech, t_max_s)
    threats = threat_records(index.recorded, assessment.tcpa_s, assessment.dcpa_m, others)
    direct = ViaPlan(status=PlanStatus.OK, waypoints_m=np.array((p, goal)), threats=threats,
                     threats_s=threats_s)
    if len(others) == 0:
        return direct
    escaping = escape(observation, assessment, decisions.escape_id, mech)
    if escaping is not None:
        return dataclasses.replace(escaping, threats=threats, threats_s=threats_s)

    clearance = np.where(index.ignored, -math.inf, assessment.radius_m - LEG_GRAZE_TOL_M)
    world = _World(others, assessment.radius_m, assessment.speed_mps, select, mech.via_margin_m,
                   t_max_s if mech.horizon_via_points else math.inf)
    legs = _Legs(p, goal)
    if index.resolve.size:
        if not resolve_first(world, legs, index.resolve, mech):
            new_wps = legs.points
            plan = None
            if mech.keep_plan:
                plan = keep_previous(decisions.previous, new_wps, assessment, clearance,
                                     t_max_s, threats, threats_s)
            return plan or dataclasses.replace(direct, status=PlanStatus.NO_FEASIBLE)
    elif not mech.direct_leg_check:
        # The paper declares threats by Eq. (6) alone: none, so the plan is [P, goal].
        return direct
    iterate_legs(world, legs, assessment, clearance, t_max_s, config.reference.max_depth)
    if mech.keep_plan:
        kept = keep_previous(decisions.previous, legs.points, assessment, clearance, t_max_s,
                             threats, threats_s)
        if kept is not None:
            return kept
    return legs.plan(others.ids, threats, threats_s)


@dataclass(frozen=True)
class ResolutionOrder:
    """The threats a cycle resolves, in order, after the encounter and commitment decisions.

    Args:
        recorded: Eq. (6)'s threats plus the committed ones, ranked (`ViaPlan.threats`).
        resolve: the ones resolved from the robot's position, in order.
        ignored: (K,) bool, the others left to themselves (on no leg).
    """

    recorded: np.ndarray
    resolve: np.ndarray
    ignored: np.ndarray


def resolution_order(observation: Observation, assessment: Assessment, decisions: Decisions,
                     mech: Mechanisms, t_max_s: float) -> ResolutionOrder:
    """Which threats step 3 resolves and in what order: Eq. (6)'s ranking, plus the others
    given way to, minus those after the goal (`Mechanisms.goal_tcpa_filter`) and those left
    to themselves, with last cycle's head-on first threat kept first
    (`Mechanisms.commitment`)."""
    others, tcpa = assessment.others, assessment.tcpa_s
    index = assessment.index
    if decisions.committed_ids and len(others):
        index = _with_committed(index, tcpa, others, decisions.committed_ids, t_max_s)
    recorded = index
    # Closest approaches after the robot can be at its goal are not its business: near the
    # goal, an overshoot would otherwise point the measured velocity at someone beyond it
    # and send the robot round the goal. The leg to the goal is still checked.
    if mech.goal_tcpa_filter:
        to_goal_m = observation.goal_distance_m
        if to_goal_m is None:
            p, goal = assessment.position_m, observation.goal_m
            to_goal_m = math.hypot(goal[0] - p[0], goal[1] - p[1])
        to_goal_s = to_goal_m / float(observation.limits.v_max_mps)
        index = index[tcpa[index] <= to_goal_s + GOAL_TCPA_MARGIN_S]
    ignored = np.zeros(len(others), dtype=bool)
    if decisions.ignored_ids and len(others):
        ignored = np.fromiter((i in decisions.ignored_ids for i in others.ids.tolist()),
                              dtype=bool, count=len(others))
        index = index[~ignored[index]]
    if mech.commitment and decisions.primary_id is not None and index.size > 1:
        index = _primary_first(observation, index, tcpa, others, decisions.primary_id,
                               mech.primary_hold_s)
    return ResolutionOrder(recorded=recorded, resolve=index, ignored=ignored)


def _primary_first(observation: Observation, index: np.ndarray, tcpa: np.ndarray,
                   others: Others, primary_id: int, hold_s: float) -> np.ndarray:
    """`index` with last cycle's first threat moved first, if it is head-on and its TCPA is
    within `hold_s` of the most imminent one's."""
    hit = (others.ids[index] == primary_id).nonzero()[0]
    if not hit.size:
        return index
    j = int(index[hit[0]])
    ego = observation.ego
    if (is_head_on(ego.heading_rad, ego.v_mps, others.velocity_mps[j])
            and tcpa[j] <= tcpa[index[0]] + hold_s):
        return np.concatenate((index[hit[:1]], np.delete(index, hit[0])))
    return index


def escape(observation: Observation, assessment: Assessment, escape_id: int | None,
           mech: Mechanisms) -> ViaPlan | None:
    """Step 2: inside an inflated disc no tangent exists; the plan steers straight out of the
    deepest one (ties by id), or None when the robot is inside none. With
    `Mechanisms.escape_all`, out of every disc it is inside (`viapoints.escape_point_many`).

    With `Mechanisms.escape_band_m`, the escape from last cycle's disc (`escape_id`) goes on
    until the robot is that far outside it: a robot that left by a centimetre would plan
    round the disc, graze it and escape again."""
    others, radius, p = assessment.others, assessment.radius_m, assessment.position_m
    ego = observation.ego
    gap = np.abs(as_complex(others.position_m) - complex(ego.x_m, ego.y_m)) - radius
    band = mech.escape_band_m
    if escape_id is not None and band > 0.0:
        held = (others.ids == escape_id) & (gap <= band)
        gap = np.where(held, np.minimum(gap, 0.0), gap)
    inside = (gap <= 0.0).nonzero()[0]
    if not inside.size:
        return None
    j = int(inside[np.lexsort((others.ids[inside], gap[inside]))[0]])
    if mech.escape_all and inside.size > 1:
        out = escape_point_many(p, others.position_m[inside], radius[inside] + band,
                                ego.heading_rad)
    else:
        out = escape_point(p, others.position_m[j], float(radius[j]) + band, ego.heading_rad)
    goal = observation.goal_m
    return ViaPlan(
        status=PlanStatus.ESCAPE,
        waypoints_m=np.stack((p, out) if ego.v_mps < ESCAPE_STANDING_MPS else (p, out, goal)),
        via_point_m=out,
        side=Side.NONE,
        resolved_id=int(others.ids[j]),
    )


class _Legs:
    """The waypoint list of a cycle while it grows: complex points x + iy, per leg the other
    it is tangent to (-1: none), per waypoint the (other index, side) it resolves."""

    def __init__(self, p: np.ndarray, goal: np.ndarray) -> None:
        self.points = [complex(p[0], p[1]), complex(goal[0], goal[1])]
        self.excluded = [-1]
        self.chosen: list[tuple[int, Side] | None] = [None, None]

    def insert(self, leg: int, via: tuple[complex, Side], k: int) -> None:
        """Split leg `leg` at a via-point that resolves other k."""
        self.points.insert(leg + 1, via[0])
        self.excluded[leg : leg + 1] = [k, -1]
        self.chosen.insert(leg + 1, (k, via[1]))

    def arrival_s(self, speed_mps: float) -> list[float]:
        """When the robot reaches each waypoint at top speed [s]."""
        pts = self.points
        return [0.0, *itertools.accumulate(abs(b - a) / speed_mps for a, b in zip(pts, pts[1:]))]

    def plan(self, ids: np.ndarray, threats: tuple[Threat, ...], threats_s: float) -> ViaPlan:
        """The finished plan (status OK)."""
        waypoints = np.array([(z.real, z.imag) for z in self.points])
        head = self.chosen[1]
        return ViaPlan(
            status=PlanStatus.OK,
            waypoints_m=waypoints,
            via_point_m=None if head is None else waypoints[1].copy(),
            side=Side.NONE if head is None else head[1],
            resolved_id=None if head is None else int(ids[head[0]]),
            threats=threats,
            resolved_sides=tuple((int(ids[c[0]]), c[1]) for c in self.chosen if c is not None),
            threats_s=threats_s,
        )


def resolve_first(world: _World, legs: _Legs, order: np.ndarray, mech: Mechanisms) -> bool:
    """Step 3: the first via-point, for the first threat in `order` (with
    `Mechanisms.horizon_via_points`, the first one that has a feasible candidate).

    Returns:
        False when none is resolvable (the cycle is NO_FEASIBLE).
    """
    candidates = order.tolist() if mech.horizon_via_points else order.tolist()[:1]
    for k in candidates:
        split = world.resolve(legs.points[0], 0.0, legs.points[1], k)
        if split is not None:
            legs.insert(0, split, k)
            return True
    return False


def iterate_legs(world: _World, legs: _Legs, assessment: Assessment, clearance: np.ndarray,
                 t_max_s: float, max_depth: int) -> None:
    """Step 4: re-check every leg from the last split on and split the first resolvable one,
    until no leg needs a via-point or `max_depth` via-points are placed."""
    others = assessment.others
    position = as_complex(others.position_m)
    velocity = as_complex(others.velocity_mps)
    first = 0
    while len(legs.points) - 2 < max_depth:
        wps = legs.points
        arrival = legs.arrival_s(assessment.speed_mps)
        hit, leg_tcpa = legs_threats(wps[first:-1], wps[first + 1:], arrival[first:-1],
                                     assessment.speed_mps, position, velocity, clearance,
                                     t_max_s, legs.excluded[first:])
        found = None
        for row in np.flatnonzero(hit.any(axis=1)).tolist():
            leg = first + row
            for k in ranked(hit[row].nonzero()[0], leg_tcpa[row], others.ids).tolist():
                split = world.resolve(wps[leg], arrival[leg], wps[leg + 1], k)
                if split is not None:
                    found = (leg, split, k)
                    break
            if found is not None:
                break
        if found is None:
            return
        leg, split, k = found
        legs.insert(leg, split, k)
        first = leg


def keep_previous(previous: ViaPlan | None, new_wps: list[complex], assessment: Assessment,
                  clearance: np.ndarray, t_max_s: float, threats: tuple[Threat, ...],
                  threats_s: float) -> ViaPlan | None:
    """`Mechanisms.keep_plan`: last cycle's plan instead of the new one (`new_wps`, or
    [P, goal] when the cycle found no feasible via-point), if it still holds
    (`kept_plan.kept_waypoints`)."""
    if previous is None or not previous.resolved_sides:
        return None
    others = assessment.others
    kept = kept_waypoints(previous.waypoints_m, previous.resolved_sides, new_wps,
                          assessment.speed_mps,
                          as_complex(others.position_m), as_complex(others.velocity_mps),
                          clearance, t_max_s, others.ids)
    if kept is None:
        return None
    kept_wps, kept_sides = kept
    return ViaPlan(status=PlanStatus.OK, waypoints_m=kept_wps, via_point_m=kept_wps[1].copy(),
                   side=kept_sides[0][1], resolved_id=kept_sides[0][0], threats=threats,
                   resolved_sides=kept_sides, threats_s=threats_s)


COMMIT_RELEASE_FACTOR = 2.0
"""A committed threat (`_with_committed`) is released when its TCPA exceeds this multiple of
T_max."""


def _with_committed(
    index: np.ndarray,
    tcpa: np.ndarray,
    others: Others,
    committed_ids: frozenset[int],
    t_max_s: float,
) -> np.ndarray:
    """Eq. (6)'s threats plus the committed others still approaching, re-ranked by TCPA.

    Without this, a threat assessed at the measured velocity vanishes as soon as the robot
    swerves for it (its DCPA grows past D_thresh), the robot turns back to its goal, the
    threat reappears, and the robot weaves. A committed threat is released once it has
    been passed (TCPA <= 0) or is far from imminent (TCPA >= `COMMIT_RELEASE_FACTOR` T_max;
    not T_max itself: the swerve lengthens TCPA, which would release it at once).
    """
    # Plain Python over the (at most neighbour-cap) others: per-element numpy reads cost more.
    ranked_now = set(index.tolist())
    release_s = COMMIT_RELEASE_FACTOR * t_max_s
    extra = [
        k
        for k, (other_id, tcpa_k) in enumerate(zip(others.ids.tolist(), tcpa.tolist()))
        if other_id in committed_ids and 0.0 < tcpa_k < release_s and k not in ranked_now
    ]
    if not extra:
        return index
    merged = np.concatenate([index, np.array(extra, dtype=index.dtype)])
    return ranked(merged, tcpa, others.ids)


class _World:
    """The others of one cycle in plain floats, to build candidates one disc at a time."""

    def __init__(
        self, others: Others, radius: np.ndarray, speed: float, select: CandidateSelector,
        via_margin_m: float, via_time_max_s: float = math.inf,
    ) -> None:
        self.position = others.position_m.tolist()
        self.velocity = others.velocity_mps.tolist()
        self.radius = radius.tolist()
        self.speed = speed
        self.select = select
        self.via_margin_m = via_margin_m
        self.via_time_max_s = via_time_max_s

    def resolve(
        self, a: complex, start_time_s: float, b: complex, k: int
    ) -> tuple[complex, Side] | None:
        """The via-point that resolves other k on leg a -> b, or None if it has none.

        The candidates are built from a, with other k advanced to the time the robot is
        there; a start on (or in) the disc, within `ON_DISC_REL_TOL`, has none.
        """
        (cx, cy), (vx, vy), l_k = self.position[k], self.velocity[k], self.radius[k]
        cx += start_time_s * vx
        cy += start_time_s * vy
        ax, ay = a.real, a.imag
        if (cx - ax) ** 2 + (cy - ay) ** 2 <= (l_k * (1.0 + ON_DISC_REL_TOL)) ** 2:
            return None
        pair = candidate_pair(ax, ay, cx, cy, vx, vy, l_k, self.speed, self.via_margin_m,
                              self.via_time_max_s)
        if pair is None:
            return None
        (xr, yr, tr), (xl, yl, tl) = pair
        pick = self.select(k, (complex(xr, yr), complex(xl, yl)), (tr, tl), a, b)
        if pick is None or pair[pick][2] == math.inf:
            return None
        return complex(*pair[pick][:2]), SIDES[pick]
