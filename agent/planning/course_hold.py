"""Hold the course instead of turning back towards a threat (`Mechanisms.hold_course`).

Not in the paper. A via-point is one point outside the threat's inflated disc, but what it
stands for is a side: pass the threat on the far side of that disc. Replanned every cycle,
the point moves by tenths of a metre as the threat's estimated velocity and the other
threats of the cycle change; the robot, 2-4 m from it, turns by tenths of a radian each
time, towards the threat as often as away from it, and weaves. A turn *towards* the threat
it resolves (inwards, against the side) only brings the robot back to the edge of the
margin it already has, so it is not made while the course held so far still passes clear:
the first via-point is moved onto the robot's heading, at the same distance, when

- the robot is moving (at least `MIN_SPEED_MPS`),
- the via-point lies inwards of the heading (on the threat's side) by at most
  `MAX_HOLD_RAD`,
- and the held plan still holds by the kept plan's test (`kept_plan.plan_holds`): every leg
  of [P, held point, the rest of the plan] clear of every disc within T_max at top speed,
  and the path at most `kept_plan.KEEP_PLAN_RATIO` longer.

Turns away from a threat (outwards) and every turn of a robot that has nothing to resolve
are left as planned. Pure: complex numbers in, a list out.
"""

from __future__ import annotations

import cmath
import math

import numpy as np

from agent.core.types import Side
from agent.planning.kept_plan import plan_holds

MAX_HOLD_RAD = math.radians(20.0)
"""The largest inward turn towards the first via-point that the course hold replaces."""

MIN_SPEED_MPS = 0.3
"""Below this a robot has no course to hold: it turns where its plan leads."""


def held_waypoints(wps: list[complex], side: Side, heading_rad: float, v_mps: float,
                   speed: float, position: np.ndarray, velocity: np.ndarray,
                   clearance: np.ndarray, t_max_s: float) -> list[complex] | None:
    """The plan with its first via-point moved onto the robot's heading, or None.

    Args:
        wps: the cycle's plan as complex points: robot P, via-points, goal (at least one
            via-point).
        side: the side on which the first via-point passes the threat it resolves.
        heading_rad, v_mps: the robot's heading [rad] and speed [m/s].
        speed: the robot's top speed (the legs' test speed) [m/s].
        position, velocity: (K,) the others as complex numbers [m], [m/s].
        clearance: (K,) distance below which other j is in the way [m].
        t_max_s: T_max [s].

    Returns:
        The held plan, or None when the rule does not apply or the held plan fails.
    """
    if len(wps) < 3 or side == Side.NONE or v_mps < MIN_SPEED_MPS:
        return None
    p, via = wps[0], wps[1]
    to_via = via - p
    dist = abs(to_via)
    if dist <= 0.0:
        return None
    off = cmath.phase(to_via * cmath.exp(-1j * heading_rad))  # + : left of the heading
    # Passing on the RIGHT leaves the threat on the left: a turn to the left is inward.
    inward = off > 0.0 if side == Side.RIGHT else off < 0.0
    if not inward or abs(off) > MAX_HOLD_RAD:
        return None
    held = [p, p + dist * cmath.exp(1j * heading_rad), *wps[2:]]
    if not plan_holds(held, wps, speed, position, velocity, clearance, t_max_s):
        return None
    return held
