"""Holding the course instead of turning back towards the threat (`course_hold`)."""

import cmath
import math

import numpy as np
import pytest

from agent.core.types import PlanStatus, Side
from agent.planning.course_hold import MAX_HOLD_RAD, MIN_SPEED_MPS, held_waypoints
from agent.planning.kept_plan import KEEP_PLAN_RATIO
from tests.unit.agent.planning.test_ifp import L, _plan, _rules, observe, others

NOBODY = np.zeros(0, dtype=complex)
CLEAR = np.zeros(0)


def _held(wps, side=Side.RIGHT, heading=0.0, v=1.0, position=NOBODY, velocity=NOBODY,
          clearance=CLEAR):
    return held_waypoints(wps, side, heading, v, 1.1, position, velocity, clearance, 8.0)


def _via(angle_rad, dist_m=3.0):
    return dist_m * cmath.exp(1j * angle_rad)


@pytest.mark.parametrize("side, off_rad", [(Side.RIGHT, 0.2), (Side.LEFT, -0.2)])
def test_a_small_turn_towards_the_threat_is_replaced_by_the_heading(side, off_rad):
    # Passing on the RIGHT leaves the threat on the left: a via-point left of the heading
    # is a turn towards it. The held via-point lies on the heading, as far away.
    wps = [0j, _via(off_rad), 10 + 0j]
    held = _held(wps, side=side)
    assert held is not None
    assert held[0] == 0j and held[2] == 10 + 0j
    assert abs(held[1] - 3.0) < 1e-12  # on the heading (0 rad), 3 m out


@pytest.mark.parametrize("side, off_rad", [(Side.RIGHT, -0.2), (Side.LEFT, 0.2)])
def test_a_turn_away_from_the_threat_is_left_as_planned(side, off_rad):
    assert _held([0j, _via(off_rad), 10 + 0j], side=side) is None


def test_no_hold_beyond_the_angle_when_slow_without_a_side_or_a_via_point():
    assert _held([0j, _via(MAX_HOLD_RAD + 0.01), 10 + 0j]) is None
    assert _held([0j, _via(MAX_HOLD_RAD - 0.01), 10 + 0j]) is not None
    assert _held([0j, _via(0.2), 10 + 0j], v=MIN_SPEED_MPS - 0.01) is None
    assert _held([0j, _via(0.2), 10 + 0j], side=Side.NONE) is None
    assert _held([0j, 10 + 0j]) is None
    assert _held([0j, 0j, 10 + 0j]) is None  # a via-point on the robot: no direction


def test_the_held_plan_must_clear_every_disc_and_not_be_much_longer():
    wps = [0j, _via(0.2), 10 + 0j]
    # A disc at rest 2 m along the heading: the held leg would run through it.
    blocked = _held(wps, position=np.array([2.0 + 0j]), velocity=np.array([0j]),
                    clearance=np.array([L]))
    assert blocked is None
    # The same disc off to the side is no obstacle to the held plan.
    aside = _held(wps, position=np.array([2.0 - 2.0j]), velocity=np.array([0j]),
                  clearance=np.array([L]))
    assert aside is not None
    # A far via-point at the largest angle held, goal just past it and off the heading:
    # the held detour is more than KEEP_PLAN_RATIO longer, so it is not taken.
    near_goal = [0j, _via(MAX_HOLD_RAD - 0.01, 6.0), _via(1.0, 6.5)]
    held_len = 6.0 + abs(near_goal[2] - 6.0)
    plan_len = 6.0 + abs(near_goal[2] - near_goal[1])
    assert held_len > (1 + KEEP_PLAN_RATIO) * plan_len
    assert _held(near_goal) is None


def test_the_planning_cycle_holds_the_course_only_with_the_mechanism():
    # A disc at rest 0.5 m left of the straight leg to the goal: the plan passes it on the
    # RIGHT, through a tangent via-point about 0.14 rad left of the robot's heading (-0.2
    # rad): a turn towards the disc. Held, the robot keeps its heading, which passes the
    # disc farther out, and the plan still resolves the same disc on the same side.
    heading = -0.2
    obs = observe(others([(4.0, 0.5)]), heading=heading, v=1.0, goal=(10.0, 0.0))
    rules = {"direct_leg_check": True}
    plain = _plan(obs, _rules(**rules))
    assert plain.status is PlanStatus.OK and plain.side is Side.RIGHT
    first = complex(*plain.waypoints_m[1])
    off = cmath.phase(first * cmath.exp(-1j * heading))
    assert 0.0 < off <= MAX_HOLD_RAD  # inward: towards the disc on the robot's left
    held = _plan(obs, _rules(hold_course=True, **rules))
    assert held.side is Side.RIGHT and held.resolved_id == plain.resolved_id
    assert held.resolved_sides == plain.resolved_sides
    direction = math.atan2(held.waypoints_m[1][1], held.waypoints_m[1][0])
    assert direction == pytest.approx(heading, abs=1e-9)
    assert abs(complex(*held.waypoints_m[1])) == pytest.approx(abs(first))
    np.testing.assert_allclose(held.via_point_m, held.waypoints_m[1])
    np.testing.assert_allclose(held.waypoints_m[-1], plain.waypoints_m[-1])
    # A robot heading 0.3 rad further right than the tangent would turn back by more than
    # MAX_HOLD_RAD: that turn is planned as before.
    steep = observe(others([(4.0, 0.5)]), heading=-0.45, v=1.0, goal=(10.0, 0.0))
    np.testing.assert_allclose(_plan(steep, _rules(hold_course=True, **rules)).waypoints_m,
                               _plan(steep, _rules(**rules)).waypoints_m)
