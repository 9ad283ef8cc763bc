"""Iterative Forecast Planner (IFP): the baseline via-point planner.

One planning cycle, as `plan_ifp` runs it:

1. Neighbours: the others inside the sensing radius, at most `max_neighbors`.
2. Escape: if the robot is inside an inflated disc (Q <= L, Eq. 7) the plan is
   [P, escape point, goal], status ESCAPE (the deepest disc wins, ties by id); for a robot
   standing (below `ESCAPE_STANDING_MPS`) just [P, escape point] (see there).
3. Threats of Eq. (5) at the robot's measured velocity, ranked by TCPA (Eq. 6). If there
   are any, the nearest one is resolved from P: its RIGHT/LEFT candidates (Eqs. 8-13) are
   built and the selector picks one (IFP: the earliest, smallest lambda*). If neither
   survives the plan is [P, goal], status NO_FEASIBLE.
4. Iteration (up to `max_depth` via-points in all): every leg of the waypoint list, from
   the robot outwards, is re-checked with `threats.legs_threats` at top speed, starting at
   the time the robot reaches the leg's start. The most imminent resolvable threat on a
   leg gets a via-point, inserted into that leg, built from the leg's start with the
   others advanced to that time; the shortened leg is then checked again. A leg whose
   threats all lack candidates is left as it is.

Choices the paper leaves open (documented here, tested in tests/agent/test_ifp.py):

- Step 3 uses the measured velocity v_r as in Eq. (3). A robot that stands still (v_r = 0)
  sees no static obstacle as a threat under Eq. (5), so when Eq. (5) finds nothing the
  direct leg P -> goal still goes through the leg check of step 4
  (`PlannerConfig.direct_leg_check`; not in the paper, off in `config.paper_config`: then
  a cycle whose Eq. (5) finds nothing plans [P, goal]).
- The leg check counts other j as a threat when the closest approach on the leg is below
  its inflated radius L_j (not D_thresh, which is a detection radius): the plan must clear
  the inflated discs. Grazing within `LEG_GRAZE_TOL_M` is not a threat, so a leg that is
  tangent to a disc by construction is not flagged by rounding.
- The leg from a via-point's predecessor to the via-point is tangent to the disc it
  resolves, so that disc is excluded on that leg; it is checked on every other leg.
- Via-points are pushed radially `VIA_MARGIN_M` out of the moving disc they resolve
  (`viapoints.via_point_candidates(margin_m=...)`). On the boundary itself a via-point
  would have no tangent to the same disc, and a next leg that cuts back into it (the
  usual case when the goal lies behind the obstacle) could not be fixed; from outside it
  gets a further tangent, so the iteration wraps the disc with a short polygon. The leg
  into a pushed via-point still clears the disc (it runs outside the tangent line).
- A candidate is only built from a leg start outside the disc by more than
  `ON_DISC_REL_TOL` of L.
- Step 3 drops threats whose TCPA is more than `GOAL_TCPA_MARGIN_S` past the time the
  robot needs to reach its goal at top speed (`PlannerConfig.goal_tcpa_filter`; not in the
  paper, off in `config.paper_config`): near the goal the measured velocity of an
  overshoot points at whoever stands beyond it, and resolving that sends the robot round
  its goal. Such others still count on the legs of step 4.
- `ViaPlan.via_point_m` is the first via-point after P (where the robot heads now), with
  the side and the id of the threat that via-point resolves.

`CycleRules` holds eIFP-MPC's changes to this cycle (not in the paper; the default
`PAPER_RULES` is the cycle above, which `ifp` and `eifp` run): threats are only the others
whose DCPA falls inside the pair's inflated radius L; via-points lie further out of their
discs; an escape, once begun, goes on until the robot is a band clear of the disc; a
head-on threat resolved first last cycle is kept first for a while (stop 24); a candidate
reached only after `via_time_max_s` is infeasible, and in step 3 a first threat without a
feasible candidate hands the first via-point to the next threat in rank order that has
one, instead of giving up (stop 25). Why, and what each did to the dense crossings, is in
`agent.core.config.PlannerConfig` and the README ("Stop 24", "Stop 25").
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from agent.core.config import PlannerConfig
from agent.core.types import Observation, Others, PlanStatus, Side, Threat
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
v = 0 a turn does not move the position to first order) found standing best: two robots
inside each other's inflated discs, each goal behind the other, stood for 80 s (setup E at
100 +- 30 ms with 10 % loss, lockstep link seed 2). The short plan makes the reference turn
to the escape direction and leave; the next cycle, outside, plans round the disc. A moving
robot keeps the goal in its escape plan (the reference then continues where it goes)."""

