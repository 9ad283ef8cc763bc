"""The time-parametrised reference through the waypoints (trajectory smoothing).

Two paths (`build_reference`): `LineArcPath`, the waypoint legs joined by arcs (our
change, eIFP-MPC's default, `agent.planning.mechanisms.Mechanisms.lines_arcs`), and the paper's
cubic spline (Eq. 19), described here.

The paper fits cubic splines S_x(t), S_y(t) through the waypoints with t in [0, 1]. We
parametrise by cumulative chord length u instead (u_0 = 0, u_i = u_{i-1} + |p_i - p_{i-1}|):
the spline is then close to unit speed in u, and after a small arc-length table maps
distance travelled to u, timing the reference at the robot's speed is direct.

The spline is natural (zero second derivative at both ends) and hand-written: points are
complex numbers x + iy, so one polynomial carries both coordinates, and the M - 2 interior
second derivatives come from one tridiagonal system solved by the Thomas algorithm in
plain Python (M <= max_depth + 2, a handful). It matches
`scipy.interpolate.CubicSpline(bc_type="natural")` to 1e-10
(tests/unit/agent/planning/test_spline.py) and, for a handful of points, builds several
times faster, which matters at one reference per cycle.

Timing: distance along the path follows the speed profile
v_ref(s) = min(v_max, sqrt(2 a (S - s))) (cruise, then constant deceleration a to a stop
at the goal, S the path length), optionally also min(..., sqrt(v0^2 + 2 a s)) to ramp up
from the current speed. The profile is integrated in closed form, so the samples land
exactly where the profile says. Past the goal the reference holds there with v = 0.
"""

from __future__ import annotations

import cmath
import itertools
import math
from dataclasses import dataclass

import numpy as np

from agent.planning.threats import require_finite

# A clamped start is used only when the first via-point lies within this angle of the
# heading: then the clamp smooths the small cycle-to-cycle moves of the via-point (which
# otherwise couple two robots' weaving through their velocity estimates); a sharper turn
# (an emergency, or a new threat) starts natural so the robot turns at once.
CLAMP_MAX_OFF_HEADING_RAD = math.radians(30.0)
CLAMP_MAX_COS = math.cos(CLAMP_MAX_OFF_HEADING_RAD)

START_RADIUS_M = 5.0
"""Radius of `LineArcPath`'s start arc along the robot's heading [m]: gentle enough that a
via-point that moves a little between cycles bends the path ahead of the robot (a lateral
offset of 0.1 m over the first 1-2 m) instead of swinging the reference under it."""

# Consecutive waypoints closer than this are merged [m].
MIN_WAYPOINT_SPACING_M = 1.0e-3

# Sub-intervals per spline segment in the arc-length table.
_ARC_SUBDIVISIONS = 24
_ARC_FRACTIONS = np.arange(_ARC_SUBDIVISIONS) / _ARC_SUBDIVISIONS
_POWERS = np.arange(4)
_ARC_POWERS = _ARC_FRACTIONS[:, None] ** _POWERS  # (subdivisions, 4)

_TWO_PI = 2.0 * math.pi

# |dp/du| below this has no direction: curvature is set to 0 there.
_MIN_TANGENT_NORM = 1.0e-9


@dataclass(frozen=True)
class Reference:
    """A reference trajectory sampled every dt_s, from the robot's position on.

    Args:
        t_s: (N+1,) sample times from now [s].
        x_m, y_m: (N+1,) positions [m].
        heading_rad: (N+1,) path tangent direction, unwrapped, the first within pi of the
            robot's heading [rad].
        v_mps: (N+1,) speed along the path [m/s]; 0 once the goal is reached.
        omega_radps: (N+1,) turn rate, curvature times speed [rad/s].
        s_m: (N+1,) distance along the path [m].
        length_m: the whole path's length S [m].
    """

    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    v_mps: np.ndarray
    omega_radps: np.ndarray
    s_m: np.ndarray
    length_m: float

    @property
    def n_steps(self) -> int:
        """N, the number of steps (N+1 samples)."""
        return int(self.t_s.shape[0]) - 1

    def states(self) -> np.ndarray:
        """(N+1, 3) x [m], y [m], heading [rad]: the form an MPC tracker consumes."""
        return np.stack((self.x_m, self.y_m, self.heading_rad), axis=1)


