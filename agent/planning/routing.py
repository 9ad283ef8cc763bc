"""Global routes over the static map: a visibility graph round the inflated static discs.

Not in the paper (arXiv 2508.08264, "Forecast-Driven MPC for Decentralized Multi-Robot
Collision Avoidance"): eIFP is a local planner, and against a wall of discs its goal
pulls a robot into the wall's local minimum. The scenario's static obstacles are a map
every robot knows before it starts (moving obstacles and the other robots are still only
sensed). Each robot routes over it once at the start (and again when a passage stays
blocked, `agent.planning.liveness`), and eIFP plans towards the farthest route waypoint it
can see (`RouteFollower.intermediate_goal`), so its legs never lead into the map.

The graph (`plan_route`):

- Nodes: the start, the goal, and `RING_NODES` points on a circle round every static
  disc, of radius (r_j + clearance) / cos(pi / RING_NODES), so that the chord between two
  neighbouring ring points still clears the inflated disc. Ring points inside another
  inflated disc are dropped (a wall of overlapping discs keeps only its ends and its
  doorways). A doorway barely wider than the clearance loses the ring points facing
  across it that way, so it gets nodes of its own: its middle and a lead-in on either side
  (`_doorway_points`).
- Edges: every pair of nodes whose segment clears every inflated disc
  (`segment_clears`), weighted by its length. A start or goal already inside an inflated
  disc (a robot parked next to a pillar) clears that disc by its own distance to it
  instead, so it is never cut off by the margin alone.
- Search: Dijkstra (`scipy.sparse.csgraph.dijkstra`) from the start; the route is the
  shortest path to the goal, or None when the goal is not connected.

The clearance is the inflated radius of Eq. (8) (robot radius + obstacle radius +
d_safety) plus `ROUTE_MARGIN_M`. `route_or_tight` falls back to the robot's radius alone
(plus `TIGHT_MARGIN_M`) when a passage admits the robot but not its safety margin and the
way round is much longer (`TIGHT_DETOUR_RATIO`): the robot is then routed through it and
eIFP's via-points and the MPC keep what clearance the passage has. A goal that no route
reaches even then is unreachable (`unreachable_reason`; scenario validation refuses it).

Cost: the graph has n = 2 + RING_NODES x M nodes for M static discs and n^2/2 candidate
segments. Checking each against all M discs is O(n^2 M) (a walled hall of 426 discs:
8.2 s before this was staged), so `clear_pairs` checks in stages, each exact for the
discs it looks at: first against the `NEAR_DISCS` discs nearest each end (most segments
between ring nodes run into a disc next to one of their ends), then against those nearest
the segment's middle, and only the few segments still clear against every disc that can
reach them (a k-d tree query round the middle, radius half the length plus the largest
clearance). The result is the same edge set as the full check
(tests/unit/agent/planning/test_routing.py compares them); the same hall takes 1.2 s
(`orchestrator bench --routes 14`). A re-route round a knot of robots
(`VisibilityGraph.with_discs`) re-checks the map's edges against the new discs only.
Maps of more than `MAX_ROUTED_OBSTACLES` discs are not routed (`StaticMap.routable`):
robots then plan locally, as without a map, and validation does not check reachability.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from agent.core.scenario import ObstacleSpec

RING_NODES = 8
"""Graph nodes placed round every static disc."""

ROUTE_MARGIN_M = 0.1
"""Routes keep this much more than the inflated radius from a static disc [m]: a route
corner exactly on the inflated disc would put eIFP's via-point on its boundary."""

TIGHT_MARGIN_M = 0.02
"""A tight route (`route_or_tight`) keeps the robot's radius plus this from a disc [m]."""

TIGHT_DETOUR_RATIO = 1.5
"""A tight passage is taken when the way round with full clearance is more than this
many times longer (`route_or_tight`)."""

MAX_ROUTED_OBSTACLES = 512
"""Maps with more static discs than this are not routed (the graph's build grows with the
number of ring nodes squared: 512 discs of walls take a few seconds, once per process)."""

NEAR_DISCS = 8
"""Discs nearest each end (and the middle) of a candidate segment checked first
(`clear_pairs`)."""

