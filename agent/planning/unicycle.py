"""Discrete unicycle model of Eq. (1), its Jacobians, command limits and a tracking law.

State x = [x, y, theta] (m, m, rad) and control u = [v, omega] (m/s, rad/s):

    x_{k+1} = x_k + v_k cos(theta_k) dt
    y_{k+1} = y_k + v_k sin(theta_k) dt
    theta_{k+1} = theta_k + omega_k dt

The heading is integrated without wrapping (a continuous angle); `wrap_angle` maps it to
[-pi, pi) where a bounded angle is needed. Everything here is pure: no I/O, no clock.
"""

from __future__ import annotations

import math

import numpy as np

from agent.core.config import RobotLimits

LOOKAHEAD_S = 0.6
"""The tracking law of ifp, eifp (`track_reference`) aims this far ahead on the reference, at
top speed [s]: about the time a heading error takes to decay at `HEADING_GAIN`, so the
robot aims where it can be on the path once it has turned."""

HEADING_GAIN = 2.5
"""Proportional gain of the tracking and heading laws on heading error [1/s] (ifp, eifp,
orca): a 0.6 rad error commands the full 1.5 rad/s turn rate."""


def wrap_angle(angle_rad: float | np.ndarray) -> float | np.ndarray:
    """Map angles to [-pi, pi).

    Args:
        angle_rad: scalar or array of angles [rad].
    """
    wrapped = np.mod(np.asarray(angle_rad, dtype=float) + np.pi, 2.0 * np.pi) - np.pi
    if np.ndim(wrapped) == 0:
        return float(wrapped)
    return wrapped


def step(state: np.ndarray, control: np.ndarray, dt_s: float) -> np.ndarray:
    """One step of Eq. (1), vectorised over robots.

    Args:
        state: (3,) or (n, 3) [x_m, y_m, theta_rad].
        control: (2,) or (n, 2) [v_mps, omega_radps]; broadcast against `state`.
        dt_s: step length.

    Returns:
        The next state, with the broadcast shape of `state` and `control` ((3,) or (n, 3)).
    """
    state = np.asarray(state, dtype=float)
    control = np.asarray(control, dtype=float)
    if state.shape[-1] != 3 or state.ndim > 2:
        raise ValueError(f"state: expected shape (3,) or (n, 3), got {state.shape}")
    if control.shape[-1] != 2 or control.ndim > 2:
        raise ValueError(f"control: expected shape (2,) or (n, 2), got {control.shape}")
    theta = state[..., 2]
    v = control[..., 0]
    omega = control[..., 1]
    delta = np.stack(
        np.broadcast_arrays(v * np.cos(theta) * dt_s, v * np.sin(theta) * dt_s, omega * dt_s),
        axis=-1,
    )
    stepped: np.ndarray = state + delta
    return stepped


def rollout(state: np.ndarray, controls: np.ndarray, dt_s: float) -> np.ndarray:
    """Apply Eq. (1) N times from one state.

    The heading sequence does not depend on position, so the rollout is three cumulative
    sums instead of a Python loop.

    Args:
        state: (3,) initial [x_m, y_m, theta_rad].
        controls: (N, 2) [v_mps, omega_radps] per step.
        dt_s: step length.

    Returns:
        (N + 1, 3) states, the first being `state`.
    """
    return rollout_with_trig(state, controls, dt_s)[0]