def dedup_waypoints(
    waypoints_m: np.ndarray, min_spacing_m: float = MIN_WAYPOINT_SPACING_M
) -> np.ndarray:
    """Drop waypoints closer than `min_spacing_m` to the previous kept one.

    The first point (the robot) is always kept; the last (the goal) replaces the previous
    kept point if the two are too close, unless that point is the first.

    Args:
        waypoints_m: (M, 2) waypoints [m].
        min_spacing_m: merge distance [m].

    Returns:
        (M', 2) waypoints, 1 <= M' <= M.
    """
    pts = waypoints_m.tolist()
    kept = [pts[0]]
    for x, y in pts[1:-1]:
        if math.hypot(x - kept[-1][0], y - kept[-1][1]) > min_spacing_m:
            kept.append([x, y])
    if len(pts) > 1:
        gx, gy = pts[-1]
        if math.hypot(gx - kept[-1][0], gy - kept[-1][1]) > min_spacing_m:
            kept.append([gx, gy])
        elif len(kept) > 1:
            kept[-1] = [gx, gy]
    return np.array(kept)


class NaturalCubicSpline:
    """Natural cubic spline p(u) through M points, u = cumulative chord length.

    With `start_tangent` the start is clamped instead (p'(0) given, the end stays natural):
    the reference then leaves the robot along its heading, so a via-point that moves
    between cycles bends the path ahead rather than turning the reference under the robot.

    Points are complex numbers x + iy, so one polynomial carries both coordinates. On
    segment i, with tau = u - u_i: p = a_i + b_i tau + c_i tau^2 + d_i tau^3. The interior
    second derivatives m solve the tridiagonal system
    h_{i-1} m_{i-1} + 2 (h_{i-1} + h_i) m_i + h_i m_{i+1} = 6 (slope_i - slope_{i-1}),
    m_0 = m_{M-1} = 0, by the Thomas algorithm in plain Python (M is a handful).

    Args:
        points: M >= 2 complex points with distinct consecutive entries [m].
        start_tangent: p'(0) as a complex number (a unit vector: |p'| ~ 1 in u), or None
            for a natural start.
    """

    def __init__(self, points: list[complex], start_tangent: complex | None = None) -> None:
        n = len(points) - 1  # segments
        h = [abs(q - p) for p, q in zip(points, points[1:])]
        slope = [(q - p) / hi for p, q, hi in zip(points, points[1:], h)]
        m = [0j] * (n + 1)
        # Rows of the tridiagonal system: sub, diagonal, super, right-hand side. A clamped
        # start (p'(0) = start_tangent) adds row 0: 2 h_0 m_0 + h_0 m_1 = 6 (slope_0 - p'(0)).
        rows = []
        if start_tangent is not None:
            rows.append((0.0, 2.0 * h[0], h[0], 6.0 * (slope[0] - start_tangent)))
        rows += [(h[i - 1], 2.0 * (h[i - 1] + h[i]), h[i], 6.0 * (slope[i] - slope[i - 1]))
                 for i in range(1, n)]
        first = 0 if start_tangent is not None else 1
        if rows:
            diag: list[float] = []
            rhs: list[complex] = []
            for sub, d_i, _sup, r_i in rows:  # forward sweep
                if diag:
                    f = sub / diag[-1]
                    d_i -= f * rows[len(diag) - 1][2]
                    r_i -= f * rhs[-1]
                diag.append(d_i)
                rhs.append(r_i)
            for j in range(len(rows) - 1, -1, -1):  # back substitution; m_n = 0
                i = first + j
                m[i] = (rhs[j] - rows[j][2] * m[i + 1]) / diag[j]
        rows9 = []
        for i in range(n):
            b = slope[i] - h[i] * (2.0 * m[i] + m[i + 1]) / 6.0
            c = 0.5 * m[i]
            d = (m[i + 1] - m[i]) / (6.0 * h[i])
            # p's coefficients a, b, c, d; then dp/du's (b, 2c, 3d) and d2p/du2's (2c, 6d).
            rows9.append((points[i], b, c, d, b, 2.0 * c, 3.0 * d, 2.0 * c, 6.0 * d))
        self._all = np.array(rows9)  # (n, 9)
        self.coef = self._all[:, :4]  # (n, 4): a, b, c, d
        self.h = np.array(h)
        self.knots = np.array([0.0, *itertools.accumulate(h)])
        self.end = points[-1]

    def evaluate(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, first and second derivative at parameters u, as complex numbers.

        Args:
            u: (n,) parameters, clipped to [0, chord length] [m].

        Returns:
            p, dp/du, d2p/du2, each (n,) complex.
        """
        u = np.minimum(np.maximum(u, 0.0), self.knots[-1])
        seg = np.searchsorted(self.knots[1:-1], u, side="right")
        powers = (u - self.knots[seg])[:, None] ** _POWERS  # (n, 4): 1, tau, tau^2, tau^3
        c = self._all[seg]
        p = np.einsum("ij,ij->i", powers, c[:, :4])
        dp = np.einsum("ij,ij->i", powers[:, :3], c[:, 4:7])
        ddp = np.einsum("ij,ij->i", powers[:, :2], c[:, 7:])
        return p, dp, ddp

    def arc_table(self) -> tuple[np.ndarray, np.ndarray]:
        """Arc length at a grid of parameters (`_ARC_SUBDIVISIONS` chords per segment).

        Returns:
            u: (n,) increasing parameters from 0 to the chord length [m].
            s: (n,) arc length at each [m].
        """
        # On segment i at tau = h_i f: p = sum_k (coef_ik h_i^k) f^k, one product per grid.
        scaled = self.coef * self.h[:, None] ** _POWERS
        n = scaled.shape[0] * _ARC_SUBDIVISIONS
        p = np.empty(n + 1, dtype=complex)
        p[:n] = (scaled @ _ARC_POWERS.T).reshape(-1)
        p[n] = self.end
        u = np.empty(n + 1)
        u[:n] = (self.knots[:-1, None] + self.h[:, None] * _ARC_FRACTIONS).reshape(-1)
        u[n] = self.knots[-1]
        s = np.empty(n + 1)
        s[0] = 0.0
        np.cumsum(np.abs(p[1:] - p[:-1]), out=s[1:])
        return u, s


def distance_profile(
    t_s: np.ndarray,
    length_m: float,
    v_max_mps: float,
    accel_mps2: float,
    v_start_mps: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Distance and speed at times t under v(s) = min(v_max, sqrt(2 a (S - s))[, ramp]).

    Without `v_start_mps` the robot may start at any speed the stop profile allows; with
    it the profile is also capped by sqrt(v0^2 + 2 a s) (accelerate from v0 at a). The
    result is a trapezoid (or triangle) in time, integrated exactly.

    Args:
        t_s: (n,) times from now, >= 0 [s].
        length_m: S, the path length [m].
        v_max_mps: cruise speed [m/s] (> 0).
        accel_mps2: a, acceleration and deceleration [m/s^2] (> 0).
        v_start_mps: current speed v0 [m/s], or None for no ramp.

    Returns:
        s: (n,) distance along the path, at most S [m].
        v: (n,) speed [m/s].
    """
    a = accel_mps2
    stop_speed = math.sqrt(2.0 * a * length_m)
    v0 = v_max_mps if v_start_mps is None else min(max(v_start_mps, 0.0), v_max_mps)
    v_se = min(v0, stop_speed)
    v_peak = min(v_max_mps, math.sqrt(0.5 * (v_se * v_se + stop_speed * stop_speed)))
    t1 = (v_peak - v_se) / a  # end of the ramp
    # Cruise distance: S minus the ramp (v_peak^2 - v_se^2) / 2a and the brake v_peak^2 / 2a.
    s2 = max(length_m - (2.0 * v_peak * v_peak - v_se * v_se) / (2.0 * a), 0.0)
    t2 = t1 + (s2 / v_peak if v_peak > 0.0 else 0.0)  # end of the cruise
    t3 = t2 + v_peak / a  # stop
    if t1 <= 0.0 and t2 >= t_s[-1]:  # cruising over the whole window
        return v_peak * t_s, np.full_like(t_s, v_peak)
    # v(t) is piecewise linear: ramp, cruise, brake; s(t) sums the three phase integrals.
    ramp = np.minimum(t_s, t1)
    brake = np.minimum(np.maximum(t_s - t2, 0.0), t3 - t2)
    s = (
        ramp * (v_se + 0.5 * a * ramp)
        + v_peak * (np.minimum(np.maximum(t_s, t1), t2) - t1)
        + brake * (v_peak - 0.5 * a * brake)
    )
    v = np.where(t_s < t1, v_se + a * t_s, v_peak - a * brake)
    v[t_s >= t3] = 0.0
    return np.minimum(s, length_m), v


class LineArcPath:
    """The waypoint polyline with its corners rounded by circular arcs (lines and arcs).

    Our alternative to the paper's cubic spline (`agent.planning.mechanisms.Mechanisms.lines_arcs`,
    eIFP-MPC's default). A via-point is built for a robot that drives the straight leg to it (the
    tangent to the other's inflated disc, reached at the cone time; `agent.planning.viapoints`);
    a cubic spline through robot, via-point and goal bows off that leg and turns along
    the whole of it. Here the reference runs along the legs and turns only where they
    meet:

    - Corner at via-point i (turn delta between its two legs): an arc of radius
      `corner_radius_m`, tangent to both legs, so it starts R tan(|delta| / 2) before the
      via-point. That cut is capped at half of a leg between two via-points and at the
      whole of the first and the last leg (if the caps of one leg's two corners overlap,
      both are scaled down to share it): a corner between short legs gets a tighter arc,
      and the arcs of a short polygon round a disc join into a curve.
    - Start (`start_radius_m` > 0): when the first leg lies within
      `CLAMP_MAX_OFF_HEADING_RAD` of the robot's heading, the path leaves along the
      heading on an arc of that radius and then runs straight to where the first corner's
      arc begins (a Dubins-like turn-then-line; it meets that arc at a small kink, the
      difference between its line and the leg). The clamped spline start's job: a
      via-point that moves a little between cycles bends the path ahead instead of
      swinging the reference under the robot. A sharper turn starts straight along the
      leg, and the robot turns to it at once. Also none when the first leg's straight part
      is empty, or the arc would have to turn by more than pi.

    Each piece is a line or an arc, p(sigma) = p0 + u0 sigma (kappa = 0) or
    p0 + u0 (exp(i kappa sigma) - 1) / (i kappa), heading arg(u0) + kappa sigma: position
    and heading in closed form at any distance.

    Args:
        points: M >= 3 complex points, distinct consecutive entries [m].
        heading_rad: the robot's heading, for the start arc [rad].
        corner_radius_m: R of the corner arcs (0: sharp corners, the polyline) [m].
        start_radius_m: radius of the start arc (0: none) [m].
    """

    def __init__(self, points: list[complex], heading_rad: float, corner_radius_m: float,
                 start_radius_m: float) -> None:
        legs = [q - p for p, q in zip(points, points[1:])]
        lengths = [abs(d) for d in legs]
        units = [d / n for d, n in zip(legs, lengths)]
        n = len(legs)
        turn = [0.0] * (n + 1)  # turn at each point (0 at both ends)
        cut = [0.0] * (n + 1)  # how far before and after each point its arc starts and ends
        for i in range(1, n):
            turn[i] = cmath.phase(units[i] / units[i - 1])
            if turn[i] != 0.0:
                cut[i] = min(corner_radius_m * math.tan(0.5 * abs(turn[i])),
                             lengths[i - 1] * (1.0 if i == 1 else 0.5),
                             lengths[i] * (1.0 if i == n - 1 else 0.5))
        for i in range(n):  # two corners of one leg share it
            both = cut[i] + cut[i + 1]
            if both > lengths[i]:
                cut[i] *= lengths[i] / both
                cut[i + 1] *= lengths[i] / both
        # Pieces (start point, unit direction at start, curvature, length).
        pieces: list[tuple[complex, complex, float, float]] = []
        for i in range(n):
            straight = lengths[i] - cut[i] - cut[i + 1]
            if straight > 0.0:
                pieces.append((points[i] + units[i] * cut[i], units[i], 0.0, straight))
            if i + 1 < n and cut[i + 1] > 0.0:
                radius = cut[i + 1] / math.tan(0.5 * abs(turn[i + 1]))
                pieces.append((points[i + 1] - units[i] * cut[i + 1], units[i],
                               math.copysign(1.0 / radius, turn[i + 1]),
                               radius * abs(turn[i + 1])))
        if start_radius_m > 0.0 and lengths[0] - cut[1] > 0.0:
            pieces[0:1] = self._start(points[0], heading_rad, pieces[0], start_radius_m)
        self.start = np.array([0.0, *itertools.accumulate(pc[3] for pc in pieces)])
        self.length_m = float(self.start[-1])
        self._p0 = np.array([pc[0] for pc in pieces])
        self._u0 = np.array([pc[1] for pc in pieces])
        self._kappa = np.array([pc[2] for pc in pieces])
        self._len = np.array([pc[3] for pc in pieces])

    @staticmethod
    def _start(p: complex, heading_rad: float, line: tuple[complex, complex, float, float],
               radius_m: float) -> list[tuple[complex, complex, float, float]]:
        """The first straight piece replaced by an arc along the heading and a line."""
        ahead = cmath.exp(1j * heading_rad)
        off = cmath.phase(line[1] / ahead)
        if not 0.0 < abs(off) < CLAMP_MAX_OFF_HEADING_RAD:
            return [line]
        side = 1.0 if off > 0.0 else -1.0  # turn left (+) or right (-)
        centre = p + side * radius_m * 1j * ahead
        end = line[0] + line[1] * line[3]  # where the first corner's arc begins
        to_end = end - centre
        dist = abs(to_end)
        if not dist > radius_m:
            return [line]
        # The tangent point T on the circle from which the line runs to `end`.
        leave = cmath.phase(to_end) - side * math.acos(radius_m / dist)
        swept = (side * (leave - cmath.phase(p - centre))) % (2.0 * math.pi)
        if swept >= math.pi:
            return [line]
        tangent_point = centre + radius_m * cmath.exp(1j * leave)
        rest = abs(end - tangent_point)
        return [(p, ahead, side / radius_m, radius_m * swept),
                (tangent_point, (end - tangent_point) / rest, 0.0, rest)]

    def evaluate(self, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position (complex) and heading (not unwrapped) at distances s along the path.

        Args:
            s_m: (n,) distances, clipped to [0, length] [m].
        """
        s = np.minimum(np.maximum(s_m, 0.0), self.length_m)
        k = np.minimum(np.searchsorted(self.start[1:-1], s, side="right"), self._len.size - 1)
        sigma = np.minimum(s - self.start[k], self._len[k])
        kappa = self._kappa[k]
        bent = kappa != 0.0
        along = sigma.astype(complex)
        along[bent] = (np.exp(1j * kappa[bent] * sigma[bent]) - 1.0) / (1j * kappa[bent])
        u0 = self._u0[k]
        return self._p0[k] + u0 * along, np.angle(u0) + kappa * sigma


def build_reference(
    waypoints_m: np.ndarray,
    heading_rad: float,
    v_max_mps: float,
    accel_mps2: float,
    dt_s: float,
    horizon_steps: int,
    v_start_mps: float | None = None,
    min_spacing_m: float = MIN_WAYPOINT_SPACING_M,
    clamp_heading: bool = False,
    lines_arcs: bool = False,
    corner_radius_m: float = 1.0,
    start_radius_m: float = START_RADIUS_M,
) -> Reference:
    """Spline the waypoints and sample it every dt_s at the speed profile.

    Args:
        waypoints_m: (M, 2) robot position first, goal last [m]; M >= 1. Near-duplicate
            consecutive points are merged (`dedup_waypoints`); two points give a straight
            line; one (robot at goal) gives a reference that holds still.
        heading_rad: the robot's current heading; the reference heading is unwrapped and
            shifted by a multiple of 2 pi to start within pi of it [rad].
        v_max_mps: cruise speed [m/s] (> 0).
        accel_mps2: deceleration to the goal (and ramp from v_start_mps) [m/s^2] (> 0).
        dt_s: sample period [s] (> 0).
        horizon_steps: N; the reference has N + 1 samples (>= 1).
        v_start_mps: current speed for the ramp-up, or None (profile as the paper's spec).
        min_spacing_m: merge distance for near-duplicate waypoints [m].
        clamp_heading: start the spline along `heading_rad` (clamped start) when there are
            via-points (M >= 3) and the first one is within `CLAMP_MAX_OFF_HEADING_RAD` of
            the heading; otherwise (and for a two-point plan, a straight line) natural.
        lines_arcs: with via-points (M >= 3), the reference follows `LineArcPath` (legs
            joined by arcs) instead of the cubic spline; `clamp_heading` then does not
            apply. Its `omega_radps` is 0: the arcs place positions and headings, and the
            tracker turns as much as their errors ask for (a turn-rate feed-forward along
            the arcs turns the robot early on every re-planned corner).
        corner_radius_m: `LineArcPath` corner radius [m] (>= 0).
        start_radius_m: `LineArcPath` start arc radius, 0 for none [m] (>= 0).

    Returns:
        The sampled reference.

    Raises:
        ValueError: on non-finite input, bad shapes or non-positive limits.
    """
    wp = np.asarray(waypoints_m, dtype=float)
    if wp.ndim != 2 or wp.shape[1] != 2 or wp.shape[0] < 1:
        raise ValueError(f"waypoints_m: expected shape (M, 2), got {wp.shape}")
    require_finite("build_reference", wp, heading_rad, v_max_mps, accel_mps2, dt_s)
    if v_start_mps is not None:
        require_finite("build_reference", v_start_mps)
    if not (v_max_mps > 0.0 and accel_mps2 > 0.0 and dt_s > 0.0 and horizon_steps >= 1):
        raise ValueError("build_reference: v_max, accel and dt must be positive, N >= 1")
    if lines_arcs:
        require_finite("build_reference", corner_radius_m, start_radius_m)
        if corner_radius_m < 0.0 or start_radius_m < 0.0:
            raise ValueError("build_reference: corner and start radii must be >= 0")
    wp = dedup_waypoints(wp, min_spacing_m)
    t = np.arange(horizon_steps + 1) * dt_s
    if wp.shape[0] == 1:
        return _held_reference(t, wp, heading_rad)
    if lines_arcs and wp.shape[0] >= 3:
        return _line_arc_reference(
            LineArcPath([complex(x, y) for x, y in wp.tolist()], heading_rad, corner_radius_m,
                        start_radius_m),
            t, heading_rad, v_max_mps, accel_mps2, v_start_mps)
    tangent = _start_tangent(wp, heading_rad) if clamp_heading and wp.shape[0] >= 3 else None
    spline = NaturalCubicSpline([complex(x, y) for x, y in wp.tolist()], tangent)
    return _spline_reference(spline, wp.shape[0] == 2, t, heading_rad, v_max_mps, accel_mps2,
                             v_start_mps)


def _held_reference(t: np.ndarray, wp: np.ndarray, heading_rad: float) -> Reference:
    """`build_reference` of a robot at its goal (`wp`: (1, 2)): it holds still there."""
    zeros = np.zeros_like(t)
    return Reference(
        t_s=t,
        x_m=np.full_like(t, wp[0, 0]),
        y_m=np.full_like(t, wp[0, 1]),
        heading_rad=np.full_like(t, heading_rad),
        v_mps=zeros,
        omega_radps=zeros.copy(),
        s_m=zeros.copy(),
        length_m=0.0,
    )


def _start_tangent(wp: np.ndarray, heading_rad: float) -> complex | None:
    """The clamped spline's start tangent: the heading, if the first via-point of `wp`
    ((M, 2), M >= 3) lies within `CLAMP_MAX_OFF_HEADING_RAD` of it, else None (natural)."""
    tangent = complex(math.cos(heading_rad), math.sin(heading_rad))
    chord = complex(wp[1, 0] - wp[0, 0], wp[1, 1] - wp[0, 1])
    if (chord * tangent.conjugate()).real <= CLAMP_MAX_COS * abs(chord):
        return None  # a sharp turn: the robot must turn now, not swing out first
    return tangent


def _spline_reference(spline: NaturalCubicSpline, straight: bool, t: np.ndarray,
                      heading_rad: float, v_max_mps: float, accel_mps2: float,
                      v_start_mps: float | None) -> Reference:
    """`build_reference` on a cubic spline (`straight`: through two points, a line): the
    speed profile, the tangent's heading and the turn rate of the curvature."""
    if straight:
        u_table = s_table = spline.knots  # a straight line: chord length is arc length
    else:
        u_table, s_table = spline.arc_table()
    length = float(s_table[-1])
    s, v = distance_profile(t, length, v_max_mps, accel_mps2, v_start_mps)
    p, dp, ddp = spline.evaluate(np.interp(s, s_table, u_table))
    # Heading: the tangent's angle at the first sample, plus the turn between samples
    # (each far below pi), so the sequence is unwrapped; then within pi of the robot.
    heading = np.empty_like(t)
    heading[0] = cmath.phase(complex(dp[0]))
    np.cumsum(np.angle(dp[1:] * dp[:-1].conjugate()), out=heading[1:])
    heading[1:] += heading[0]
    # Curvature = cross(p', p'') / |p'|^3.
    speed_sq = (dp * dp.conjugate()).real
    curvature = np.divide(
        (dp.conjugate() * ddp).imag,
        speed_sq * np.sqrt(speed_sq),
        out=np.zeros_like(speed_sq),
        where=speed_sq > _MIN_TANGENT_NORM * _MIN_TANGENT_NORM,
    )
    return _sampled(t, s, v, p, heading, heading_rad, curvature * v, length)


def _line_arc_reference(path: LineArcPath, t: np.ndarray, heading_rad: float, v_max_mps: float,
                        accel_mps2: float, v_start_mps: float | None) -> Reference:
    """`build_reference` on a `LineArcPath`: the same speed profile, no turn feed-forward."""
    s, v = distance_profile(t, path.length_m, v_max_mps, accel_mps2, v_start_mps)
    p, heading = path.evaluate(s)
    return _sampled(t, s, v, p, _unwrap(heading), heading_rad, np.zeros_like(t),
                    path.length_m)


def _unwrap(heading_rad: np.ndarray) -> np.ndarray:
    """`numpy.unwrap` of a 1-d float array (period 2 pi), by the same operations in the
    same order (so the same floats), without its generic set-up.

    Each step is wrapped to [-pi, pi) (+pi where the step is exactly +pi), and steps under
    pi keep their own value.
    """
    step = heading_rad[1:] - heading_rad[:-1]
    wrapped = np.mod(step + math.pi, _TWO_PI) - math.pi
    np.copyto(wrapped, math.pi, where=(wrapped == -math.pi) & (step > 0))
    correction = wrapped - step
    np.copyto(correction, 0.0, where=np.abs(step) < math.pi)
    out = heading_rad.copy()
    out[1:] = heading_rad[1:] + correction.cumsum()
    return out


def _sampled(t: np.ndarray, s: np.ndarray, v: np.ndarray, p: np.ndarray, heading: np.ndarray,
             robot_heading_rad: float, omega: np.ndarray, length_m: float) -> Reference:
    """The `Reference`, its unwrapped heading shifted by 2 pi k to start within pi of the
    robot's (in place)."""
    heading += _TWO_PI * round((robot_heading_rad - float(heading[0])) / _TWO_PI)
    return Reference(t_s=t, x_m=p.real.copy(), y_m=p.imag.copy(), heading_rad=heading,
                     v_mps=v, omega_radps=omega, s_m=s, length_m=length_m)


def reference_point_ahead(reference: Reference, lookahead_s: float) -> np.ndarray:
    """The reference state `lookahead_s` ahead, linearly interpolated (pure pursuit).

    Args:
        reference: a sampled reference.
        lookahead_s: time ahead, clipped to [0, t_N] [s].

    Returns:
        (3,) x [m], y [m], heading [rad].
    """
    t = min(max(float(lookahead_s), 0.0), float(reference.t_s[-1]))
    return np.array(
        [
            np.interp(t, reference.t_s, reference.x_m),
            np.interp(t, reference.t_s, reference.y_m),
            np.interp(t, reference.t_s, reference.heading_rad),
        ]
    )


def polyline_point_ahead(waypoints_m: np.ndarray, distance_m: float) -> np.ndarray:
    """The point `distance_m` along the polyline through the waypoints (pure pursuit).

    Args:
        waypoints_m: (M, 2) waypoints, M >= 1 [m].
        distance_m: distance from the first waypoint, clipped to [0, length] [m].

    Returns:
        (2,) the point [m].
    """
    wp = np.asarray(waypoints_m, dtype=float)
    if wp.shape[0] == 1:
        first: np.ndarray = wp[0].copy()
        return first
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(wp, axis=0).T))))
    d = min(max(float(distance_m), 0.0), float(s[-1]))
    return np.array([np.interp(d, s, wp[:, 0]), np.interp(d, s, wp[:, 1])])