WAYPOINT_REACHED_M = 0.3
"""A route waypoint (not the goal) closer to the robot than this is reached
(`RouteFollower.intermediate_goal`): the next waypoint after it is looked at with this
much less clearance, the most a line from anywhere that close can lose against the
route's own leg to it. Without it a robot pushed a little off a corner of its route heads
back to the corner, which may lie behind it; a unicycle standing there may not find its
way to a point 0.2 m behind it at all (the MPC, linearised about standing, sees no gain
in turning). eIFP's legs still keep every inflated disc, so the route's guidance is all
that is relaxed."""

WAYPOINT_PASSED_M = 1.0
"""A route waypoint (not the goal) closer than this is also reached once the robot is past
it along the route's next leg (on the far side of the line through it square to that leg),
as a path follower switches waypoints: a robot pushed 0.37 m past a corner of its route,
round a pillar, otherwise turned back for it and stood (`pillar_circle` 40, evaluation seed
0, found while the evaluation ran). The next waypoint after it is then looked at with as
much less clearance as the robot is away from it, the most a line from there can lose
against the route's leg. About a robot's diameter."""

LOOKAHEAD_TOLERANCE_M = 1.0e-6
"""A sight line clears a disc when it keeps the clearance less this (rounding) [m]."""

_EDGE_CHUNK = 4096
"""Node pairs checked per vectorised block (bounds the temporary arrays)."""


@dataclass(frozen=True)
class StaticMap:
    """The static discs every robot knows in advance.

    Args:
        center_m: (M, 2) disc centres [m].
        radius_m: (M,) disc radii [m].
        ids: (M,) the obstacle ids the discs have in the poses (so the planner knows which
            sensed discs are on its map); None: not sensed as such (discs added for a
            re-route, test maps).
    """

    center_m: np.ndarray
    radius_m: np.ndarray
    ids: np.ndarray | None = None

    def __post_init__(self) -> None:
        c = np.asarray(self.center_m, dtype=float).reshape(-1, 2)
        r = np.asarray(self.radius_m, dtype=float).reshape(-1)
        if c.shape[0] != r.shape[0]:
            raise ValueError(f"StaticMap: {c.shape[0]} centres but {r.shape[0]} radii")
        if self.ids is not None:
            ids = np.asarray(self.ids, dtype=np.int64).reshape(-1)
            if ids.shape[0] != r.shape[0]:
                raise ValueError(f"StaticMap: {ids.shape[0]} ids but {r.shape[0]} radii")
            ids.flags.writeable = False
            object.__setattr__(self, "ids", ids)
        if not (np.isfinite(c).all() and np.isfinite(r).all() and (r > 0.0).all()):
            raise ValueError("StaticMap: centres must be finite and radii positive")
        c.flags.writeable = False
        r.flags.writeable = False
        object.__setattr__(self, "center_m", c)
        object.__setattr__(self, "radius_m", r)

    @staticmethod
    def empty() -> StaticMap:
        """No static discs."""
        return StaticMap(np.zeros((0, 2)), np.zeros(0))

    @staticmethod
    def of_obstacles(obstacles: Iterable[ObstacleSpec]) -> StaticMap:
        """The static obstacles of a scenario (velocity 0), with their ids."""
        kept = [o for o in obstacles if o.velocity[0] == 0.0 and o.velocity[1] == 0.0]
        return StaticMap.from_rows([(o.id, *o.center, o.radius_m) for o in kept])

    @staticmethod
    def from_rows(rows: Iterable[tuple[int, float, float, float]]) -> StaticMap:
        """A map from (id, x [m], y [m], radius [m]) rows (`RunConfigMsg.static_map`)."""
        table = list(rows)
        if not table:
            return StaticMap(np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=np.int64))
        return StaticMap(np.array([r[1:3] for r in table], dtype=float),
                         np.array([r[3] for r in table], dtype=float),
                         np.array([r[0] for r in table], dtype=np.int64))

    def rows(self) -> tuple[tuple[int, float, float, float], ...]:
        """(id, x, y, radius) per disc, for the wire (ids must be known)."""
        if self.ids is None:
            raise ValueError("StaticMap.rows: the map has no ids")
        return tuple((int(i), float(c[0]), float(c[1]), float(r))
                     for i, c, r in zip(self.ids, self.center_m, self.radius_m))

    def __len__(self) -> int:
        return int(self.radius_m.shape[0])

    @property
    def routable(self) -> bool:
        """Whether routes are planned on this map (1..`MAX_ROUTED_OBSTACLES` discs)."""
        return 0 < len(self) <= MAX_ROUTED_OBSTACLES

    def with_discs(self, center_m: np.ndarray, radius_m: np.ndarray) -> StaticMap:
        """This map plus more discs (a re-route round robots that block a passage)."""
        return StaticMap(np.concatenate((self.center_m, np.reshape(center_m, (-1, 2)))),
                         np.concatenate((self.radius_m, np.reshape(radius_m, -1))))


