"""Discrete unicycle of Eq. (1), its Jacobians, command limits and the eIFP tracking law."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.config import RobotLimits
from agent.planning.unicycle import (
    clamp_command,
    heading_law,
    jacobians,
    lookahead_point,
    rollout,
    step,
    track_reference,
    wrap_angle,
)
from tests.examples import examples

LIM = RobotLimits()
finite = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False)


def test_step_matches_hand_computation():
    # x = 1 + 2 cos(pi/6) 0.5, y = 2 + 2 sin(pi/6) 0.5, theta = pi/6 + 0.4 * 0.5
    nxt = step(np.array([1.0, 2.0, math.pi / 6]), np.array([2.0, 0.4]), 0.5)
    np.testing.assert_allclose(nxt, [1.0 + math.sqrt(3) / 2, 2.5, math.pi / 6 + 0.2], atol=1e-15)


def test_step_is_vectorised_and_broadcasts_one_control():
    states = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, math.pi / 2]])
    out = step(states, np.array([1.0, 0.0]), 0.1)
    np.testing.assert_allclose(out, [[0.1, 0.0, 0.0], [1.0, 1.1, math.pi / 2]], atol=1e-15)
    per_robot = step(states, np.array([[1.0, 1.0], [0.0, -1.0]]), 0.1)
    np.testing.assert_allclose(per_robot[:, 2], [0.1, math.pi / 2 - 0.1])
    with pytest.raises(ValueError):
        step(np.zeros(2), np.zeros(2), 0.1)


def test_heading_is_not_wrapped_by_the_model():
    nxt = step(np.array([0.0, 0.0, 3.1]), np.array([0.0, 1.0]), 0.1)
    assert nxt[2] == pytest.approx(3.2)


def test_rollout_equals_repeated_step_bit_for_bit():
    rng = np.random.default_rng(3)
    controls = rng.normal(size=(25, 2))
    x0 = np.array([1.0, -2.0, 0.7])
    out = rollout(x0, controls, 0.1)
    assert out.shape == (26, 3)
    x = x0
    for k in range(25):
        x = step(x, controls[k], 0.1)
        np.testing.assert_array_equal(out[k + 1], x)


def test_rollout_of_constant_turn_stays_on_the_circle_chord_polygon():
    # v = 1, omega = 1, dt = 2 pi / 100: 100 steps close the polygon (back to the start).
    dt = 2 * math.pi / 100
    out = rollout(np.zeros(3), np.tile([1.0, 1.0], (100, 1)), dt)
    np.testing.assert_allclose(out[-1, :2], [0.0, 0.0], atol=1e-12)
    assert out[-1, 2] == pytest.approx(2 * math.pi)


@settings(max_examples=50, deadline=None)
@given(theta=finite, v=finite, w=finite)
def test_jacobians_match_finite_differences(theta, v, w):
    dt, eps = 0.1, 1e-6
    x0 = np.array([0.3, -0.2, theta])
    u0 = np.array([v, w])
    A, B = jacobians(np.array([theta]), np.array([v]), dt)
    assert A.shape == (1, 3, 3) and B.shape == (1, 3, 2)
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        fd = (step(x0 + d, u0, dt) - step(x0 - d, u0, dt)) / (2 * eps)
        np.testing.assert_allclose(A[0, :, i], fd, atol=1e-6 * (1 + abs(v)))
    for i in range(2):
        d = np.zeros(2)
        d[i] = eps
        fd = (step(x0, u0 + d, dt) - step(x0, u0 - d, dt)) / (2 * eps)
        np.testing.assert_allclose(B[0, :, i], fd, atol=1e-8)


def test_jacobians_are_vectorised():
    A, B = jacobians(np.array([0.0, math.pi / 2]), np.array([1.0, 2.0]), 0.5)
    np.testing.assert_allclose(A[0], [[1, 0, 0], [0, 1, 0.5], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(A[1], [[1, 0, -1.0], [0, 1, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(B[1], [[0, 0], [0.5, 0], [0, 0.5]], atol=1e-15)


@pytest.mark.parametrize(
    ("angle", "expected"),
    [
        (0.0, 0.0),
        (math.pi, -math.pi),
        (-math.pi, -math.pi),
        (3 * math.pi / 2, -math.pi / 2),
        (-7.0, -7.0 + 2 * math.pi),
        (4 * math.pi + 0.1, 0.1),
    ],
)
def test_wrap_angle(angle, expected):
    assert wrap_angle(angle) == pytest.approx(expected, abs=1e-12)


def test_wrap_angle_array():
    out = wrap_angle(np.array([0.0, 2 * math.pi + 0.5, -0.5 - 2 * math.pi]))
    np.testing.assert_allclose(out, [0.0, 0.5, -0.5], atol=1e-12)


def test_clamp_command_bounds_and_rates():
    assert clamp_command(5.0, -9.0, LIM) == (LIM.v_max_mps, -LIM.omega_max_radps)
    assert clamp_command(-1.0, 0.3, LIM) == (LIM.v_min_mps, 0.3)
    # From rest, v may rise by accel_max dt = 0.15 and omega by alpha_max dt = 0.6.
    v, w = clamp_command(1.0, 1.5, LIM, 0.0, 0.0, 0.1)
    assert v == pytest.approx(0.15) and w == pytest.approx(0.6)
    v, w = clamp_command(0.0, -1.5, LIM, 1.0, 1.0, 0.1)
    assert v == pytest.approx(0.85) and w == pytest.approx(0.4)
    with pytest.raises(ValueError):
        clamp_command(0.0, 0.0, LIM, 1.0, 0.0)


def test_clamp_command_bounds_win_over_an_out_of_bounds_last_command():
    v, w = clamp_command(3.0, 0.0, LIM, 3.0, 0.0, 0.1)
    assert v == LIM.v_max_mps


@settings(max_examples=examples(200), deadline=None)
@given(v=finite, w=finite, lv=finite, lw=finite, dt=st.floats(1e-3, 1.0))
def test_clamp_command_always_within_bounds(v, w, lv, lw, dt):
    cv, cw = clamp_command(v, w, LIM, lv, lw, dt)
    assert LIM.v_min_mps <= cv <= LIM.v_max_mps
    assert abs(cw) <= LIM.omega_max_radps
    if LIM.v_min_mps <= lv <= LIM.v_max_mps:
        assert abs(cv - lv) <= LIM.accel_max_mps2 * dt + 1e-12
    if abs(lw) <= LIM.omega_max_radps:
        assert abs(cw - lw) <= LIM.alpha_max_radps2 * dt + 1e-12


def test_clamp_command_non_finite_request_holds_the_last_command():
    assert clamp_command(math.nan, math.inf, LIM, 0.5, 0.2, 0.1) == (0.5, 0.2)
    assert clamp_command(math.nan, math.nan, LIM) == (0.0, 0.0)


def test_heading_law_turns_before_it_goes():
    v, w = heading_law(0.0, 0.0, 1.0, LIM, 2.5)
    assert (v, w) == (1.0, 0.0)
    v, w = heading_law(0.0, math.pi / 3, 1.0, LIM, 2.5)  # cos(60 deg) = 0.5
    assert v == pytest.approx(0.5) and w == pytest.approx(1.5)  # 2.5 * 1.047 clipped
    v, w = heading_law(0.0, -math.pi / 6, 1.0, LIM, 2.5)
    assert v == pytest.approx(math.cos(math.pi / 6)) and w == pytest.approx(-2.5 * math.pi / 6)
    v, w = heading_law(0.0, 2.0, 1.0, LIM, 2.5)  # more than 90 deg off: turn on the spot
    assert v == 0.0 and w == LIM.omega_max_radps


def test_lookahead_point_walks_along_the_polyline():
    xs, ys = np.array([0.0, 1.0, 2.0, 2.0]), np.array([0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(lookahead_point(0.1, 0.2, xs, ys, 0.5), [0.5, 0.0])
    np.testing.assert_allclose(lookahead_point(1.1, 0.0, xs, ys, 1.5), [2.0, 0.5])
    np.testing.assert_allclose(lookahead_point(0.0, 0.0, xs, ys, 10.0), [2.0, 1.0])


def test_track_reference_aims_at_the_lookahead_point():
    xs, ys = np.linspace(0.0, 5.0, 51), np.zeros(51)
    # Robot 0.5 m left of the line, heading along it: aim 1 m ahead, so err = -atan(0.5).
    v, w = track_reference(0.0, 0.5, 0.0, xs, ys, 1.0, 1.0, LIM, 2.0)
    err = -math.atan2(0.5, 1.0)
    assert w == pytest.approx(2.0 * err)
    assert v == pytest.approx(math.cos(err))
    # With the last command, the rates are limited too.
    v, w = track_reference(0.0, 0.5, 0.0, xs, ys, 1.0, 1.0, LIM, 2.0, np.zeros(2), 0.1)
    assert v == pytest.approx(0.15) and w == pytest.approx(-0.6)


def test_track_reference_converges_onto_a_line_in_closed_loop():
    xs, ys = np.linspace(0.0, 30.0, 301), np.zeros(301)
    x = np.array([0.0, 1.0, math.pi / 2])  # 1 m off, facing away from the line's direction
    cmd = np.zeros(2)
    for _ in range(200):
        cmd = np.array(track_reference(*x, xs, ys, 1.0, 0.6, LIM, 2.5, cmd, 0.1))
        assert LIM.v_min_mps <= cmd[0] <= LIM.v_max_mps and abs(cmd[1]) <= LIM.omega_max_radps
        x = step(x, cmd, 0.1)
    assert abs(x[1]) < 0.02
    assert abs(wrap_angle(x[2])) < 0.05


def test_rollout_with_trig_gives_the_rollout_and_its_headings_trig() -> None:
    from agent.planning.unicycle import rollout_with_trig

    rng = np.random.default_rng(4)
    controls = rng.uniform(-1.0, 1.0, (20, 2))
    states, cos, sin = rollout_with_trig(np.array([1.0, -2.0, 0.3]), controls, 0.1)
    assert states.tobytes() == rollout(np.array([1.0, -2.0, 0.3]), controls, 0.1).tobytes()
    np.testing.assert_array_equal(cos, np.cos(states[:-1, 2]))
    np.testing.assert_array_equal(sin, np.sin(states[:-1, 2]))
