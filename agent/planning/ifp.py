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
  last cycle's via-points while those still hold (`_keep_previous`).
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
from agent.planning.liveness import LivenessConfig
from agent.planning.threats import (
    as_complex,
    legs_threats,
    nearby_others,
    rank_threats,
    ranked,
    require_finite,
    threat_records,
)
from agent.planning.viapoints import SIDES, candidate_pair, escape_point, inflated_radius

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

# How far outside its inflated disc a via-point is placed [m].
VIA_MARGIN_M = 0.05

# A leg start within L * (1 + this) of a disc centre is on the disc: no tangent from it.
ON_DISC_REL_TOL = 1.0e-6

HEAD_ON_MAX_DEG = 45.0
"""A threat whose course lies within this angle of the reciprocal of the robot's heading is
head-on (`is_head_on`)."""

HEAD_ON_MIN_SPEED_MPS = 0.2
"""Below this speed (the robot's or the other's) a course has no direction: not head-on."""

_HEAD_ON_COS = math.cos(math.radians(HEAD_ON_MAX_DEG))

ARC_VIA_MARGIN_M = 0.3
"""How far outside its inflated disc a via-point lies when the reference joins the legs with
arcs (`Mechanisms.lines_arcs`): an arc of radius R turning by angle a at a via-point passes
R (1 / cos(a / 2) - 1) inside the corner, towards the disc it turns round; 0.3 m covers a
1 m arc up to about 75 degrees of turn."""

ESCAPE_BAND_M = 0.1
"""An escape goes on until the robot is this far outside the disc (`Mechanisms.escape_band`):
two robots on each other's boundary otherwise alternate between escaping and planning
round each other every cycle."""

KEEP_PLAN_RATIO = 0.1
"""With `Mechanisms.keep_plan`, last cycle's via-points are kept while every leg through
them is still clear and the path through them is at most this fraction longer than the
new plan's."""

PASSED_VIA_M = 0.3
"""A kept via-point closer to the robot than this, or behind it along the next leg, has
been passed [m]."""

PRIMARY_HOLD_S = 3.0
"""A head-on threat resolved first last cycle stays first while its TCPA is within this of
the most imminent one's (`Mechanisms.commitment`): the order of two nearly simultaneous
threats otherwise flips with small changes of TCPA, and the first via-point with it."""


@dataclass(frozen=True)
class Mechanisms:
    """This project's additions to the paper's cycle; every one off is the paper's
    (`PAPER_MECHANISMS`). `mechanisms` gives each planner its set.

    Args:
        direct_leg_check: when Eq. (6) finds no threat, the direct leg to the goal still
            goes through the leg check (step 4): a robot standing still (v_r = 0) sees no
            threat by Eq. (6), even a disc on its way.
        goal_tcpa_filter: threats whose TCPA is more than `GOAL_TCPA_MARGIN_S` past the
            robot's time to its goal are not resolved (near the goal an overshoot's
            measured velocity points at whoever stands beyond it).
        encounter_rules: the reciprocal convention of `agent.planning.encounters` against
            other robots (eIFP's selector): mirrored robots choose sides that fit together.
        inflated_threats: a threat of Eq. (6) needs DCPA <= L (a predicted incursion of the
            inflated disc, Eq. 8) instead of D_thresh, a detection radius 2.2 times L for
            two 0.5 m robots: neighbours that would pass clear are left alone.
        commitment: a head-on threat that the last plan resolved first stays first while
            its TCPA is within `PRIMARY_HOLD_S` of the most imminent one's, so the first
            via-point (where the robot heads now) does not flip between two nearly
            simultaneous threats.
        via_margin_m: how far outside its inflated disc a via-point is placed [m].
        escape_band_m: an escape goes on from the same disc until the robot is this far
            outside it, towards a point that far out (0: only while inside) [m].
        horizon_via_points: a candidate reached after more than T_max (lambda*, Eq. 14) is
            infeasible: past the threat horizon the constant-velocity forecast that placed
            it is not to be trusted (for an other as fast as the robot, a tangent point
            receding nearly as fast is met kilometres down its track); and when the first
            threat has no feasible candidate, the next one in rank order that has one gets
            the first via-point, instead of a plan straight through the first.
        lines_arcs: the reference follows the waypoint legs joined by arcs
            (`agent.planning.spline.LineArcPath`) instead of the cubic spline (Eq. 19).
        clamp_heading: the spline leaves along the robot's heading when the first
            via-point lies within 30 degrees of it, instead of natural end conditions.
        braking_guard: eIFP-MPC's command speed is capped so the robot can still stop its
            own approach to every disc it faces (`agent.planning.safety`): the MPC's
            half-planes are soft and can trade a stopped neighbour's gap away.
        keep_plan: last cycle's via-points are kept, minus those passed, while every leg
            through them is still clear and the path is at most `KEEP_PLAN_RATIO` longer
            than the one the cycle just built (`_keep_previous`). Rebuilt from scratch each
            cycle, a plan in a crowd jumps between unrelated via-point sequences as the
            ranking of nearly simultaneous threats reorders; a plan that still holds is
            the same decision made again, so only a failing or clearly worse plan is
            replaced.
        routing: the robot routes round the scenario's static obstacles, known in
            advance (`agent.planning.routing`), and eIFP plans towards the farthest route
            waypoint it can see (`agent.planning.guidance`). eIFP still resolves the
            static discs it meets on its legs like any other disc.
        liveness: with thresholds (not None), the robot monitors its progress and, when
            stuck, re-routes round the knot or yields to lower ids
            (`agent.planning.liveness`).
    """

    direct_leg_check: bool = False
    goal_tcpa_filter: bool = False
    encounter_rules: bool = False
    inflated_threats: bool = False
    commitment: bool = False
    via_margin_m: float = VIA_MARGIN_M
    escape_band_m: float = 0.0
    horizon_via_points: bool = False
    lines_arcs: bool = False
    clamp_heading: bool = False
    braking_guard: bool = False
    keep_plan: bool = False
    routing: bool = False
    liveness: LivenessConfig | None = None