def rollout_with_trig(state: np.ndarray, controls: np.ndarray, dt_s: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`rollout`, and the cosine and sine of the headings it stepped from.

    Returns:
        (N + 1, 3) states, and (N,) cos and sin of the states' headings 0..N-1 (the MPC's
        linearisation needs them: `jacobians`).
    """
    state = np.asarray(state, dtype=float)
    controls = np.asarray(controls, dtype=float)
    if state.shape != (3,):
        raise ValueError(f"state: expected shape (3,), got {state.shape}")
    if controls.ndim != 2 or controls.shape[1] != 2:
        raise ValueError(f"controls: expected shape (N, 2), got {controls.shape}")
    n = controls.shape[0]
    # Each component is the running sum [x_0, d_0, d_1, ...]: add.accumulate is sequential,
    # so this is the recursion of `step`, in the same order of floating-point operations.
    theta = np.empty(n + 1)
    theta[0] = state[2]
    np.multiply(controls[:, 1], dt_s, out=theta[1:])
    np.add.accumulate(theta, out=theta)
    v = controls[:, 0]
    cos = np.cos(theta[:-1])
    sin = np.sin(theta[:-1])
    xs = np.empty(n + 1)
    xs[0] = state[0]
    xs[1:] = v * cos * dt_s
    ys = np.empty(n + 1)
    ys[0] = state[1]
    ys[1:] = v * sin * dt_s
    out = np.empty((n + 1, 3))
    np.add.accumulate(xs, out=out[:, 0])
    np.add.accumulate(ys, out=out[:, 1])
    out[:, 2] = theta
    return out, cos, sin


def jacobians(
    theta_rad: np.ndarray, v_mps: np.ndarray, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of Eq. (1) about nominal headings and speeds.

    A_k = df/dx = [[1, 0, -v_k sin(theta_k) dt], [0, 1, v_k cos(theta_k) dt], [0, 0, 1]]
    B_k = df/du = [[cos(theta_k) dt, 0], [sin(theta_k) dt, 0], [0, dt]]

    Args:
        theta_rad: (N,) nominal headings.
        v_mps: (N,) nominal speeds.
        dt_s: step length.

    Returns:
        A: (N, 3, 3) and B: (N, 3, 2).
    """
    theta_rad = np.asarray(theta_rad, dtype=float).reshape(-1)
    v_mps = np.asarray(v_mps, dtype=float).reshape(-1)
    if theta_rad.shape != v_mps.shape:
        raise ValueError(f"theta_rad {theta_rad.shape} and v_mps {v_mps.shape} differ")
    n = theta_rad.shape[0]
    c = np.cos(theta_rad) * dt_s
    s = np.sin(theta_rad) * dt_s
    A = np.zeros((n, 3, 3))
    A[:, 0, 0] = A[:, 1, 1] = A[:, 2, 2] = 1.0
    A[:, 0, 2] = -v_mps * s
    A[:, 1, 2] = v_mps * c
    B = np.zeros((n, 3, 2))
    B[:, 0, 0] = c
    B[:, 1, 0] = s
    B[:, 2, 1] = dt_s
    return A, B


def clamp_command(
    v_mps: float,
    omega_radps: float,
    limits: RobotLimits,
    last_v_mps: float | None = None,
    last_omega_radps: float | None = None,
    dt_s: float | None = None,
) -> tuple[float, float]:
    """Clip a command to the robot's bounds and, if the last command is given, its rates.

    v ends in [v_min, v_max] and |omega| <= omega_max (Eq. 2) always. Given the previous
    command and the control period, v also moves by at most accel_max dt and omega by at
    most alpha_max dt. If the previous command was itself out of bounds the rate window
    may miss the bounds; the bounds win (the result is the nearest bound).

    Args:
        v_mps, omega_radps: the desired command.
        limits: actuation limits.
        last_v_mps, last_omega_radps: the previously applied command (or None).
        dt_s: control period [s] (needed with a previous command).

    Returns:
        (v_mps, omega_radps) within bounds. A non-finite request maps to the last command
        (or zero) before clipping.
    """
    v = float(v_mps)
    w = float(omega_radps)
    if last_v_mps is not None:
        if dt_s is None:
            raise ValueError("dt_s is needed to limit the rate of v")
        lv = float(last_v_mps)
        dv = limits.accel_max_mps2 * dt_s
        v = lv if not math.isfinite(v) else min(max(v, lv - dv), lv + dv)
    if last_omega_radps is not None:
        if dt_s is None:
            raise ValueError("dt_s is needed to limit the rate of omega")
        lw = float(last_omega_radps)
        dw = limits.alpha_max_radps2 * dt_s
        w = lw if not math.isfinite(w) else min(max(w, lw - dw), lw + dw)
    if not math.isfinite(v):
        v = 0.0
    if not math.isfinite(w):
        w = 0.0
    v = min(max(v, limits.v_min_mps), limits.v_max_mps)
    w = min(max(w, -limits.omega_max_radps), limits.omega_max_radps)
    return v, w


