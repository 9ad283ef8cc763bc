"""eIFP: IFP whose via-points are chosen by the interaction-aware cost of Eqs. (15)-(17).

The cycle is IFP's (`agent.planning.ifp`: TCPA-ranked threats, the nearest resolved first, legs
re-checked up to `max_depth`); only the choice between a threat's RIGHT and LEFT candidate
changes. Candidate i on the leg A -> B costs

    J_i = w_g l_i + w_d sum_j w_j / d_ij + w_a sum_j w_j phi_ij            (Eq. 15)

with l_i = (|A - v_i| + |v_i - B|) / (|A - B| + eps) (Eq. 16; A = robot, B = goal on the
first leg) and phi_ij = 1 - cos(v_i - A, g_j - s_j) (Eq. 17). The sums run over every
sensed other j (robots and moving or static obstacles alike; w_j decides how much each
counts).

Choices the paper leaves open:

- Predicted path of j (for d_ij): the segment from its current position to
  position + v_j * `GHOST_HORIZON_S`; d_ij is the point-to-segment distance, floored at
  `MIN_PATH_DISTANCE_M` so a candidate on a path costs a lot but finitely.
- Ghost path {s_j, g_j^ghost} (for phi_ij and discarding): s_j = `Others.track_start_m`
  (the oldest observed position of the estimation window) and g_j^ghost = position +
  v_j * `GHOST_HORIZON_S`, the straight-line projection of the observed motion. phi_ij is 0
  when |g_j - s_j| or |v_i - A| is ~0.
- w_j = `Others.linearity`, the straightness of j's observed history (estimated
  elsewhere); w_j = 0 switches both interaction terms off for j.
- Discarding: a candidate closer than the pair's inflated radius L_j to the ghost path of
  any other j except the threat it resolves is dropped
  (the threat's own clearance is already built into its tangent construction). If that
  drops every feasible candidate, the feasible set is used unfiltered so the robot still
  has a plan.
- Stability: a memory {threat id -> side chosen last time} is passed in and returned.
  A candidate on the other side than the remembered one is taken only if its cost is
  below (1 - `CostConfig.side_hysteresis`) times the kept side's: a side is kept unless
  the other is clearly cheaper, relative to the costs themselves, so the noise of the
  velocity estimates does not flip it. Entries live while their id is
  still among the sensed neighbours.
- Symmetry breaking: costs equal within `TIE_REL_TOL` (relative) resolve to Side.RIGHT,
  the right-hand passing rule of COLREGs rule 14: the robot turns to its right and leaves
  the threat on its left. Two robots meeting head-on both turn to their own right and
  pass each other left side to left side.
- Near-ties against robots (with the encounter rules, `Mechanisms.encounter_rules`): what
  breaks reciprocity is two robots whose costs differ by tiny, unrelated amounts (goals a
  centimetre off the line of approach), so that they pick the same world side. On a first
  choice against another robot LEFT must therefore beat RIGHT by `RIGHT_HAND_MARGIN` of
  the cost. Static and scenario obstacles do not reciprocate: against them only the
  exact-tie rule applies. The side memory and its hysteresis take over after the first
  choice.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.config import PlannerConfig
from agent.core.types import Observation, Others, PlanStatus, Side
from agent.planning.encounters import Role, encounter_roles, update_role_memory
from agent.planning.ifp import (
    Assessment,
    CandidateSelector,
    Decisions,
    ViaPlan,
    assess_threats,
    plan_cycle,
)
from agent.planning.mechanisms import PAPER_MECHANISMS, Mechanisms
from agent.planning.threats import as_complex
from agent.planning.viapoints import SIDES, inflated_radius

GHOST_HORIZON_S = 4.0
"""How far ahead an other's predicted path and ghost goal are projected (d_ij and g_j of
Eqs. 15 and 17) [s]: half the threat horizon T_max, the part of a constant-velocity
forecast the side choice leans on."""

RIGHT_HAND_MARGIN = 0.05
"""On a first choice against another robot, LEFT must beat RIGHT by this fraction of the
cost (with the encounter rules): the shared right-hand convention then decides near-ties
the same way for both robots of a mirrored encounter."""

# Floor on the distance to a predicted path in Eq. (15) [m].
MIN_PATH_DISTANCE_M = 0.05

# eps of Eq. (16) [m].
LENGTH_EPS_M = 1.0e-6

# Costs this close (relative) are a tie, broken to Side.RIGHT.
TIE_REL_TOL = 1.0e-9

# Vectors shorter than this [m] have no direction (phi = 0).
_NO_DIRECTION_M = 1.0e-9

_RIGHT = SIDES.index(Side.RIGHT)


class GhostPaths:
    """The per-cycle geometry of Eqs. (15)-(17): predicted and ghost paths of K others.

    Everything that does not depend on the candidate is computed once here: the 2K
    segments (K predicted paths, then K ghost paths, as complex numbers x + iy) and, for
    the angle term, sum_j w_j phi_ij = W - u_i . G with u_i the unit direction of v_i - A,
    W = sum_j w_j [g_j != s_j] and G = sum_j w_j (g_j - s_j) / |g_j - s_j|.

    Args:
        others: the sensed neighbours.
        ghost_horizon_s: how far ahead paths are projected [s] (`GHOST_HORIZON_S`).
        clearance_m: (K,) minimum distance of a candidate to ghost path j [m].
    """

    def __init__(self, others: Others, ghost_horizon_s: float, clearance_m: np.ndarray) -> None:
        k = len(others)
        self.k = k
        self.weight = others.linearity
        position = as_complex(others.position_m)
        ghost_goal = position + ghost_horizon_s * as_complex(others.velocity_mps)
        self.seg_start = np.concatenate((position, as_complex(others.track_start_m)))
        self.seg = np.concatenate((ghost_goal, ghost_goal)) - self.seg_start
        seg_len = np.abs(self.seg)
        has_len = seg_len > _NO_DIRECTION_M  # shorter segments count as their start point
        # 1 / seg, so that Re(rel / seg) = rel . seg / |seg|^2 is the projection parameter.
        self.seg_inv = np.divide(1.0, self.seg, out=np.zeros_like(self.seg), where=has_len)
        w_dir = np.where(has_len[k:], self.weight, 0.0)
        self.angle_total = float(w_dir.sum())
        # G = sum_j w_j (g_j - s_j) / |g_j - s_j| = sum_j w_j conj(1 / seg_j) |seg_j|.
        self.angle_dir = complex(w_dir @ (self.seg_inv[k:].conjugate() * seg_len[k:]))
        self.clearance_m = clearance_m

    def distances(self, points: np.ndarray) -> np.ndarray:
        """(n, 2K) distances from n complex points to the predicted, then ghost, paths (d_ij of
        Eq. 15 and the discarding test); a segment shorter than 1 nm is its start point."""
        rel = points[:, None] - self.seg_start
        along = np.minimum(np.maximum((rel * self.seg_inv).real, 0.0), 1.0)
        dist: np.ndarray = np.abs(rel - along * self.seg)
        return dist

    def evaluate(
        self,
        points: tuple[complex, ...],
        leg_start: complex,
        leg_end: complex,
        w_length: float,
        w_distance: float,
        w_angle: float,
        skip: int,
    ) -> tuple[list[float], list[bool]]:
        """J of Eq. (15) for n candidates on the leg A -> B, and whether each is clear.

        Args:
            points: n candidates v_i as complex numbers x + iy [m].
            leg_start: A, the robot's position on the first leg, complex [m].
            leg_end: B, the goal on the last leg, complex [m].
            w_length, w_distance, w_angle: w_g, w_d [m], w_a.
            skip: index of the other whose ghost path is not checked for clearance (the
                threat the candidates resolve).

        Returns:
            cost: n values of J.
            clear: n bools, at least the clearance from every ghost path but `skip`'s.
        """
        n = len(points)
        inverse: list[float]
        clear: list[bool]
        if self.k:
            dist = self.distances(np.array(points))
            near = np.maximum(dist[:, : self.k], MIN_PATH_DISTANCE_M)
            inverse = (self.weight / near).sum(axis=1).tolist()  # sum_j w_j / d_ij
            dist[:, self.k + skip] = np.inf
            clear = np.all(dist[:, self.k :] >= self.clearance_m, axis=1).tolist()
        else:
            inverse, clear = [0.0] * n, [True] * n
        a, b = leg_start, leg_end
        direct = abs(b - a) + LENGTH_EPS_M
        g_conj = self.angle_dir.conjugate()
        cost = []
        for v, inv in zip(points, inverse):
            d_av = abs(v - a)
            length = (d_av + abs(b - v)) / direct  # Eq. (16)
            # sum_j w_j phi_ij of Eq. (17); phi = 0 for a candidate at A.
            angle = 0.0
            if d_av > _NO_DIRECTION_M:
                angle = self.angle_total - ((v - a) * g_conj).real / d_av
            cost.append(w_length * length + w_distance * inv + w_angle * angle)
        return cost, clear


def choose_side(
    cost: Sequence[float],
    feasible: Sequence[bool],
    kept: Side | None,
    side_hysteresis: float,
    right_margin: float = 0.0,
) -> int | None:
    """Pick RIGHT or LEFT from their costs, with hysteresis and the right-hand rule.

    With a remembered side, the other side wins only if its cost is below
    (1 - side_hysteresis) times the kept side's. Without one, LEFT wins only if it is
    cheaper than RIGHT by more than max(right_margin, `TIE_REL_TOL`) of the larger cost:
    exact ties, and near-ties within the margin, go RIGHT.

    Args:
        cost: J of the two candidates, in `SIDES` order.
        feasible: whether each candidate is still allowed.
        kept: the side chosen last time for this threat, or None.
        side_hysteresis: fraction by which the other side must beat the kept side.
        right_margin: fraction by which LEFT must beat RIGHT on a first choice.

    Returns:
        Index into `SIDES`, or None if neither is feasible.
    """
    if not feasible[0] or not feasible[1]:
        if feasible[0]:
            return 0
        return 1 if feasible[1] else None
    if kept in SIDES:
        keep = SIDES.index(kept)
        other = 1 - keep
        return other if cost[other] < (1.0 - side_hysteresis) * cost[keep] else keep
    right, left = cost[_RIGHT], cost[1 - _RIGHT]
    margin = max(right_margin, TIE_REL_TOL) * max(abs(right), abs(left))
    return 1 - _RIGHT if right - left > margin else _RIGHT


def cost_selector(
    observation: Observation,
    config: PlannerConfig,
    others: Others,
    side_memory: Mapping[int, Side],
    give_way_ids: frozenset[int] = frozenset(),
    right_margin: float = 0.0,
) -> CandidateSelector:
    """The eIFP candidate selector for one cycle (plugs into `ifp.plan_via_points`).

    Args:
        observation: what the robot knows now (for its radius).
        config: the cost weights and side hysteresis (`CostConfig`), d_safety.
        others: the neighbours the cycle plans against.
        side_memory: threat id -> side chosen last time.
        give_way_ids: others given way to (`agent.planning.encounters`): their RIGHT candidate is
            taken whenever it is feasible, whatever the cost (both robots of an encounter
            must follow the same convention for it to work).
        right_margin: fraction by which LEFT must beat RIGHT on a first choice against
            another robot (`RIGHT_HAND_MARGIN` with the encounter rules, else 0).
    """
    ids, is_robot = others.ids, others.is_robot
    paths: list[GhostPaths] = []  # built on first use: most cycles have no threat

    def select(
        k: int,
        points: tuple[complex, complex],
        times: tuple[float, float],
        leg_start: complex,
        leg_end: complex,
    ) -> int | None:
        feasible = (times[0] < math.inf, times[1] < math.inf)
        if not (feasible[0] or feasible[1]):
            return None
        if int(ids[k]) in give_way_ids:
            return _RIGHT if feasible[_RIGHT] else 1 - _RIGHT
        if not paths:
            clearance = inflated_radius(observation.radius_m, others.radius_m,
                                        config.safety.d_safety_m)
            paths.append(GhostPaths(others, GHOST_HORIZON_S, clearance))
        w = config.cost
        cost, clear = paths[0].evaluate(
            points, leg_start, leg_end, w.w_length, w.w_distance, w.w_angle, k
        )
        allowed = (feasible[0] and clear[0], feasible[1] and clear[1])
        if not (allowed[0] or allowed[1]):
            allowed = feasible  # everything is near someone's path: still plan
        return choose_side(
            cost,
            allowed,
            side_memory.get(int(ids[k])),
            w.side_hysteresis,
            right_margin if is_robot[k] else 0.0,
        )

    return select


def plan_eifp(
    observation: Observation,
    config: PlannerConfig,
    side_memory: Mapping[int, Side] | None = None,
    timer: Callable[[], float] | None = None,
    primary_id: int | None = None,
    mech: Mechanisms = PAPER_MECHANISMS,
    escape_id: int | None = None,
    previous: ViaPlan | None = None,
) -> ViaPlan:
    """One eIFP cycle without the encounter rules (with `PAPER_MECHANISMS`, the paper's
    eIFP); see `plan_eifp_encounters`."""
    return _plan_eifp(observation, config, side_memory, timer, None, primary_id, mech,
                      escape_id, previous)[0]


def plan_eifp_encounters(
    observation: Observation,
    config: PlannerConfig,
    side_memory: Mapping[int, Side] | None,
    role_memory: Mapping[int, Role],
    timer: Callable[[], float] | None = None,
    primary_id: int | None = None,
    mech: Mechanisms = PAPER_MECHANISMS,
    escape_id: int | None = None,
    previous: ViaPlan | None = None,
) -> tuple[ViaPlan, dict[int, Role]]:
    """One eIFP cycle with the encounter rules; returns (plan, role memory for next cycle)."""
    plan, roles = _plan_eifp(observation, config, side_memory, timer, role_memory, primary_id,
                             mech, escape_id, previous)
    return plan, roles or {}


def _plan_eifp(
    observation: Observation,
    config: PlannerConfig,
    side_memory: Mapping[int, Side] | None,
    timer: Callable[[], float] | None,
    role_memory: Mapping[int, Role] | None,
    primary_id: int | None,
    mech: Mechanisms = PAPER_MECHANISMS,
    escape_id: int | None = None,
    previous: ViaPlan | None = None,
) -> tuple[ViaPlan, dict[int, Role] | None]:
    """One eIFP cycle: IFP's iteration with cost-based candidate selection (Eqs. 15-17).

    The cycle in its named steps: assess the threats (`ifp.assess_threats`), classify the
    encounters against other robots (`assess_encounters`, with the encounter rules), build
    the cost selector (`cost_selector`), then escape, resolve and iterate the legs
    (`ifp.plan_cycle`) with every decision of earlier cycles passed in `ifp.Decisions`.

    Args:
        observation: what the robot knows now.
        config: planner parameters.
        side_memory: threat id -> side chosen last time (None: no memory). Use
            `update_side_memory` to carry it to the next cycle, or `EifpSelector`.
        timer: a wall clock for the stage timings only.
        role_memory: with the encounter rules, the encounter roles of earlier cycles
            (`agent.planning.encounters`); None: the rules are not applied.
        primary_id: the threat the previous cycle resolved first.
        mech: the cycle's mechanisms (`agent.planning.mechanisms.Mechanisms`).
        escape_id: the other the previous cycle escaped from, if any.
        previous: the previous cycle's plan, if it was OK.

    Returns:
        The plan, and (with `role_memory`) the role memory for the next cycle, else None.

    Raises:
        ValueError: on non-finite inputs or configuration.
    """
    memory = side_memory or {}
    t_start = timer() if timer is not None else 0.0
    assessment = assess_threats(observation, config, mech)
    encounters = None
    decisions = Decisions(primary_id=primary_id, escape_id=escape_id, previous=previous)
    if role_memory is not None and len(assessment.others):
        encounters = assess_encounters(observation, assessment, role_memory)
        # A give-way manoeuvre is kept until the other is passed, or it would be undone as
        # soon as it works (the swerve pushes DCPA past D_thresh).
        decisions = Decisions(ignored_ids=encounters.stand_on_ids,
                              committed_ids=encounters.give_way_ids & frozenset(memory),
                              primary_id=primary_id, escape_id=escape_id, previous=previous)
    select = cost_selector(observation, config, assessment.others, memory,
                           encounters.give_way_ids if encounters is not None else frozenset(),
                           RIGHT_HAND_MARGIN if mech.encounter_rules else 0.0)
    threats_s = timer() - t_start if timer is not None else 0.0
    plan = plan_cycle(observation, config, assessment, select, decisions, mech, threats_s)
    if role_memory is None:
        return plan, None
    return plan, (encounters.memory if encounters is not None else {})


@dataclass(frozen=True)
class Encounters:
    """One cycle's encounter roles (`agent.planning.encounters`), by id.

    Args:
        give_way_ids: others resolved on their RIGHT tangent.
        stand_on_ids: others left to give way themselves.
        memory: the role memory to carry to the next cycle.
    """

    give_way_ids: frozenset[int]
    stand_on_ids: frozenset[int]
    memory: dict[int, Role]


def assess_encounters(
    observation: Observation,
    assessment: Assessment,
    memory: Mapping[int, Role],
) -> Encounters:
    """Classify the encounters of this cycle (see `agent.planning.encounters`).

    Args:
        observation: what the robot knows now (its pose and speed).
        assessment: the cycle's neighbours and their Eqs. (3)-(7) assessment
            (`ifp.assess_threats`).
        memory: the role memory of earlier cycles.
    """
    ego = observation.ego
    others = assessment.others
    roles = encounter_roles(ego.heading_rad, ego.v_mps, assessment.position_m, others,
                            assessment.tcpa_s, assessment.dcpa_m, assessment.radius_m, memory)
    threat = np.zeros(len(others), dtype=bool)
    threat[assessment.index] = True
    ids = others.ids
    return Encounters(
        give_way_ids=frozenset(ids[roles == int(Role.GIVE_WAY)].tolist()),
        stand_on_ids=frozenset(ids[roles == int(Role.STAND_ON)].tolist()),
        memory=update_role_memory(others, roles, assessment.tcpa_s, threat, memory),
    )


def update_side_memory(
    side_memory: Mapping[int, Side], plan: ViaPlan, sensed_ids: np.ndarray
) -> dict[int, Side]:
    """The side memory after a cycle: old entries still sensed, overwritten by this plan's.

    Args:
        side_memory: threat id -> side before the cycle.
        plan: the cycle's plan (its `resolved_sides`).
        sensed_ids: (K,) ids of the others sensed this cycle.
    """
    sensed = set(sensed_ids.tolist())
    memory = {i: s for i, s in side_memory.items() if i in sensed}
    memory.update(plan.resolved_sides)
    return memory


class EifpSelector:
    """eIFP with its side memory: `select` once per cycle, `reset` to forget.

    Deterministic: the same sequence of observations gives the same plans.

    Args:
        config: planner settings.
        mech: the cycle's mechanisms (`agent.planning.mechanisms.mechanisms`: eifp's or
            eifp-mpc's by profile).
    """

    def __init__(self, config: PlannerConfig, mech: Mechanisms = PAPER_MECHANISMS) -> None:
        self.config = config
        self.mech = mech
        self._memory: dict[int, Side] = {}
        self._roles: dict[int, Role] = {}
        self._primary: int | None = None
        self._escaping: int | None = None
        self._previous: ViaPlan | None = None

    @property
    def side_memory(self) -> dict[int, Side]:
        """A copy of the memory {threat id -> side chosen last time}."""
        return dict(self._memory)

    def select(
        self, observation: Observation, timer: Callable[[], float] | None = None
    ) -> ViaPlan:
        """Plan one cycle and remember the sides chosen (see `plan_eifp`)."""
        primary = self._primary
        if self.mech.encounter_rules:
            plan, self._roles = plan_eifp_encounters(observation, self.config, self._memory,
                                                     self._roles, timer, primary, self.mech,
                                                     self._escaping, self._previous)
        else:
            plan = plan_eifp(observation, self.config, self._memory, timer, primary,
                             self.mech, self._escaping, self._previous)
        self._previous = plan if plan.status == PlanStatus.OK else None
        self._memory = update_side_memory(self._memory, plan, observation.others.ids)
        self._primary = plan.resolved_id
        self._escaping = plan.resolved_id if plan.status == PlanStatus.ESCAPE else None
        return plan

    def reset(self) -> None:
        """Forget every remembered side and encounter role."""
        self._memory.clear()
        self._roles.clear()
        self._primary = None
        self._escaping = None
        self._previous = None