@dataclass(frozen=True)
class Route:
    """A route from a start to a goal round the static map.

    Args:
        waypoints_m: (K, 2) start first, goal last (K >= 2) [m].
        clearance_m: how far from each disc's edge the route stays [m].
        tight: True when only the robot's radius fits (`route_or_tight`).
    """

    waypoints_m: np.ndarray
    clearance_m: float
    tight: bool = False

    @property
    def length_m(self) -> float:
        """Length of the polyline [m]."""
        return float(np.hypot(*np.diff(self.waypoints_m, axis=0).T).sum())


def segment_disc_distance(a_m: np.ndarray, b_m: np.ndarray, center_m: np.ndarray
                          ) -> np.ndarray:
    """Distance from each of E segments to each of M points.

    Args:
        a_m, b_m: (E, 2) segment ends [m] (a segment of zero length is a point).
        center_m: (M, 2) points [m].

    Returns:
        (E, M) distances [m].
    """
    ax, ay = a_m[:, 0:1], a_m[:, 1:2]
    sx, sy = b_m[:, 0:1] - ax, b_m[:, 1:2] - ay
    seg_sq = sx * sx + sy * sy
    rx, ry = center_m[None, :, 0] - ax, center_m[None, :, 1] - ay
    t = np.clip(np.divide(rx * sx + ry * sy, seg_sq, out=np.zeros_like(rx),
                          where=seg_sq > 0.0), 0.0, 1.0)
    dist: np.ndarray = np.hypot(rx - t * sx, ry - t * sy)
    return dist


def segment_clears(a_m: np.ndarray, b_m: np.ndarray, center_m: np.ndarray,
                   keep_m: np.ndarray) -> np.ndarray:
    """Whether each segment keeps at least keep_m[e, m] from every centre m.

    Args:
        a_m, b_m: (E, 2) segment ends [m].
        center_m: (M, 2) disc centres [m].
        keep_m: (E, M) or (M,) required distances [m].

    Returns:
        (E,) bool.
    """
    if center_m.shape[0] == 0:
        return np.ones(a_m.shape[0], dtype=bool)
    d = segment_disc_distance(a_m, b_m, center_m)
    clears: np.ndarray = np.all(d >= keep_m - LOOKAHEAD_TOLERANCE_M, axis=1)
    return clears


def _endpoint_keep(point_m: np.ndarray, center_m: np.ndarray, keep_m: np.ndarray) -> np.ndarray:
    """The distance a segment from `point_m` must keep from each disc: the clearance, or
    less when the point itself is closer (a start inside a margin is not cut off)."""
    here = np.hypot(*(center_m - point_m).T)
    keep: np.ndarray = np.minimum(keep_m, np.maximum(here - LOOKAHEAD_TOLERANCE_M, 0.0))
    return keep


def _ring_nodes(static: StaticMap, keep_m: np.ndarray, of: slice = slice(None),
                doorways: bool = True) -> np.ndarray:
    """(n, 2) the graph's nodes of the discs `of` (every disc by default), outside every
    inflated disc of the map: per disc, its ring points, then (with `doorways`) its
    doorway points (`_doorway_points`) with the discs before it. Disc by disc, so that
    the nodes of discs added to a map (`VisibilityGraph.with_discs`) come last, as
    `build` on the grown map orders them."""
    index = np.arange(len(static))[of]
    if index.size == 0:
        return np.zeros((0, 2))
    centers = static.center_m[index]
    angle = 2.0 * math.pi * np.arange(RING_NODES) / RING_NODES
    ring = keep_m[index] / math.cos(math.pi / RING_NODES)
    pts = (centers[:, None, :]
           + ring[:, None, None] * np.stack((np.cos(angle), np.sin(angle)), axis=1)[None])
    owner = np.repeat(index, RING_NODES)
    door, door_owner = (_doorway_points(static, keep_m, index) if doorways
                        else (np.zeros((0, 2)), np.zeros(0, dtype=np.intp)))
    pts = np.concatenate((pts.reshape(-1, 2), door))
    owner = np.concatenate((owner, door_owner))
    pts = pts[np.argsort(owner, kind="stable")]
    d = np.hypot(*(pts[:, None, :] - static.center_m[None, :, :]).transpose(2, 0, 1))
    outside: np.ndarray = pts[(d >= keep_m[None, :] - LOOKAHEAD_TOLERANCE_M).all(axis=1)]
    return outside


