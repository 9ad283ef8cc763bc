"""`agent.planning.goal_guard`: where a robot at its goal stands clear of a moving obstacle,
and the planner and controller around it (a parked robot keeps watching, goes, returns)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.config import PlannerConfig
from agent.core.types import EgoState, Observation, Others, PlanStatus
from agent.planning.goal_guard import REFUGE_MARGIN_M, WATCH_FROM_M, refuge_point
from agent.planning.planners import make_planner
from agent.planning.routing import StaticMap

D_SAFETY_M = 0.3
R_ROBOT_M = 0.5
R_OBST_M = 0.6
REACH_M = R_ROBOT_M + R_OBST_M + D_SAFETY_M + REFUGE_MARGIN_M


def discs(rows, *, robots=()):
    """Others from (id, x, y, vx, vy, radius) rows; ids in `robots` are robots."""
    a = np.array(rows, dtype=float).reshape(-1, 6)
    ids = a[:, 0].astype(int)
    return Others(ids=ids, position_m=a[:, 1:3], velocity_mps=a[:, 3:5], radius_m=a[:, 5],
                  linearity=np.ones(len(a)), track_start_m=a[:, 1:3],
                  is_robot=np.isin(ids, list(robots)))


def refuge(others, goal=(0.0, 0.0), static=None, horizon_s=8.0):
    return refuge_point(np.array(goal), R_ROBOT_M, others, D_SAFETY_M, horizon_s, static)


def test_an_obstacle_crossing_the_goal_within_the_horizon_sends_the_robot_beside_its_track():
    # Moving +x along y = -0.3, at the goal in 5 s: the goal lies on the track's +y side.
    point = refuge(discs([(-1, -5.0, -0.3, 1.0, 0.0, R_OBST_M)]))
    assert point is not None
    np.testing.assert_allclose(point, [0.0, -0.3 + REACH_M], atol=1e-12)


def test_on_the_track_itself_the_refuge_is_on_the_obstacles_right():
    point = refuge(discs([(-1, -5.0, 0.0, 1.0, 0.0, R_OBST_M)]))  # heading +x: right is -y
    np.testing.assert_allclose(point, [0.0, -REACH_M], atol=1e-12)


@pytest.mark.parametrize("row, why", [
    ((-1, -10.0, 0.0, 1.0, 0.0, R_OBST_M), "closest approach 10 s away, past the horizon"),
    ((-1, -5.0, 2.0, 1.0, 0.0, R_OBST_M), "passes 2 m off, beyond L + margin"),
    ((-1, 3.0, 0.0, 1.0, 0.0, R_OBST_M), "moving away, already 3 m off"),
    ((-1, -3.0, 0.0, 0.1, 0.0, R_OBST_M), "slower than MOVING_MPS: a static disc"),
    ((4, -3.0, 0.0, 1.0, 0.0, R_ROBOT_M), "a robot: it plans round a parked robot itself"),
])
def test_no_refuge_when_the_goal_is_not_threatened(row, why):
    assert refuge(discs([row], robots=(4,))) is None, why


def test_an_obstacle_still_within_reach_while_leaving_keeps_the_robot_away():
    # Past its closest approach (moving away) but only 1 m off: not back yet.
    point = refuge(discs([(-1, 1.0, -0.2, 1.0, 0.0, R_OBST_M)]))
    np.testing.assert_allclose(point, [0.0, -0.2 + REACH_M], atol=1e-12)


def test_the_most_imminent_of_two_obstacles_sets_the_refuge():
    late = (-1, 0.0, -7.0, 0.0, 1.0, R_OBST_M)  # from below, at the goal in 7 s
    soon = (-2, -3.0, 0.2, 1.0, 0.0, R_OBST_M)  # from the left, in 3 s
    # The soon one sets it (the late one would put it on its own right, at (REACH_M, 0)).
    # Its near side, below its track, is on the late one's track 5.6 s ahead, so the far
    # side is taken, which the late one reaches only after the 8 s horizon.
    np.testing.assert_allclose(refuge(discs([late, soon])), [0.0, 0.2 + REACH_M], atol=1e-12)
    # The late one alone, set aside to x = 3: the soon one's near refuge is clear.
    np.testing.assert_allclose(refuge(discs([(-1, 3.0, -7.0, 0.0, 1.0, R_OBST_M), soon])),
                               [0.0, 0.2 - REACH_M], atol=1e-12)


def test_a_refuge_inside_a_static_disc_gives_way_to_the_far_side():
    others = discs([(-1, -5.0, -0.3, 1.0, 0.0, R_OBST_M)])
    near = np.array([0.0, -0.3 + REACH_M])
    wall = StaticMap(near[None, :] + [0.0, 0.5], np.array([0.5]))
    point = refuge(others, static=wall)
    np.testing.assert_allclose(point, [0.0, -0.3 - REACH_M], atol=1e-12)
    # both sides blocked: the near one is kept (no better place to be)
    both = StaticMap(np.array([near, [0.0, -0.3 - REACH_M]]), np.array([0.5, 0.5]))
    np.testing.assert_allclose(refuge(others, static=both), near, atol=1e-12)


def test_the_refuge_does_not_move_while_the_obstacle_comes_on():
    points = [refuge(discs([(-1, -6.0 + t, -0.4, 1.0, 0.0, R_OBST_M)])) for t in (0, 2, 4, 6)]
    for p in points[1:]:
        np.testing.assert_allclose(p, points[0], atol=1e-12)


def observation(xy, others, goal=(0.0, 0.0), heading=0.0, v=0.0):
    return Observation(robot_id=0, ego=EgoState(xy[0], xy[1], heading, v, 0.0),
                       goal_m=np.array(goal), radius_m=R_ROBOT_M, others=others)


@pytest.mark.parametrize("name", ["eifp-mpc", "eifp", "ifp"])
def test_a_parked_planner_leaves_its_goal_for_the_refuge_and_stands_there(name):
    planner = make_planner(name, PlannerConfig())
    mover = discs([(-1, -6.0, 0.0, 1.0, 0.0, R_OBST_M)])
    at_goal = observation((0.0, 0.0), Others.empty())
    assert planner.plan(at_goal, 0.0).status is PlanStatus.ARRIVED
    going = planner.plan(observation((0.0, 0.0), mover), 0.1)
    assert going.status is PlanStatus.STAND_CLEAR
    np.testing.assert_allclose(going.waypoints_m[-1], [0.0, -REACH_M], atol=1e-9)
    there = planner.plan(observation((0.0, -REACH_M), mover), 0.2)
    assert there.status is PlanStatus.STAND_CLEAR and there.v_mps == 0.0
    # Once the obstacle has gone by, the goal is the goal again.
    gone = discs([(-1, 6.0, 0.0, 1.0, 0.0, R_OBST_M)])
    back = planner.plan(observation((0.0, -REACH_M), gone), 0.3)
    assert back.status is not PlanStatus.STAND_CLEAR
    np.testing.assert_allclose(back.waypoints_m[-1], [0.0, 0.0], atol=1e-9)


def test_a_robot_about_to_arrive_heads_for_the_refuge_instead_and_one_far_off_does_not():
    mover = discs([(-1, 0.0, -5.0, 0.0, 1.0, R_OBST_M)])  # crossing the goal from below
    near = WATCH_FROM_M - 0.5
    planner = make_planner("eifp-mpc", PlannerConfig())
    res = planner.plan(observation((-near, 0.0), mover), 0.0)
    assert res.status is PlanStatus.STAND_CLEAR
    assert math.hypot(*(res.waypoints_m[-1] - [0.0, 0.0])) == pytest.approx(REACH_M)
    far = make_planner("eifp-mpc", PlannerConfig())
    res = far.plan(observation((-(WATCH_FROM_M + 2.0), 0.0), mover), 0.0)
    assert res.status is not PlanStatus.STAND_CLEAR
    np.testing.assert_allclose(res.waypoints_m[-1], [0.0, 0.0], atol=1e-9)


def test_without_the_guard_a_parked_planner_stands_whatever_comes():
    planner = make_planner("eifp-mpc", PlannerConfig(without="goal_guard"))
    mover = discs([(-1, -3.0, 0.0, 1.0, 0.0, R_OBST_M)])
    planner.plan(observation((0.0, 0.0), Others.empty()), 0.0)
    assert planner.plan(observation((0.0, 0.0), mover), 0.1).status is PlanStatus.ARRIVED
    paper = make_planner("eifp-mpc", PlannerConfig(profile="paper"))
    assert paper.plan(observation((0.0, 0.0), mover), 0.1).status is PlanStatus.ARRIVED
