"""Braking guard: the speed at which a robot can still stop its own approach in time.

Not in the paper. eIFP-MPC's half-planes are soft (`agent.mpc`): in a crowd the QP can be
infeasible, and then the slack is spread over the neighbours by cost alone, so a robot
squeezed between a stopped neighbour and one coming at it may choose to drive into the
stopped one (seen at 100 ms link latency in setup G: 0.2 -> 1.1 m/s into a robot that
stood still and spun). The guard is a last filter on the command that the QP cannot
trade away. It follows the responsibility rule of the RSS model (Shalev-Shwartz et al.,
2017) along the line to each sensed disc: a robot is responsible for its own approach
and must be able to cancel it before the gap is gone, given how late its command acts.

For each other disc j at centre distance d, with gap g = d - r - r_j - margin, unit vector
u from the robot to j and heading h, the robot closes along u at v cos a with cos a = h . u;
a is the smallest angle between u and the headings the robot sweeps if it keeps turning at
the commanded rate until a braking command can act (tau). Sweeping on through the stop
(tau + v / decel) was measured too: as safe under latency, but it slowed the crowded
centre of setup G without faults (oscillations 7.7 -> 9.3 per robot, one of 30 seeds out
of time). Over
the reaction time tau it keeps closing at that rate (the command in flight and the one
period it is held), then brakes at `decel` (its closing speed falls at decel cos a). The
other's speed along u, w = v_j . u, changes the room R the robot has:

  * receding (w > 0): it can brake as hard, which leaves w^2 / (2 decel) more room;
  * approaching (w < 0): it needs its own stopping distance c tau + c^2 / (2 decel),
    c = -w, out of the same gap (the RSS rule for two that drive at each other: each
    answers for its own approach, and the gap must hold both stops);

and the largest safe speed solves v cos a tau + v^2 cos a / (2 decel) = R:

    v_safe = decel (-tau + sqrt(tau^2 + 2 R / (decel cos a))),

with v_safe = 0 when R is not positive. Discs the robot does not face (cos a <= 0) put no
limit. tau is the pose age (the poses are forward-predicted to now, the command link is
assumed as slow as the pose link) plus one control period; the others' velocities are
estimates from their observed poses.
"""

from __future__ import annotations

import math

import numpy as np


def braking_speed_limit(
    position_m: tuple[float, float],
    heading_rad: float,
    radius_m: float,
    others_position_m: np.ndarray,
    others_velocity_mps: np.ndarray,
    others_radius_m: np.ndarray,
    *,
    reaction_s: float,
    decel_mps2: float,
    margin_m: float,
    sweep_rad: float = 0.0,
    up_to_mps: float = math.inf,
) -> float:
    """The largest forward speed from which the robot can still stop its approach in time.

    Args:
        position_m: (x, y) of the robot.
        heading_rad: its heading now.
        radius_m: the robot's radius.
        others_position_m, others_velocity_mps: (K, 2) the other discs (predicted to now).
        others_radius_m: (K,) their radii.
        reaction_s: tau, how long the command acts before a braking one can (>= 0).
        decel_mps2: the robot's braking deceleration (> 0).
        margin_m: gap kept at the end of the braking (>= 0).
        sweep_rad: how far the heading turns (signed) while the robot reacts;
            0 checks the heading now only.
        up_to_mps: the speed the caller asks about: a disc whose room allows it even when
            faced squarely is skipped before any trigonometry (the planning cycle's cheap
            path), so the result is exact where it is below `up_to_mps`.

    Returns:
        v_safe in m/s (0 when a disc it faces is already within the margin); `math.inf`
        when no disc limits the speed (to `up_to_mps`).
    """
    if decel_mps2 <= 0.0 or reaction_s < 0.0 or margin_m < 0.0:
        raise ValueError("decel_mps2 > 0, reaction_s >= 0 and margin_m >= 0 required")
    x, y = float(position_m[0]), float(position_m[1])
    limit = math.inf
    # room that lets up_to_mps through even straight at the disc (cos a = 1)
    enough = up_to_mps * reaction_s + up_to_mps * up_to_mps / (2.0 * decel_mps2)
    pos, vel = others_position_m.tolist(), others_velocity_mps.tolist()
    rad = others_radius_m.tolist()
    for j, (ox, oy) in enumerate(pos):
        dx, dy = ox - x, oy - y
        dist = math.hypot(dx, dy)
        if dist < 1e-9:
            return 0.0  # on its centre: no direction to trust
        ux, uy = dx / dist, dy / dist
        w = vel[j][0] * ux + vel[j][1] * uy  # the other's speed away from the robot
        if w >= 0.0:
            share = -w * w / (2.0 * decel_mps2)  # it can brake too: more room
        else:
            share = -w * reaction_s + w * w / (2.0 * decel_mps2)  # its own stop
        room = dist - radius_m - rad[j] - margin_m - share
        if room >= enough and room > 0.0:
            continue  # cannot limit below up_to_mps
        cos_a = _worst_cos(math.atan2(dy, dx) - heading_rad, sweep_rad)
        if cos_a <= 1e-9:  # not faced (cos of a right angle rounds to 6e-17)
            continue
        if room <= 0.0:
            return 0.0
        v_safe = decel_mps2 * (
            -reaction_s + math.sqrt(reaction_s * reaction_s + 2.0 * room / (decel_mps2 * cos_a))
        )
        limit = min(limit, v_safe)
    return limit


def heading_sweep_rad(omega_radps: float, reaction_s: float) -> float:
    """The signed heading change over the reaction time at a constant turn rate, at most a
    half turn either way."""
    return max(-math.pi, min(math.pi, omega_radps * reaction_s))


def _worst_cos(delta_rad: float, sweep_rad: float) -> float:
    """max cos(delta - s) over s between 0 and `sweep_rad` (the headings swept)."""
    delta = math.remainder(delta_rad, 2.0 * math.pi)  # in [-pi, pi]
    lo, hi = min(0.0, sweep_rad), max(0.0, sweep_rad)
    turn = 2.0 * math.pi
    if any(lo <= d <= hi for d in (delta, delta - turn, delta + turn)):
        return 1.0
    return max(math.cos(delta - lo), math.cos(delta - hi))