# A committed threat is released when its TCPA exceeds this multiple of T_max.
COMMIT_RELEASE_FACTOR = 2.0

# Closest approaches this close to L still clear the disc [m] (tangent legs, rounding).
LEG_GRAZE_TOL_M = 1.0e-6

# Eq. (5) threats whose TCPA exceeds the time to the goal at top speed by more than this
# are not resolved [s].
GOAL_TCPA_MARGIN_S = 0.5

# How far outside its inflated disc a via-point is placed [m].
VIA_MARGIN_M = 0.05

# A leg start within L * (1 + this) of a disc centre is on the disc: no tangent from it.
ON_DISC_REL_TOL = 1.0e-6

HEAD_ON_MAX_DEG = 45.0
"""`CycleRules.head_on_hold_s` holds a threat whose course lies within this angle of the
reciprocal of the robot's heading."""

HEAD_ON_MIN_SPEED_MPS = 0.2
"""Below this speed (the robot's or the other's) a course has no direction: not head-on."""

_HEAD_ON_COS = math.cos(math.radians(HEAD_ON_MAX_DEG))


@dataclass(frozen=True)
class CycleRules:
    """eIFP-MPC's changes to the IFP cycle (not in the paper); the defaults are the paper's.

    Args:
        threats_within_inflated: a threat of Eq. (5) needs DCPA <= L, the pair's inflated
            radius (Eq. 7), instead of D_thresh (an explicit `PlannerConfig.d_thresh_m`
            still wins).
        threat_release_margin_m: with `threats_within_inflated`, an other that the
            previous cycle's plan resolved stays a threat while its DCPA is within
            L + this (a Schmitt trigger: in at L, out at L + margin) [m].
        via_margin_m: how far outside its inflated disc a via-point is placed [m].
        escape_hysteresis_m: an escape goes on, from the same disc, until the robot is this
            far outside it, and heads for a point that far out (0: escape only while inside).
        head_on_hold_s: a head-on threat (course within `HEAD_ON_MAX_DEG` of reciprocal)
            that the previous cycle resolved first is resolved first again while its TCPA
            is within this of the most imminent one's (0: off) [s].
        via_time_max_s: a via-point candidate reached later than this at top speed
            (lambda*, Eq. 13) is infeasible (`agent.planning.viapoints.candidate_pair`) [s].
        primary_fallback: when the first-ranked threat has no feasible via-point, the next
            threat in rank order that has one is resolved first, instead of the cycle
            giving up with NO_FEASIBLE (a plan straight to the goal); the MPC's
            constraints still keep the robot off every disc.
    """

    threats_within_inflated: bool = False
    threat_release_margin_m: float = 0.0
    via_margin_m: float = VIA_MARGIN_M
    escape_hysteresis_m: float = 0.0
    head_on_hold_s: float = 0.0
    via_time_max_s: float = math.inf
    primary_fallback: bool = False

    @staticmethod
    def from_config(config: PlannerConfig) -> CycleRules:
        """The rules `config` sets for eIFP-MPC."""
        return CycleRules(
            threats_within_inflated=config.threats_within_inflated,
            threat_release_margin_m=config.threat_release_margin_m,
            via_margin_m=config.via_margin_m,
            escape_hysteresis_m=config.escape_hysteresis_m,
            head_on_hold_s=config.head_on_hold_s,
            via_time_max_s=(math.inf if config.via_time_max_s is None
                            else config.via_time_max_s),
            primary_fallback=config.primary_fallback,
        )


PAPER_RULES = CycleRules()
"""The paper's cycle (IFP and eIFP)."""


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
# rules, given the cycle's neighbours and their Eq. (5) assessment (threat indices ranked,
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
        threats: the threats of Eq. (5) at the measured velocity, ranked by TCPA.
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
    """One IFP cycle: earliest-feasible via-points, iterated up to `max_depth`.

    Args:
        observation: what the robot knows now.
        config: planner parameters (d_safety, D_thresh, T_max, sensing, max_depth).

    Returns:
        The waypoint plan; feed `waypoints_m` to `spline.build_reference`.

    Raises:
        ValueError: on non-finite inputs or configuration.
    """
    return plan_via_points(observation, config, lambda _others: select_earliest, timer=timer)


