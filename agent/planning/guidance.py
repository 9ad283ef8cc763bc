"""Where eIFP should head this cycle: a route's next visible waypoint, or stand and yield.

Ties the static-map routes (`agent.planning.routing`) to the progress monitor and its
strategies (`agent.planning.liveness`) for one robot. `RouteGuide.guide` runs once per
cycle before the via-points: it returns the intermediate goal eIFP plans towards, the rest
of the route (appended to the via-points so the reference runs on past the intermediate
goal instead of braking at it), the route length left, and whether to yield.

- The route is planned on the first cycle, from where the robot is (`route_or_tight`),
  again when none of its waypoints ahead is in sight (other robots pushed the robot off
  it), and when the liveness rules ask for a re-route round a knot of slow robots.
- Without a map (no static discs, or more than `routing.MAX_ROUTED_OBSTACLES`) the route
  is the straight line to the goal: progress is still monitored, and rule 2 of
  `agent.planning.liveness` (yield by id) still applies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.core.types import Observation, Others
from agent.planning.liveness import Liveness, LivenessConfig, Strategy, knot
from agent.planning.passages import (
    HOLD_M,
    NEAR_M,
    SPOT_REACHED_M,
    HoldState,
    Passage,
    centre_route,
    distance_along,
    must_hold,
    on_track,
    waiting_spot,
)
from agent.planning.routing import (
    MAX_ROUTED_OBSTACLES,
    ROUTE_MARGIN_M,
    TIGHT_MARGIN_M,
    Route,
    RouteFollower,
    StaticMap,
    plan_route,
    route_or_tight,
    shared_graph,
)

_NO_TAIL = np.zeros((0, 2))
_NO_TAIL.flags.writeable = False


@dataclass(frozen=True)
class Guidance:
    """One cycle's guidance.

    Args:
        goal_m: (2,) the goal eIFP plans towards (the final goal, or a route waypoint) [m].
        tail_m: (k, 2) the route's waypoints after `goal_m`, final goal last; (0, 2) when
            `goal_m` is the final goal [m].
        left_m: route length still to go [m].
        strategy: GO, or YIELD (stand this cycle); REROUTE never leaves `RouteGuide`.
        squeeze: plan with the squeeze margin against still discs this cycle
            (`agent.planning.liveness`, rule 2).
        stuck: the progress monitor found the robot stuck this cycle, or it yields after
            a stuck spell (a turn on the spot may start, `agent.planning.turning`).
        passage_ids: obstacle ids of the discs bounding a narrow passage the robot is
            near (`agent.planning.passages`); planned against with `passage_margin_m`.
        passage_margin_m: the margin against those discs [m] (inf: none).
        hold: the robot gives way before a one-lane passage: it heads for its waiting
            spot (`goal_m`, strategy GO) or stands there (YIELD, even inside a wall's
            inflated disc, which a yield by id does not).
    """

    goal_m: np.ndarray
    tail_m: np.ndarray
    left_m: float
    strategy: Strategy = Strategy.GO
    squeeze: bool = False
    stuck: bool = False
    passage_ids: frozenset[int] = frozenset()
    passage_margin_m: float = math.inf
    hold: bool = False


class RouteGuide:
    """Routes and liveness for one robot (module docstring).

    Args:
        static: the static map (may be empty).
        d_safety_m: the safety margin of Eq. (8) [m].
        routes: plan routes over the map (`Mechanisms.routing`).
        liveness: monitor progress and change strategy when stuck (`Mechanisms.liveness`),
            with these thresholds; None: never.
        passages: centre routes in their narrow passages, plan against a passage's discs
            with the margin it leaves, and take one-lane passages one way at a time
            (`Mechanisms.passages`, `agent.planning.passages`).
        lanes: with `passages`, drive corridors in lanes, each robot on its right
            (`Mechanisms.lanes`).
    """

    def __init__(self, static: StaticMap, d_safety_m: float, *, routes: bool = True,
                 liveness: LivenessConfig | None = None, passages: bool = False,
                 lanes: bool = False) -> None:
        self.static = static
        self.d_safety_m = float(d_safety_m)
        self.routes = routes and static.routable
        self.liveness = Liveness(liveness) if liveness is not None else None
        self.passages_on = passages
        self.lanes_on = lanes
        self._passages: tuple[Passage, ...] = ()
        self._passage_ends: tuple[int, ...] = ()  # route index of each passage's far mouth
        self._passage_starts: tuple[int, ...] = ()  # and of its first point (lead-in)
        self._left = 0  # passages the robot has left by their far mouth
        self._passage_ids: tuple[frozenset[int], ...] = ()  # obstacle ids per passage
        self._hold = HoldState()
        self.holds = 0  # cycles spent giving way at a one-lane passage
        self._follower: RouteFollower | None = None
        self._goal: tuple[float, float] | None = None
        self._round_knot = False  # the route goes round a knot of slow robots
        self.replans = 0

    def prepare(self, radius_m: float) -> None:
        """Build the map's route graphs for a robot of `radius_m` now (both clearances of
        `route_or_tight`) instead of on the first cycle: on a map of hundreds of discs that
        takes seconds (docs/method.md, "Routes over large maps"), which a robot process
        spends at start-up rather than standing in a running world."""
        if self.routes:
            shared_graph(self.static, radius_m + self.d_safety_m + ROUTE_MARGIN_M)
            shared_graph(self.static, radius_m + TIGHT_MARGIN_M, doorways=False)

    def reset(self) -> None:
        """Forget the route and the liveness state."""
        self._follower = None
        self._goal = None
        self._round_knot = False
        self._passages, self._passage_ends, self._passage_starts = (), (), ()
        self._left = 0
        self._hold = HoldState()
        if self.liveness is not None:
            self.liveness.reset()

    @property
    def route(self) -> Route | None:
        """The route being followed (None before the first cycle, or without routes)."""
        return self._follower.route if self._follower is not None else None

    def _plan(self, here: np.ndarray, goal: np.ndarray, radius_m: float) -> RouteFollower:
        route = None
        self._passages, self._passage_ends, self._passage_starts = (), (), ()
        self._left = 0
        if self.routes:
            route = route_or_tight(here, goal, self.static, radius_m, self.d_safety_m)
        if route is None:  # no map, or no route from here (validation saw one from the start)
            route = Route(np.stack((here, goal)), 0.0)
            return RouteFollower(route, StaticMap.empty())
        if self.passages_on:
            full = radius_m + self.d_safety_m + ROUTE_MARGIN_M
            route, self._passages = centre_route(route, self.static, radius_m,
                                                 self.d_safety_m, full, lanes=self.lanes_on)
            wps = route.waypoints_m
            found = [np.flatnonzero((wps == p.far_mouth_m).all(axis=1))
                     for p in self._passages]
            if not all(f.size for f in found):  # cannot happen: each line is in the route
                self._passages = ()
            self._passage_ends = tuple(int(f[0]) for f in found) if self._passages else ()
            self._passage_starts = tuple(max(end - (p.line_m.shape[0] - 1), 0)
                                         for p, end in zip(self._passages,
                                                           self._passage_ends))
            ids = self.static.ids
            self._passage_ids = tuple(  # once per route, not per cycle
                frozenset(int(i) for i in ids[p.disc_index]) if ids is not None
                else frozenset() for p in self._passages)
        return RouteFollower(route, self.static)

    def _passage_ahead(self, here: np.ndarray) -> int | None:
        """Index of the first passage on the route the robot has not yet left by its far
        mouth (None: none left). The route follower may aim past a passage it can see
        through, so leaving is told by where the robot is, not by the follower."""
        while self._left < len(self._passages):
            line = self._passages[self._left].line_m
            s, _ = distance_along(line, here)
            if s < float(np.hypot(*np.diff(line, axis=0).T).sum()) - 1e-6 \
                    and not self._cut_out(self._left, here):
                return self._left
            if self._follower is not None:  # aim on from the far mouth
                self._follower.skip_to(self._passage_ends[self._left])
            self._left += 1
            self._hold = HoldState()
        return None

    def guide(self, observation: Observation, now_s: float,
              everyone: Others | None = None) -> Guidance:
        """This cycle's goal, route tail and strategy; `everyone`: all the sensed others
        (the one-lane rule looks past the nearest few; default `observation.others`)."""
        ego = observation.ego
        here = np.array([ego.x_m, ego.y_m])
        goal = observation.goal_m
        key = (float(goal[0]), float(goal[1]))
        if self._follower is None or self._goal != key:
            self._follower = self._plan(here, goal, observation.radius_m)
            self._goal = key
            self._round_knot = False
        strategy = Strategy.GO
        ahead = self._passage_ahead(here)
        if ahead is not None and self._holds(self._passages[ahead], observation, here, now_s,
                                             everyone):
            self.holds += 1
            left = self._follower.progress_left_m(here)
            if self.liveness is not None:  # waiting is not being stuck
                self.liveness.monitor.restart(now_s, left)
            spot = waiting_spot(self._passages[ahead], here, self.static,
                                observation.radius_m)
            away = float(math.hypot(*(spot - here)))
            if away > SPOT_REACHED_M:  # to its waiting spot, off the line
                return Guidance(goal_m=spot, tail_m=_NO_TAIL, left_m=away, hold=True)
            return Guidance(goal_m=self._follower.remaining_m[0], tail_m=_NO_TAIL,
                            left_m=left, strategy=Strategy.YIELD, hold=True)
        if self.liveness is not None:
            left = self._follower.progress_left_m(here)
            strategy = self.liveness.decide(now_s, observation.robot_id, here, left,
                                            observation.others)
            if strategy is Strategy.REROUTE:
                taken = self._reroute(here, goal, observation)
                strategy = self.liveness.rerouted(now_s, taken)
        also = None
        if self._round_knot and self.liveness is not None:
            slow = knot(here, observation.others, math.inf, self.liveness.config.slow_mps)
            also = StaticMap(observation.others.position_m[slow],
                             observation.others.radius_m[slow])
        ahead = self._passage_ahead(here)  # a re-route round a knot drops the passages
        tracked = self._track(ahead, here)
        if tracked is not None:
            return self._guidance(tracked[0], tracked[1], here, strategy, now_s)
        target = self._follower.intermediate_goal(here, also)
        if ahead is not None and target is not None:  # never past the passage's lead-in
            start = self._passage_starts[ahead]
            if self._follower.next_index > start:
                target = self._follower.route.waypoints_m[start]
                return self._guidance(target, self._follower.route.waypoints_m[start + 1:],
                                      here, strategy, now_s)
        if target is None:  # pushed off the route: a new one from here
            self._follower = self._plan(here, goal, observation.radius_m)
            self._round_knot = False
            self.replans += 1
            target = self._follower.intermediate_goal(here)
            if target is None:  # nothing in sight even so (squeezed into the margin)
                target = self._follower.remaining_m[0]
        rest = self._follower.remaining_m
        tail = rest[1:] if rest.shape[0] > 1 else _NO_TAIL
        return self._guidance(target, tail, here, strategy, now_s)

    def _guidance(self, target: np.ndarray, tail: np.ndarray, here: np.ndarray,
                  strategy: Strategy, now_s: float) -> Guidance:
        assert self._follower is not None
        squeeze = self.liveness is not None and self.liveness.squeezing(now_s)
        stuck = self.liveness is not None and self.liveness.stuck_now
        ahead = self._passage_ahead(here)
        ids, margin = self._passage_discs(ahead, here)
        if tail.shape[0] == 0:
            tail = _NO_TAIL
        return Guidance(goal_m=target, tail_m=tail,
                        left_m=self._follower.progress_left_m(here), strategy=strategy,
                        squeeze=squeeze, stuck=stuck, passage_ids=ids,
                        passage_margin_m=margin)

    def _cut_out(self, index: int, here: np.ndarray) -> bool:
        """Whether the robot has left lane `index` (`passages.Passage.lane`) before its far
        mouth, towards the route's next waypoint: it is nearer that waypoint than the far
        mouth is. A lane does not hold a robot in as a one-lane gap's walls do; one that
        cut the corner at its end stood beside the far mouth, aiming back at it, until the
        time limit (`maze_counterflow`, docs/results.md)."""
        passage = self._passages[index]
        wps = self._follower.route.waypoints_m if self._follower is not None else None
        end = self._passage_ends[index]
        if not passage.lane or wps is None or end + 1 >= wps.shape[0]:
            return False
        after = wps[end + 1]
        return bool(math.hypot(*(after - here)) < math.hypot(*(after - passage.far_mouth_m)))

    def _track(self, ahead: int | None, here: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray] | None:
        """In a passage: its line's aim point and the rest of the route after it
        (`passages.on_track`); None elsewhere. Leaving it at the far mouth moves the route
        follower on to the far mouth."""
        if ahead is None:
            return None
        passage, end = self._passages[ahead], self._passage_ends[ahead]
        assert self._follower is not None
        wps = self._follower.route.waypoints_m
        aim = on_track(passage, here)
        if aim is None:
            return None
        carrot, rest = aim
        return carrot, np.concatenate((rest, wps[end + 1:]))

    def _holds(self, passage: Passage, observation: Observation, here: np.ndarray,
               now_s: float, everyone: Others | None) -> bool:
        """Whether the robot gives way before a one-lane passage this cycle: it has not
        entered it, stands within `passages.HOLD_M` of its mouth, and `must_hold` says so."""
        if not passage.one_lane or passage.entered:
            return False
        mouth = passage.mouth_m
        ego, limits = observation.ego, observation.limits
        stopping = ego.v_mps * ego.v_mps / (2.0 * limits.accel_max_mps2)
        if math.hypot(*(here - mouth)) - stopping > HOLD_M:
            self._hold = HoldState()
            return False
        s, off = distance_along(passage.line_m[passage.mouth_index:], here)
        if s > 0.0 and off <= passage.width_m / 2.0:
            return False  # in it: go on
        others = everyone if everyone is not None else observation.others
        return must_hold(passage, observation.robot_id, here, others, now_s, self._hold)

    def _passage_discs(self, ahead: int | None, here: np.ndarray
                       ) -> tuple[frozenset[int], float]:
        """The obstacle ids bounding the passage ahead (index `ahead`) and its margin, when
        the robot is within `passages.NEAR_M` of it."""
        if ahead is None or self.static.ids is None:
            return frozenset(), math.inf
        passage = self._passages[ahead]
        _, off = distance_along(passage.line_m, here)
        if off > NEAR_M:
            return frozenset(), math.inf
        return self._passage_ids[ahead], passage.margin_m

    def _reroute(self, here: np.ndarray, goal: np.ndarray, observation: Observation) -> bool:
        """Rule 1 of `agent.planning.liveness`: a route round the slow robots near, if one
        is at most `detour_ratio` times the straight distance left. True when taken."""
        assert self.liveness is not None
        cfg = self.liveness.config
        others = observation.others
        near = knot(here, others, math.inf, cfg.slow_mps)
        if near.size == 0:
            return False
        if len(self.static) > MAX_ROUTED_OBSTACLES:
            return False  # a map too large to route (`StaticMap.routable`)
        clearance = observation.radius_m + self.d_safety_m + ROUTE_MARGIN_M
        graph = shared_graph(self.static, clearance).with_discs(others.position_m[near],
                                                                 others.radius_m[near])
        route = plan_route(here, goal, graph.static, clearance, graph)
        straight = float(math.hypot(*(goal - here)))
        if route is None or route.waypoints_m.shape[0] <= 2 or \
                route.length_m > cfg.detour_ratio * max(straight, 1e-9):
            return False
        # Followed against the map and the slow robots as they are each cycle (`guide`):
        # the knot's discs were a snapshot, and a robot of the knot that has moved on
        # must not hide the route's next waypoint.
        self._follower = RouteFollower(route, self.static)
        self._round_knot = True
        self._passages, self._passage_ends, self._passage_starts = (), (), ()
        return True