def _doorway_points(static: StaticMap, keep_m: np.ndarray, index: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Three points per doorway between a disc of `index` and a disc before it: its
    middle, and a lead-in on either side, square to the line between the two centres and
    as far out as the larger inflated radius (a line into the middle must come almost
    straight across); and the later disc of each pair (their owner).

    A doorway is a gap between two inflated discs (free width w >= 0, so it admits the
    clearance) narrower than the two ring points facing across it stand out from their
    own inflated discs together (ring - keep of each): those ring points then fall inside
    the other disc's inflated disc and are dropped, and the gap had no node. A route
    through it could only be one straight edge threading it from far off (`rooms`,
    tuning seed 104: a lone robot's route ran back to a room's far corner to line up with
    a door 0.1 m wider than its clearance; pushed off that line it planned the same
    detour again, and circled in the room until the time limit)."""
    if index.size == 0 or len(static) < 2:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.intp)
    centers = static.center_m
    stand_out = keep_m * (1.0 / math.cos(math.pi / RING_NODES) - 1.0)
    rel = centers[None, :, :] - centers[index][:, None, :]  # (k, M, 2): later -> earlier
    dist = np.hypot(rel[..., 0], rel[..., 1])
    width = dist - keep_m[index][:, None] - keep_m[None, :]
    before = np.arange(len(static))[None, :] < index[:, None]
    door = before & (width >= 0.0) & (width < stand_out[index][:, None] + stand_out[None, :])
    a, b = np.nonzero(door)
    if a.size == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.intp)
    unit = rel[a, b] / dist[a, b][:, None]
    mid = centers[index[a]] + unit * (keep_m[index[a]] + 0.5 * width[a, b])[:, None]
    lead = np.maximum(keep_m[index[a]], keep_m[b])[:, None] * np.column_stack(
        (-unit[:, 1], unit[:, 0]))
    points = np.stack((mid - lead, mid, mid + lead), axis=1).reshape(-1, 2)
    return points, np.repeat(index[a], 3)


def _hits(a_m: np.ndarray, b_m: np.ndarray, center_m: np.ndarray, keep_m: np.ndarray
          ) -> np.ndarray:
    """(S, K) whether segment s comes closer than keep_m[s, k] to centre center_m[s, k]:
    `segment_disc_distance`'s arithmetic on a candidate disc per segment and column, so
    that a disc found here is one the full check finds too."""
    ax, ay = a_m[:, 0:1], a_m[:, 1:2]
    sx, sy = b_m[:, 0:1] - ax, b_m[:, 1:2] - ay
    seg_sq = sx * sx + sy * sy
    rx, ry = center_m[..., 0] - ax, center_m[..., 1] - ay
    t = np.clip(np.divide(rx * sx + ry * sy, seg_sq, out=np.zeros_like(rx),
                          where=seg_sq > 0.0), 0.0, 1.0)
    hit: np.ndarray = np.hypot(rx - t * sx, ry - t * sy) < keep_m - LOOKAHEAD_TOLERANCE_M
    return hit


def clear_pairs(nodes_m: np.ndarray, i: np.ndarray, j: np.ndarray, static: StaticMap,
                keep_m: np.ndarray) -> np.ndarray:
    """Whether each segment nodes_m[i[s]] -> nodes_m[j[s]] keeps keep_m[m] from every disc
    m of the map: the same answer as `segment_clears`, found in stages (module docstring,
    "Cost").

    Args:
        nodes_m: (n, 2) points [m].
        i, j: (S,) indices into nodes_m, the ends of each segment.
        static: the map (M discs).
        keep_m: (M,) required distance from each centre [m].

    Returns:
        (S,) bool.
    """
    n_seg, n_disc = i.shape[0], len(static)
    if n_disc == 0 or n_seg == 0:
        return np.ones(n_seg, dtype=bool)
    centers = static.center_m
    tree = cKDTree(centers)
    k = min(NEAR_DISCS, n_disc)

    def nearest(points: np.ndarray) -> np.ndarray:
        idx = np.asarray(tree.query(points, k=k)[1], dtype=np.intp)
        return idx.reshape(points.shape[0], k)

    near = nearest(nodes_m)
    own = near[:, :1]  # stage 0: the disc nearest each end alone (a ring node's own disc)
    blocked = np.zeros(n_seg, dtype=bool)
    for lo in range(0, n_seg, 4 * _EDGE_CHUNK):
        ii, jj = i[lo:lo + 4 * _EDGE_CHUNK], j[lo:lo + 4 * _EDGE_CHUNK]
        cand = np.concatenate((own[ii], own[jj]), axis=1)
        blocked[lo:lo + 4 * _EDGE_CHUNK] = _hits(nodes_m[ii], nodes_m[jj], centers[cand],
                                                 keep_m[cand]).any(axis=1)
    rest = np.flatnonzero(~blocked)
    for lo in range(0, rest.size, _EDGE_CHUNK):  # stage 1: the discs nearest either end
        sel = rest[lo:lo + _EDGE_CHUNK]
        ii, jj = i[sel], j[sel]
        cand = np.concatenate((near[ii], near[jj]), axis=1)
        blocked[sel] = _hits(nodes_m[ii], nodes_m[jj], centers[cand],
                             keep_m[cand]).any(axis=1)
    alive = np.flatnonzero(~blocked)
    if alive.size:  # stage 2: the discs nearest the middle
        a, b = nodes_m[i[alive]], nodes_m[j[alive]]
        cand = nearest(0.5 * (a + b))
        alive = alive[~_hits(a, b, centers[cand], keep_m[cand]).any(axis=1)]
    clear = np.zeros(n_seg, dtype=bool)
    if alive.size:  # stage 3: every disc that can reach the segment
        a, b = nodes_m[i[alive]], nodes_m[j[alive]]
        reach = 0.5 * np.hypot(*(b - a).T) + float(keep_m.max())
        lists = tree.query_ball_point(0.5 * (a + b), reach)
        counts = np.fromiter(map(len, lists), dtype=np.intp, count=len(lists))
        disc = np.fromiter(itertools.chain.from_iterable(lists), dtype=np.intp,
                           count=int(counts.sum()))
        seg = np.repeat(np.arange(alive.size), counts)
        hit = _hits(a[seg], b[seg], centers[disc][:, None, :], keep_m[disc][:, None])[:, 0]
        blocked = np.zeros(alive.size, dtype=bool)
        np.logical_or.at(blocked, seg, hit)
        clear[alive[~blocked]] = True
    return clear


@dataclass(frozen=True)
class VisibilityGraph:
    """The part of the route graph that depends on the map and the clearance only: the
    ring nodes and the ring-to-ring edges (`plan_route` adds a start and a goal).

    Args:
        static: the map.
        clearance_m: distance kept from each disc's edge [m].
        nodes_m: (n, 2) ring nodes [m].
        edges: (E, 2) node index pairs (i < j, in `np.triu_indices` order) whose segment
            clears every inflated disc.
        doorways: whether the nodes include doorway nodes (`_doorway_points`).
    """

    static: StaticMap
    clearance_m: float
    nodes_m: np.ndarray
    edges: np.ndarray
    doorways: bool = True

    @staticmethod
    def build(static: StaticMap, clearance_m: float, doorways: bool = True
              ) -> VisibilityGraph:
        """Ring nodes (and doorway nodes) and the clear segments between them
        (`clear_pairs`). The tight clearance's graph is built without doorway nodes
        (`route_or_tight`): in a hall of shelves every gap between two shelf discs is a
        doorway at that clearance: at 426 discs (`route_bench.halls(14)`, idle machine)
        they took its nodes from 1024 to 1756 and its build from 1.04 to 3.51 s; a tight
        route is centred in its passage anyway (`agent.planning.passages`)."""
        keep = static.radius_m + clearance_m
        nodes = _ring_nodes(static, keep, doorways=doorways)
        i, j = np.triu_indices(nodes.shape[0], k=1)
        ok = clear_pairs(nodes, i, j, static, keep)
        return VisibilityGraph(static, float(clearance_m), nodes,
                               np.column_stack((i[ok], j[ok])), doorways)

    def with_discs(self, center_m: np.ndarray, radius_m: np.ndarray) -> VisibilityGraph:
        """This graph on the map plus more discs, as `build` makes it on that map (the
        same nodes, edges and order), without re-checking the map's edges against the map:
        nodes inside a new disc go, edges that a new disc blocks go, and the new discs'
        ring nodes are joined to every node."""
        static = self.static.with_discs(center_m, radius_m)
        keep = static.radius_m + self.clearance_m
        new = slice(len(self.static), None)
        added_center, added_keep = static.center_m[new], keep[new]
        kept = np.flatnonzero(segment_clears(self.nodes_m, self.nodes_m, added_center,
                                             added_keep))
        nodes = np.concatenate((self.nodes_m[kept],
                                _ring_nodes(static, keep, new, self.doorways)))
        index = np.full(self.nodes_m.shape[0], -1)
        index[kept] = np.arange(kept.size)
        old = index[self.edges].reshape(-1, 2)
        old = old[(old >= 0).all(axis=1)]
        old = old[segment_clears(nodes[old[:, 0]], nodes[old[:, 1]], added_center,
                                 added_keep)]
        i, j = np.triu_indices(nodes.shape[0], k=1)
        joins = j >= kept.size  # pairs with a new node
        i, j = i[joins], j[joins]
        ok = clear_pairs(nodes, i, j, static, keep)
        edges = np.concatenate((old, np.column_stack((i[ok], j[ok]))))
        edges = edges[np.lexsort((edges[:, 1], edges[:, 0]))]
        return VisibilityGraph(static, self.clearance_m, nodes, edges, self.doorways)


def plan_route(start_m: np.ndarray, goal_m: np.ndarray, static: StaticMap,
               clearance_m: float, graph: VisibilityGraph | None = None) -> Route | None:
    """The shortest route from start to goal keeping `clearance_m` from every disc's edge.

    Args:
        start_m, goal_m: (2,) [m].
        static: the static map.
        clearance_m: distance kept from each disc's edge (robot radius + d_safety + margin
            for a normal route) [m].
        graph: the map's `VisibilityGraph` for this clearance, if already built (robots
            of one radius share it); built here otherwise.

    Returns:
        The route (start and goal included; [start, goal] when the straight line clears),
        or None when the goal is not connected to the start.
    """
    start = np.asarray(start_m, dtype=float).reshape(2)
    goal = np.asarray(goal_m, dtype=float).reshape(2)
    keep = static.radius_m + clearance_m
    centers = static.center_m
    start_keep = _endpoint_keep(start, centers, keep)
    goal_keep = _endpoint_keep(goal, centers, keep)
    if segment_clears(start[None], goal[None], centers, np.minimum(start_keep, goal_keep))[0]:
        return Route(np.stack((start, goal)), clearance_m)
    if graph is None or graph.clearance_m != clearance_m or len(graph.static) != len(static):
        graph = VisibilityGraph.build(static, clearance_m)
    ring = graph.nodes_m
    n = ring.shape[0] + 2  # node 0: start, node 1: goal, then the ring nodes
    ends = []
    for k, (point, need) in enumerate(((start, start_keep), (goal, goal_keep))):
        seen = segment_clears(np.broadcast_to(point, ring.shape), ring, centers, need)
        ends.append(np.column_stack((np.full(int(seen.sum()), k), np.flatnonzero(seen) + 2)))
    pairs = np.concatenate((*ends, graph.edges + 2))
    nodes = np.concatenate((start[None], goal[None], ring))
    i, j = pairs[:, 0], pairs[:, 1]
    w = np.hypot(*(nodes[i] - nodes[j]).T)
    matrix = csr_matrix((np.concatenate((w, w)), (np.concatenate((i, j)),
                                                  np.concatenate((j, i)))), shape=(n, n))
    # scipy-stubs type `indices` as an array or a sequence; scipy also takes one index
    dist, pred = dijkstra(matrix, directed=True, indices=0,  # type: ignore[call-overload]
                          return_predecessors=True)
    if not math.isfinite(float(dist[1])):
        return None
    path = [1]
    while path[-1] != 0:
        path.append(int(pred[path[-1]]))
    return Route(nodes[path[::-1]], clearance_m)


@functools.lru_cache(maxsize=8)
def _shared_graph(centers: bytes, radii: bytes, clearance_m: float, doorways: bool
                  ) -> VisibilityGraph:
    """The visibility graph of one map and clearance, built once per process: every robot
    of a lockstep run with the same radius shares it (a memo of a pure function)."""
    static = StaticMap(np.frombuffer(centers).reshape(-1, 2), np.frombuffer(radii))
    return VisibilityGraph.build(static, clearance_m, doorways)


def shared_graph(static: StaticMap, clearance_m: float, doorways: bool = True
                 ) -> VisibilityGraph:
    """`VisibilityGraph.build(static, clearance_m, doorways)`, memoised on the map's
    contents."""
    return _shared_graph(static.center_m.tobytes(), static.radius_m.tobytes(),
                         float(clearance_m), doorways)


def route_or_tight(start_m: np.ndarray, goal_m: np.ndarray, static: StaticMap,
                   robot_radius_m: float, d_safety_m: float) -> Route | None:
    """A route with the full clearance (robot radius + d_safety + `ROUTE_MARGIN_M`), or a
    tight one (robot radius + `TIGHT_MARGIN_M`) when there is no full one or the full one
    is more than `TIGHT_DETOUR_RATIO` times longer; None when neither exists (unreachable).
    """
    clearance = robot_radius_m + d_safety_m + ROUTE_MARGIN_M
    full = plan_route(start_m, goal_m, static, clearance, shared_graph(static, clearance))
    if full is not None and full.waypoints_m.shape[0] == 2:
        return full  # the straight line
    clearance = robot_radius_m + TIGHT_MARGIN_M
    tight = plan_route(start_m, goal_m, static, clearance,
                       shared_graph(static, clearance, doorways=False))
    if tight is None or (full is not None
                         and full.length_m <= TIGHT_DETOUR_RATIO * tight.length_m):
        return full
    return Route(tight.waypoints_m, tight.clearance_m, tight=True)


def unreachable_reason(start_m: np.ndarray, goal_m: np.ndarray, static: StaticMap,
                       robot_radius_m: float) -> str | None:
    """Why no route reaches the goal from the start, or None when one does.

    Only the robot's own radius (plus `TIGHT_MARGIN_M`) counts here (a passage narrower
    than the robot is closed; one narrower than its safety margin is not), and only static
    discs: a passage blocked by other robots is theirs to clear, never a reason to refuse
    a scenario.
    """
    if not static.routable:
        return None
    clearance = robot_radius_m + TIGHT_MARGIN_M
    if plan_route(start_m, goal_m, static, clearance,
                  shared_graph(static, clearance, doorways=False)) is not None:
        return None
    keep = static.radius_m + robot_radius_m
    goal = np.asarray(goal_m, dtype=float)
    if (np.hypot(*(static.center_m - goal).T) < keep).any():
        return "its goal lies where the robot does not fit next to a static obstacle"
    return ("no path round the static obstacles reaches its goal (enclosed, or behind "
            f"gaps narrower than the robot's {2.0 * robot_radius_m:g} m diameter)")


class RouteFollower:
    """Where along its route a robot is, and the farthest route waypoint it can see.

    The intermediate goal handed to eIFP is the farthest route waypoint (goal included)
    whose sight line from the robot keeps the route's clearance from every static disc
    (less what the robot already lacks of it, `_endpoint_keep`; past a waypoint within
    `WAYPOINT_REACHED_M`, or within `WAYPOINT_PASSED_M` and past it along the next leg,
    the next waypoint's with the distance to it less too, and so on the cycles after while
    the robot is within `WAYPOINT_PASSED_M` of the passed one); waypoints before it are
    passed and never looked at again, so the goal moves only forward along the route.
    Cost per cycle: one sight-line check of the next few waypoints against the map.

    Args:
        route: the route to follow.
        static: the map it was planned on.
    """

    def __init__(self, route: Route, static: StaticMap) -> None:
        self.route = route
        self.static = static
        self._next = 1  # index of the first waypoint not yet reached

    @property
    def next_index(self) -> int:
        """Index in the route of the first waypoint not yet passed (the one aimed at)."""
        return self._next

    def skip_to(self, index: int) -> None:
        """Aim at waypoint `index` from now on (a robot that left a narrow passage at its
        far mouth, `agent.planning.guidance`); never backwards."""
        self._next = max(self._next, min(int(index), self.route.waypoints_m.shape[0] - 1))

    @property
    def remaining_m(self) -> np.ndarray:
        """(k, 2) the route waypoints not yet passed (goal last)."""
        return self.route.waypoints_m[self._next:]

    def intermediate_goal(self, position_m: np.ndarray,
                          also: StaticMap | None = None) -> np.ndarray | None:
        """The farthest visible route waypoint from `position_m` (advances the follower),
        or None when none of the waypoints ahead is in sight (the robot was pushed off
        its route: re-route from where it is).

        Args:
            position_m: (2,) the robot [m].
            also: more discs that block the sight lines now (the slow robots a route
                round a knot goes round, as they are this cycle); None: the map only.
        """
        wps = self.route.waypoints_m
        blocking = self.static if also is None else self.static.with_discs(
            also.center_m, also.radius_m)
        aim: np.ndarray
        if self._next >= wps.shape[0] - 1 and len(blocking) == 0:
            aim = wps[-1]
            return aim
        keep = blocking.radius_m + self.route.clearance_m
        here = np.asarray(position_m, dtype=float)
        ahead = wps[self._next:]
        need = _endpoint_keep(here, blocking.center_m, keep)
        starts = np.broadcast_to(here, ahead.shape)
        seen = segment_clears(starts, ahead, blocking.center_m, need)
        away = np.hypot(*(ahead[:-1] - here).T)
        past = ((here - ahead[:-1]) * (ahead[1:] - ahead[:-1])).sum(axis=1) > 0.0
        reached = np.flatnonzero((away < WAYPOINT_REACHED_M)
                                 | (past & (away < WAYPOINT_PASSED_M)))
        behind = (float(math.hypot(*(wps[self._next - 1] - here)))
                  if not reached.size and self._next >= 2 else math.inf)
        if behind < WAYPOINT_PASSED_M:
            # The waypoint passed last, while the robot is still near it, gives the next
            # one the slack it gave the cycle it was passed: a waypoint aimed at through
            # the slack stays in sight from where it was seen. Without this the robot
            # re-routed the next cycle, from a spot a few mm away, and a route round the
            # other side of a wall could win: `random_walls` 14, seed 7, one robot turned
            # on the spot for 110 s between two routes.
            slack = max(WAYPOINT_REACHED_M, behind)
            seen[:1] |= segment_clears(starts[:1], ahead[:1], blocking.center_m,
                                       np.maximum(need - slack, 0.0))
        if reached.size:
            last = int(reached[-1])
            seen[last] = True
            # Only the next waypoint gets the slack: the line to it stays within `slack` of
            # the route's own leg (which keeps the full clearance), and no line to one
            # farther does (from 0.31 m off a corner beside a pillar the goal beyond it
            # came "in sight" through the pillar, and a robot turned back and forth
            # between that goal and the corner for 50 s: `pillar_circle` 24).
            slack = max(WAYPOINT_REACHED_M, float(away[last]))
            nxt = slice(last + 1, last + 2)
            seen[nxt] |= segment_clears(starts[nxt], ahead[nxt], blocking.center_m,
                                        np.maximum(need - slack, 0.0))
        if not seen.any():
            return None
        self._next += int(np.flatnonzero(seen)[-1])
        aim = wps[self._next]
        return aim

    def progress_left_m(self, position_m: np.ndarray) -> float:
        """Route length still to go: to the next waypoint, then along the route [m]."""
        wps = self.route.waypoints_m[self._next:]
        here = np.asarray(position_m, dtype=float)
        rest = float(np.hypot(*np.diff(wps, axis=0).T).sum()) if wps.shape[0] > 1 else 0.0
        return float(math.hypot(*(wps[0] - here))) + rest