def plan_via_points(
    observation: Observation,
    config: PlannerConfig,
    make_selector: Callable[[Others], CandidateSelector],
    committed_ids: frozenset[int] = frozenset(),
    timer: Callable[[], float] | None = None,
    ignored_ids: frozenset[int] = frozenset(),
    primary_id: int | None = None,
    encounter_rule: EncounterRule | None = None,
    rules: CycleRules = PAPER_RULES,
    escape_id: int | None = None,
    resolved_ids: frozenset[int] = frozenset(),
) -> ViaPlan:
    """The IFP cycle (module docstring) with a pluggable candidate selector.

    Args:
        observation: what the robot knows now.
        config: planner parameters.
        make_selector: given the neighbours the cycle plans against (after the sensing
            radius and neighbour cap), returns the rule that picks one candidate of a
            threat; IFP's is `select_earliest`, eIFP's cost rule is in `agent.planning.eifp`.
            Called after `encounter_rule`.
        committed_ids: others the robot is already resolving (eIFP's threat commitment):
            they stay threats while still approaching (0 < TCPA < T_max), even when the
            robot's own swerve has pushed their DCPA past D_thresh.
        timer: a wall clock, only to time the threat assessment (`ViaPlan.threats_s`);
            it never influences the plan.
        ignored_ids: others the robot leaves to themselves (eIFP's stand-on encounters,
            `agent.planning.encounters`): never resolved, on no leg; still escaped from if the robot
            is inside their inflated disc, and still listed in `ViaPlan.threats`.
        primary_id: the other the previous cycle's first via-point resolved (eIFP): if it
            is still a threat it is resolved first again unless another one's TCPA is
            more than `config.primary_margin_s` smaller (hysteresis on the ranking).
        encounter_rule: eIFP's encounter rules (`EncounterRule`): their ignored ids join
            `ignored_ids`, their committed ids `committed_ids`.
        rules: eIFP-MPC's changes to the cycle (`CycleRules`); the paper's by default.
            With `head_on_hold_s` > 0 a head-on `primary_id` is held that long, and
            without `config.primary_hysteresis` only a head-on one is held.
        escape_id: the other the previous cycle escaped from, if it did
            (`CycleRules.escape_hysteresis_m`).
        resolved_ids: the others the previous cycle's plan resolved
            (`CycleRules.threat_release_margin_m`).

    Raises:
        ValueError: on non-finite inputs or configuration.
    """
    validate_inputs(observation, config)
    ego = observation.ego
    p = np.array([ego.x_m, ego.y_m])
    goal = observation.goal_m
    others = nearby_others(p, observation.others, config.sensing_radius_m, config.max_neighbors)
    speed = float(observation.limits.v_max_mps)
    radius = inflated_radius(observation.radius_m, others.radius_m, config.d_safety_m)

    # Eqs. (3)-(6) at the measured velocity.
    t_start = timer() if timer is not None else 0.0
    v_r = ego.v_mps * np.array([math.cos(ego.heading_rad), math.sin(ego.heading_rad)])
    d_thresh: float | np.ndarray = config.dcpa_threshold_m(observation.radius_m)
    if rules.threats_within_inflated and config.d_thresh_m is None:
        d_thresh = radius
        if resolved_ids and rules.threat_release_margin_m > 0.0 and len(others):
            kept = np.fromiter((i in resolved_ids for i in others.ids.tolist()), dtype=bool,
                               count=len(others))
            d_thresh = np.where(kept, radius + rules.threat_release_margin_m, radius)
    index, tcpa, dcpa = rank_threats(p, v_r, others, d_thresh, config.t_max_s)
    if encounter_rule is not None and len(others):
        more_ignored, more_committed = encounter_rule(others, index, tcpa, dcpa, radius)
        ignored_ids = ignored_ids | more_ignored
        committed_ids = committed_ids | more_committed
    select = make_selector(others)
    if committed_ids and len(others):
        index = _with_committed(index, tcpa, others, committed_ids, config.t_max_s)
    threats = threat_records(index, tcpa, dcpa, others)
    # Closest approaches after the robot can be at its goal are not its business: near the
    # goal, an overshoot would otherwise point the measured velocity at someone beyond it
    # and send the robot round the goal. The leg to the goal is still checked below.
    if config.goal_tcpa_filter:
        to_goal_s = (math.hypot(goal[0] - p[0], goal[1] - p[1])
                     / float(observation.limits.v_max_mps))
        index = index[tcpa[index] <= to_goal_s + GOAL_TCPA_MARGIN_S]
    ignored = np.zeros(len(others), dtype=bool)
    if ignored_ids and len(others):
        ignored = np.fromiter((i in ignored_ids for i in others.ids.tolist()), dtype=bool,
                              count=len(others))
        index = index[~ignored[index]]
    if primary_id is not None and index.size > 1:
        hit = (others.ids[index] == primary_id).nonzero()[0]
        if hit.size:
            j = int(index[hit[0]])
            margin_s = config.primary_margin_s
            if rules.head_on_hold_s > 0.0:
                if not config.primary_hysteresis:
                    margin_s = -math.inf  # the head-on hold alone
                if is_head_on(ego.heading_rad, ego.v_mps, others.velocity_mps[j]):
                    margin_s = max(margin_s, rules.head_on_hold_s)
            if tcpa[j] <= tcpa[index[0]] + margin_s:
                index = np.concatenate((index[hit[:1]], np.delete(index, hit[0])))
    threats_s = timer() - t_start if timer is not None else 0.0
    if len(others) == 0:
        return ViaPlan(status=PlanStatus.OK, waypoints_m=np.stack((p, goal)), threats=threats,
                       threats_s=threats_s)

    # Inside an inflated disc: no tangent exists, steer straight out of the deepest one.
    position = as_complex(others.position_m)
    gap = np.abs(position - complex(ego.x_m, ego.y_m)) - radius
    band = rules.escape_hysteresis_m
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

    # Waypoints as complex numbers x + iy while the list changes.
    world = _World(others, radius, speed, select, rules.via_margin_m, rules.via_time_max_s)
    wps = [complex(ego.x_m, ego.y_m), complex(goal[0], goal[1])]
    excluded = [-1]  # per leg: index of the other the leg is tangent to, or -1
    chosen: list[tuple[int, Side] | None] = [None, None]  # per waypoint: (index, side)

    if index.size:
        k = int(index[0])
        split = world.resolve(wps[0], 0.0, wps[1], k)
        if split is None and rules.primary_fallback:
            for other_k in index[1:].tolist():
                split = world.resolve(wps[0], 0.0, wps[1], other_k)
                if split is not None:
                    k = other_k
                    break
        if split is None:
            return ViaPlan(
                status=PlanStatus.NO_FEASIBLE, waypoints_m=np.stack((p, goal)), threats=threats,
                threats_s=threats_s,
            )
        wps.insert(1, split[0])
        excluded[0:1] = [k, -1]
        chosen.insert(1, (k, split[1]))
    elif not config.direct_leg_check:
        # The paper declares threats by Eq. (5) alone: none, so the plan is [P, goal].
        return ViaPlan(status=PlanStatus.OK, waypoints_m=np.stack((p, goal)), threats=threats,
                       threats_s=threats_s)

    # Iteration: re-check every leg from `first` on; split the first resolvable one.
    velocity = as_complex(others.velocity_mps)
    clearance = np.where(ignored, -math.inf, radius - LEG_GRAZE_TOL_M)
    first = 0
    while len(wps) - 2 < config.max_depth:
        arrival = [0.0, *itertools.accumulate(abs(b - a) / speed for a, b in zip(wps, wps[1:]))]
        hit, leg_tcpa = legs_threats(
            wps[first:-1],
            wps[first + 1 :],
            arrival[first:-1],
            speed,
            position,
            velocity,
            clearance,
            config.t_max_s,
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


def _with_committed(
    index: np.ndarray,
    tcpa: np.ndarray,
    others: Others,
    committed_ids: frozenset[int],
    t_max_s: float,
) -> np.ndarray:
    """Eq. (5)'s threats plus the committed others still approaching, re-ranked by TCPA.

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
