"""Narrow passages on a route: centred, crossed with a margin the passage leaves, one way
at a time where two robots cannot pass each other.

Not in the paper (arXiv 2508.08264). A tight route (`routing.route_or_tight`) goes through
a gap that admits the robot but not its safety margin: a doorway or corridor a little
wider than the robot. Three things kept a robot out of such a gap (probe
`rooms_lane_2`, docs/results.md: a lone robot stood at a corridor 1.3 m wide, its
diameter 1.0 m, until the time limit):

1. the tight route hugs one side (its corners are ring points at the robot's radius plus
   2 cm from a disc), so a robot following it has no room for tracking error;
2. eIFP inflates every disc by d_safety (Eq. 8), which closes the gap: its via-points
   zig-zag at the mouth instead of leading in; and the MPC keeps `clearance_margin_m`
   from every disc, which in the gap leaves a tube a few centimetres wide;
3. two robots that meet head-on inside a gap one robot wide can only back out.

The rules here, in the order a cycle applies them:

- **Centring** (`centre_route`): where the clear width across a tight route is less than
  twice the full route clearance (robot radius + d_safety + `ROUTE_MARGIN_M`), or across
  any route less than `one_lane_width_m` (two robots cannot pass each other there with
  their margins: a door 2.2 m clear that 16 robots crossing both ways jammed,
  `wide_door_crowd`), the route's points are moved to the middle of the gap (halfway
  between the nearest disc edges on its left and right), sampled every `SAMPLE_STEP_M` and
  thinned to the corners that matter, with a lead-in point `LEAD_IN_M` before the mouth on
  the centre line so the robot arrives aligned. Centring never lowers a point's clearance
  (the middle of a gap is at least as far from both sides as any point in it).
- **Following the line** (`on_track`): past the lead-in, the robot aims
  `TRACK_LOOKAHEAD_M` ahead of its nearest point on the centre line, and before the mouth
  no nearer than `ALIGN_M` short of it; the route follower (whose sight lines find nothing
  in such a gap once the robot is off the line) is not used there.
- **Passage margin** (`Passage.margin_m`): while the robot is within `NEAR_M` of a
  passage it has not yet left, eIFP plans against the discs bounding it with the margin
  the passage leaves: half its clear width less the robot's radius, less
  `TRACKING_TUBE_M` for tracking, but never more than d_safety and never below
  `MIN_MARGIN_M`. The MPC's clearance from them is set in
  `agent.planning.planners` (`PASSAGE_GUARD_ROOM_M`, `PASSAGE_SLACK_M`).
- **One way at a time** (`must_hold`): a passage narrower than two robots side by side
  (`Passage.one_lane`) is entered only when no sensed robot is in it coming the other
  way, and no robot waiting or coming at either mouth has the right of way. Right of way
  outside: the robot past its hold line (`HOLD_M` from its mouth) before one that is not,
  then the robot nearer its mouth (by more than `TIE_M`), then the lower id. A robot
  that must give way waits at `waiting_spot`, off the line out of the mouth, so the
  way out is clear for the robots coming out. A robot inside always has the right of
  way over one outside. Robots sense each other's positions and ids (not their plans), so both sides
  compute the same priority; a robot that gives way to one that stands still (parked,
  or stuck itself) stops giving way after `HOLD_STILL_S`, so no wait is for ever.

**Lanes** (`Mechanisms.lanes`, the ``lanes`` profile only; docs/results.md, "Lanes in
corridors: an opt-in profile"). A corridor at least `one_lane_width_m` wide but narrower
than `two_lane_width_m` (two robots on routes along opposite walls, each the full route
clearance from its wall, would come within L of each other: 3.3 m for r = 0.5 m) is driven
in lanes: the route's samples there move to the lane on the robot's right of travel
(`_lane_offset_m`: the middle of the right half, but at least L/2 + `LANE_SLACK_M` from the
middle and never nearer the wall than the radius plus `TRACKING_TUBE_M`), and the stretch
is a passage (`Passage.lane`: followed along its line, its wall planned against with the
margin the lane leaves, never one way at a time). Routes round inner corners otherwise put
robots going both ways on the same side of such a corridor: in a maze of 3 m corridors
and doors with six robots each way (`maze_counterflow`) 9 of 12 stood at a door. A
stretch is a lane only between walls that face each other across the route
(`_walls_across`), and only along a corridor at least `LANE_MIN_M` long, with the short
stretches next to one (the door between two corridors) joined to it (`_corridors`): not
at a door in a thin wall, nor between two pillars. A robot that leaves a lane short of its
far mouth, towards the route's next waypoint, has left it (`guidance.RouteGuide`): a lane
does not hold a robot in as a one-lane gap's walls do.

Why the one-way rule cannot deadlock: right of way is a strict order (past the hold line,
then distance to the mouth, then id), the same for both robots, so of two robots at
opposite mouths exactly one holds; a robot inside never holds; and a hold on a robot that
does not move ends after `HOLD_STILL_S` (docs/method.md, "Narrow passages", says where
this is weaker).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from agent.core.types import Others
from agent.planning.routing import Route, StaticMap, segment_clears, segment_disc_distance

SAMPLE_STEP_M = 0.1
"""Spacing of the route samples at which the gap's width is measured [m]."""
NEAREST_DISCS = 8
"""Discs looked at round each sample for the nearest edge on either side."""
THIN_TOLERANCE_M = 0.05
"""A centred sample is kept as a route point where dropping it would move the line more
than this (Douglas-Peucker) [m]."""
LEAD_IN_M = 2.0
"""The centre line is extended this far before the mouth (the robot arrives aligned) [m]."""
TRACKING_TUBE_M = 0.1
"""Room left for tracking error on either side of the centre line in a passage [m]."""
MIN_MARGIN_M = 0.02
"""The passage margin's floor [m]."""
NEAR_M = 3.0
"""A robot this close to a passage (its centre line, lead-in included) plans with the
passage margin [m]."""
HOLD_M = 2.5
"""A robot giving way stands this far before the mouth (centre distance) [m]."""
LOOK_M = 4.0
"""Robots within this of the far mouth, outside, count as waiting or coming [m]."""
SPOT_M = 2.2
"""A robot giving way waits this far from the mouth (inside its hold line) [m]."""
SPOT_ANGLE_RAD = math.radians(50.0)
"""... and this far round from the line out of the mouth (`waiting_spot`)."""
SPOT_CLEAR_M = 0.3
"""A waiting spot keeps this much more than the robot's radius from every static disc [m]."""
SPOT_REACHED_M = 0.3
"""A robot this close to its waiting spot stands there [m]."""
TIE_M = 0.5
"""Distances to the mouths within this of each other are a tie (the lower id goes) [m]."""
HOLD_STILL_S = 8.0
"""A robot stops giving way to robots that have each stood still this long [s]."""
TRACK_LOOKAHEAD_M = 1.5
"""On a passage's line, the robot aims this far ahead of its nearest point on it [m]."""
TRACK_OFFSET_M = 1.0
"""A robot past the lead-in and within this of the line follows the line (`on_track`) [m].
1.5 m was tried (2026-12-07, not kept): it ended an orbit round a door's lead-in seen on
`rooms` 10 evaluation seed 5, but lost 2 robots of `rooms` seed 121 on seeds 114-129 (in
neither named set), where 1.0 m brings all 160 (docs/results.md)."""
ALIGN_M = 1.0
"""A robot before a passage aims at its centre line no nearer the mouth than this, so it
is on the line when it gets there (about the reference's corner radius) [m]."""
SLOW_MPS = 0.1
"""Slower than this, a robot stands (for `HOLD_STILL_S` and for the direction test) [m/s]."""
LANE_SLACK_M = 0.05
"""Two robots in opposite lanes pass this much outside each other's inflated radius [m]."""
ACROSS_RAD = math.radians(30.0)
"""A stretch is driven in lanes only where its walls face each other within this of square
across the route (`_walls_across`)."""
OPPOSITE_RAD = math.radians(40.0)
"""... and its nearest disc edges either side within this of straight opposite
(`_walls_across`). Worked by hand for one point each: 148 degrees apart 0.3 m off the
middle of a corridor 3 m wide between discs 1.14 m apart, 136 degrees 0.5 m out of a door
3 m wide on a route crossing it at a slant."""
LANE_MIN_M = 3.0
"""A stretch is driven in lanes only where it is at least this long: a corridor, not a
door in a wall or the gap between two pillars, where robots meeting pass by the planner's
own rules as before (the suite's `obstacles_circle` has hundreds of such gaps)."""
FILL_SAMPLES = 20
"""Samples (`SAMPLE_STEP_M` each) of a notch between lane samples filled in (`_closed`), and
the farthest a short stretch may be from a corridor to be joined to it (`_corridors`):
the turn out of a corridor into a door 2.8-3.2 m wide is up to 1.4 m of wider samples."""
_CENTRED, _LANE = 1, 2
"""What `centre_route` does with a route sample: centre it, or move it to the right lane."""
_END_M = 1e-6
"""Arc lengths this close to a line's ends are at the ends (rounding) [m]."""


