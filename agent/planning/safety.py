"""Braking guard: the speed at which a robot can still stop its own approach in time.

Not in the paper (eIFP-MPC only). The MPC's half-planes are soft (`agent.planning.mpc`): in
a crowd the QP can be infeasible, and the slack is then spread over the neighbours by cost
alone, so a robot squeezed between a stopped neighbour and one coming at it may choose to
drive into the stopped one. The guard is a last filter on the command that the QP cannot
trade away. It follows the responsibility rule of the RSS model (Shalev-Shwartz et al.,
2017) along the line to each sensed disc: a robot answers for its own approach and must be
able to cancel it before the gap is gone, given how late its command acts.

For each other disc j at centre distance d, with gap g = d - r - r_j - margin, unit vector
u from the robot to j and heading h, the robot closes along u at v cos a, where a is the
smallest angle between u and the headings the robot sweeps (`sweep_rad`); the planner passes
the sweep at the commanded rate on through the stop (tau + v / decel), because the world
brakes a robot along its commanded arc (`agent.planning.planners.ViaPointPlanner
._braking_guard`). Over tau it keeps closing at that rate, then brakes at `decel`. The
other's speed along u, w = v_j . u, changes the room R the robot has:

  * receding (w > 0): it can brake as hard, which leaves w^2 / (2 decel) more room;
  * approaching (w < 0): it needs its own stopping distance c tau + c^2 / (2 decel),
    c = -w, out of the same gap (two that drive at each other each answer for their own
    approach, and the gap must hold both stops).

The estimate w lags: a least-squares slope over the last `window` seconds of poses trails a
constant acceleration by window / 2, and the poses are `age` old. Over that lag the other
may have sped up towards the robot, so w is taken `unseen_dv` smaller than estimated
(`unseen_speed_up_mps`): a unicycle speeds up along its heading (forward only), which may
have turned by omega_max lag meanwhile, and never past v_max, so

    unseen_dv = min(a_max lag, v_max - |v_j|) max(0, cos(max(0, d - omega_max lag))),

d the angle between the other's observed heading and the direction from it to the robot;
and one heading away from the robot may have braked as late (a leader the robot follows),
which closes the gap by

    unseen_dv_brake = min(a_max lag, |v_j|) max(0, -cos d);

the larger of the two counts. Both bounds assume the worst over the whole lag. Where the
speed between an other's two newest samples is known (`Others.recent_speed_mps`, only from
fresh poses), each term is instead the change those samples already show plus a_max over
half their interval and the pose age, if that is less: a leader that keeps its speed no
longer counts as braking. The others' limits are taken as the robot's own (a fleet of like
robots; a robot cannot sense another's limits); an unknown heading counts as facing the
robot; scenario obstacles move at constant velocity.

From delayed poses a turn term is added too (`unseen_turn_closing_mps`): the estimate's
direction trails a turn by about window / 2 and the observed heading by the pose age, so an
other whose heading, carried on at its observed turn rate, points more at the robot than
its estimate closes that much faster; per other the larger of it and the speed term counts.

The largest safe speed solves v cos a tau + v^2 cos a / (2 decel) = R:

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
    unseen_dv_mps: np.ndarray | float = 0.0,
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
        unseen_dv_mps: scalar or (K,) >= 0, how much faster than estimated each other may
            be closing (its velocity estimate lags; see the module docstring).

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
    if isinstance(unseen_dv_mps, float | int):  # the guard's first pass: no numpy here
        unseen = [float(unseen_dv_mps)] * len(pos)
        checked = unseen[:1]  # one value for all: check it once
    else:
        unseen = np.broadcast_to(np.asarray(unseen_dv_mps, dtype=float), (len(pos),)).tolist()
        checked = unseen
    if not all(0.0 <= u < math.inf for u in checked):  # NaN fails this too
        raise ValueError("unseen_dv_mps must be finite and >= 0")
    for j, (ox, oy) in enumerate(pos):
        dx, dy = ox - x, oy - y
        dist = math.hypot(dx, dy)
        if dist < 1e-9:
            return 0.0  # on its centre: no direction to trust
        ux, uy = dx / dist, dy / dist
        # the other's speed away from the robot, as fast towards it as it may be by now
        w = vel[j][0] * ux + vel[j][1] * uy - unseen[j]
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


def unseen_speed_up_mps(
    position_m: tuple[float, float],
    others_position_m: np.ndarray,
    others_heading_rad: np.ndarray,
    is_robot: np.ndarray,
    *,
    accel_mps2: float,
    turn_rate_radps: float,
    lag_s: float,
    others_speed_mps: np.ndarray | None = None,
    v_max_mps: float = math.inf,
    recent_speed_mps: np.ndarray | None = None,
    recent_lag_s: np.ndarray | None = None,
) -> np.ndarray:
    """How much faster than its estimate each other may be closing on the robot by now.

    Args:
        position_m: (x, y) of the robot.
        others_position_m: (K, 2) the others' positions.
        others_heading_rad: (K,) their observed headings (NaN: unknown, any heading).
        is_robot: (K,) False for scenario obstacles (constant velocity: 0).
        accel_mps2: the others' largest acceleration (> 0).
        turn_rate_radps: their largest turn rate (>= 0).
        lag_s: how far their velocity estimates trail (>= 0).
        others_speed_mps: (K,) their estimated speeds; with `v_max_mps`, a robot cannot
            have sped up past v_max (None: no bound).
        v_max_mps: their largest speed.
        recent_speed_mps: (K,) with `others_speed_mps`: each one's speed over the newest
            interval of its observed history (NaN: unknown), which shows most of a speed
            change the estimate trails; None: not used.
        recent_lag_s: (K,) how old that speed is: half the interval plus the pose age.

    Returns:
        (K,) unseen_dv in m/s, in [0, accel_mps2 lag_s]: the larger of a speed-up towards
        the robot (at most to v_max) and, with `others_speed_mps`, a braking of one
        heading away from it (at most to rest). Where a recent speed is known, each is
        the change already seen (recent speed against the estimate) plus `accel_mps2`
        over `recent_lag_s`, if that is less than the bound over `lag_s`.
    """
    if not (accel_mps2 > 0.0 and turn_rate_radps >= 0.0 and lag_s >= 0.0):
        raise ValueError("accel_mps2 > 0, turn_rate_radps >= 0 and lag_s >= 0 required")
    to_robot = np.asarray(position_m, dtype=float) - others_position_m
    bearing = np.arctan2(to_robot[:, 1], to_robot[:, 0])
    off = np.abs(np.remainder(bearing - others_heading_rad + np.pi, 2.0 * np.pi) - np.pi)
    facing = np.cos(np.maximum(off - turn_rate_radps * lag_s, 0.0))
    facing = np.where(np.isnan(facing), 1.0, np.maximum(facing, 0.0))
    bound = accel_mps2 * lag_s
    up = np.full(len(others_position_m), bound)
    if others_speed_mps is not None:
        up = np.clip(v_max_mps - others_speed_mps, 0.0, up)
        down = np.minimum(bound, others_speed_mps)
        if recent_speed_mps is not None and recent_lag_s is not None:
            # what the newest interval already shows, and what it cannot show yet
            since = accel_mps2 * np.maximum(recent_lag_s, 0.0)
            change = recent_speed_mps - others_speed_mps  # NaN where unknown
            known = ~np.isnan(change)
            change = np.where(known, change, 0.0)
            up = np.where(known, np.minimum(up, np.maximum(change, 0.0) + since), up)
            down = np.where(known, np.minimum(down, np.maximum(-change, 0.0) + since), down)
    closing = up * facing
    if others_speed_mps is not None:
        # one heading away from the robot may have braked since: as much closer, down to rest
        away = np.where(np.isnan(off), 0.0, np.maximum(-np.cos(off), 0.0))
        closing = np.maximum(closing, down * away)
    return np.where(is_robot, closing, 0.0)


def unseen_turn_closing_mps(
    position_m: tuple[float, float],
    others_position_m: np.ndarray,
    others_velocity_mps: np.ndarray,
    others_heading_rad: np.ndarray,
    others_turn_rate_radps: np.ndarray,
    is_robot: np.ndarray,
    *,
    turn_rate_max_radps: float,
    age_s: float,
    reaction_s: float,
) -> np.ndarray:
    """How much faster than its estimate each other may be closing because it turns.

    The estimated velocity's direction trails a turn by about window / 2 (a least-squares
    slope over a curved track), the observed heading by the pose age only. An other that
    keeps its observed turn rate (`Others.recent_turn_rate_radps`, at most the largest)
    heads, from now until a braking command of the robot acts, somewhere between
    h + omega age and h + omega (age + reaction); at its estimated speed its closing speed
    is then up to |v_j| max cos(bearing to the robot - heading) over those headings. The
    term is how much that exceeds the estimate's closing speed, never negative. Unknown
    heading: 0 (`unseen_speed_up_mps` already takes any heading as facing the robot);
    unknown turn rate: the heading now only; scenario obstacles: 0.

    Args:
        position_m: (x, y) of the robot.
        others_position_m, others_velocity_mps: (K, 2) the others (predicted to now) and
            their estimated velocities.
        others_heading_rad: (K,) observed headings (NaN: unknown).
        others_turn_rate_radps: (K,) observed turn rates (NaN: unknown).
        is_robot: (K,) False for scenario obstacles.
        turn_rate_max_radps: the others' largest turn rate (>= 0).
        age_s: how old the observed headings are (>= 0).
        reaction_s: how long until a braking command of the robot acts (>= 0).

    Returns:
        (K,) the extra closing speed in m/s, >= 0 and at most 2 |v_j|.
    """
    if not (turn_rate_max_radps >= 0.0 and age_s >= 0.0 and reaction_s >= 0.0):
        raise ValueError("turn_rate_max_radps, age_s and reaction_s must be >= 0")
    to_robot = np.asarray(position_m, dtype=float) - others_position_m
    dist = np.hypot(to_robot[:, 0], to_robot[:, 1])
    unit = to_robot / np.maximum(dist, 1e-9)[:, None]
    estimated = (others_velocity_mps * unit).sum(axis=1)  # closing speed, > 0 approaching
    speed = np.hypot(others_velocity_mps[:, 0], others_velocity_mps[:, 1])
    omega = np.clip(np.nan_to_num(others_turn_rate_radps, nan=0.0),
                    -turn_rate_max_radps, turn_rate_max_radps)
    bearing = np.arctan2(unit[:, 1], unit[:, 0])
    # the bearing seen from the heading now, and the heading's sweep over the reaction
    delta = np.remainder(bearing - others_heading_rad - omega * age_s + np.pi,
                         2.0 * np.pi) - np.pi
    sweep = omega * reaction_s  # |sweep| < pi for any sensible reaction time
    inside = np.where(sweep >= 0.0, (delta >= 0.0) & (delta <= sweep),
                      (delta <= 0.0) & (delta >= sweep))
    best = np.where(inside, 1.0, np.maximum(np.cos(delta), np.cos(delta - sweep)))
    extra = np.maximum(speed * best - estimated, 0.0)
    known = ~np.isnan(others_heading_rad) & np.asarray(is_robot, dtype=bool) & (dist > 1e-9)
    return np.where(known, np.nan_to_num(extra, nan=0.0), 0.0)


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
