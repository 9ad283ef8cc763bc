"""Candidate via-points: tangents to inflated discs, filtered by the velocity cone (Eqs. 7-13).

For each other disc the robot at P draws the two tangents to the disc inflated to
L = r_robot + r_obstacle + d_safety (Eq. 7); the tangent points S1 (RIGHT, alpha - theta)
and S2 (LEFT, alpha + theta) are the raw candidates (Eqs. 8-10).

Velocity-cone feasibility (Eqs. 11-13), our interpretation of the paper: a tangent point
is attached to its obstacle, so in (x, y, t) it moves on the line s_i + lambda (v_o, 1).
The robot can reach, at time t, exactly the points of the cone |(x, y) - P| = r t rooted
at P whose aperture r is the robot's top speed. Substituting the line into the cone gives

    (|v_o|^2 - r^2) lambda^2 + 2 (s_i - P).v_o lambda + |s_i - P|^2 = 0,

and the smallest positive root lambda* is the earliest time at which the robot, driving
straight at full speed, meets the moving tangent point; the via-point is s_i + lambda* v_o.
Candidates without a positive real root are dropped (time = inf, feasible = False). A
static obstacle gives lambda* = M / r; an obstacle exactly as fast as the cone (|v_o| = r)
makes the quadratic linear, handled by the cancellation-free root formula (`cone_time`).
Planners may push the via-point a margin further out of the moving disc (`margin_m`, see
`agent.planning.ifp`), and may cap lambda* (`max_time_s`): a candidate reached later is infeasible.
The cap is ours, for eIFP-MPC (T_max, `agent.planning.mechanisms.Mechanisms.horizon_via_points`).
With the others as fast as the robot the quadratic is nearly linear, and a tangent point
that recedes almost as fast as the robot closes on it is met only after tens or thousands
of seconds: the via-point then lies far down the other's track, and the robot heads along
that track instead of round the disc.

Inside an inflated disc (Q <= L) there is no tangent; `escape_point` gives the defined way
out instead.

`via_point_candidates` is vectorised over discs; `candidate_pair` is the same computation
for one disc in plain floats, for the planners' per-threat inner loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.core.types import Side
from agent.planning.threats import require_finite

# Order of the candidate axis in every (K, 2, ...) array of this module.
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
    """L = r_robot + r_obstacle + d_safety (Eq. 7).

    Args:
        robot_radius_m: own radius [m].
        other_radius_m: (K,) radii of the others [m].
        d_safety_m: safety margin [m].

    Returns:
        (K,) inflated radii [m].
    """
    return np.asarray(other_radius_m, dtype=float) + (robot_radius_m + d_safety_m)


def tangent_points(
    position_m: np.ndarray, centre_m: np.ndarray, inflated_radius_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Tangent points from P to K inflated discs (Eqs. 8-10), RIGHT and LEFT.

    With Q = |c - P|, M = sqrt(Q^2 - L^2), alpha the bearing of c and theta = asin(L/Q),
    the tangent points are P + M (cos(alpha -+ theta), sin(alpha -+ theta)). Written with
    the unit bearing u and its left normal n: P + M (M/Q u -+ L/Q n), no trigonometry.

    Args:
        position_m: (2,) robot position P [m].
        centre_m: (K, 2) disc centres c [m].
        inflated_radius_m: (K,) inflated radii L [m].

    Returns:
        points: (K, 2, 2) tangent points, axis 1 in `SIDES` order (RIGHT, LEFT) [m]; for
            a disc that contains P (Q <= L) both entries are P itself.
        outside: (K,) bool, True where Q > L and the tangent points exist.

    Raises:
        ValueError: on a non-finite input.
    """
    p = np.asarray(position_m, dtype=float)
    c = np.asarray(centre_m, dtype=float).reshape(-1, 2)
    radius = np.asarray(inflated_radius_m, dtype=float).reshape(-1)
    require_finite("tangent_points", p, c, radius)
    return _tangent_points(p, c - p, radius)


