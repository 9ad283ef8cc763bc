"""Collision prediction with TCPA and DCPA under constant velocities (Eqs. 3-7).

`tcpa_dcpa` is the vectorised kernel; `rank_threats` applies the threat test of Eq. (6)
and the ranking of Eq. (7) and returns indices; `threat_records` turns those into typed
`Threat` records. `legs_threats` / `leg_threats` are the check the IFP iteration runs on
the straight legs of a plan; `nearby_others` applies the sensing radius and neighbour cap.

Inside the kernels plane vectors are complex numbers x + iy (`as_complex`): one numpy
call per vector operation on a flat (K,) array instead of several on (K, 2), and
a * conj(b) gives the dot product (real part) and the cross product (imaginary part) of
a and b at once. The public API takes and returns row-major (K, 2) float arrays.

All functions are pure: numpy in, numpy out, no clock and no state.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from agent.core.types import Others, Threat

# Below this squared relative speed [m^2/s^2] the relative velocity counts as zero:
# TCPA = 0 and DCPA = |r| (the paper's rule after Eq. 5).
ZERO_REL_SPEED_SQ = 1.0e-12

# Floor on |v_rel|^2 in the leg check's division [m^2/s^2] (never reached when closing).
_TINY = 1.0e-300

_EMPTY_INDEX = np.zeros(0, dtype=np.intp)
_EMPTY_FLOAT = np.zeros(0)


def require_finite(name: str, *values: npt.ArrayLike) -> None:
    """Raise `ValueError` naming `name` if any value holds a NaN or an infinity.

    Args:
        name: what the caller calls the input (goes into the message).
        values: scalars or arrays of any shape.
    """
    for value in values:
        if isinstance(value, (float, int)):  # a tuple: checks faster than `float | int`
            if not math.isfinite(value):
                raise ValueError(f"{name}: non-finite value {value!r}")
        elif not np.isfinite(value).all():
            raise ValueError(f"{name}: non-finite value")


def as_complex(xy: np.ndarray) -> np.ndarray:
    """(K, 2) float array -> (K,) complex array x + iy (a view when already contiguous)."""
    if xy.dtype != np.float64 or not xy.flags.c_contiguous:
        xy = np.ascontiguousarray(xy, dtype=np.float64)
    return xy.view(np.complex128).reshape(-1)


def as_xy(z: np.ndarray) -> np.ndarray:
    """(K,) complex array -> (K, 2) float array [x, y] (a view)."""
    return np.ascontiguousarray(z, dtype=np.complex128).view(float).reshape(-1, 2)


def tcpa_dcpa(
    p_r: np.ndarray, v_r: np.ndarray, p_o: np.ndarray, v_o: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """TCPA and DCPA of one robot against K others (Eqs. 3-5).

    With r = p_o - p_r and v_rel = v_o - v_r (Eq. 3), TCPA = -r.v_rel / |v_rel|^2
    (Eq. 4) and DCPA = |r + TCPA v_rel| (Eq. 5). When |v_rel|^2 is below
    `ZERO_REL_SPEED_SQ` the pair keeps its distance: TCPA = 0, DCPA = |r|, so it is never
    a threat under the 0 < TCPA rule.

    Args:
        p_r: (2,) robot position [m].
        v_r: (2,) robot velocity [m/s].
        p_o: (K, 2) other positions [m].
        v_o: (K, 2) other velocities [m/s].

    Returns:
        tcpa: (K,) time to the closest point of approach [s]; negative when receding.
        dcpa: (K,) distance at that time [m].

    Raises:
        ValueError: on a non-finite input.
    """
    p_r = np.asarray(p_r, dtype=float).reshape(2)
    v_r = np.asarray(v_r, dtype=float).reshape(2)
    p_o = np.asarray(p_o, dtype=float).reshape(-1, 2)
    v_o = np.asarray(v_o, dtype=float).reshape(-1, 2)
    require_finite("tcpa_dcpa", p_r, v_r, p_o, v_o)
    return _tcpa_dcpa(
        as_complex(p_o) - complex(p_r[0], p_r[1]), as_complex(v_o) - complex(v_r[0], v_r[1])
    )


def _tcpa_dcpa(r: np.ndarray, v_rel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eqs. (4)-(5) on complex relative positions and velocities, both (K,)."""
    vv = v_rel.real * v_rel.real + v_rel.imag * v_rel.imag
    rv = (r * v_rel.conjugate()).real
    moving = vv > ZERO_REL_SPEED_SQ
    if moving.all():  # the usual case; the same quotients as the masked divide, sooner
        tcpa = -rv / vv
    else:
        tcpa = np.divide(-rv, vv, out=np.zeros_like(vv), where=moving)
    return tcpa, np.abs(r + tcpa * v_rel)


