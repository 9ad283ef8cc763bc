"""Candidate via-points: tangents to inflated discs, filtered by the velocity cone (Eqs. 8-14).

For each other disc the robot at P draws the two tangents to the disc inflated to
L = r_robot + r_obstacle + d_safety (Eq. 8); the tangent points S1 (RIGHT, alpha - theta)
and S2 (LEFT, alpha + theta) are the raw candidates (Eqs. 9-11).

Velocity-cone feasibility (Eqs. 12-14), our interpretation of the paper: a tangent point
is attached to its obstacle, so in (x, y, t) it moves on the line s_i + lambda (v_o, 1).
The robot can reach, at time t, exactly the points of the cone |(x, y) - P| = r t rooted
at P whose aperture r is the robot's top speed. Substituting the line into the cone gives

    (|v_o|^2 - r^2) lambda^2 + 2 (s_i - P).v_o lambda + |s_i - P|^2 = 0,

and the smallest positive root lambda* is the earliest time at which the robot, driving
straight at full speed, meets the moving tangent point; the via-point is s_i + lambda* v_o.
Candidates without a positive real root are dropped (time = inf). A static obstacle gives
lambda* = M / r; an obstacle exactly as fast as the cone (|v_o| = r) makes the quadratic
linear, handled by the cancellation-free root formula q = -(b + sign(b) sqrt(disc)) / 2,
roots q/a and c/q (c/q tends to the linear root -c/b as a -> 0).
Planners may push the via-point a margin further out of the moving disc (`margin_m`, see
`agent.planning.ifp`), and may cap lambda* (`max_time_s`): a candidate reached later is infeasible.
The cap is ours, for eIFP-MPC (T_max, `agent.planning.mechanisms.Mechanisms.horizon_via_points`).
With the others as fast as the robot the quadratic is nearly linear, and a tangent point
that recedes almost as fast as the robot closes on it is met only after tens or thousands
of seconds: the via-point then lies far down the other's track, and the robot heads along
that track instead of round the disc.

Inside an inflated disc (Q <= L) there is no tangent; `escape_point` gives the defined way
out instead.

`candidate_pair` is the one implementation of Eqs. (9)-(14): the planners call it once per
threat they resolve, in plain floats (numpy's per-call overhead on (1, 2) arrays would
dominate). tests/unit/agent/planning/test_viapoints.py checks it against the paper's
trigonometric form of the equations.
"""

from __future__ import annotations

import math

import numpy as np

from agent.core.types import Side
from agent.planning.threats import require_finite

# Order of the two candidates of `candidate_pair`.
SIDES: tuple[Side, Side] = (Side.RIGHT, Side.LEFT)

# How far outside the inflated disc an escape point lies [m].
ESCAPE_MARGIN_M = 0.05

# |a| of the cone quadratic below which it is solved as linear [m^2/s^2] (|v_o| = r).
_LINEAR_A_TOL = 1.0e-12

# Below this distance [m] the robot and the disc centre coincide (escape by heading).
_COINCIDENT_M = 1.0e-9


def inflated_radius(
    robot_radius_m: float, other_radius_m: np.ndarray | float, d_safety_m: float
) -> np.ndarray:
    """L = r_robot + r_obstacle + d_safety (Eq. 8).

    Args:
        robot_radius_m: own radius [m].
        other_radius_m: (K,) radii of the others [m].
        d_safety_m: safety margin [m].

    Returns:
        (K,) inflated radii [m].
    """
    return np.asarray(other_radius_m, dtype=float) + (robot_radius_m + d_safety_m)


def candidate_pair(
    px: float,
    py: float,
    cx: float,
    cy: float,
    vx: float,
    vy: float,
    radius_m: float,
    cone_speed_mps: float,
    margin_m: float = 0.0,
    max_time_s: float = math.inf,
) -> tuple[tuple[float, float, float], tuple[float, float, float]] | None:
    """The RIGHT and LEFT via-points of one moving disc (Eqs. 9-14), in plain floats.

    With Q = |c - P| and M = sqrt(Q^2 - L^2), the tangent points are
    P + M (cos(alpha -+ theta), sin(alpha -+ theta)) (Eqs. 10-11); written with the bearing
    c - P and its left normal: P + (M/Q)^2 (c - P) -+ (M L / Q^2) n, no trigonometry. Each
    then moves with the disc and is met at the smallest positive root lambda* of the cone
    quadratic (Eq. 14, see the module docstring). Inputs are not validated.

    Args:
        px, py: cone apex P [m].
        cx, cy: disc centre at the cone's time origin [m].
        vx, vy: disc velocity [m/s].
        radius_m: inflated radius L [m].
        cone_speed_mps: cone aperture r [m/s] (> 0).
        margin_m: radial push of feasible via-points out of the disc [m].
        max_time_s: candidates with lambda* above this are infeasible [s].

    Returns:
        None if P is inside the disc (Q <= L); else ((x, y, lambda*) RIGHT,
        (x, y, lambda*) LEFT), with lambda* = inf and (x, y) the raw tangent point where
        the cone has no positive root.
    """
    rx, ry = cx - px, cy - py
    q_sq = rx * rx + ry * ry
    l_sq = radius_m * radius_m
    if not q_sq > l_sq:
        return None
    # Eqs. (9)-(11): the tangent points relative to P, along the bearing and across it.
    m_sq = q_sq - l_sq
    along = m_sq / q_sq
    across = math.sqrt(m_sq) * radius_m / q_sq
    ax, ay = along * rx, along * ry
    nx, ny = -across * ry, across * rx
    vv = vx * vx + vy * vy
    a = vv - cone_speed_mps * cone_speed_mps
    push = margin_m / radius_m  # (1 + push) (s - c) is the pushed offset from the centre
    out = []
    for sign in (-1.0, 1.0):  # SIDES order: RIGHT (alpha - theta), LEFT (alpha + theta)
        ox, oy = ax + sign * nx, ay + sign * ny
        # Eq. (14): a lambda^2 + b lambda + c = 0, the moving tangent point on the cone.
        b = 2.0 * (ox * vx + oy * vy)
        c = ox * ox + oy * oy
        disc = b * b - 4.0 * a * c
        lam = math.inf
        if disc >= 0.0:
            root = math.sqrt(disc)
            q = -0.5 * (b + (root if b >= 0.0 else -root))
            if abs(a) > _LINEAR_A_TOL and q / a > 0.0:
                lam = q / a
            if q != 0.0 and 0.0 < c / q < lam:
                lam = c / q
            if lam > max_time_s:
                lam = math.inf
        if lam < math.inf:
            sx, sy = ox - rx, oy - ry  # tangent point relative to the centre
            out.append(
                (
                    px + ox + lam * vx + push * sx,
                    py + oy + lam * vy + push * sy,
                    lam,
                )
            )
        else:
            out.append((px + ox, py + oy, lam))
    return out[0], out[1]


