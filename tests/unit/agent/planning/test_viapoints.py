"""Tangent points (Eqs. 7-10), velocity-cone feasibility (Eqs. 11-13) and escape points."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.types import Side
from agent.planning.viapoints import (
    ESCAPE_MARGIN_M,
    SIDES,
    candidate_pair,
    cone_time,
    escape_point,
    inflated_radius,
    tangent_points,
    via_point_candidates,
)

RIGHT, LEFT = SIDES.index(Side.RIGHT), SIDES.index(Side.LEFT)


def test_sides_order_is_right_then_left():
    assert SIDES == (Side.RIGHT, Side.LEFT)


def test_inflated_radius_is_the_sum_eq7():
    np.testing.assert_allclose(inflated_radius(0.2, np.array([0.2, 0.5]), 0.3), [0.7, 1.0])


def test_tangent_points_by_hand():
    # P = (0, 0), c = (5, 0), L = 3: Q = 5, M = 4, theta = asin(3/5); S = 4 (cos, sin)(-+theta).
    points, outside = tangent_points([0, 0], [[5, 0]], [3.0])
    assert outside.tolist() == [True]
    np.testing.assert_allclose(points[0, RIGHT], [3.2, -2.4], atol=1e-12)  # alpha - theta
    np.testing.assert_allclose(points[0, LEFT], [3.2, 2.4], atol=1e-12)  # alpha + theta


def test_tangent_points_of_an_obstacle_behind_follow_eq9_and_eq10():
    # alpha = pi: RIGHT at pi - theta is (-3.2, +2.4), LEFT at pi + theta is (-3.2, -2.4).
    points, _ = tangent_points([1, 1], [[-4, 1]], [3.0])
    np.testing.assert_allclose(points[0, RIGHT], [1 - 3.2, 1 + 2.4], atol=1e-12)
    np.testing.assert_allclose(points[0, LEFT], [1 - 3.2, 1 - 2.4], atol=1e-12)


def test_tangent_points_match_the_paper_trigonometry():
    rng = np.random.default_rng(1)
    p = np.array([0.4, -1.2])
    centres = rng.uniform(-8, 8, size=(6, 2))
    radius = rng.uniform(0.2, 1.0, size=6)
    points, outside = tangent_points(p, centres, radius)
    for j in np.flatnonzero(outside):
        q = math.dist(p, centres[j])
        alpha = math.atan2(centres[j, 1] - p[1], centres[j, 0] - p[0])
        theta = math.asin(radius[j] / q)
        m = math.sqrt(q * q - radius[j] ** 2)
        for idx, ang in ((RIGHT, alpha - theta), (LEFT, alpha + theta)):
            expected = p + m * np.array([math.cos(ang), math.sin(ang)])
            np.testing.assert_allclose(points[j, idx], expected, atol=1e-9)


def test_inside_disc_has_no_tangent_and_stays_finite():
    points, outside = tangent_points([0, 0], [[0.5, 0], [0, 0], [3, 0]], [1.0, 1.0, 3.0])
    assert outside.tolist() == [False, False, False]  # Q < L, Q = 0, Q == L
    assert np.all(np.isfinite(points))
    cands = via_point_candidates([0, 0], [[0.5, 0]], [[0, 0]], [1.0], 1.0)
    assert not cands.feasible.any() and np.all(np.isinf(cands.time_s))
    assert np.all(np.isfinite(cands.point_m))
    assert candidate_pair(0, 0, 0.5, 0, 0, 0, 1.0, 1.0) is None


# --- the velocity cone ----------------------------------------------------------------


def test_static_obstacle_lambda_is_m_over_r():
    cands = via_point_candidates([0, 0], [[5, 0]], [[0, 0]], [3.0], 2.0)
    np.testing.assert_allclose(cands.time_s[0], [2.0, 2.0])  # M / r = 4 / 2
    np.testing.assert_allclose(cands.point_m[0, RIGHT], [3.2, -2.4], atol=1e-12)
    assert cands.feasible.all()


def test_head_on_obstacle_root_by_hand():
    # S = (3.2, -2.4) moves with v = (-1, 0); cone r = 2:
    # (1 - 4) lam^2 + 2 (S.v) lam + |S|^2 = -3 lam^2 - 6.4 lam + 16 = 0.
    lam = (-6.4 + math.sqrt(6.4**2 + 4 * 3 * 16)) / (2 * 3)
    cands = via_point_candidates([0, 0], [[5, 0]], [[-1, 0]], [3.0], 2.0)
    assert cands.time_s[0, RIGHT] == pytest.approx(lam)
    np.testing.assert_allclose(cands.point_m[0, RIGHT], [3.2 - lam, -2.4], atol=1e-12)
    # The robot reaches it at full speed exactly at lam.
    assert np.hypot(*cands.point_m[0, RIGHT]) == pytest.approx(2.0 * lam)


def test_obstacle_as_fast_as_the_cone_is_the_linear_case():
    # |v_o| = r = 1: -6.4 lam + 16 = 0 -> lam = 2.5, via (0.7, -2.4), |via| = 2.5.
    cands = via_point_candidates([0, 0], [[5, 0]], [[-1, 0]], [3.0], 1.0)
    assert cands.time_s[0, RIGHT] == pytest.approx(2.5)
    np.testing.assert_allclose(cands.point_m[0, RIGHT], [0.7, -2.4], atol=1e-12)
    # Receding at exactly r: the linear root is negative -> dropped.
    away = via_point_candidates([0, 0], [[5, 0]], [[1, 0]], [3.0], 1.0)
    assert not away.feasible.any()


def test_receding_faster_than_the_cone_is_dropped():
    cands = via_point_candidates([0, 0], [[5, 0]], [[3, 0]], [3.0], 1.0)
    assert not cands.feasible.any()
    assert np.all(np.isinf(cands.time_s))
    np.testing.assert_allclose(cands.point_m[0, RIGHT], [3.2, -2.4])  # the raw tangent point


def test_fast_obstacle_with_no_real_root_is_dropped():
    # A slow robot (r = 0.1) cannot meet tangent points sweeping past at 2 m/s.
    cands = via_point_candidates([0, 0], [[5, 0]], [[-2, 0]], [0.7], 0.1)
    assert not cands.feasible.any()


def test_cone_time_vectorised_edge_cases():
    lam = cone_time(
        np.array([[4.0, 0.0], [4.0, 0.0], [0.0, 0.0], [0.0, 3.0]]),
        np.array([[0.0, 0.0], [-2.0, 0.0], [0.0, 0.0], [1.0, 0.0]]),
        1.0,
    )
    assert lam[0] == pytest.approx(4.0)  # static
    assert lam[1] == pytest.approx(4.0 / 3.0)  # closing head-on: 4 - 2 lam = lam
    assert math.isinf(lam[2])  # at the apex: only lam = 0, not positive
    assert math.isinf(lam[3])  # |v| = r perpendicular: a = b = 0, c > 0, no root


def test_margin_pushes_the_via_point_radially_out_of_the_moving_disc():
    # Static: the tangent point (3.2, -2.4) of the disc at (5, 0), L = 3, moved to L + 0.5.
    cands = via_point_candidates([0, 0], [[5, 0]], [[0, 0]], [3.0], 2.0, margin_m=0.5)
    np.testing.assert_allclose(cands.point_m[0, RIGHT], [5 - 1.8 * 3.5 / 3, -2.4 * 3.5 / 3])
    assert cands.time_s[0, RIGHT] == pytest.approx(2.0)  # lambda* is unchanged
    # Moving: pushed away from the centre where the disc is at lambda*.
    cands = via_point_candidates([0, 0], [[5, 0]], [[-1, 0]], [3.0], 2.0, margin_m=0.5)
    lam = cands.time_s[0, LEFT]
    centre = np.array([5 - lam, 0.0])
    assert math.dist(cands.point_m[0, LEFT], centre) == pytest.approx(3.5)


def test_candidate_pair_matches_the_vectorised_form():
    rng = np.random.default_rng(5)
    for i in range(200):
        p = rng.uniform(-5, 5, 2)
        c = rng.uniform(-5, 5, 2)
        v = rng.uniform(-2, 2, 2)
        radius, speed = rng.uniform(0.3, 1.5), rng.uniform(0.2, 2.0)
        margin = 0.0 if i % 2 else 0.05
        cap = math.inf if i % 3 else rng.uniform(0.5, 8.0)
        vec = via_point_candidates(p, c[None], v[None], [radius], speed, margin, cap)
        pair = candidate_pair(*p, *c, *v, radius, speed, margin, cap)
        if pair is None:
            assert not vec.outside[0]
            continue
        for idx in (RIGHT, LEFT):
            x, y, lam = pair[idx]
            assert lam == pytest.approx(vec.time_s[0, idx], rel=1e-9)
            np.testing.assert_allclose([x, y], vec.point_m[0, idx], atol=1e-9)


def test_max_time_drops_a_tangent_point_that_recedes_almost_as_fast_as_the_robot():
    # A neighbour converging from the left at nearly the robot's speed (1.0 of 1.1 m/s):
    # its RIGHT tangent point is met only after 460 s, 462 m away down its track.
    args = (0.0, 0.0, 1.5, 2.5, 1.0, -0.45, 1.6, 1.1, 0.3)
    (xr, yr, tr), (xl, yl, tl) = candidate_pair(*args)
    assert tr == pytest.approx(460.03, abs=0.01) and math.hypot(xr, yr) > 400.0
    assert tl == pytest.approx(2.467, abs=0.001)
    (xr8, yr8, tr8), left8 = candidate_pair(*args, max_time_s=8.0)
    assert math.isinf(tr8)
    assert math.hypot(xr8, yr8) < 3.0  # the raw tangent point, as for any infeasible one
    assert left8 == (xl, yl, tl)  # under the cap: unchanged
    (_, _, tr2), (_, _, tl2) = candidate_pair(*args, max_time_s=2.0)
    assert math.isinf(tr2) and math.isinf(tl2)
    vec = via_point_candidates([0, 0], [[1.5, 2.5]], [[1.0, -0.45]], [1.6], 1.1, 0.3, 8.0)
    assert vec.feasible[0].tolist() == [False, True]
    with pytest.raises(ValueError, match="max_time_s"):
        via_point_candidates([0, 0], [[1.5, 2.5]], [[1.0, -0.45]], [1.6], 1.1, 0.3, 0.0)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_input_raises(bad):
    with pytest.raises(ValueError):
        tangent_points([0, bad], [[5, 0]], [3.0])
    with pytest.raises(ValueError):
        via_point_candidates([0, 0], [[5, 0]], [[bad, 0]], [3.0], 1.0)
    with pytest.raises(ValueError):
        via_point_candidates([0, 0], [[5, 0]], [[0, 0]], [3.0], bad)
    with pytest.raises(ValueError):
        escape_point([0, 0], [bad, 0], 1.0, 0.0)
    with pytest.raises(ValueError):
        via_point_candidates([0, 0], [[5, 0]], [[0, 0]], [3.0], 0.0)  # no cone


coord = st.floats(-20, 20, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(
    st.tuples(coord, coord),
    st.tuples(coord, coord),
    st.tuples(st.floats(-3, 3), st.floats(-3, 3)),
    st.floats(0.05, 3.0),
    st.floats(0.05, 3.0),
)
def test_property_feasible_candidates_are_on_the_cone_and_the_moving_disc(p, c, v, radius, speed):
    cands = via_point_candidates(p, [c], [v], [radius], speed)
    assert np.all(np.isfinite(cands.point_m))
    assert not np.any(np.isnan(cands.time_s))
    for idx in np.flatnonzero(cands.feasible[0]):
        lam = cands.time_s[0, idx]
        via = cands.point_m[0, idx]
        scale = 1.0 + np.hypot(*via) + speed * lam
        # Reached at full speed at lam ...
        assert math.dist(via, p) == pytest.approx(speed * lam, abs=1e-7 * scale)
        # ... exactly when the moving disc's boundary is there.
        centre = np.array(c) + lam * np.array(v)
        assert math.dist(via, centre) == pytest.approx(radius, abs=1e-7 * scale)


@settings(max_examples=200, deadline=None)
@given(st.tuples(coord, coord), st.tuples(coord, coord), st.floats(0.05, 3.0))
def test_property_tangent_points_touch_the_disc_at_right_angles(p, c, radius):
    points, outside = tangent_points(p, [c], [radius])
    if not outside[0]:
        return
    q = math.dist(p, c)
    if q < radius * (1 + 1e-6):
        return  # grazing: M ~ 0, the right angle is numerically meaningless
    for s in points[0]:
        assert math.dist(s, c) == pytest.approx(radius, rel=1e-7, abs=1e-9)
        radial, chord = s - np.array(c), s - np.array(p)
        assert abs(radial @ chord) <= 1e-7 * (1 + q * q)


# --- escape ---------------------------------------------------------------------------


def test_escape_straight_out_along_p_minus_c():
    out = escape_point([1.0, 0.0], [0.0, 0.0], 2.0, heading_rad=1.0)
    np.testing.assert_allclose(out, [2.0 + ESCAPE_MARGIN_M, 0.0])


def test_escape_when_coincident_goes_to_the_right_of_the_heading():
    out = escape_point([3.0, 3.0], [3.0, 3.0], 1.0, heading_rad=0.0)
    np.testing.assert_allclose(out, [3.0, 3.0 - 1.0 - ESCAPE_MARGIN_M], atol=1e-12)
    out = escape_point([0.0, 0.0], [0.0, 0.0], 1.0, heading_rad=math.pi / 2)
    np.testing.assert_allclose(out, [1.0 + ESCAPE_MARGIN_M, 0.0], atol=1e-12)
    assert np.all(np.isfinite(out))


def test_escape_from_several_discs_leaves_all_of_them_not_into_the_next():
    from agent.planning.viapoints import escape_point_many

    # Squeezed between two discs of L = 1.3 whose centres are 1.05 m apart (the robot 0.05 m
    # from the east one, 1.0 m from the west one): straight out of the deepest leads into
    # the other; the combined escape leaves both, sideways.
    p = np.array([0.0, 0.0])
    centres = np.array([[-1.0, 0.0], [0.05, 0.9]])
    radii = np.array([1.3, 1.3])
    single = escape_point(p, centres[1], 1.3, 0.0)
    assert math.dist(single, centres[0]) < 1.3  # straight out of one, still in the other
    out = escape_point_many(p, centres, radii, heading_rad=0.0)
    for c, r in zip(centres, radii):
        assert math.dist(out, c) >= r + ESCAPE_MARGIN_M - 1e-9
    # the direction moves away from both centres
    d = out - p
    assert all(d @ (p - c) > 0.0 for c in centres)
    # one disc: escape_point itself
    np.testing.assert_allclose(escape_point_many(p, centres[:1], radii[:1], 0.0),
                               escape_point(p, centres[0], 1.3, 0.0))
    # a symmetric squeeze (the pulls cancel): across it, to the right of the heading (+x)
    sym = np.array([[-0.5, 0.0], [0.5, 0.0]])
    out = escape_point_many(p, sym, radii, heading_rad=0.0)
    assert out[0] == pytest.approx(0.0, abs=1e-12) and out[1] < 0.0
    assert min(math.dist(out, c) for c in sym) == pytest.approx(1.3 + ESCAPE_MARGIN_M)
    with pytest.raises(ValueError, match="no disc"):
        escape_point_many(p, np.zeros((0, 2)), np.zeros(0), 0.0)