def ranked(index: np.ndarray, tcpa: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """`index` sorted by TCPA ascending, ties by id (Eq. 7, made order-independent).

    Args:
        index: (n,) indices into the K others.
        tcpa: (K,) TCPA of every other [s].
        ids: (K,) ids of the others.
    """
    if index.shape[0] < 2:
        return index
    return index[np.lexsort((ids[index], tcpa[index]))]


def rank_threats(
    position_m: np.ndarray,
    velocity_mps: np.ndarray,
    others: Others,
    d_thresh_m: float | np.ndarray,
    t_max_s: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices of the others that are threats (Eq. 6), ranked by TCPA (Eq. 7).

    A threat has DCPA <= D_thresh and 0 < TCPA < T_max; ties in TCPA are broken by id so
    the ranking does not depend on the order of `others`.

    Args:
        position_m: (2,) robot position p_r [m].
        velocity_mps: (2,) robot velocity v_r [m/s].
        others: the K sensed others (validated on construction).
        d_thresh_m: D_thresh of Eq. (6), one for all or (K,) one per other [m].
        t_max_s: T_max of Eq. (6) [s].

    Returns:
        index: (n,) indices into `others`, most imminent first.
        tcpa: (K,) TCPA of every other [s].
        dcpa: (K,) DCPA of every other [m].

    Raises:
        ValueError: on a non-finite input.
    """
    px, py = float(position_m[0]), float(position_m[1])
    vx, vy = float(velocity_mps[0]), float(velocity_mps[1])
    require_finite("rank_threats", px, py, vx, vy, d_thresh_m, float(t_max_s))
    if len(others) == 0:
        return _EMPTY_INDEX, _EMPTY_FLOAT, _EMPTY_FLOAT
    tcpa, dcpa = _tcpa_dcpa(
        as_complex(others.position_m) - complex(px, py),
        as_complex(others.velocity_mps) - complex(vx, vy),
    )
    hit = (dcpa <= d_thresh_m) & (tcpa > 0.0) & (tcpa < t_max_s)
    return ranked(hit.nonzero()[0], tcpa, others.ids), tcpa, dcpa


def threat_records(
    index: np.ndarray, tcpa: np.ndarray, dcpa: np.ndarray, others: Others
) -> tuple[Threat, ...]:
    """Typed `Threat` records for ranked indices (as returned by `rank_threats`)."""
    return tuple(
        map(Threat, others.ids[index].tolist(), tcpa[index].tolist(), dcpa[index].tolist())
    )


def legs_threats(
    starts: list[complex],
    ends: list[complex],
    start_times_s: list[float],
    speed_mps: float,
    position: np.ndarray,
    velocity: np.ndarray,
    clearance_m: np.ndarray,
    horizon_s: float,
    exclude: list[int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Which others come too close to a robot travelling each of L straight legs.

    On leg l the robot leaves A_l at t0_l (from now) and drives straight to B_l at
    `speed_mps`. The others are advanced to that time (p_o + v_o t0_l) and Eqs. (3)-(5)
    are applied with the TCPA limited to the part of the leg inside the horizon:
    t_cap = min(|B - A| / speed, horizon_s - t0_l). Other j is a threat on leg l when
    they are closing (r.v_rel < 0, so TCPA > 0) and their distance at min(TCPA, t_cap) is
    strictly below `clearance_m[j]`. A leg of zero length, or one starting after the
    horizon, has no threats.

    All legs are checked in one vectorised pass, on complex vectors (`as_complex`). The
    inputs are not validated: this runs in the planner's inner loop on checked data.

    Args:
        starts: L complex leg starts A [m].
        ends: L complex leg ends B [m].
        start_times_s: L times at which the robot is at A, from now [s].
        speed_mps: speed along the legs (> 0).
        position: (K,) complex positions of the others at time 0 [m].
        velocity: (K,) complex velocities of the others [m/s].
        clearance_m: (K,) distance below which other j counts as a threat [m].
        horizon_s: T_max; nothing after this time counts [s].
        exclude: optional L indices of an other not to check on each leg (-1: none),
            e.g. the disc a leg is tangent to by construction.

    Returns:
        hit: (L, K) bool, other j is a threat on leg l.
        tcpa: (L, K) TCPA from the leg start where closing, else 0 [s].
    """
    v_r, t_cap = [], []
    for a, b, t0 in zip(starts, ends, start_times_s):
        length = abs(b - a)
        # unit direction first, per component: speed / length overflows for a denormal
        # leg, and so does numpy's complex division (0 * inf = NaN)
        d = b - a
        v_r.append(complex(d.real / length, d.imag / length) * speed_mps
                   if length > 0.0 else 0j)
        t_cap.append(min(length / speed_mps, horizon_s - t0))
    r = position - np.array(starts)[:, None]  # (L, K), then advanced to t0
    r += np.array(start_times_s)[:, None] * velocity
    w = velocity - np.array(v_r)[:, None]
    w_conj = w.conjugate()
    rw = (r * w_conj).real
    ww = (w * w_conj).real
    # TCPA where closing (rw < 0 implies |v_rel| > 0), else 0; the floor only avoids 0/0.
    tcpa = np.maximum(-rw, 0.0) / np.maximum(ww, _TINY)
    t = np.minimum(tcpa, np.array(t_cap)[:, None])
    hit = (rw < 0.0) & (np.abs(r + t * w) < clearance_m)
    for leg, cap in enumerate(t_cap):
        if cap <= 0.0:
            hit[leg] = False
        elif exclude is not None and exclude[leg] >= 0:
            hit[leg, exclude[leg]] = False
    return hit, tcpa


def leg_threats(
    start_m: np.ndarray,
    end_m: np.ndarray,
    speed_mps: float,
    start_time_s: float,
    others: Others,
    clearance_m: np.ndarray,
    horizon_s: float,
    exclude: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Others that come too close to a robot travelling one straight leg, ranked.

    The single-leg, (2,)-array form of `legs_threats` (see there for the test).

    Args:
        start_m: (2,) leg start A [m].
        end_m: (2,) leg end B [m].
        speed_mps: speed along the leg [m/s]; <= 0 means the leg is not travelled.
        start_time_s: time at which the robot is at A, from now [s].
        others: the K sensed others (positions at time 0).
        clearance_m: (K,) distance below which other j counts as a threat [m].
        horizon_s: T_max [s].
        exclude: optional (K,) bool mask of others not to check.

    Returns:
        index: (n,) indices into `others`, ranked by TCPA ascending, ties by id.
        tcpa: (n,) their TCPA from the leg start [s].

    Raises:
        ValueError: on a non-finite input.
    """
    clearance_m = np.asarray(clearance_m, dtype=float)
    require_finite(
        "leg_threats", start_m, end_m, float(speed_mps), float(start_time_s), clearance_m
    )
    require_finite("leg_threats", float(horizon_s))
    if len(others) == 0 or speed_mps <= 0.0:
        return _EMPTY_INDEX, _EMPTY_FLOAT
    hit, tcpa = legs_threats(
        [complex(start_m[0], start_m[1])],
        [complex(end_m[0], end_m[1])],
        [float(start_time_s)],
        float(speed_mps),
        as_complex(others.position_m),
        as_complex(others.velocity_mps),
        clearance_m,
        float(horizon_s),
    )
    mask = hit[0] if exclude is None else hit[0] & ~np.asarray(exclude, dtype=bool)
    index = ranked(mask.nonzero()[0], tcpa[0], others.ids)
    return index, tcpa[0, index]


def nearby_others(
    position_m: np.ndarray, others: Others, sensing_radius_m: float, max_neighbors: int
) -> Others:
    """The others within the sensing radius, at most `max_neighbors`, nearest first.

    Distances are centre to centre; ties are broken by id. When nothing is filtered out
    the same `Others` object is returned (no copy), in its original order.

    Args:
        position_m: (2,) robot position [m].
        others: the K sensed others.
        sensing_radius_m: others farther than this are dropped [m].
        max_neighbors: keep at most this many (>= 0).
    """
    k = len(others)
    if k == 0:
        return others
    dist = np.abs(as_complex(others.position_m) - complex(position_m[0], position_m[1]))
    seen = dist <= sensing_radius_m
    n_seen = int(np.count_nonzero(seen))
    if n_seen == k and k <= max_neighbors:
        return others
    index = seen.nonzero()[0]
    index = index[np.lexsort((others.ids[index], dist[index]))][: max(max_neighbors, 0)]
    return others.subset(index)