@dataclass(frozen=True)
class Passage:
    """A stretch of a route narrower than the full clearance.

    Args:
        line_m: (k, 2) its centred line, the lead-in point first, the far mouth last [m].
        mouth_index: index in `line_m` of the near mouth (1 with a lead-in, else 0).
        width_m: the narrowest clear width across it [m].
        disc_index: indices into the static map of the discs bounding it.
        one_lane: two robots of this radius cannot pass each other in it.
        margin_m: the margin against its discs (module docstring) [m].
        entered: the route starts in it (planned again from inside): the robot is in it
            already, and neither waits before it nor aligns with its mouth.
    """

    line_m: np.ndarray
    mouth_index: int
    width_m: float
    disc_index: np.ndarray
    one_lane: bool
    margin_m: float
    entered: bool = False
    lane: bool = False

    @property
    def mouth_m(self) -> np.ndarray:
        """(2,) where the narrow stretch starts [m]."""
        mouth: np.ndarray = self.line_m[self.mouth_index]
        return mouth

    @property
    def far_mouth_m(self) -> np.ndarray:
        """(2,) where it ends [m]."""
        far: np.ndarray = self.line_m[-1]
        return far


def _resample(wps: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every `step_m` along a polyline (the vertices included) and the unit
    direction of the leg each lies on."""
    pts, dirs = [], []
    for a, b in zip(wps[:-1], wps[1:]):
        seg = b - a
        length = float(math.hypot(*seg))
        if length <= 1e-9:
            continue
        n = max(1, math.ceil(length / step_m))
        t = np.arange(n)[:, None] / n
        pts.append(a + t * seg)
        dirs.append(np.broadcast_to(seg / length, (n, 2)))
    pts.append(wps[-1:])
    dirs.append(dirs[-1][-1:] if dirs else np.array([[1.0, 0.0]]))
    return np.concatenate(pts), np.concatenate(dirs)


def _side_gaps(points: np.ndarray, dirs: np.ndarray, static: StaticMap, tree: cKDTree
               ) -> tuple[np.ndarray, np.ndarray]:
    """Distance from each point to the nearest disc edge on its left and on its right of
    the direction (inf where none of the nearest discs is on that side)."""
    _, _, left_edge, right_edge = _sided_discs(points, dirs, static, tree)
    return left_edge.min(axis=1), right_edge.min(axis=1)


def _sided_discs(points: np.ndarray, dirs: np.ndarray, static: StaticMap, tree: cKDTree
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The `NEAREST_DISCS` discs nearest each point: their centres relative to it (n, k,
    2), their distances (n, k), and their edge distances on its left and on its right of
    the direction (n, k each; inf for a disc on the other side)."""
    k = min(NEAREST_DISCS, len(static))
    _, idx = tree.query(points, k=k)
    idx = np.reshape(idx, (points.shape[0], k))
    rel = static.center_m[idx] - points[:, None, :]
    dist = np.hypot(rel[..., 0], rel[..., 1])
    edge = dist - static.radius_m[idx]
    cross = dirs[:, None, 0] * rel[..., 1] - dirs[:, None, 1] * rel[..., 0]
    return rel, dist, np.where(cross > 0.0, edge, np.inf), np.where(cross <= 0.0, edge, np.inf)


def _lane_samples(pts: np.ndarray, dirs: np.ndarray, width: np.ndarray, narrow: np.ndarray,
                  static: StaticMap, tree: cKDTree, two_lane_m: float) -> np.ndarray:
    """Which route samples are driven in a lane (module docstring, "Lanes"): not narrow,
    narrower than `two_lane_m`, between walls across the route, along a corridor."""
    lane: np.ndarray = ~narrow & (width < two_lane_m)
    if lane.any():
        # a wall of discs is scalloped: between two discs its edge lies farther off, and
        # both the width and the walls' facing come and go along it; notches are filled
        lane = _closed(lane & _walls_across(pts, dirs, static, tree), FILL_SAMPLES)
        lane = _corridors(lane & ~narrow, math.ceil(LANE_MIN_M / SAMPLE_STEP_M), FILL_SAMPLES)
    return lane


def _walls_across(points: np.ndarray, dirs: np.ndarray, static: StaticMap, tree: cKDTree
                  ) -> np.ndarray:
    """Whether a point is between two walls that face each other across the direction:
    the nearest disc edges on its left and right lie within `OPPOSITE_RAD` of straight
    opposite each other, and the line between them within `ACROSS_RAD` of square to the
    direction. Not so at a door crossed at a slant, or just out of it, where the nearest
    discs on both sides are behind the point and a lane drawn across from them would
    lead a metre or more off the route."""
    rel, dist, left_edge, right_edge = _sided_discs(points, dirs, static, tree)
    rows = np.arange(points.shape[0])
    near_left = np.argmin(left_edge, axis=1)
    near_right = np.argmin(right_edge, axis=1)
    unit = rel / np.maximum(dist, 1e-9)[..., None]
    to_left, to_right = unit[rows, near_left], unit[rows, near_right]
    span = to_left - to_right  # from the right wall to the left
    norm = np.maximum(np.hypot(span[:, 0], span[:, 1]), 1e-9)
    along = np.abs((span * dirs).sum(axis=1)) / norm
    opposite = (to_left * to_right).sum(axis=1)  # -1: the walls straight either side
    across: np.ndarray = (along < math.sin(ACROSS_RAD)) & (opposite < -math.cos(OPPOSITE_RAD))
    return across


def _closed(mask: np.ndarray, gap: int) -> np.ndarray:
    """`mask` with runs of at most `gap` False samples between two True ones set True
    (a wall of discs leaves notches between them, where the nearest discs either side
    are not straight across)."""
    true = np.flatnonzero(mask)
    out = mask.copy()
    for a, b in zip(true[:-1], true[1:]):
        if 1 < b - a <= gap + 1:
            out[a:b] = True
    return out


def _corridors(mask: np.ndarray, samples: int, gap: int) -> np.ndarray:
    """`mask` kept in its runs of True at least `samples` long (corridors), and in the
    shorter runs within `gap` samples of a kept one (the door between two corridors, or
    at a corridor's end), with the gaps between those filled (`_closed`); every other
    run set False (a door in a wall, the gap between two pillars)."""
    edges = np.flatnonzero(np.diff(np.r_[False, mask, False].astype(np.int8)))
    runs = list(zip(edges[0::2].tolist(), edges[1::2].tolist()))
    kept = [b - a >= samples for a, b in runs]
    grown = True
    while grown:
        grown = False
        for k, (a, b) in enumerate(runs):
            near = (k > 0 and kept[k - 1] and a - runs[k - 1][1] <= gap) or \
                (k + 1 < len(runs) and kept[k + 1] and runs[k + 1][0] - b <= gap)
            if not kept[k] and near:
                kept[k] = grown = True
    out = np.zeros_like(mask)
    for (a, b), keep in zip(runs, kept):
        out[a:b] = keep
    return _closed(out, gap)


def _thin(points: np.ndarray, tolerance_m: float) -> np.ndarray:
    """Douglas-Peucker: the points whose removal would move the line more than
    `tolerance_m` (the ends always)."""
    keep = np.zeros(points.shape[0], dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, points.shape[0] - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        a, b = points[i], points[j]
        seg = b - a
        length = float(math.hypot(*seg))
        mid = points[i + 1:j] - a
        if length <= 1e-9:
            dist = np.hypot(mid[:, 0], mid[:, 1])
        else:
            dist = np.abs(seg[0] * mid[:, 1] - seg[1] * mid[:, 0]) / length
        far = int(np.argmax(dist))
        if dist[far] > tolerance_m:
            keep[i + 1 + far] = True
            stack += [(i, i + 1 + far), (i + 1 + far, j)]
    thinned: np.ndarray = points[keep]
    return thinned


def _margin(width_m: float, radius_m: float, usual_m: float) -> float:
    """The margin against a passage's discs (module docstring)."""
    return float(min(usual_m, max(MIN_MARGIN_M, width_m / 2.0 - radius_m - TRACKING_TUBE_M)))


def centre_route(route: Route, static: StaticMap, radius_m: float, d_safety_m: float,
                 full_clearance_m: float, *, lanes: bool = False
                 ) -> tuple[Route, tuple[Passage, ...]]:
    """The route with its narrow stretches centred, and those stretches (module
    docstring): on a tight route, where the clear width is less than twice the full
    clearance; on any other route, where it is less than `one_lane_width_m`; and, with
    `lanes`, its corridors driven in lanes (module docstring, "Lanes"). A route with no
    such stretch, or whose centred form would not keep its own clearance (a lane's own,
    nearer its wall, on a route with lanes), comes back as it was, with no passages.

    Args:
        route: a route from `routing.route_or_tight`.
        static: the map it was planned on.
        radius_m: the robot's radius [m].
        d_safety_m: the usual margin of Eq. (8) [m].
        full_clearance_m: the full route clearance (robot radius + d_safety + margin) [m].
        lanes: drive corridors in lanes (`Mechanisms.lanes`; the ``lanes`` profile).
    """
    if len(static) == 0:
        return route, ()
    tree = cKDTree(static.center_m)
    pts, dirs = _resample(route.waypoints_m, SAMPLE_STEP_M)
    left, right = _side_gaps(pts, dirs, static, tree)
    one_lane = one_lane_width_m(radius_m, d_safety_m)
    width = left + right
    narrow = width < (2.0 * full_clearance_m if route.tight else one_lane)
    lane = _lane_samples(pts, dirs, width, narrow, static, tree,
                         two_lane_width_m(radius_m, d_safety_m, full_clearance_m)) \
        if lanes else np.zeros_like(narrow)
    kind = np.where(narrow, _CENTRED, np.where(lane, _LANE, 0)).astype(np.int8)
    start_inside = bool(kind[0])  # a route planned from inside a gap
    kind[0] = kind[-1] = 0  # the start and the goal stay where they are
    if not kind.any():
        return route, ()
    normal = np.stack((-dirs[:, 1], dirs[:, 0]), axis=1)
    shift = np.where(kind > 0, (left - right) / 2.0, 0.0)
    shift -= np.where(kind == _LANE, _lane_offset_m(width, radius_m, d_safety_m), 0.0)
    shift = np.where(np.isfinite(shift), shift, 0.0)
    centred = pts + normal * shift[:, None]
    edges = np.flatnonzero(np.diff(kind))
    starts, ends = edges[:-1] + 1, edges[1:]
    runs = [(a, b) for a, b in zip(starts, ends) if kind[a]]
    out: list[np.ndarray] = []
    passages: list[Passage] = []
    cursor = 0  # samples before this are placed
    vertex_s = _vertex_samples(route.waypoints_m, pts)
    for a, b in runs:
        line = _thin(centred[a:b + 1], THIN_TOLERANCE_M)
        narrowest = float(width[a:b + 1].min())
        in_lane = bool(kind[a] == _LANE)
        # route corners within a lead-in of the mouth are dropped (the centred line
        # replaces them), the start never
        before = [i for i in vertex_s if cursor <= i < a
                  and (i == 0 or math.hypot(*(pts[i] - line[0])) > LEAD_IN_M + SAMPLE_STEP_M)]
        head = [pts[i] for i in before]
        prev = head[-1] if head else (out[-1][-1] if out else pts[0])
        full_line = _with_lead_in(line, dirs[a], prev, static, route.clearance_m)
        lead_ok = full_line.shape[0] > line.shape[0]
        out.append(np.array(head).reshape(-1, 2))
        out.append(full_line)
        discs = _bounding_discs(line, static, full_clearance_m)
        passages.append(Passage(
            line_m=full_line, mouth_index=1 if lead_ok else 0, width_m=narrowest,
            disc_index=discs, one_lane=narrowest < one_lane,
            margin_m=(_lane_margin if in_lane else _margin)(narrowest, radius_m, d_safety_m),
            entered=start_inside and a == 1, lane=in_lane))
        cursor = b + 1
    out.append(np.array([pts[i] for i in vertex_s if i >= cursor]).reshape(-1, 2))
    wps = np.concatenate(out)
    wps = wps[np.r_[True, np.hypot(*np.diff(wps, axis=0).T) > 1e-6]]
    if wps.shape[0] < 2 or not (wps[0] == route.waypoints_m[0]).all():
        return route, ()
    if not _legs_clear(wps, passages, static, route.clearance_m, radius_m):
        # with lanes, the route centred without them
        return centre_route(route, static, radius_m, d_safety_m, full_clearance_m) \
            if lanes else (route, ())
    return Route(wps, route.clearance_m, tight=route.tight), tuple(passages)


def _legs_clear(wps: np.ndarray, passages: list[Passage], static: StaticMap,
                clearance_m: float, radius_m: float) -> bool:
    """Whether every leg of `wps` keeps `clearance_m` from the static discs, or with a
    lane among `passages` the robot's radius plus `TRACKING_TUBE_M` (a lane runs nearer
    its right-hand wall than the route's clearance, by design)."""
    floor_m = (min(clearance_m, radius_m + TRACKING_TUBE_M) if any(p.lane for p in passages)
               else clearance_m)
    return bool(segment_clears(wps[:-1], wps[1:], static.center_m,
                               static.radius_m + floor_m).all())


def _with_lead_in(line: np.ndarray, direction: np.ndarray, prev: np.ndarray,
                  static: StaticMap, clearance_m: float) -> np.ndarray:
    """`line` with a lead-in point `LEAD_IN_M` before its mouth on its axis, where the
    route's previous point `prev` is at least that far back and the way from it to the
    lead-in and on to the mouth keeps `clearance_m`; else `line` as it is."""
    axis = line[min(1, line.shape[0] - 1)] - line[0]
    if float(math.hypot(*axis)) <= 1e-9:
        axis = direction
    unit = axis / max(float(math.hypot(*axis)), 1e-9)
    lead = line[0] - unit * LEAD_IN_M
    lead_ok = bool(float((prev - line[0]) @ unit) <= -LEAD_IN_M
                   and segment_clears(prev[None], lead[None], static.center_m,
                                      static.radius_m + clearance_m).all()
                   and segment_clears(lead[None], line[:1], static.center_m,
                                      static.radius_m + clearance_m).all())
    return np.concatenate((lead[None], line)) if lead_ok else line


def one_lane_width_m(radius_m: float, d_safety_m: float) -> float:
    """The clear width below which two robots of `radius_m` cannot pass each other with
    d_safety between them and `TRACKING_TUBE_M` to either wall: a stretch of any route
    narrower than this is a passage taken one way at a time [m]."""
    return 4.0 * radius_m + d_safety_m + 2.0 * TRACKING_TUBE_M


def two_lane_width_m(radius_m: float, d_safety_m: float, full_clearance_m: float) -> float:
    """The clear width below which two robots of `radius_m` following routes along
    opposite walls (each the full route clearance from its wall) would come within the
    inflated radius L = 2 r + d_safety of each other, with `TRACKING_TUBE_M` either side:
    a stretch narrower than this (and at least `one_lane_width_m`) is driven in lanes,
    each robot on its right [m]. 3.3 m for r = 0.5 m, d_safety = 0.3 m."""
    return 2.0 * full_clearance_m + 2.0 * radius_m + d_safety_m + 2.0 * TRACKING_TUBE_M


def _lane_offset_m(width_m: np.ndarray, radius_m: float, d_safety_m: float) -> np.ndarray:
    """How far right of a stretch's middle its right-hand lane runs [m]: the middle of
    the right half, but at least half the inflated radius L plus `LANE_SLACK_M` (two
    robots in opposite lanes then pass outside each other's L), and never nearer the wall
    than the robot's radius plus `TRACKING_TUBE_M`."""
    half_l = radius_m + d_safety_m / 2.0 + LANE_SLACK_M
    offset: np.ndarray = np.minimum(width_m / 2.0 - radius_m - TRACKING_TUBE_M,
                                    np.maximum(half_l, width_m / 4.0))
    floored: np.ndarray = np.maximum(offset, 0.0)
    return floored


def _lane_margin(width_m: float, radius_m: float, usual_m: float) -> float:
    """The margin against the discs bounding a lane: what its right-hand wall leaves
    less `TRACKING_TUBE_M`, within [`MIN_MARGIN_M`, d_safety]."""
    wall = width_m / 2.0 - float(_lane_offset_m(np.array(width_m), radius_m, usual_m))
    return float(min(usual_m, max(MIN_MARGIN_M, wall - radius_m - TRACKING_TUBE_M)))


def _vertex_samples(wps: np.ndarray, pts: np.ndarray) -> list[int]:
    """Indices of the samples that are the route's own vertices (start and goal
    included), in order."""
    found, j = [], 0
    for w in wps:
        while j < pts.shape[0] and not np.allclose(pts[j], w, atol=1e-9):
            j += 1
        if j < pts.shape[0]:
            found.append(j)
    return found


def _bounding_discs(line_m: np.ndarray, static: StaticMap, full_clearance_m: float
                    ) -> np.ndarray:
    """Indices of the discs whose edge comes within the full clearance of the line."""
    if line_m.shape[0] == 1:
        line_m = np.concatenate((line_m, line_m))
    d = segment_disc_distance(line_m[:-1], line_m[1:], static.center_m).min(axis=0)
    index: np.ndarray = np.flatnonzero(d - static.radius_m < full_clearance_m)
    return index


def distance_along(line_m: np.ndarray, point_m: np.ndarray) -> tuple[float, float]:
    """(arc length of the nearest point of `line_m` to `point_m`, distance to it) [m]."""
    a, b = line_m[:-1], line_m[1:]
    if a.shape[0] == 0:
        return 0.0, float(math.hypot(*(point_m - line_m[0])))
    seg = b - a
    length = np.hypot(seg[:, 0], seg[:, 1])
    sq = np.maximum(length * length, 1e-18)
    t = np.clip(((point_m - a) * seg).sum(axis=1) / sq, 0.0, 1.0)
    near = a + t[:, None] * seg
    d = np.hypot(*(near - point_m).T)
    k = int(np.argmin(d))
    before = float(length[:k].sum())
    return before + float(t[k] * length[k]), float(d[k])


def on_track(passage: Passage, position_m: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Where a robot in a passage aims: None until it is past the lead-in point (or the
    mouth, without one) and within `TRACK_OFFSET_M` of the line, and again once past the
    far mouth; else the point `TRACK_LOOKAHEAD_M` ahead of its nearest point on the line
    (the far mouth at most) and the line's points after that (the far mouth last).

    Followed this way, the robot is drawn onto the centre line and along it, whatever
    pushed it off, with no sight-line test against the walls it is between (the route
    follower's test, which in a gap a few centimetres wider than the robot finds nothing
    in sight as soon as the robot is off the line, and re-routes).
    """
    line = passage.line_m
    if line.shape[0] < 2:
        return None
    s, off = distance_along(line, position_m)
    legs = np.hypot(*np.diff(line, axis=0).T)
    total = float(legs.sum())
    if (s <= _END_M and not passage.entered) or s >= total - _END_M or off > TRACK_OFFSET_M:
        return None
    mouth_s = float(legs[:passage.mouth_index].sum())
    aim = min(s + TRACK_LOOKAHEAD_M, total)
    # before the mouth, aim no farther than ALIGN_M short of it: the reference then joins
    # the centre line before the gap (the arc at the corner is done by the mouth), instead
    # of cutting across the mouth at an angle
    if s < mouth_s - ALIGN_M:
        aim = min(aim, mouth_s - ALIGN_M)
    ends = np.cumsum(legs)
    k = int(min(np.searchsorted(ends, aim), legs.shape[0] - 1))
    start = float(ends[k] - legs[k])
    frac = (aim - start) / max(float(legs[k]), 1e-9)
    carrot = line[k] + frac * (line[k + 1] - line[k])
    after = line[k + 1:]
    if after.shape[0] and float(math.hypot(*(after[0] - carrot))) <= 1e-6:
        after = after[1:]
    return carrot, after


def waiting_spot(passage: Passage, position_m: np.ndarray, static: StaticMap,
                 radius_m: float) -> np.ndarray:
    """Where a robot that gives way before `passage` waits: `SPOT_M` from the mouth, turned
    `SPOT_ANGLE_RAD` off the line out of the mouth, to the side the robot is on (the right,
    seen from the mouth, when it is on the line), or the other side, or on the line,
    whichever first keeps `radius_m` + `SPOT_CLEAR_M` from every static disc. Off the line,
    the robots coming out find their way clear; on it, they met a half-ring of robots
    waiting 2 m from a door (`wide_door_crowd`)."""
    line = passage.line_m
    mouth = passage.mouth_m
    out = line[0] - mouth if passage.mouth_index else mouth - line[min(1, line.shape[0] - 1)]
    norm = float(math.hypot(*out))
    out = out / norm if norm > 1e-9 else np.array([-1.0, 0.0])
    rel = position_m - mouth
    side = 1.0 if float(out[0] * rel[1] - out[1] * rel[0]) > 0.0 else -1.0
    for angle in (side * SPOT_ANGLE_RAD, -side * SPOT_ANGLE_RAD, 0.0):
        c, s_ = math.cos(angle), math.sin(angle)
        spot = mouth + SPOT_M * np.array([c * out[0] - s_ * out[1], s_ * out[0] + c * out[1]])
        if len(static) == 0 or (np.hypot(*(static.center_m - spot).T) - static.radius_m
                                >= radius_m + SPOT_CLEAR_M).all():
            return spot
    return mouth + SPOT_M * out


@dataclass
class HoldState:
    """What `must_hold` remembers between cycles: since when each sensed robot has stood
    still (id -> sim time), whether it blocked the way then or not.

    Per robot rather than one clock for the hold: as a robot walks from its waiting spot
    to the lead-in, its distance to the mouth changes and a robot parked just beyond the
    far mouth goes in and out of the right of way; a clock reset whenever nobody blocked
    for a cycle restarted the wait each time, and the robot walked between the spot and
    the lead-in for ever (`rooms` 10, structured tuning seed 100, on the machine of
    2026-12-07: a lone robot, and a robot parked 1.5 m past the far mouth of its door)."""

    still_since_s: dict[int, float] = field(default_factory=dict)


def must_hold(passage: Passage, robot_id: int, position_m: np.ndarray, others: Others,
              now_s: float, state: HoldState) -> bool:
    """Whether a robot before `passage` (one lane) must give way this cycle (module
    docstring, "One way at a time").

    Args:
        passage: the next passage on the robot's route, not yet entered.
        robot_id: this robot's id.
        position_m: (2,) its position [m].
        others: the sensed others (robots only count).
        now_s: sim time [s].
        state: the hold's memory, kept by the caller per passage.
    """
    if not passage.one_lane or len(others) == 0:
        state.still_since_s.clear()
        return False
    speed = np.hypot(others.velocity_mps[:, 0], others.velocity_mps[:, 1])
    still_ids = others.ids[others.is_robot & (speed < SLOW_MPS)].tolist()
    since = {rid: state.still_since_s.get(rid, now_s) for rid in still_ids}
    state.still_since_s = since
    line = passage.line_m[passage.mouth_index:]
    if line.shape[0] == 1:
        line = np.concatenate((line, line))
    total = float(np.hypot(*np.diff(line, axis=0).T).sum())
    mine = float(math.hypot(*(position_m - passage.mouth_m)))
    half = passage.width_m / 2.0
    blocking = []
    for k in np.flatnonzero(others.is_robot):
        p, v = others.position_m[k], others.velocity_mps[k]
        s, off = distance_along(line, p)
        tangent = _tangent_at(line, s)
        along = float(v @ tangent)
        inside = off <= half + others.radius_m[k] and _END_M < s < total - _END_M
        if inside:
            if along < SLOW_MPS:  # in it and not going my way
                blocking.append(k)
            continue
        # outside, at the mouth on its side: waiting or coming, and ahead of this robot in
        # the order (distance to its mouth, then id)
        out = p - (passage.far_mouth_m if s >= total - _END_M else passage.mouth_m)
        theirs = float(math.hypot(*out))
        if theirs > LOOK_M or float(v @ out) >= SLOW_MPS * theirs:
            continue  # far from the mouth, or moving away from it
        if _ahead_of(theirs, int(others.ids[k]), mine, robot_id):
            blocking.append(k)
    # a moving robot holds the way; a still one only until it has stood HOLD_STILL_S
    return any(now_s - since.get(int(others.ids[k]), now_s) < HOLD_STILL_S
               for k in blocking)


def _ahead_of(theirs_m: float, their_id: int, mine_m: float, my_id: int) -> bool:
    """Whether a robot `theirs_m` from its mouth goes before one `mine_m` from its own:
    a robot within `HOLD_M` of its mouth (past its hold line: it has decided) before one
    that is not; then the nearer (by more than `TIE_M`); then the lower id."""
    theirs_in, mine_in = theirs_m <= HOLD_M, mine_m <= HOLD_M
    if theirs_in != mine_in:
        return theirs_in
    if abs(theirs_m - mine_m) > TIE_M:
        return theirs_m < mine_m
    return their_id < my_id


def _tangent_at(line_m: np.ndarray, s_m: float) -> np.ndarray:
    """Unit direction of `line_m` at arc length `s_m`."""
    seg = np.diff(line_m, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    k = int(min(np.searchsorted(np.cumsum(length), s_m), seg.shape[0] - 1))
    n = float(length[k])
    if n <= 1e-9:
        return np.array([1.0, 0.0])
    tangent: np.ndarray = seg[k] / n
    return tangent
