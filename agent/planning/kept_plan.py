"""Last cycle's via-points, kept while they still hold (`Mechanisms.keep_plan`).

Rebuilt from scratch every cycle, a plan in a crowd jumps between unrelated via-point
sequences as the ranking of nearly simultaneous threats reorders. A plan that still holds is
the same decision made again, so `agent.planning.ifp.keep_previous` keeps it: only a failing
or clearly worse plan is replaced. Pure: complex numbers x + iy in, arrays out.
"""

from __future__ import annotations

import itertools

import numpy as np

from agent.core.types import Side
from agent.planning.threats import legs_threats

KEEP_PLAN_RATIO = 0.3
"""With `Mechanisms.keep_plan`, last cycle's via-points are kept while every leg through
them is still clear and the path through them is at most this fraction longer than the
new plan's. 0.3 since 2026-12-07 (0.1 before): a pass once chosen is seen through unless it
fails or costs a third more, which cut reversals on the liveness families' tuning seeds
(docs/method.md, "Tuning record"); 0.5 cut no more and left a robot of `grid_dense` 25
standing."""

PASSED_VIA_M = 0.3
"""A kept via-point closer to the robot than this, or behind it along the next leg, has
been passed [m]."""


def kept_waypoints(previous_m: np.ndarray, previous_sides: tuple[tuple[int, Side], ...],
                   new_wps: list[complex], speed: float,
                   position: np.ndarray, velocity: np.ndarray, clearance: np.ndarray,
                   t_max_s: float, ids: np.ndarray,
                   ) -> tuple[np.ndarray, tuple[tuple[int, Side], ...]] | None:
    """Last cycle's via-points from the robot's position on, if they still hold.

    They hold when every leg of [P, kept via-points, goal] is clear of every disc within
    T_max at top speed (`threats.legs_threats`) and the path is at most `KEEP_PLAN_RATIO`
    longer than the new plan's. Via-points the robot has passed are dropped first; None
    when none is left, or the plan does not hold.

    Args:
        previous_m: (M, 2) last cycle's waypoints (its position, via-points, goal) [m].
        previous_sides: (other id, side) of each of its via-points.
        new_wps: this cycle's plan as complex points, robot first, goal last [m].
        speed: the robot's top speed [m/s].
        position, velocity: (K,) the others as complex numbers [m], [m/s].
        clearance: (K,) distance below which other j is in the way [m].
        t_max_s: T_max [s].
        ids: (K,) the others' ids (a kept via-point's other must still be sensed).
    """
    p, goal = new_wps[0], new_wps[-1]
    vias = [complex(x, y) for x, y in previous_m[1:-1]]
    sides = list(previous_sides)
    if len(vias) != len(sides):
        return None
    sensed = set(ids.tolist())
    while vias:
        nxt = vias[1] if len(vias) > 1 else goal
        v = vias[0]
        if abs(v - p) < PASSED_VIA_M or ((p - v) * (nxt - v).conjugate()).real > 0.0:
            vias.pop(0)
            sides.pop(0)
        else:
            break
    if not vias or any(i not in sensed for i, _ in sides) :
        return None
    wps = [p, *vias, goal]
    length = sum(abs(b - a) for a, b in zip(wps, wps[1:]))
    new_length = sum(abs(b - a) for a, b in zip(new_wps, new_wps[1:]))
    if length > (1.0 + KEEP_PLAN_RATIO) * new_length:
        return None
    arrival = [0.0, *itertools.accumulate(abs(b - a) / speed for a, b in zip(wps, wps[1:]))]
    hit, _ = legs_threats(wps[:-1], wps[1:], arrival[:-1], speed, position, velocity,
                          clearance, t_max_s)
    if hit.any():
        return None
    return np.array([(z.real, z.imag) for z in wps]), tuple(sides)
