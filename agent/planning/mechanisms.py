"""Which of this project's additions to the paper's planning cycle a planner runs.

`Mechanisms` lists them, one field each (the reasons are on the fields and in
docs/method.md); every field at its default is the paper's cycle (`PAPER_MECHANISMS`).
`mechanisms(planner, config)` gives a planner its set under the configuration's profile,
minus the mechanisms the configuration switches off (`PlannerConfig.without`, the
ablations of `orchestrator run --without` and `orchestrator benchmark --without`):
ablations are built from the configuration, never patched into a module.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from agent.core.config import PlannerConfig
from agent.planning.liveness import LivenessConfig

VIA_MARGIN_M = 0.05
"""How far outside its inflated disc a via-point is placed in the paper's cycle [m]."""

ARC_VIA_MARGIN_M = 0.3
"""How far outside its inflated disc a via-point lies when the reference joins the legs with
arcs (`Mechanisms.lines_arcs`): an arc of radius R turning by angle a at a via-point passes
R (1 / cos(a / 2) - 1) inside the corner, towards the disc it turns round; 0.3 m covers a
1 m arc up to about 75 degrees of turn."""

ESCAPE_BAND_M = 0.1
"""An escape goes on until the robot is this far outside the disc (`Mechanisms.escape_band_m`):
two robots on each other's boundary otherwise alternate between escaping and planning
round each other every cycle."""

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
        goal_tcpa_filter: threats whose TCPA is more than `ifp.GOAL_TCPA_MARGIN_S` past the
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
        escape_all: inside several inflated discs, the escape leads out of all of them
            (`viapoints.escape_point_many`), not straight out of the deepest into the next.
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
            through them is still clear and the path is at most `kept_plan.KEEP_PLAN_RATIO` longer
            than the one the cycle just built (`ifp.keep_previous`). Rebuilt from scratch each
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
        turn_when_stuck: eIFP-MPC commits a stuck robot that stands facing away from its
            reference to one bounded turn on the spot (`agent.planning.turning`): the
            MPC, linearised about its prediction, finds no gain in turning a hemmed-in
            robot. Needs `liveness` (its progress monitor says when).
        passages: a route is centred in its narrow passages (gaps that admit the robot
            but not its margin, and gaps two robots cannot pass each other in), the discs
            bounding a passage the robot is near are planned against with the margin the
            passage leaves, and a one-lane passage is taken one way at a time, the robot
            that gives way waiting off the line (`agent.planning.passages`). Needs
            `routing`.
        goal_guard: a robot parked at its goal keeps watch on the moving obstacles it
            senses and steps aside to a refuge beside the track of one that would pass
            within the inflated radius L, returning once it has passed
            (`agent.planning.goal_guard`): a blind obstacle otherwise runs it down.
        make_way: a robot parked at its goal steps aside, across the line from it, for a
            robot that came up after it parked and stays within `make_way.PRESS_GAP_M` of
            it for `make_way.PRESS_S`, and returns once that robot has gone by
            (`agent.planning.make_way`): where a parked robot stands in the only way to
            another's goal (a corridor, a doorway), nothing else opens it.
        lanes: with `passages`, a corridor wider than one lane but narrower than two
            robots on routes along opposite walls is driven in lanes, each robot on its
            right (`agent.planning.passages`, "Lanes"). Only in the ``lanes`` profile: on
            its tuning scenes it helped a maze with counterflow and hurt a crossing of
            corridors (docs/results.md, "Lanes in corridors: an opt-in profile").
        primary_hold_s: with `commitment`, how much later than the most imminent threat's
            the TCPA of last cycle's first threat may be for it to stay first [s].
    """

    direct_leg_check: bool = False
    goal_tcpa_filter: bool = False
    encounter_rules: bool = False
    inflated_threats: bool = False
    commitment: bool = False
    via_margin_m: float = VIA_MARGIN_M
    escape_band_m: float = 0.0
    escape_all: bool = False
    horizon_via_points: bool = False
    lines_arcs: bool = False
    clamp_heading: bool = False
    braking_guard: bool = False
    keep_plan: bool = False
    routing: bool = False
    liveness: LivenessConfig | None = None
    turn_when_stuck: bool = False
    goal_guard: bool = False
    passages: bool = False
    make_way: bool = False
    lanes: bool = False
    primary_hold_s: float = PRIMARY_HOLD_S


PAPER_MECHANISMS = Mechanisms()
"""The paper's cycle (the ``paper`` profile, every planner)."""

IFP_MECHANISMS = Mechanisms(direct_leg_check=True, goal_tcpa_filter=True, clamp_heading=True,
                            goal_guard=True)
"""ifp in the default profile."""

EIFP_MECHANISMS = dataclasses.replace(IFP_MECHANISMS, encounter_rules=True)
"""eifp in the default profile: ifp's and the encounter rules. Its pure-pursuit law cuts
the corners of a lines-and-arcs reference, so it keeps the spline and the paper's cycle."""

EIFP_MPC_MECHANISMS = dataclasses.replace(
    EIFP_MECHANISMS, inflated_threats=True, commitment=True, via_margin_m=ARC_VIA_MARGIN_M,
    escape_band_m=ESCAPE_BAND_M, escape_all=True, horizon_via_points=True,
    lines_arcs=True, clamp_heading=False, braking_guard=True, keep_plan=True, routing=True,
    liveness=LivenessConfig(), turn_when_stuck=True, passages=True, make_way=True)
"""eifp-mpc in the default profile: every mechanism but `Mechanisms.lanes`."""

EIFP_MPC_LANES_MECHANISMS = dataclasses.replace(EIFP_MPC_MECHANISMS, lanes=True)
"""eifp-mpc in the ``lanes`` profile."""


def mechanisms(planner: str, config: PlannerConfig) -> Mechanisms:
    """The mechanisms `planner` runs with under `config.profile`, minus those named in
    `config.without` (each set to its value in the paper's cycle)."""
    if config.is_paper:
        return PAPER_MECHANISMS
    if planner == "eifp-mpc":
        chosen = (EIFP_MPC_LANES_MECHANISMS if config.profile == "lanes"
                  else EIFP_MPC_MECHANISMS)
    elif planner == "eifp":
        chosen = EIFP_MECHANISMS
    else:
        chosen = IFP_MECHANISMS
    off = config.without_names
    if not off:
        return chosen
    return dataclasses.replace(chosen, **{name: getattr(PAPER_MECHANISMS, name) for name in off})

