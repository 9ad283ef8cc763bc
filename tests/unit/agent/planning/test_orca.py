"""ORCA baseline (RVO2 via pyrvo) with a heading controller, closed loop on Eq. (1)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.config import PlannerConfig, RobotLimits, ThreatConfig
from agent.core.types import Others
from agent.planning.orca import OrcaCommand, OrcaController
from agent.planning.unicycle import step
from tests.examples import examples

LIM = RobotLimits()
CFG = PlannerConfig()
DT = 0.1
RADIUS = 0.3


def others_of(positions, velocities, radii, is_robot=None):
    positions = np.asarray(positions, dtype=float).reshape(-1, 2)
    k = positions.shape[0]
    return Others(
        ids=np.arange(1, k + 1),
        position_m=positions,
        velocity_mps=np.asarray(velocities, dtype=float).reshape(k, 2),
        radius_m=np.asarray(radii, dtype=float).reshape(k),
        linearity=np.ones(k),
        track_start_m=positions,
        is_robot=np.ones(k, dtype=bool) if is_robot is None else is_robot,
    )


def assert_within_limits(cmd, last):
    assert LIM.v_min_mps <= cmd[0] <= LIM.v_max_mps
    assert abs(cmd[1]) <= LIM.omega_max_radps
    assert abs(cmd[0] - last[0]) <= LIM.accel_max_mps2 * DT + 1e-9
    assert abs(cmd[1] - last[1]) <= LIM.alpha_max_radps2 * DT + 1e-9


def simulate(poses, goals, steps=400, tolerance=0.25):
    """Every robot runs its own OrcaController on what it sees; all move on Eq. (1)."""
    poses = np.array(poses, dtype=float)
    goals = np.array(goals, dtype=float)
    n = poses.shape[0]
    controllers = [OrcaController(LIM, CFG, DT) for _ in range(n)]
    cmd = np.zeros((n, 2))
    min_gap = math.inf
    for _ in range(steps):
        vel = cmd[:, :1] * np.column_stack((np.cos(poses[:, 2]), np.sin(poses[:, 2])))
        new = np.zeros((n, 2))
        for i in range(n):
            if np.hypot(*(goals[i] - poses[i, :2])) < tolerance:
                continue  # arrived: the node would command a stop
            j = np.arange(n) != i
            seen = others_of(poses[j, :2], vel[j], np.full(n - 1, RADIUS))
            out = controllers[i].command(
                poses[i, :2], poses[i, 2], vel[i], goals[i], RADIUS, seen, cmd[i]
            )
            new[i] = out.v_mps, out.omega_radps
            assert_within_limits(new[i], cmd[i])
        cmd = new  # everyone decides on the same snapshot, then all move
        poses = step(poses, cmd, DT)
        d = np.hypot(*(poses[:, None, :2] - poses[None, :, :2]).transpose(2, 0, 1))
        min_gap = min(min_gap, d[~np.eye(n, dtype=bool)].min())
    arrived = np.hypot(*(goals - poses[:, :2]).T) < tolerance
    return poses, arrived, min_gap


def test_head_on_exact_symmetry_resolves_without_deadlock():
    # RVO2 breaks the exact tie the same way for both (the "right leg"): they pass.
    _, arrived, min_gap = simulate(
        [[-5.0, 0.0, 0.0], [5.0, 0.0, math.pi]], [[5.0, 0.0], [-5.0, 0.0]]
    )
    assert min_gap > 2 * RADIUS  # no overlap
    assert arrived.all()


def test_head_on_with_a_small_offset_resolves():
    _, arrived, min_gap = simulate(
        [[-5.0, 0.0, 0.0], [5.0, 0.05, math.pi]], [[5.0, 0.0], [-5.0, 0.05]]
    )
    assert min_gap > 2 * RADIUS
    assert arrived.all()


def test_perpendicular_crossing_resolves():
    _, arrived, min_gap = simulate(
        [[-4.0, 0.0, 0.0], [0.0, -4.5, math.pi / 2]], [[4.0, 0.0], [0.0, 4.5]]
    )
    assert min_gap > 2 * RADIUS
    assert arrived.all()


def test_four_robot_cross_is_safe_but_deadlocks():
    """Characterises the baseline: the symmetric cross (paper's Setup D) never overlaps, and
    pure ORCA stops all four at the centre (0.64 m out, inflated discs touching).

    Known ORCA behaviour: from rest, with everyone in view, the symmetric configuration
    yields symmetric (radial) ORCA velocities that shrink to zero. Holonomic RVO2 with
    the same parameters does the same. If this starts to arrive, update agent/orca.py's
    docstring and this test.
    """
    poses = [
        [-4.0, 0.0, 0.0],
        [4.0, 0.0, math.pi],
        [0.0, -4.0, math.pi / 2],
        [0.0, 4.0, -math.pi / 2],
    ]
    goals = [[4.0, 0.0], [-4.0, 0.0], [0.0, 4.0], [0.0, -4.0]]
    final, arrived, min_gap = simulate(poses, goals, steps=400)
    assert min_gap > 2 * RADIUS
    assert not arrived.any()
    np.testing.assert_allclose(np.hypot(final[:, 0], final[:, 1]), 0.64, atol=0.02)


def test_free_space_heads_straight_to_the_goal():
    ctrl = OrcaController(LIM, CFG, DT)
    out = ctrl.command(
        np.zeros(2), 0.0, np.array([1.0, 0.0]), np.array([10.0, 0.0]), RADIUS, Others.empty()
    )
    assert isinstance(out, OrcaCommand)
    np.testing.assert_allclose(out.velocity_pref_mps, [LIM.v_max_mps, 0.0])
    np.testing.assert_allclose(out.velocity_orca_mps, [LIM.v_max_mps, 0.0], atol=1e-6)
    assert out.v_mps == pytest.approx(LIM.v_max_mps, abs=1e-6)
    assert out.omega_radps == pytest.approx(0.0, abs=1e-6)
    assert out.n_neighbors == 0


def test_preferred_speed_slows_near_the_goal():
    ctrl = OrcaController(LIM, CFG, DT)
    pref = ctrl.preferred_velocity(np.zeros(2), np.array([0.0, 0.12]))
    # sqrt(2 * 1.5 * 0.12) = 0.6 m/s, toward +y
    np.testing.assert_allclose(pref, [0.0, 0.6], atol=1e-12)
    np.testing.assert_array_equal(ctrl.preferred_velocity(np.ones(2), np.ones(2)), [0.0, 0.0])


def test_goal_behind_turns_on_the_spot_first():
    ctrl = OrcaController(LIM, CFG, DT)
    out = ctrl.command(np.zeros(2), 0.0, np.zeros(2), np.array([-5.0, 0.1]), RADIUS, Others.empty())
    assert out.v_mps == 0.0
    assert out.omega_radps == LIM.omega_max_radps


def test_neighbour_ahead_deflects_the_velocity():
    ctrl = OrcaController(LIM, CFG, DT)
    seen = others_of([[2.0, 0.0]], [[-1.0, 0.0]], [RADIUS])
    out = ctrl.command(np.zeros(2), 0.0, np.array([1.0, 0.0]), np.array([10.0, 0.0]), RADIUS, seen)
    assert abs(out.velocity_orca_mps[1]) > 0.05  # sidesteps instead of driving straight on
    assert out.n_neighbors == 1


def test_sensing_radius_and_neighbour_cap_select_the_nearest():
    cfg = PlannerConfig(threats=ThreatConfig(max_neighbors=2, sensing_radius_m=5.0))
    ctrl = OrcaController(LIM, cfg, DT)
    seen = others_of(
        [[4.0, 1.0], [1.5, 0.5], [3.0, -1.0], [6.0, 0.0]], np.zeros((4, 2)), np.full(4, RADIUS)
    )
    out = ctrl.command(np.zeros(2), 0.0, np.zeros(2), np.array([10.0, 0.0]), RADIUS, seen)
    assert out.n_neighbors == 2


def test_obstacle_discs_are_avoided():
    obstacle = np.array([3.0, 0.02])
    pose = np.array([0.0, 0.0, 0.0])
    goal = np.array([6.0, 0.0])
    ctrl = OrcaController(LIM, CFG, DT)
    cmd = np.zeros(2)
    gap = math.inf
    for _ in range(200):
        seen = others_of([obstacle], [[0.0, 0.0]], [0.5], is_robot=np.array([False]))
        vel = cmd[0] * np.array([math.cos(pose[2]), math.sin(pose[2])])
        out = ctrl.command(pose[:2], pose[2], vel, goal, RADIUS, seen, cmd)
        cmd = np.array([out.v_mps, out.omega_radps])
        pose = step(pose, cmd, DT)
        gap = min(gap, np.hypot(*(pose[:2] - obstacle)))
    assert gap > 0.5 + RADIUS  # a reciprocal half-share against a static disc still clears it
    assert np.hypot(*(pose[:2] - goal)) < 0.3


def test_same_inputs_give_the_same_command():
    seen = others_of([[2.0, 0.3], [1.0, -1.0]], [[-1.0, 0.0], [0.2, 0.5]], [0.3, 0.4])
    args = (
        np.array([0.1, 0.2]),
        0.3,
        np.array([0.5, 0.1]),
        np.array([8.0, 1.0]),
        RADIUS,
        seen,
        np.array([0.5, 0.0]),
    )
    a = OrcaController(LIM, CFG, DT).command(*args)
    b = OrcaController(LIM, CFG, DT).command(*args)
    assert (a.v_mps, a.omega_radps) == (b.v_mps, b.omega_radps)
    np.testing.assert_array_equal(a.velocity_orca_mps, b.velocity_orca_mps)


def test_invalid_inputs_raise():
    ctrl = OrcaController(LIM, CFG, DT)
    with pytest.raises(ValueError):
        ctrl.command(np.zeros(3), 0.0, np.zeros(2), np.ones(2), RADIUS, Others.empty())
    with pytest.raises(ValueError):
        ctrl.command(np.zeros(2), math.nan, np.zeros(2), np.ones(2), RADIUS, Others.empty())


coord = st.floats(-20.0, 20.0, allow_nan=False)


@settings(max_examples=examples(80), deadline=None)
@given(
    pose=st.tuples(coord, coord, st.floats(-10.0, 10.0)),
    goal=st.tuples(coord, coord),
    last=st.tuples(st.floats(0.0, 1.1), st.floats(-1.5, 1.5)),
    others=st.lists(
        st.tuples(coord, coord, st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(0.05, 1.0)),
        max_size=12,
    ),
)
def test_random_inputs_give_a_command_within_limits(pose, goal, last, others):
    o = np.array(others, dtype=float).reshape(-1, 5)
    seen = others_of(o[:, :2], o[:, 2:4], o[:, 4])
    last = np.array(last)
    vel = last[0] * np.array([math.cos(pose[2]), math.sin(pose[2])])
    out = OrcaController(LIM, CFG, DT).command(
        np.array(pose[:2]), pose[2], vel, np.array(goal), RADIUS, seen, last
    )
    assert_within_limits((out.v_mps, out.omega_radps), last)
    assert np.isfinite(out.velocity_orca_mps).all()
    assert np.hypot(*out.velocity_orca_mps) <= LIM.v_max_mps + 1e-5


def test_float32_round_off_does_not_push_the_orca_velocity_past_v_max():
    # Found by the random-input test: four others stacked at the goal and two on the robot's
    # line; RVO2's float32 linear program returned |v| = 1.1000104 for v_max 1.1.
    o = np.array([(0.0, 0.0, 0.0, 0.0, 1.0)] * 4
                 + [(0.0, -16.0, 0.5, 0.0, 1.0), (0.0, -19.0, 0.0, 0.0, 1.0)])
    seen = others_of(o[:, :2], o[:, 2:4], o[:, 4])
    out = OrcaController(LIM, CFG, DT).command(np.array([0.0, -17.5]), 0.0, np.zeros(2),
                                               np.array([0.0, 0.0]), RADIUS, seen, np.zeros(2))
    assert np.hypot(*out.velocity_orca_mps) <= LIM.v_max_mps
    assert np.hypot(*out.velocity_orca_mps) > LIM.v_max_mps - 1e-4  # clipped, not zeroed