PAPER_MECHANISMS = Mechanisms()
"""The paper's cycle (the ``paper`` profile, every planner)."""

IFP_MECHANISMS = Mechanisms(direct_leg_check=True, goal_tcpa_filter=True, clamp_heading=True)
"""ifp in the default profile."""

EIFP_MECHANISMS = dataclasses.replace(IFP_MECHANISMS, encounter_rules=True)
"""eifp in the default profile: ifp's and the encounter rules. Its pure-pursuit law cuts
the corners of a lines-and-arcs reference, so it keeps the spline and the paper's cycle."""

EIFP_MPC_MECHANISMS = dataclasses.replace(
    EIFP_MECHANISMS, inflated_threats=True, commitment=True, via_margin_m=ARC_VIA_MARGIN_M,
    escape_band_m=ESCAPE_BAND_M, horizon_via_points=True, lines_arcs=True,
    clamp_heading=False, braking_guard=True, keep_plan=True, routing=True,
    liveness=LivenessConfig())
"""eifp-mpc in the default profile: every mechanism."""


def mechanisms(planner: str, config: PlannerConfig) -> Mechanisms:
    """The mechanisms `planner` runs with under `config.profile`."""
    if config.is_paper:
        return PAPER_MECHANISMS
    if planner == "eifp-mpc":
        return EIFP_MPC_MECHANISMS
    if planner == "eifp":
        return EIFP_MECHANISMS
    return IFP_MECHANISMS


def is_head_on(heading_rad: float, speed_mps: float, other_velocity_mps: np.ndarray) -> bool:
    """Whether an other's course lies within `HEAD_ON_MAX_DEG` of the reciprocal of the
    robot's heading, both moving at least `HEAD_ON_MIN_SPEED_MPS`."""
    vx, vy = float(other_velocity_mps[0]), float(other_velocity_mps[1])
    other_speed = math.hypot(vx, vy)
    if speed_mps < HEAD_ON_MIN_SPEED_MPS or other_speed < HEAD_ON_MIN_SPEED_MPS:
        return False
    towards = -(vx * math.cos(heading_rad) + vy * math.sin(heading_rad)) / other_speed
    return towards >= _HEAD_ON_COS

