"""Crossing encounters of each robot with the others (pure).

A *crossing encounter* of robot a is another robot b whose centre-to-centre distance to a
falls below `ENCOUNTER_DISTANCE_M` at some sample, and whose heading differs from a's by
more than `ENCOUNTER_HEADING_RAD` (wrapped to [0, pi]) at the sample of their closest
approach (the first such sample on a tie). Robots moving together in a stream, or one
overtaking another, do not cross; a head-on pass or a 90 degree crossing does. Each other
robot counts at most once, over every sample of the trajectory (a common time grid: every
robot has a pose at every sample). The relation is symmetric, so a crossing counts one
encounter for each of the two robots.

`orchestrator.analysis.metrics` divides a run's reversals (oscillations) by its
encounters, so that decisiveness can be read per encounter rather than per robot.

Cost: `crossing_encounters` first bounds each pair's distance from below over windows of
`PREFILTER_STRIDE` samples (the distance at the window's first sample, less how far each
of the two moves from there within the window; `near_pairs`) and finds the closest
approach sample by sample only for the pairs whose bound falls below the encounter
distance somewhere. The bound is exact (no pair that comes close is dropped), and in a
large fleet spread over a wide area it leaves only the pairs that are ever neighbours.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

ENCOUNTER_DISTANCE_M = 2.5
ENCOUNTER_HEADING_RAD = math.radians(45.0)
PREFILTER_STRIDE = 25
"""Samples per window of the lower bound of `near_pairs` (0.5 s at the world's 50 Hz)."""
# Pair-samples per block of `closest_approach`: bounds its memory (about 32 MB of float64).
_BLOCK_PAIR_SAMPLES = 1 << 21


def near_pairs(xy_m: np.ndarray, distance_m: float, stride: int = PREFILTER_STRIDE
               ) -> tuple[np.ndarray, np.ndarray]:
    """The pairs i < j that may come closer than `distance_m` at some sample.

    Over each window of `stride` samples, |p_i(t) - p_j(t)| >= |p_i(s) - p_j(s)| - m_i - m_j,
    with s the window's first sample and m_r the farthest robot r gets from p_r(s) within
    the window; a pair whose bound stays at or above `distance_m` in every window never
    comes closer. A robot without a pose at s (NaN) bounds nothing in that window.

    Args:
        xy_m: (T, n, 2) positions [m] on a common time grid.
        distance_m: the distance of interest [m].
        stride: samples per window (>= 1).

    Returns:
        (i, j): (P,) each, the candidate pairs in the order of `np.triu_indices`.
    """
    xy = np.asarray(xy_m, dtype=float)
    i, j = np.triu_indices(xy.shape[1], k=1)
    if xy.shape[0] == 0 or not i.size:
        return i, j
    stride = max(1, int(stride))
    anchors = xy[::stride]  # (W, n, 2)
    w = anchors.shape[0]
    pad = w * stride - xy.shape[0]
    padded = np.concatenate((xy, np.full((pad,) + xy.shape[1:], np.nan))) if pad else xy
    moved = np.hypot(*np.moveaxis(padded.reshape(w, stride, *xy.shape[1:])
                                  - anchors[:, None], -1, 0))  # (W, stride, n)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows
        reach = np.nanmax(moved, axis=1)  # (W, n)
    reach = np.where(np.isnan(anchors[..., 0]) | np.isnan(reach), np.inf, reach)
    near = np.zeros(i.size, dtype=bool)
    block = max(1, _BLOCK_PAIR_SAMPLES // i.size)
    for w0 in range(0, w, block):
        rel = anchors[w0:w0 + block, j] - anchors[w0:w0 + block, i]  # (b, P, 2)
        bound = np.hypot(rel[..., 0], rel[..., 1]) - reach[w0:w0 + block, i] \
            - reach[w0:w0 + block, j]
        np.nan_to_num(bound, copy=False, nan=-np.inf)
        near |= np.any(bound < distance_m, axis=0)
    return i[near], j[near]


def closest_approach(xy_m: np.ndarray, pairs: tuple[np.ndarray, np.ndarray] | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each pair's smallest centre distance and the first sample at which it occurs.

    Args:
        xy_m: (T, n, 2) positions [m] on a common time grid, T >= 1.
        pairs: (i, j) the pairs to look at; None: all n (n - 1) / 2 pairs i < j.

    Returns:
        (i, j, distance_m, sample): (P,) each, one entry per pair.
    """
    xy = np.asarray(xy_m, dtype=float)
    i, j = np.triu_indices(xy.shape[1], k=1) if pairs is None else pairs
    if not i.size:
        return i, j, np.zeros(0), np.zeros(0, dtype=np.int64)
    best = np.full(i.size, np.inf)
    sample = np.zeros(i.size, dtype=np.int64)
    block = max(1, _BLOCK_PAIR_SAMPLES // max(1, i.size))
    for t0 in range(0, xy.shape[0], block):
        rel = xy[t0:t0 + block, j] - xy[t0:t0 + block, i]  # (t, P, 2)
        dist = np.hypot(rel[..., 0], rel[..., 1])
        # A sample without a pose (NaN) is no approach; left NaN, argmin would pick it and
        # hide the pair's real closest approach in the whole block.
        np.nan_to_num(dist, copy=False, nan=np.inf)
        k = np.argmin(dist, axis=0)
        d = dist[k, np.arange(i.size)]
        # Strictly closer only: a tie keeps the earlier sample.
        closer = d < best
        best[closer] = d[closer]
        sample[closer] = k[closer] + t0
    return i, j, best, sample


def crossing_encounters(xy_m: np.ndarray, heading_rad: np.ndarray, *,
                        distance_m: float = ENCOUNTER_DISTANCE_M,
                        heading_diff_rad: float = ENCOUNTER_HEADING_RAD) -> np.ndarray:
    """The crossing encounters of each robot (module docstring).

    Args:
        xy_m: (T, n, 2) positions [m], one row per sample of the common time grid.
        heading_rad: (T, n) headings [rad], wrapped or not.
        distance_m: closer than this (centre to centre) is close [m].
        heading_diff_rad: headings further apart than this at the closest approach cross
            [rad].

    Returns:
        (n,) int counts; zeros without samples or with a single robot.
    """
    xy = np.asarray(xy_m, dtype=float)
    heading = np.asarray(heading_rad, dtype=float)
    if xy.ndim != 3 or xy.shape[2] != 2 or heading.shape != xy.shape[:2]:
        raise ValueError(f"xy_m must be (T, n, 2) and heading_rad (T, n); got {xy.shape} "
                         f"and {heading.shape}")
    n = xy.shape[1]
    if xy.shape[0] == 0 or n < 2:
        return np.zeros(n, dtype=np.int64)
    i, j, dist, sample = closest_approach(xy, near_pairs(xy, distance_m))
    diff = heading[sample, j] - heading[sample, i]
    wrapped = np.abs(np.angle(np.exp(1j * diff)))  # in [0, pi]
    crossing = (dist < distance_m) & (wrapped > heading_diff_rad)
    return (np.bincount(i[crossing], minlength=n)
            + np.bincount(j[crossing], minlength=n)).astype(np.int64)
