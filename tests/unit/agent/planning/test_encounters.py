"""Encounter rules: give way / stand on, the stream rule, the safety net, the memory."""

import math

import numpy as np
import pytest

from agent.core.types import Others
from agent.planning.encounters import (
    MOVING_MPS,
    Role,
    classify,
    encounter_roles,
    update_role_memory,
)

V = 1.1


def one(pos, vel, robot=True, rid=7):
    pos = np.asarray(pos, dtype=float).reshape(1, 2)
    vel = np.asarray(vel, dtype=float).reshape(1, 2)
    return Others(ids=np.array([rid]), position_m=pos, velocity_mps=vel,
                  radius_m=np.array([0.5]), linearity=np.ones(1), track_start_m=pos - vel,
                  is_robot=np.array([robot]))


def role(heading, me, pos, vel, speed=V, robot=True):
    roles, _ = classify(heading, speed, np.asarray(me, dtype=float), one(pos, vel, robot))
    return Role(int(roles[0]))


def heading_vel(angle_rad, speed=V):
    return (speed * math.cos(angle_rad), speed * math.sin(angle_rad))


def test_mirrored_crossing_one_gives_way_the_other_stands_on():
    # Setup A: robot 0 from the top left heading south-east, robot 1 its mirror image.
    h0, h1 = -math.pi / 4, math.pi / 4
    p0, p1 = (-5.0, 5.0), (-5.0, -5.0)
    # Robot 1 is on robot 0's right: 0 gives way. Robot 0 is on robot 1's left: 1 stands on.
    assert role(h0, p0, p1, heading_vel(h1)) is Role.GIVE_WAY
    assert role(h1, p1, p0, heading_vel(h0)) is Role.STAND_ON


def test_head_on_both_give_way_even_slightly_offset():
    assert role(0.0, (0, 0), (10, 0.5), heading_vel(math.pi)) is Role.GIVE_WAY
    assert role(math.pi, (10, 0.5), (0, 0), heading_vel(0.0)) is Role.GIVE_WAY
    # 40 degrees off reciprocal, the other on our left: still head-on.
    assert role(0.0, (0, 0), (10, 2.0), heading_vel(math.pi + math.radians(40))) is Role.GIVE_WAY


def test_perpendicular_crossing_from_the_left_stands_on_and_from_the_right_gives_way():
    assert role(0.0, (0, 0), (5, 5), heading_vel(-math.pi / 2)) is Role.STAND_ON
    assert role(0.0, (0, 0), (5, -5), heading_vel(math.pi / 2)) is Role.GIVE_WAY


def test_overtaking_resolves_and_being_overtaken_stands_on():
    # Same course, the other ahead and slower: we overtake it (ordinary eIFP choice).
    assert role(0.0, (0, 0), (5, 0.2), heading_vel(0.0, 0.5)) is Role.RESOLVE
    # Same course, the other behind: it overtakes us.
    assert role(0.0, (0, 0), (-5, 0.2), heading_vel(0.0, 1.5)) is Role.STAND_ON


def test_obstacles_slow_robots_and_a_robot_that_barely_moves_itself():
    assert role(0.0, (0, 0), (5, 5), heading_vel(-math.pi / 2), robot=False) is Role.RESOLVE
    slow = 0.5 * MOVING_MPS
    assert role(0.0, (0, 0), (5, 5), heading_vel(-math.pi / 2, slow)) is Role.RESOLVE
    assert role(0.0, (0, 0), (5, 5), heading_vel(-math.pi / 2), speed=slow) is Role.RESOLVE


def roles_of(heading, me, pos, vel, tcpa, dcpa, memory=None, inflated=1.3):
    o = one(pos, vel)
    return Role(int(encounter_roles(heading, V, np.asarray(me, float), o, np.array([tcpa]),
                                    np.array([dcpa]), np.array([inflated]),
                                    memory or {}, emergency_s=2.0)[0]))


