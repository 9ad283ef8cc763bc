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
"""

from __future__ import annotations

import math

import numpy as np

ENCOUNTER_DISTANCE_M = 2.5
ENCOUNTER_HEADING_RAD = math.radians(45.0)
# Pair-samples per block of `closest_approach`: bounds its memory (about 32 MB of float64).
_BLOCK_PAIR_SAMPLES = 1 << 21


def closest_approach(xy_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each pair's smallest centre distance and the first sample at which it occurs.

    Args:
        xy_m: (T, n, 2) positions [m] on a common time grid, T >= 1.

    Returns:
        (i, j, distance_m, sample): (P,) each, P = n (n - 1) / 2 pairs i < j.
    """
    xy = np.asarray(xy_m, dtype=float)
    i, j = np.triu_indices(xy.shape[1], k=1)
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
    i, j, dist, sample = closest_approach(xy)
    diff = heading[sample, j] - heading[sample, i]
    wrapped = np.abs(np.angle(np.exp(1j * diff)))  # in [0, pi]
    crossing = (dist < distance_m) & (wrapped > heading_diff_rad)
    return (np.bincount(i[crossing], minlength=n)
            + np.bincount(j[crossing], minlength=n)).astype(np.int64)
