"""World dynamics: exact arcs, clamping, braking on time-out, contacts, arrival."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.config import PlannerConfig, RobotLimits
from agent.core.scenario import ObstacleSpec, RobotSpec, Scenario
from tests.examples import examples
from world.sim.dynamics import (
    ALL_PAIRS_MAX_N,
    WorldSim,
    integrate_unicycle,
    near_pair_gaps,
    near_pairs,
    pair_gaps,
)


def make_scenario(robots, obstacles=(), tol=0.25):
    return Scenario(
        name="t", description="", time_limit_s=100.0, goal_tolerance_m=tol,
        planner_config=PlannerConfig(), robots=tuple(robots), obstacles=tuple(obstacles),
    )


def test_straight_line_integration():
    pose = np.array([[1.0, 2.0, 0.0]])
    out = integrate_unicycle(pose, np.array([2.0]), np.array([0.0]), 0.5)
    np.testing.assert_allclose(out, [[2.0, 2.0, 0.0]], atol=1e-12)


def test_quarter_circle_arc_is_exact():
    # v = 1, omega = 1 -> circle of radius 1; a quarter turn from the origin heading +x
    # ends at (1, 1) heading +y.
    pose = np.array([[0.0, 0.0, 0.0]])
    out = integrate_unicycle(pose, np.array([1.0]), np.array([1.0]), math.pi / 2)
    np.testing.assert_allclose(out, [[1.0, 1.0, math.pi / 2]], atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(st.floats(-3, 3), st.floats(0, 2), st.floats(-2, 2))
def test_arc_matches_fine_euler(theta, v, w):
    pose = np.array([[0.0, 0.0, theta]])
    exact = integrate_unicycle(pose, np.array([v]), np.array([w]), 0.2)
    p = pose.copy()
    for _ in range(2000):
        p = p + 1e-4 * np.array([[v * math.cos(p[0, 2]), v * math.sin(p[0, 2]), w]])
    np.testing.assert_allclose(exact[0, :2], p[0, :2], atol=1e-4)


def test_pair_gaps():
    pairs, gaps = pair_gaps(np.array([[0.0, 0.0], [3.0, 4.0], [0.0, 1.0]]), np.array([1, 1, 0.5]))
    assert pairs.tolist() == [[0, 1], [0, 2], [1, 2]]
    np.testing.assert_allclose(gaps, [3.0, -0.5, math.hypot(3, 3) - 1.5])


def test_commands_are_clamped_and_held():
    lim = RobotLimits(v_max_mps=1.0, omega_max_radps=0.5)
    sim = WorldSim(make_scenario([RobotSpec(0, (0, 0, 0), (50, 0), limits=lim)]))
    sim.set_command(0, 5.0, -3.0)
    np.testing.assert_allclose(sim.command[0], [1.0, -0.5])
    for _ in range(10):
        sim.step(0.02)
    np.testing.assert_allclose(sim.applied[0], [1.0, -0.5])
    assert sim.t_s == pytest.approx(0.2)
    assert sim.tick == 10


def test_stale_command_brakes_to_stop_and_is_counted_once():
    lim = RobotLimits(v_max_mps=1.0, accel_max_mps2=2.0)
    sim = WorldSim(make_scenario([RobotSpec(0, (0, 0, 0), (50, 0), limits=lim)]),
                   cmd_timeout_s=0.5)
    sim.set_command(0, 1.0, 0.3)
    timeouts = []
    speeds = []
    for _ in range(60):  # 1.2 s, no new command
        ev = sim.step(0.02)
        timeouts.extend(ev.timeouts)
        speeds.append(sim.applied[0, 0])
    assert timeouts == [0]
    assert sim.timeout_count == 1
    assert speeds[-1] == 0.0
    # Deceleration never exceeds the limit: 2 m/s^2 * 0.02 s per tick.
    assert np.all(np.diff(speeds) >= -2.0 * 0.02 - 1e-12)
    assert sim.applied[0, 1] == 0.0


def test_command_outliving_its_hold_brakes_until_a_newer_one_comes():
    lim = RobotLimits(v_max_mps=1.0, accel_max_mps2=2.0)
    sim = WorldSim(make_scenario([RobotSpec(0, (0, 0, 0), (50, 0), limits=lim)]),
                   cmd_timeout_s=0.5)
    sim.set_command(0, 1.0, 0.3, hold_s=0.1)
    applied = []
    for _ in range(8):  # 0.16 s, no new command
        ev = sim.step(0.02)
        assert ev.timeouts == ()  # braking on the hold is not a time-out
        applied.append(tuple(sim.applied[0]))
    # held for the five ticks that start within 0.1 s, then braking at 2 m/s^2 along the
    # commanded arc (curvature 0.3 / 1.0 kept)
    assert applied[:5] == [(1.0, 0.3)] * 5
    np.testing.assert_allclose(applied[5:], [(0.96, 0.288), (0.92, 0.276), (0.88, 0.264)])
    assert sim.hold_expiry_count == 1 and sim.timeout_count == 0
    sim.set_command(0, 0.9, -0.2, hold_s=0.1)  # a newer command applies at once
    sim.step(0.02)
    np.testing.assert_allclose(sim.applied[0], [0.9, -0.2])
    for _ in range(10):
        sim.step(0.02)
    assert sim.hold_expiry_count == 2  # counted once per command


def test_command_without_hold_lasts_until_the_time_out():
    sim = WorldSim(make_scenario([RobotSpec(0, (0, 0, 0), (50, 0))]), cmd_timeout_s=0.5)
    sim.set_command(0, 1.0, 0.0)
    for _ in range(25):  # 0.5 s
        sim.step(0.02)
    assert sim.applied[0, 0] == 1.0 and sim.hold_expiry_count == 0
    sim.step(0.02)
    assert sim.applied[0, 0] < 1.0 and sim.timeout_count == 1


def test_offline_robot_stops_and_stays_visible():
    robots = [RobotSpec(0, (0, 0, 0), (50, 0)), RobotSpec(1, (0, 5, 0), (50, 5))]
    sim = WorldSim(make_scenario(robots))
    sim.set_command(0, 1.0, 0.0)
    sim.set_command(1, 1.0, 0.0)
    sim.step(0.02)
    sim.set_offline(0, True)
    for _ in range(100):
        sim.set_command(1, 1.0, 0.0)
        sim.step(0.02)
    assert sim.applied[0, 0] == 0.0
    assert 0 in sim.snapshot().ids.tolist()
    assert sim.pose[1, 0] > sim.pose[0, 0] + 1.0


@settings(max_examples=examples(60), deadline=None)
@given(n=st.integers(0, 300), side=st.floats(1.0, 200.0), reach=st.floats(0.1, 30.0),
       seed=st.integers(0, 2**31 - 1))
def test_near_pairs_equals_brute_force(n, side, reach, seed):
    """The grid finds exactly the pairs all-pairs finds, in the same order."""
    xy = np.random.default_rng(seed).uniform(-side / 2, side / 2, size=(n, 2))
    if n > 3:
        xy[1] = xy[0]  # coincident discs and cell borders must not be missed
        xy[3] = np.floor(xy[2] / reach) * reach
    i, j = np.triu_indices(n, k=1)
    close = np.hypot(*(xy[i] - xy[j]).T) <= reach
    expected = np.stack([i[close], j[close]], axis=1)
    assert np.array_equal(near_pairs(xy, reach), expected)


def test_near_pair_gaps_keeps_gaps_up_to_the_reach():
    n = ALL_PAIRS_MAX_N + 20  # the grid path
    xy = np.stack([np.arange(n) * 1.5, np.zeros(n)], axis=1)  # a row, 1.5 m apart
    radius = np.full(n, 0.5)
    pairs, gaps = near_pair_gaps(xy, radius, reach_gap_m=2.0)
    # Gaps: 0.5 m to the next disc, 2.0 m to the one after, 3.5 m beyond (dropped).
    assert sorted(np.round(gaps, 9).tolist()) == [0.5] * (n - 1) + [2.0] * (n - 2)
    assert np.all(pairs[:, 1] - pairs[:, 0] <= 2)
    all_pairs, all_gaps = pair_gaps(xy, radius)
    assert np.isclose(gaps.min(), all_gaps.min())


def test_world_contacts_in_a_crowd_match_brute_force():
    """60 robots (the grid path) driven into each other: contacts as all-pairs sees them."""
    rng = np.random.default_rng(3)
    robots, placed = [], []
    while len(robots) < 60:
        p = rng.uniform(-12, 12, size=2)
        if all(np.hypot(*(p - q)) > 1.05 for q in placed):
            placed.append(p)
            robots.append(RobotSpec(len(robots), (p[0], p[1], rng.uniform(-3, 3)), (0, 0)))
    sim = WorldSim(make_scenario(robots))
    seen = set()
    for _ in range(150):
        for r in robots:
            sim.set_command(r.id, 1.0, 0.3)
        for a, b, _ in sim.step(0.02).new_contacts:
            seen.add((a, b))
        pairs, gaps = pair_gaps(sim.pose[:, :2], sim.radius_m)
        touching = {tuple(int(x) for x in p) for p in pairs[gaps < -1e-3]}
        assert touching == sim._in_contact
    assert seen  # the crowd did collide


def test_contact_reported_once_per_encounter_and_min_gap():
    robots = [RobotSpec(0, (0, 0, 0), (10, 0)), RobotSpec(1, (3, 0, math.pi), (-10, 0))]
    sim = WorldSim(make_scenario(robots))
    contacts = []
    for _ in range(100):
        sim.set_command(0, 1.0, 0.0)
        sim.set_command(1, 1.0, 0.0)
        contacts.extend(sim.step(0.02).new_contacts)
    assert [(a, b) for a, b, _ in contacts] == [(0, 1)]
    assert sim.min_gap_m < -0.001


def test_obstacle_contact_and_motion():
    obstacles = [ObstacleSpec(-1, (2.0, 0.0), 0.5, velocity=(-1.0, 0.0))]
    sim = WorldSim(make_scenario([RobotSpec(0, (0, 0, 0), (10, 0))], obstacles))
    events = [sim.step(0.05) for _ in range(30)]
    contacts = [c for ev in events for c in ev.new_contacts]
    assert contacts and contacts[0][:2] == (0, -1)
    np.testing.assert_allclose(sim.obstacle_positions_m(), [[0.5, 0.0]])
    snap = sim.snapshot()
    assert snap.ids.tolist() == [0, -1]


def test_arrival_latched_with_time():
    sim = WorldSim(make_scenario([RobotSpec(0, (0, 0, 0), (1.0, 0))], tol=0.25))
    arrivals = []
    for _ in range(100):
        sim.set_command(0, 1.0, 0.0)
        arrivals.extend(sim.step(0.02).arrivals)
    assert arrivals == [0]
    assert sim.all_arrived()
    assert sim.arrival_time_s[0] == pytest.approx(0.76, abs=0.021)


def test_bad_inputs_raise():
    sim = WorldSim(make_scenario([RobotSpec(0, (0, 0, 0), (1.0, 0))]))
    with pytest.raises(KeyError):
        sim.set_command(7, 1.0, 0.0)
    with pytest.raises(ValueError):
        sim.step(0.0)
    with pytest.raises(ValueError):
        sim.set_command(0, float("nan"), 0.0)
    for hold in (0.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="hold_s"):
            sim.set_command(0, 1.0, 0.0, hold_s=hold)