def _tangent_points(
    p: np.ndarray, rel: np.ndarray, radius: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """`tangent_points` on centres relative to P, (K, 2); no validation."""
    q_sq = np.einsum("ij,ij->i", rel, rel)
    l_sq = radius * radius
    outside = q_sq > l_sq
    # M/Q^2 and L/Q^2 scale the unnormalised bearing; zero inside (points collapse onto P).
    m = np.sqrt(np.where(outside, q_sq - l_sq, 0.0))
    inv_q_sq = np.divide(1.0, q_sq, out=np.zeros_like(q_sq), where=outside)
    along = (m * m * inv_q_sq)[:, None] * rel
    across = (m * radius * inv_q_sq)[:, None] * np.stack((-rel[:, 1], rel[:, 0]), axis=1)
    points = np.empty((rel.shape[0], 2, 2))
    points[:, 0] = p + along - across  # RIGHT: alpha - theta
    points[:, 1] = p + along + across  # LEFT: alpha + theta
    return points, outside


def cone_time(offset_m: np.ndarray, velocity_mps: np.ndarray, cone_speed_mps: float) -> np.ndarray:
    """Earliest positive lambda where a moving point meets the robot's cone (Eqs. 11-13).

    The point starts at P + offset and moves with `velocity_mps`; the cone is
    |(x, y) - P| = r t. Solves (|v|^2 - r^2) lambda^2 + 2 offset.v lambda + |offset|^2 = 0
    with the cancellation-free form q = -(b + sign(b) sqrt(disc)) / 2, roots q/a and c/q:
    for a -> 0 (|v| = r) the root c/q tends to the linear solution -c/b, and for a static
    point (v = 0) it is |offset| / r.

    Args:
        offset_m: (n, 2) start of each point relative to the cone apex P [m].
        velocity_mps: (n, 2) velocity of each point [m/s].
        cone_speed_mps: cone aperture r, the robot's top speed [m/s] (> 0).

    Returns:
        (n,) lambda* [s]; inf where no positive real root exists.
    """
    a = np.einsum("ij,ij->i", velocity_mps, velocity_mps) - cone_speed_mps * cone_speed_mps
    b = 2.0 * np.einsum("ij,ij->i", offset_m, velocity_mps)
    c = np.einsum("ij,ij->i", offset_m, offset_m)
    disc = b * b - 4.0 * a * c
    real = disc >= 0.0
    root = np.sqrt(np.where(real, disc, 0.0))
    q = -0.5 * (b + np.where(b >= 0.0, root, -root))
    inf = np.full_like(a, np.inf)
    # A quotient too large for a float is a root beyond any horizon: inf, as "no root".
    with np.errstate(over="ignore"):
        lam1 = np.divide(q, a, out=inf.copy(), where=real & (np.abs(a) > _LINEAR_A_TOL))
        lam2 = np.divide(c, q, out=inf.copy(), where=real & (q != 0.0))
    lam1 = np.where(lam1 > 0.0, lam1, np.inf)
    lam2 = np.where(lam2 > 0.0, lam2, np.inf)
    return np.minimum(lam1, lam2)


@dataclass(frozen=True)
class ViaCandidates:
    """The RIGHT and LEFT via-point candidates for K discs.

    Args:
        point_m: (K, 2, 2) via-points s_i + lambda* v_o, axis 1 in `SIDES` order [m];
            the raw tangent point where infeasible, P where no tangent exists.
        time_s: (K, 2) lambda*, the time to reach each via-point at top speed [s]; inf
            where infeasible.
        feasible: (K, 2) bool, a tangent exists and the cone has a positive root.
        outside: (K,) bool, the robot is outside the inflated disc (Q > L).
    """

    point_m: np.ndarray
    time_s: np.ndarray
    feasible: np.ndarray
    outside: np.ndarray


def via_point_candidates(
    position_m: np.ndarray,
    centre_m: np.ndarray,
    velocity_mps: np.ndarray,
    inflated_radius_m: np.ndarray,
    cone_speed_mps: float,
    margin_m: float = 0.0,
    max_time_s: float = math.inf,
) -> ViaCandidates:
    """Tangent candidates for K moving discs, filtered by the velocity cone (Eqs. 8-13).

    The via-point is the tangent point where the cone meets it, s_i + lambda* v_o, which
    lies on the moving disc's boundary at time lambda*. With `margin_m` > 0 it is then
    pushed radially out of the disc (centre c + lambda* v_o) to distance L + margin: a
    plan's next leg can then still be tangent to the same disc (the IFP iteration needs
    a point strictly outside the disc to draw tangents from).

    Args:
        position_m: (2,) robot position P, the cone apex [m].
        centre_m: (K, 2) disc centres at the cone's time origin [m].
        velocity_mps: (K, 2) disc velocities v_o [m/s].
        inflated_radius_m: (K,) inflated radii L (Eq. 7) [m] (> 0).
        cone_speed_mps: cone aperture r, the robot's top speed [m/s] (> 0).
        margin_m: radial push of feasible via-points out of the disc [m].
        max_time_s: candidates with lambda* above this are infeasible [s] (> 0; inf: none).

    Raises:
        ValueError: on a non-finite input or a non-positive cone speed or cap.
    """
    p = np.asarray(position_m, dtype=float)
    c = np.asarray(centre_m, dtype=float).reshape(-1, 2)
    v = np.asarray(velocity_mps, dtype=float).reshape(-1, 2)
    radius = np.asarray(inflated_radius_m, dtype=float).reshape(-1)
    require_finite("via_point_candidates", p, c, v, radius, cone_speed_mps, margin_m)
    if not cone_speed_mps > 0.0:
        raise ValueError("via_point_candidates: cone speed must be positive")
    if not max_time_s > 0.0:
        raise ValueError("via_point_candidates: max_time_s must be positive")
    points, outside = _tangent_points(p, c - p, radius)
    k = c.shape[0]
    time = cone_time((points - p).reshape(2 * k, 2), np.repeat(v, 2, axis=0), cone_speed_mps)
    time = time.reshape(k, 2)
    time[~outside] = np.inf
    time[time > max_time_s] = np.inf
    feasible = np.isfinite(time)
    lam = np.where(feasible, time, 0.0)[:, :, None]
    # c + lam v + (1 + margin / L) (s - c): on the moving boundary, pushed out by margin.
    push = np.where(feasible, margin_m / np.maximum(radius, 1e-300)[:, None], 0.0)[:, :, None]
    moved = points + lam * v[:, None, :] + push * (points - c[:, None, :])
    return ViaCandidates(point_m=moved, time_s=time, feasible=feasible, outside=outside)


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
    """`via_point_candidates` for one disc, in plain floats (the planners' inner loop).

    Same maths, same results as the vectorised form (tested), without numpy's per-call
    overhead on (1, 2) arrays. Inputs are not validated.

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