# rule(others, index, tcpa, dcpa, inflated) -> (ignored ids, committed ids): eIFP's encounter
# rules, given the cycle's neighbours and their Eqs. (3)-(7) assessment (threat indices ranked,
# TCPA, DCPA, inflated radii L), so the assessment is made once per cycle.
EncounterRule = Callable[
    [Others, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    "tuple[frozenset[int], frozenset[int]]",
]

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


def plan_via_points(
    observation: Observation,
    config: PlannerConfig,
    make_selector: Callable[[Others], CandidateSelector],
    committed_ids: frozenset[int] = frozenset(),
    timer: Callable[[], float] | None = None,
    ignored_ids: frozenset[int] = frozenset(),
    primary_id: int | None = None,
    encounter_rule: EncounterRule | None = None,
    mech: Mechanisms = PAPER_MECHANISMS,
    escape_id: int | None = None,
    previous: ViaPlan | None = None,
) -> ViaPlan:
    """The IFP cycle (module docstring) with a pluggable candidate selector.

    Args:
        observation: what the robot knows now.
        config: planner parameters.
        make_selector: given the neighbours the cycle plans against (after the sensing
            radius and neighbour cap), returns the rule that picks one candidate of a
            threat; IFP's is `select_earliest`, eIFP's cost rule is in `agent.planning.eifp`.
            Called after `encounter_rule`.
        committed_ids: others the robot is already giving way to (eIFP's encounter rules):
            they stay threats while still approaching (0 < TCPA < 2 T_max), even when the
            robot's own swerve has pushed their DCPA past the threshold.
        timer: a wall clock, only to time the threat assessment (`ViaPlan.threats_s`);
            it never influences the plan.
        ignored_ids: others the robot leaves to themselves (eIFP's stand-on encounters,
            `agent.planning.encounters`): never resolved, on no leg; still escaped from if the robot
            is inside their inflated disc, and still listed in `ViaPlan.threats`.
        primary_id: the other the previous cycle's first via-point resolved: with
            `Mechanisms.commitment`, a head-on one is resolved first again unless another
            one's TCPA is more than `PRIMARY_HOLD_S` smaller.
        encounter_rule: eIFP's encounter rules (`EncounterRule`): their ignored ids join
            `ignored_ids`, their committed ids `committed_ids`.
        mech: the mechanisms of the cycle (`Mechanisms`); the paper's by default.
        escape_id: the other the previous cycle escaped from, if it did
            (`Mechanisms.escape_band_m`).

    Raises:
        ValueError: on non-finite inputs or configuration.
    """
    validate_inputs(observation, config)
    ego = observation.ego
    p = np.array([ego.x_m, ego.y_m])
    goal = observation.goal_m
    threats_cfg = config.threats
    t_max_s = threats_cfg.t_max_s
    others = nearby_others(p, observation.others, threats_cfg.sensing_radius_m,
                           threats_cfg.max_neighbors)
    speed = float(observation.limits.v_max_mps)
    radius = inflated_radius(observation.radius_m, others.radius_m, config.safety.d_safety_m)

    # Eqs. (3)-(7) at the measured velocity.
    t_start = timer() if timer is not None else 0.0
    v_r = ego.v_mps * np.array([math.cos(ego.heading_rad), math.sin(ego.heading_rad)])
    d_thresh: float | np.ndarray = config.dcpa_threshold_m(observation.radius_m)
    if mech.inflated_threats:
        d_thresh = radius
    index, tcpa, dcpa = rank_threats(p, v_r, others, d_thresh, t_max_s)
    if encounter_rule is not None and len(others):
        more_ignored, more_committed = encounter_rule(others, index, tcpa, dcpa, radius)
        ignored_ids = ignored_ids | more_ignored
        committed_ids = committed_ids | more_committed
    select = make_selector(others)
    if committed_ids and len(others):
        index = _with_committed(index, tcpa, others, committed_ids, t_max_s)
    threats = threat_records(index, tcpa, dcpa, others)
    # Closest approaches after the robot can be at its goal are not its business: near the
    # goal, an overshoot would otherwise point the measured velocity at someone beyond it
    # and send the robot round the goal. The leg to the goal is still checked below.
    if mech.goal_tcpa_filter:
        to_goal_m = observation.goal_distance_m
        if to_goal_m is None:
            to_goal_m = math.hypot(goal[0] - p[0], goal[1] - p[1])
        to_goal_s = to_goal_m / float(observation.limits.v_max_mps)
        index = index[tcpa[index] <= to_goal_s + GOAL_TCPA_MARGIN_S]
    ignored = np.zeros(len(others), dtype=bool)
    if ignored_ids and len(others):
        ignored = np.fromiter((i in ignored_ids for i in others.ids.tolist()), dtype=bool,
                              count=len(others))
        index = index[~ignored[index]]
    if mech.commitment and primary_id is not None and index.size > 1:
        hit = (others.ids[index] == primary_id).nonzero()[0]
        if hit.size:
            j = int(index[hit[0]])
            if (is_head_on(ego.heading_rad, ego.v_mps, others.velocity_mps[j])
                    and tcpa[j] <= tcpa[index[0]] + PRIMARY_HOLD_S):
                index = np.concatenate((index[hit[:1]], np.delete(index, hit[0])))
    threats_s = timer() - t_start if timer is not None else 0.0
    if len(others) == 0:
        return ViaPlan(status=PlanStatus.OK, waypoints_m=np.stack((p, goal)), threats=threats,
                       threats_s=threats_s)

    # Inside an inflated disc: no tangent exists, steer straight out of the deepest one.
    position = as_complex(others.position_m)
    gap = np.abs(position - complex(ego.x_m, ego.y_m)) - radius
    band = mech.escape_band_m
    if escape_id is not None and band > 0.0:
        # Still escaping from the same disc until a band clear of it: a robot that left
        # by a centimetre would plan round the disc, graze it and escape again.
        held = (others.ids == escape_id) & (gap <= band)
        gap = np.where(held, np.minimum(gap, 0.0), gap)
    inside = (gap <= 0.0).nonzero()[0]
    if inside.size:
        j = int(inside[np.lexsort((others.ids[inside], gap[inside]))[0]])
        out = escape_point(p, others.position_m[j], float(radius[j]) + band, ego.heading_rad)
        return ViaPlan(
            status=PlanStatus.ESCAPE,
            waypoints_m=np.stack((p, out) if ego.v_mps < ESCAPE_STANDING_MPS else (p, out, goal)),
            via_point_m=out,
            side=Side.NONE,
            resolved_id=int(others.ids[j]),
            threats=threats,
            threats_s=threats_s,
        )

    velocity = as_complex(others.velocity_mps)
    clearance = np.where(ignored, -math.inf, radius - LEG_GRAZE_TOL_M)

    def keep(new_wps: list[complex]) -> ViaPlan | None:
        """Last cycle's plan instead of the new one (`new_wps`, or [P, goal] when the cycle
        found no feasible via-point), if it still holds (`keep_plan`)."""
        if not (mech.keep_plan and previous is not None and previous.resolved_sides):
            return None
        kept = _keep_previous(previous, new_wps, speed, position, velocity, clearance,
                              t_max_s, others.ids)
        if kept is None:
            return None
        kept_wps, kept_sides = kept
        return ViaPlan(status=PlanStatus.OK, waypoints_m=kept_wps,
                       via_point_m=kept_wps[1].copy(), side=kept_sides[0][1],
                       resolved_id=kept_sides[0][0], threats=threats,
                       resolved_sides=kept_sides, threats_s=threats_s)

    # Waypoints as complex numbers x + iy while the list changes.
    world = _World(others, radius, speed, select, mech.via_margin_m,
                   t_max_s if mech.horizon_via_points else math.inf)
    wps = [complex(ego.x_m, ego.y_m), complex(goal[0], goal[1])]
    excluded = [-1]  # per leg: index of the other the leg is tangent to, or -1
    chosen: list[tuple[int, Side] | None] = [None, None]  # per waypoint: (index, side)

    if index.size:
        k = int(index[0])
        split = world.resolve(wps[0], 0.0, wps[1], k)
        if split is None and mech.horizon_via_points:
            for other_k in index[1:].tolist():
                split = world.resolve(wps[0], 0.0, wps[1], other_k)
                if split is not None:
                    k = other_k
                    break
        if split is None:
            return keep(wps) or ViaPlan(
                status=PlanStatus.NO_FEASIBLE, waypoints_m=np.stack((p, goal)), threats=threats,
                threats_s=threats_s,
            )
        wps.insert(1, split[0])
        excluded[0:1] = [k, -1]
        chosen.insert(1, (k, split[1]))
    elif not mech.direct_leg_check:
        # The paper declares threats by Eq. (6) alone: none, so the plan is [P, goal].
        return ViaPlan(status=PlanStatus.OK, waypoints_m=np.stack((p, goal)), threats=threats,
                       threats_s=threats_s)

    # Iteration: re-check every leg from `first` on; split the first resolvable one.
    first = 0
    while len(wps) - 2 < config.reference.max_depth:
        arrival = [0.0, *itertools.accumulate(abs(b - a) / speed for a, b in zip(wps, wps[1:]))]
        hit, leg_tcpa = legs_threats(
            wps[first:-1],
            wps[first + 1 :],
            arrival[first:-1],
            speed,
            position,
            velocity,
            clearance,
            t_max_s,
            excluded[first:],
        )
        split = None
        for row in hit.any(axis=1).nonzero()[0].tolist():
            leg = first + row
            for hit_k in ranked(hit[row].nonzero()[0], leg_tcpa[row], others.ids).tolist():
                split = world.resolve(wps[leg], arrival[leg], wps[leg + 1], hit_k)
                if split is not None:
                    k = hit_k
                    break
            if split is not None:
                break
        if split is None:
            break
        wps.insert(leg + 1, split[0])
        excluded[leg : leg + 1] = [k, -1]
        chosen.insert(leg + 1, (k, split[1]))
        first = leg

    waypoints = np.array([(z.real, z.imag) for z in wps])
    resolved = tuple((int(others.ids[c[0]]), c[1]) for c in chosen if c is not None)
    head = chosen[1]
    kept_plan = keep(wps)
    if kept_plan is not None:
        return kept_plan
    return ViaPlan(
        status=PlanStatus.OK,
        waypoints_m=waypoints,
        via_point_m=None if head is None else waypoints[1].copy(),
        side=Side.NONE if head is None else head[1],
        resolved_id=None if head is None else int(others.ids[head[0]]),
        threats=threats,
        resolved_sides=resolved,
        threats_s=threats_s,
    )


def _keep_previous(previous: ViaPlan, new_wps: list[complex], speed: float,
                   position: np.ndarray, velocity: np.ndarray, clearance: np.ndarray,
                   t_max_s: float, ids: np.ndarray,
                   ) -> tuple[np.ndarray, tuple[tuple[int, Side], ...]] | None:
    """Last cycle's via-points from the robot's position on, if they still hold.

    They hold when every leg of [P, kept via-points, goal] is clear of every disc within
    T_max at top speed (`threats.legs_threats`) and the path is at most `KEEP_PLAN_RATIO`
    longer than the new plan's. Via-points the robot has passed are dropped first; None
    when none is left, or the plan does not hold.
    """
    p, goal = new_wps[0], new_wps[-1]
    vias = [complex(x, y) for x, y in previous.waypoints_m[1:-1]]
    sides = list(previous.resolved_sides)
    if len(vias) != len(sides):
        return None
    sensed = set(ids.tolist())
    while vias:
        nxt = vias[1] if len(vias) > 1 else goal
        v = vias[0]
        if abs(v - p) < PASSED_VIA_M or ((p - v) * (nxt - v).conjugate()).real > 0.0:
            vias.pop(0)
            sides.pop(0)
        else:
            break
    if not vias or any(i not in sensed for i, _ in sides) :
        return None
    wps = [p, *vias, goal]
    length = sum(abs(b - a) for a, b in zip(wps, wps[1:]))
    new_length = sum(abs(b - a) for a, b in zip(new_wps, new_wps[1:]))
    if length > (1.0 + KEEP_PLAN_RATIO) * new_length:
        return None
    arrival = [0.0, *itertools.accumulate(abs(b - a) / speed for a, b in zip(wps, wps[1:]))]
    hit, _ = legs_threats(wps[:-1], wps[1:], arrival[:-1], speed, position, velocity,
                          clearance, t_max_s)
    if hit.any():
        return None
    return np.array([(z.real, z.imag) for z in wps]), tuple(sides)


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
    extra = [
        k
        for k in range(len(others))
        if int(others.ids[k]) in committed_ids
        and 0.0 < tcpa[k] < COMMIT_RELEASE_FACTOR * t_max_s
        and k not in index
    ]
    if not extra:
        return index
    merged = np.concatenate([index, np.array(extra, dtype=index.dtype)])
    return ranked(merged, tcpa, others.ids)


class _World:
    """The others of one cycle in plain floats, to build candidates one disc at a time."""

    def __init__(
        self, others: Others, radius: np.ndarray, speed: float, select: CandidateSelector,
        via_margin_m: float = VIA_MARGIN_M, via_time_max_s: float = math.inf,
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