def test_stream_neighbours_outside_the_inflated_radius_are_left_alone():
    # A robot of our own cohort, ahead and to the side, converging a little.
    ahead = ((4.0, 1.5), heading_vel(-0.05, 1.0))
    assert roles_of(0.0, (0, 0), *ahead, tcpa=5.0, dcpa=2.0) is Role.STAND_ON
    assert roles_of(0.0, (0, 0), *ahead, tcpa=5.0, dcpa=0.8) is Role.RESOLVE


def test_safety_net_turns_an_imminent_stand_on_into_give_way():
    left = ((3.0, 3.0), heading_vel(-math.pi / 2))
    assert roles_of(0.0, (0, 0), *left, tcpa=3.0, dcpa=0.5) is Role.STAND_ON
    assert roles_of(0.0, (0, 0), *left, tcpa=1.5, dcpa=0.5) is Role.GIVE_WAY
    assert roles_of(0.0, (0, 0), *left, tcpa=1.5, dcpa=2.0) is Role.STAND_ON  # misses: no


def test_memory_keeps_a_role_while_approaching_and_drops_it_once_passed():
    left = ((3.0, 3.0), heading_vel(-math.pi / 2))
    # Remembered as GIVE_WAY: kept although the geometry now says STAND_ON.
    assert roles_of(0.0, (0, 0), *left, tcpa=4.0, dcpa=1.0, memory={7: Role.GIVE_WAY}) \
        is Role.GIVE_WAY
    o = one(*left)
    roles = np.array([int(Role.GIVE_WAY)])
    threat = np.array([False])
    assert update_role_memory(o, roles, np.array([4.0]), threat, {7: Role.GIVE_WAY}) == {
        7: Role.GIVE_WAY}
    assert update_role_memory(o, roles, np.array([-0.1]), threat, {7: Role.GIVE_WAY}) == {}
    # Not remembered before it is a threat of Eq. (6); remembered from then on.
    assert update_role_memory(o, roles, np.array([4.0]), threat, {}) == {}
    assert update_role_memory(o, roles, np.array([4.0]), np.array([True]), {}) == {
        7: Role.GIVE_WAY}


@pytest.mark.parametrize("angle_deg", [10, 35, 60, 90, 120, 150, 170])
def test_mirror_images_never_both_stand_on_or_both_resolve_by_cost(angle_deg):
    # Two robots converging on one point from mirrored directions: a chiral rule must give
    # them different roles (one gives way), or both give way (head-on); never the mirror
    # pair of choices that the cost of Eq. (15) produces.
    a = math.radians(angle_deg) / 2
    h0, h1 = -a, a
    p0 = (-5 * math.cos(a), 5 * math.sin(a))
    p1 = (-5 * math.cos(a), -5 * math.sin(a))
    r0 = role(h0, p0, p1, heading_vel(h1))
    r1 = role(h1, p1, p0, heading_vel(h0))
    assert Role.GIVE_WAY in (r0, r1)
    assert not (r0 is Role.RESOLVE and r1 is Role.RESOLVE)


def test_a_denormal_speed_is_a_parked_robot_without_overflow():
    # Found by hypothesis in tests/agent/test_planners.py: |v| = 2e-313 overflowed v / |v|
    # (a RuntimeWarning, an error under -W error).
    two = Others(ids=np.array([1, 2]), position_m=np.array([[3.0, 0.0], [0.0, 3.0]]),
                 velocity_mps=np.array([[-V, 0.0], [0.0, 2.2250738585e-313]]),
                 radius_m=np.full(2, 0.5), linearity=np.ones(2),
                 track_start_m=np.zeros((2, 2)), is_robot=np.ones(2, dtype=bool))
    roles, overtaken = classify(0.0, V, np.zeros(2), two)
    assert [Role(int(r)) for r in roles] == [Role.GIVE_WAY, Role.RESOLVE]
    assert not overtaken.any()
