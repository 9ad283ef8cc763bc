"""Standing clear at the goal: a parked robot steps aside from a moving obstacle.

Not in the paper (arXiv 2508.08264). A robot at its goal stops planning
(`agent.planning.planners.arrived_result`) and stands. Other robots plan round it, but a
moving scenario obstacle is blind: it keeps its course and runs a parked robot down. On
random scenes with four obstacles crossing at 0.5 m/s (scenarios none of the benchmark
families contained), two of three runs ended with robots hit where they stood at their
goals, overlaps up to 0.98 m.

So a robot that has arrived, or is within `WATCH_FROM_M` of its goal, keeps watch on the
moving obstacles it senses (`refuge_point`):
when one will pass its goal closer than the inflated radius L (Eq. 8) plus
`REFUGE_MARGIN_M` within the threat horizon T_max, or is that close to the goal now, the
robot steps aside to a *refuge*: the point level with the goal beside the obstacle's
track, L + `REFUGE_MARGIN_M` from it, on the goal's side of the track (on the obstacle's
right when the goal lies on its track). It goes there with the ordinary planner, so every
other disc is still avoided on the way, stands there, and returns to its goal once the
goal is clear. For an obstacle on a straight course the refuge stays where it is from one
cycle to the next (the foot of the goal on the track does not move), so the robot does not
chase a moving point.

Choices the issue left open, and why:

- Only obstacles are watched here, not robots: robots plan round a parked robot
  themselves, and a parked robot that also stepped aside for every robot coming by would
  be a second mover in the same place. Where no way round exists, a robot that stays
  pressed against a parked one sends it aside (`agent.planning.make_way`, after this
  rule). An obstacle moves when its estimated speed is at least `encounters.MOVING_MPS`.
- The most imminent threat (earliest closest approach; an obstacle already within reach
  counts as now) sets the refuge. A refuge inside the inflated disc of a static obstacle,
  or itself in reach of another moving obstacle, is replaced by the one on the far side
  of the track (2 (L + margin) across); when that is no better, the near one is kept.

Pure: arrays in, a point out; no clock, no I/O.
"""

from __future__ import annotations

import math

import numpy as np

from agent.core.types import Others
from agent.planning.encounters import MOVING_MPS
from agent.planning.routing import StaticMap
from agent.planning.threats import tcpa_dcpa

WATCH_FROM_M = 3.0
"""A robot watches its goal from this far out, not only once parked [m]: one that arrives
just before an obstacle crosses its goal cannot step aside in time (a robot arriving 0.06 s
before a 1 m/s obstacle reached it, on the scenes above)."""

_AT_REST = np.zeros(2)

REFUGE_MARGIN_M = 0.2
"""How far beyond the inflated radius L from an obstacle's track the refuge lies, and how
far beyond L the obstacle must be from the goal before the robot returns [m]."""


def _threat_times_s(point: np.ndarray, others: Others, movers: np.ndarray,
                    reach_m: np.ndarray, horizon_s: float) -> np.ndarray:
    """When each of the moving obstacles `movers` threatens `point`, on a straight course:
    0 when it is within `reach_m` now, its TCPA (Eqs. 3-5, `threats.tcpa_dcpa` against a
    point at rest) when that is in (0, horizon_s] with DCPA < `reach_m`, else inf."""
    position, reach = others.position_m[movers], reach_m[movers]
    tcpa, dcpa = tcpa_dcpa(point, _AT_REST, position, others.velocity_mps[movers])
    now = np.hypot(*(position - point).T) < reach
    later = (tcpa > 0.0) & (tcpa <= horizon_s) & (dcpa < reach)
    return np.where(now, 0.0, np.where(later, tcpa, math.inf))


def refuge_point(goal_m: np.ndarray, radius_m: float, others: Others, d_safety_m: float,
                 horizon_s: float, static: StaticMap | None = None) -> np.ndarray | None:
    """Where a robot parked at `goal_m` should stand instead, or None when the goal is clear.

    Args:
        goal_m: (2,) the robot's goal.
        radius_m: the robot's radius.
        others: what the robot senses; only moving obstacles (not robots) are watched.
        d_safety_m: the safety margin of Eq. (8).
        horizon_s: how far ahead a closest approach counts (T_max) [s].
        static: the scenario's static discs; a refuge within L of one is avoided.

    Returns:
        (2,) the refuge, or None.
    """
    speed = np.hypot(*others.velocity_mps.T) if len(others) else np.zeros(0)
    movers = np.flatnonzero(~others.is_robot & (speed >= MOVING_MPS))
    if movers.size == 0:
        return None
    goal = np.asarray(goal_m, dtype=float)
    reach = radius_m + others.radius_m + d_safety_m + REFUGE_MARGIN_M
    times = _threat_times_s(goal, others, movers, reach, horizon_s)
    if not np.isfinite(times).any():
        return None
    pick = int(np.argmin(times))  # the most imminent (the first of equals)
    first = int(movers[pick])
    o, u = others.position_m[first], others.velocity_mps[first]
    foot = o + u * (float((goal - o) @ u) / float(u @ u))
    off = goal - foot
    gap = math.hypot(off[0], off[1])
    normal = off / gap if gap > 1e-9 else np.array([u[1], -u[0]]) / speed[first]
    near: np.ndarray = foot + normal * reach[first]
    far: np.ndarray = foot - normal * reach[first]
    rest = np.delete(movers, pick)
    for candidate in (near, far):
        if _clear(candidate, rest, others, reach, horizon_s, radius_m, d_safety_m, static):
            return candidate
    return near


def _clear(point: np.ndarray, movers: np.ndarray, others: Others, reach: np.ndarray,
           horizon_s: float, radius_m: float, d_safety_m: float,
           static: StaticMap | None) -> bool:
    """Whether a refuge is outside every static disc's inflated radius and out of reach
    of every moving obstacle in `movers` (all but the one it is for)."""
    if static is not None and len(static.radius_m):
        gaps = np.hypot(*(static.center_m - point).T) - static.radius_m
        if (gaps < radius_m + d_safety_m).any():
            return False
    return bool(movers.size == 0 or np.isinf(
        _threat_times_s(point, others, movers, reach, horizon_s)).all())
