"""Routes and liveness in the planning cycle (`agent.planning.guidance` and its use in
`agent.planning.planners`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from agent.core.config import PlannerConfig, RobotLimits
from agent.core.types import EgoState, Observation, Others, PlanStatus
from agent.planning.guidance import RouteGuide
from agent.planning.liveness import LivenessConfig, Strategy
from agent.planning.mechanisms import EIFP_MPC_MECHANISMS
from agent.planning.planners import Planner, make_planner
from agent.planning.routing import StaticMap, segment_disc_distance
from world.sim.dynamics import integrate_unicycle


def closed_wall(reach_m: float = 6.0) -> StaticMap:
    """Touching 0.6 m discs along x = 0 from -reach to reach: no doorway."""
    ys = np.arange(-reach_m, reach_m + 1e-9, 1.2)
    return StaticMap(np.column_stack((np.zeros(ys.size), ys)), np.full(ys.size, 0.6),
                     -(np.arange(ys.size) + 1))


def cup() -> StaticMap:
    """A closed wall at x = 0 (y in [-6, 6]) with arms back to x = -6 at y = +-6: a cup
    open to the left, the classic local minimum for a goal on the right."""
    wall = closed_wall()
    xs = np.arange(-6.0, -0.1, 1.2)
    arms = np.concatenate((np.column_stack((xs, np.full(xs.size, 6.0))),
                           np.column_stack((xs, np.full(xs.size, -6.0)))))
    n = len(wall) + arms.shape[0]
    return StaticMap(np.concatenate((wall.center_m, arms)),
                     np.concatenate((wall.radius_m, np.full(arms.shape[0], 0.6))),
                     -(np.arange(n) + 1))


def as_others(static: StaticMap) -> Others:
    n = len(static)
    return Others(ids=static.ids, position_m=static.center_m,
                  velocity_mps=np.zeros((n, 2)), radius_m=static.radius_m,
                  linearity=np.zeros(n), track_start_m=static.center_m,
                  is_robot=np.zeros(n, dtype=bool))


def observation(x: float, y: float, heading: float, v: float, goal: tuple[float, float],
                others: Others, robot_id: int = 0) -> Observation:
    return Observation(robot_id=robot_id,
                       ego=EgoState(x_m=x, y_m=y, heading_rad=heading, v_mps=v,
                                    omega_radps=0.0),
                       goal_m=np.array(goal), radius_m=0.5, limits=RobotLimits(),
                       goal_tolerance_m=0.25, others=others)


def test_the_guide_heads_for_a_visible_route_waypoint_and_hands_on_the_rest() -> None:
    static = closed_wall()
    guide = RouteGuide(static, 0.3)
    g = guide.guide(observation(-4.0, 0.0, 0.0, 0.0, (4.0, 0.0), as_others(static)), 0.0)
    assert guide.route is not None and guide.route.waypoints_m.shape[0] > 2
    assert g.strategy is Strategy.GO
    assert g.tail_m.shape[0] >= 1 and np.allclose(g.tail_m[-1], (4.0, 0.0))
    # the intermediate goal is in sight: the leg to it clears every disc by the route's
    # clearance
    d = segment_disc_distance(np.array([[-4.0, 0.0]]), g.goal_m[None], static.center_m)
    assert (d - static.radius_m).min() >= 0.9 - 1e-6
    assert g.left_m > 8.0  # round the wall, not through it


def test_without_a_map_the_goal_is_the_goal() -> None:
    guide = RouteGuide(StaticMap.empty(), 0.3, liveness=LivenessConfig())
    g = guide.guide(observation(0.0, 0.0, 0.0, 0.0, (5.0, 0.0), Others.empty()), 0.0)
    assert np.allclose(g.goal_m, (5.0, 0.0)) and g.tail_m.shape == (0, 2)
    assert math.isclose(g.left_m, 5.0)


def closed_loop(planner: Planner, others: Others, start: tuple[float, float, float],
                goal: tuple[float, float], seconds: float, robot_id: int = 0
                ) -> tuple[np.ndarray, float]:
    """Plan and step one robot among still `others` (10 Hz plans, 50 Hz unicycle); the
    path and the smallest gap between its disc (0.5 m) and theirs."""
    x, y, th = start
    v = w = 0.0
    path = [(x, y)]
    for k in range(int(seconds * 10)):
        res = planner.plan(observation(x, y, th, v, goal, others, robot_id), k * 0.1)
        if res.status == PlanStatus.ARRIVED:
            break
        v, w = res.v_mps, res.omega_radps
        for _ in range(5):
            x, y, th = integrate_unicycle(np.array([[x, y, th]]), np.array([v]),
                                          np.array([w]), 0.02)[0].tolist()
            path.append((x, y))
    pts = np.array(path)
    gap = np.hypot(*(pts[:, None, :] - others.position_m[None]).transpose(2, 0, 1))
    return pts, float((gap - others.radius_m - 0.5).min())


def drive(planner_name: str, static: StaticMap, start: tuple[float, float, float],
          goal: tuple[float, float], seconds: float = 40.0) -> tuple[np.ndarray, float]:
    """One robot alone with the static map; the path and the smallest gap to a disc."""
    planner = make_planner(planner_name, PlannerConfig(), static_map=static)
    return closed_loop(planner, as_others(static), start, goal, seconds)


def test_eifp_mpc_leaves_a_cup_that_traps_eifp_without_a_route() -> None:
    static = cup()
    goal = (4.0, 0.0)
    path, gap = drive("eifp-mpc", static, (-3.0, 0.0, 0.0), goal, seconds=60.0)
    assert math.dist(path[-1], goal) < 0.25  # arrived
    assert gap > 0.0  # never touched the cup
    # eIFP (no routes; otherwise the same via-points) stays in the cup's local minimum
    path, _ = drive("eifp", static, (-3.0, 0.0, 0.0), goal, seconds=60.0)
    assert (path[:, 0] < 0.0).all() and (np.abs(path[:, 1]) < 6.0).all()


def test_a_robot_held_in_place_yields_to_a_moving_lower_id_and_never_to_a_higher() -> None:
    """The planner's side of rule 3: a robot that makes no progress for `stuck_after_s`
    a second time (rules 1 and 2 did not help) stands (status YIELD, v = 0) while a lower
    id moves near it; with a higher id there it keeps planning."""
    def run(other_id: int, cycles: int) -> list[PlanStatus]:
        planner = make_planner("eifp-mpc", PlannerConfig())
        statuses = []
        for k in range(cycles):
            t = 0.1 * k
            # an other crossing 3 m ahead of the robot, which is held still (no progress)
            other = Others(ids=np.array([other_id]),
                           position_m=np.array([[3.0, -2.0 + 0.035 * k]]),
                           velocity_mps=np.array([[0.0, 0.35]]), radius_m=np.array([0.5]),
                           linearity=np.ones(1), track_start_m=np.array([[3.0, -2.5]]),
                           is_robot=np.array([True]))
            res = planner.plan(observation(0.0, 0.0, 0.0, 0.0, (10.0, 0.0), other, robot_id=5), t)
            statuses.append(res.status)
            if res.status == PlanStatus.YIELD:
                assert res.v_mps == 0.0 and res.omega_radps == 0.0
        return statuses

    lower = run(2, 100)
    # stuck at 4 s: no slow robot to route round, so rule 2 (squeeze) at once
    assert PlanStatus.YIELD not in lower[:80]
    assert PlanStatus.YIELD in lower[80:]  # stuck again at 8 s: rule 3
    assert PlanStatus.YIELD not in run(9, 100)


def test_a_route_round_a_knot_is_followed_against_the_map_not_the_knot() -> None:
    """Rule 1 routes round the slow robots in the way; once they have moved on, the robot
    heads for the goal again instead of for a waypoint round where they stood."""
    guide = RouteGuide(StaticMap.empty(), 0.3, liveness=LivenessConfig())
    knot = Others(ids=np.array([7, 8]), position_m=np.array([[2.0, 0.0], [2.0, 1.0]]),
                  velocity_mps=np.zeros((2, 2)), radius_m=np.full(2, 0.5),
                  linearity=np.zeros(2), track_start_m=np.array([[2.0, 0.0], [2.0, 1.0]]),
                  is_robot=np.ones(2, dtype=bool))
    here = (0.0, 0.0, 0.0, 0.0, (6.0, 0.0))
    for k in range(41):  # held in place for 4 s: stuck, and rule 1 re-routes round the knot
        g = guide.guide(observation(*here, knot), 0.1 * k)
    assert guide.liveness is not None and guide.liveness.reroutes == 1
    assert not np.allclose(g.goal_m, (6.0, 0.0))  # round the knot
    # the knot has left: the goal is in sight on the (empty) map
    g = guide.guide(observation(*here, Others.empty()), 4.2)
    assert np.allclose(g.goal_m, (6.0, 0.0)) and g.tail_m.shape == (0, 2)


def parked_cell(spacing_m: float) -> Others:
    """Robots parked on the corners of a square lattice cell round the origin, and the
    next column to the right: the cell is closed to inflated discs when spacing <= 2L."""
    h = 0.5 * spacing_m
    xy = np.array([(-h, -h), (-h, h), (h, -h), (h, h), (3 * h, -h), (3 * h, h)])
    n = xy.shape[0]
    # seen standing over the last interval too, as the estimator reports parked robots
    return Others(ids=np.arange(1, n + 1), position_m=xy, velocity_mps=np.zeros((n, 2)),
                  radius_m=np.full(n, 0.5), linearity=np.zeros(n), track_start_m=xy,
                  is_robot=np.ones(n, dtype=bool), heading_rad=np.zeros(n),
                  recent_speed_mps=np.zeros(n), recent_interval_s=np.full(n, 0.1),
                  recent_turn_rate_radps=np.zeros(n))


def drive_among(liveness: LivenessConfig, others: Others, goal: tuple[float, float],
                seconds: float) -> tuple[np.ndarray, float]:
    """One eIFP-MPC robot from the origin among still `others`, with these liveness
    thresholds; its path and the smallest gap between its disc and theirs."""
    mech = dataclasses.replace(EIFP_MPC_MECHANISMS, liveness=liveness)
    planner = make_planner("eifp-mpc", PlannerConfig(), mechanisms=mech)
    return closed_loop(planner, others, (0.0, 0.0, 0.0), goal, seconds, robot_id=9)


def test_a_robot_in_a_cell_of_parked_robots_2L_apart_squeezes_out_to_its_goal() -> None:
    """Rule 2: parked robots 2.6 m apart (2L with d_safety 0.3) close every side of the
    cell to inflated discs, though a robot's body passes with 0.3 m either side (the last
    robots of a 5x5 mirror grid stood in such cells). The squeeze gets it out to a goal
    beyond the next column, keeping the tracker's margin; without it (a squeeze margin
    equal to d_safety changes nothing) the robot never leaves the cell."""
    others, goal = parked_cell(2.6), (5.0, 0.0)
    path, gap = drive_among(LivenessConfig(), others, goal, 40.0)
    assert math.dist(path[-1], goal) < 0.25
    assert gap >= 0.05
    path, _ = drive_among(LivenessConfig(squeeze_margin_m=0.3), others, goal, 40.0)
    assert (np.abs(path) < 1.3).all()  # never out of the cell


def test_a_controller_builds_its_route_graphs_before_its_first_cycle() -> None:
    from agent.core.scenario import RobotSpec
    from agent.planning import routing
    from agent.planning.controller import RobotController

    # a map of its own (the graph memo is per map): the cup, moved
    static = StaticMap(cup().center_m + np.array([123.0, 45.0]), cup().radius_m)
    spec = RobotSpec(id=0, start=(120.0, 45.0, 0.0), goal=(130.0, 45.0), planner="eifp-mpc")
    before = routing._shared_graph.cache_info()
    controller = RobotController(spec, PlannerConfig(), 0.25, static_map=static)
    built = routing._shared_graph.cache_info()
    assert built.misses == before.misses + 2  # the full and the tight clearance
    guide = getattr(controller.planner, "guide", None)
    assert guide is not None
    route = routing.route_or_tight(np.array([120.0, 45.0]), np.array([130.0, 45.0]), static,
                                   spec.radius_m, PlannerConfig().safety.d_safety_m)
    assert route is not None and route.waypoints_m.shape[0] > 2  # round the cup
    assert routing._shared_graph.cache_info().misses == built.misses  # nothing new to build