def escape_point(
    position_m: np.ndarray,
    centre_m: np.ndarray,
    inflated_radius_m: float,
    heading_rad: float,
    margin_m: float = ESCAPE_MARGIN_M,
) -> np.ndarray:
    """Where a robot inside an inflated disc (Q <= L) heads to get out of it.

    The point lies on the ray from the centre through P at distance L + margin, i.e.
    straight out along P - c. If P coincides with c (no ray), the robot leaves towards its
    own right: the direction perpendicular-right of its heading, (sin h, -cos h), the same
    right-hand convention the planners use to break ties. Always finite.

    Args:
        position_m: (2,) robot position P [m].
        centre_m: (2,) disc centre c [m].
        inflated_radius_m: L [m].
        heading_rad: robot heading, used only when P = c [rad].
        margin_m: how far beyond L the point lies [m].

    Raises:
        ValueError: on a non-finite input.
    """
    p = np.asarray(position_m, dtype=float)
    c = np.asarray(centre_m, dtype=float)
    require_finite("escape_point", p, c, inflated_radius_m, heading_rad, margin_m)
    away = p - c
    q = math.hypot(away[0], away[1])
    if q < _COINCIDENT_M:
        direction = np.array([math.sin(heading_rad), -math.cos(heading_rad)])
    else:
        direction = away / q
    return c + (inflated_radius_m + margin_m) * direction


def escape_point_many(
    position_m: np.ndarray,
    centres_m: np.ndarray,
    inflated_radii_m: np.ndarray,
    heading_rad: float,
    margin_m: float = ESCAPE_MARGIN_M,
) -> np.ndarray:
    """Where a robot inside several inflated discs heads to get out of all of them.

    Not in the paper (`Mechanisms.escape_all`). Straight out of the deepest disc alone
    (`escape_point`) can lead straight into the next: a robot squeezed between two others
    escapes from one towards the other, whose braking guard then stops it, and both
    stand. Here the direction is the sum of the unit vectors out of each disc, each
    weighted by how deep the robot is inside it (plus 1 cm, so a disc it only touches still
    counts); the point is where that ray leaves the last of the discs, `margin_m` beyond.
    When the weighted vectors cancel (a symmetric squeeze), the direction is across the
    line of the squeeze, to the robot's right (the planners' right-hand convention).

    Args:
        position_m: (2,) robot position P [m].
        centres_m: (n, 2) centres of the discs the robot is inside [m].
        inflated_radii_m: (n,) their radii L [m].
        heading_rad: robot heading (`escape_point`'s tie rule) [rad].
        margin_m: how far beyond each L the point lies [m].

    Raises:
        ValueError: on a non-finite input or no disc.
    """
    p = np.asarray(position_m, dtype=float)
    c = np.asarray(centres_m, dtype=float).reshape(-1, 2)
    r = np.asarray(inflated_radii_m, dtype=float).reshape(-1) + margin_m
    require_finite("escape_point_many", p, c, r, heading_rad)
    if c.shape[0] == 0:
        raise ValueError("escape_point_many: no disc")
    away = p - c
    q = np.hypot(away[:, 0], away[:, 1])
    deepest = int(np.argmax(r - q))
    if c.shape[0] == 1 or np.any(q < _COINCIDENT_M):
        return escape_point(p, c[deepest], float(r[deepest]) - margin_m, heading_rad, margin_m)
    weight = np.maximum(r - q, 0.0) + 0.01
    pull = (weight[:, None] * away / q[:, None]).sum(axis=0)
    norm = math.hypot(pull[0], pull[1])
    if norm < 1e-6 * float(weight.sum()):
        # the pulls cancel: across the line of the squeeze, to the robot's right
        radial = away[deepest] / q[deepest]
        d = np.array([radial[1], -radial[0]])
        if d @ (math.sin(heading_rad), -math.cos(heading_rad)) < 0.0:
            d = -d
    else:
        d = pull / norm
    # |away_k + t d| = r_k: t_k = -(away_k . d) + sqrt((away_k . d)^2 - q_k^2 + r_k^2)
    along = away @ d
    t = -along + np.sqrt(np.maximum(along * along - q * q + r * r, 0.0))
    return p + float(t.max()) * d