def lookahead_point(
    x_m: float, y_m: float, ref_x_m: np.ndarray, ref_y_m: np.ndarray, lookahead_m: float
) -> np.ndarray:
    """The point `lookahead_m` of arc length past the reference vertex nearest the robot.

    Args:
        x_m, y_m: robot position.
        ref_x_m, ref_y_m: (M,) reference polyline, M >= 1.
        lookahead_m: arc length ahead of the nearest vertex.

    Returns:
        (2,) the aim point, interpolated on the polyline; its end if the polyline is shorter.
    """
    pts = np.column_stack((np.asarray(ref_x_m, dtype=float), np.asarray(ref_y_m, dtype=float)))
    if pts.shape[0] == 0:
        raise ValueError("reference: empty")
    nearest = int(np.argmin(np.sum((pts - (x_m, y_m)) ** 2, axis=1)))
    ahead = pts[nearest:]
    aim: np.ndarray
    if ahead.shape[0] == 1:
        aim = ahead[0].copy()
        return aim
    seg = np.hypot(*np.diff(ahead, axis=0).T)
    arc = np.concatenate(([0.0], np.cumsum(seg)))
    if lookahead_m >= arc[-1]:
        aim = ahead[-1].copy()
        return aim
    i = int(np.searchsorted(arc, lookahead_m, side="right")) - 1
    frac = (lookahead_m - arc[i]) / seg[i] if seg[i] > 0.0 else 0.0
    aim = ahead[i] + frac * (ahead[i + 1] - ahead[i])
    return aim


def heading_law(
    heading_rad: float,
    direction_rad: float,
    speed_mps: float,
    limits: RobotLimits,
    heading_gain: float,
) -> tuple[float, float]:
    """Unicycle law that turns toward a direction before it goes.

    err = wrap(direction - heading); omega = clip(k err, +-omega_max);
    v = speed max(0, cos(err)), clipped to [v_min, v_max]: full speed when aligned, nothing
    when the direction is 90 deg or more off, so the robot turns on the spot first.

    Args:
        heading_rad: current heading theta.
        direction_rad: desired direction of motion.
        speed_mps: desired speed along it (>= 0).
        limits: actuation limits.
        heading_gain: k [1/s].

    Returns:
        (v_mps, omega_radps) within the bounds (no rate limit; see `clamp_command`).
    """
    err = float(wrap_angle(direction_rad - heading_rad))
    omega = heading_gain * err
    v = max(speed_mps, 0.0) * max(0.0, np.cos(err))
    return clamp_command(v, omega, limits)


def track_reference(
    x_m: float,
    y_m: float,
    heading_rad: float,
    ref_x_m: np.ndarray,
    ref_y_m: np.ndarray,
    ref_v_mps: float,
    lookahead_m: float,
    limits: RobotLimits,
    heading_gain: float,
    last_command: np.ndarray | None = None,
    dt_s: float | None = None,
) -> tuple[float, float]:
    """Tracking law of the planner `eifp` (no MPC, as in the paper's eIFP).

    The robot aims at the point `lookahead_m` of arc length ahead of the reference vertex
    nearest to it (pure-pursuit style), then applies `heading_law`:
    err = wrap(atan2(aim - p) - theta), omega = clip(k err), v = v_ref max(0, cos(err)).
    If the aim point coincides with the robot (reference exhausted) the heading error is 0.

    Args:
        x_m, y_m, heading_rad: robot pose.
        ref_x_m, ref_y_m: (M,) reference path (the spline samples), M >= 1.
        ref_v_mps: desired speed along it.
        lookahead_m: aim distance along the reference (e.g. lookahead_s * v_max).
        limits: actuation limits.
        heading_gain: k [1/s].
        last_command: (2,) previously applied [v, omega]; with `dt_s`, rates are limited.
        dt_s: control period.

    Returns:
        (v_mps, omega_radps) within the bounds (and the rate limits if `last_command` is given).
    """
    aim = lookahead_point(x_m, y_m, ref_x_m, ref_y_m, lookahead_m)
    dx, dy = aim[0] - x_m, aim[1] - y_m
    direction = np.arctan2(dy, dx) if np.hypot(dx, dy) > 1e-9 else heading_rad
    v, omega = heading_law(heading_rad, direction, ref_v_mps, limits, heading_gain)
    if last_command is not None:
        v, omega = clamp_command(v, omega, limits, last_command[0], last_command[1], dt_s)
    return v, omega
