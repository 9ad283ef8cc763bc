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

from agent.core.types import Observation
from agent.planning.liveness import Liveness, LivenessConfig, Strategy, knot
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
    """

    goal_m: np.ndarray
    tail_m: np.ndarray
    left_m: float
    strategy: Strategy = Strategy.GO
    squeeze: bool = False
    stuck: bool = False


class RouteGuide:
    """Routes and liveness for one robot (module docstring).

    Args:
        static: the static map (may be empty).
        d_safety_m: the safety margin of Eq. (8) [m].
        routes: plan routes over the map (`Mechanisms.routing`).
        liveness: monitor progress and change strategy when stuck (`Mechanisms.liveness`),
            with these thresholds; None: never.
    """

    def __init__(self, static: StaticMap, d_safety_m: float, *, routes: bool = True,
                 liveness: LivenessConfig | None = None) -> None:
        self.static = static
        self.d_safety_m = float(d_safety_m)
        self.routes = routes and static.routable
        self.liveness = Liveness(liveness) if liveness is not None else None
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
            shared_graph(self.static, radius_m + TIGHT_MARGIN_M)

    def reset(self) -> None:
        """Forget the route and the liveness state."""
        self._follower = None
        self._goal = None
        self._round_knot = False
        if self.liveness is not None:
            self.liveness.reset()

    @property
    def route(self) -> Route | None:
        """The route being followed (None before the first cycle, or without routes)."""
        return self._follower.route if self._follower is not None else None

    def _plan(self, here: np.ndarray, goal: np.ndarray, radius_m: float) -> RouteFollower:
        route = None
        if self.routes:
            route = route_or_tight(here, goal, self.static, radius_m, self.d_safety_m)
        if route is None:  # no map, or no route from here (validation saw one from the start)
            route = Route(np.stack((here, goal)), 0.0)
            return RouteFollower(route, StaticMap.empty())
        return RouteFollower(route, self.static)

    def guide(self, observation: Observation, now_s: float) -> Guidance:
        """This cycle's goal, route tail and strategy."""
        ego = observation.ego
        here = np.array([ego.x_m, ego.y_m])
        goal = observation.goal_m
        key = (float(goal[0]), float(goal[1]))
        if self._follower is None or self._goal != key:
            self._follower = self._plan(here, goal, observation.radius_m)
            self._goal = key
            self._round_knot = False
        strategy = Strategy.GO
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
        target = self._follower.intermediate_goal(here, also)
        if target is None:  # pushed off the route: a new one from here
            self._follower = self._plan(here, goal, observation.radius_m)
            self._round_knot = False
            self.replans += 1
            target = self._follower.intermediate_goal(here)
            if target is None:  # nothing in sight even so (squeezed into the margin)
                target = self._follower.remaining_m[0]
        follower = self._follower
        rest = follower.remaining_m
        tail = rest[1:] if rest.shape[0] > 1 else _NO_TAIL
        squeeze = self.liveness is not None and self.liveness.squeezing(now_s)
        stuck = self.liveness is not None and self.liveness.stuck_now
        return Guidance(goal_m=target, tail_m=tail, left_m=follower.progress_left_m(here),
                        strategy=strategy, squeeze=squeeze, stuck=stuck)

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
        return True
