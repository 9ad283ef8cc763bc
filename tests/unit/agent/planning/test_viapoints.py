"""Tangent points (Eqs. 8-11), velocity-cone feasibility (Eqs. 12-14) and escape points.

`candidate_pair` computes the tangent points without trigonometry and solves the cone
quadratic with the cancellation-free root formula; `paper_via_points` below writes the same
equations the way the paper does (atan2, asin, cos and sin, the textbook quadratic roots)
and is the reference it is checked against.
"""

import math
from typing import NamedTuple

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from agent.core.types import Side
from agent.planning.viapoints import (
    ESCAPE_MARGIN_M,
    SIDES,
    candidate_pair,
    escape_point,
    inflated_radius,
)
from tests.examples import examples

RIGHT, LEFT = SIDES.index(Side.RIGHT), SIDES.index(Side.LEFT)


class PaperCandidate(NamedTuple):
    """One candidate of `paper_via_points`."""

    x: float
    y: float
    lam: float
    """lambda* [s]; inf where the cone has no positive root (or it is past the cap)."""
    rel_disc: float
    """The quadratic's discriminant over b^2 + |4ac|: near 0, a nearly double root."""


def paper_via_points(p, c, v, radius, speed, margin=0.0, max_time=math.inf):
    """Eqs. (8)-(14) as the paper writes them: None inside the disc, else the RIGHT (S1) and
    LEFT (S2) `PaperCandidate`, at the raw tangent point where infeasible. A feasible
    via-point is pushed `margin` radially out of the disc where it is at lambda* (centre
    c + lambda* v)."""
    (xp, yp), (xc, yc), (vx, vy) = p, c, v
    q = math.hypot(xc - xp, yc - yp)  # Eq. (8)
    if q <= radius:
        return None
    alpha = math.atan2(yc - yp, xc - xp)  # Eq. (9)
    theta = math.asin(radius / q)
    m = math.sqrt(q * q - radius * radius)
    out = []
    for angle in (alpha - theta, alpha + theta):  # S1 (Eq. 10), S2 (Eq. 11)
        sx, sy = xp + m * math.cos(angle), yp + m * math.sin(angle)
        # Eq. (12) the line (sx, sy, 0) + lambda (vx, vy, 1), Eq. (13) the cone
        # (x - xp)^2 + (y - yp)^2 = r^2 z^2, Eq. (14) the quadratic in lambda.
        a = vx * vx + vy * vy - speed * speed
        b = 2.0 * ((sx - xp) * vx + (sy - yp) * vy)
        cc = (sx - xp) ** 2 + (sy - yp) ** 2
        disc = b * b - 4.0 * a * cc
        roots = [] if disc < 0.0 else [(-b - math.sqrt(disc)) / (2.0 * a),
                                       (-b + math.sqrt(disc)) / (2.0 * a)]
        lam = min((r for r in roots if r > 0.0), default=math.inf)
        if lam > max_time:
            lam = math.inf
        rel_disc = disc / (b * b + abs(4.0 * a * cc))
        if math.isinf(lam):
            out.append(PaperCandidate(sx, sy, lam, rel_disc))
        else:
            grow = (radius + margin) / radius
            out.append(PaperCandidate(xc + lam * vx + grow * (sx - xc),
                                      yc + lam * vy + grow * (sy - yc), lam, rel_disc))
    return tuple(out)


def test_sides_order_is_right_then_left():
    assert SIDES == (Side.RIGHT, Side.LEFT)


def test_inflated_radius_is_the_sum_eq8():
    np.testing.assert_allclose(inflated_radius(0.2, np.array([0.2, 0.5]), 0.3), [0.7, 1.0])


def test_tangent_points_by_hand():
    # P = (0, 0), c = (5, 0), L = 3: Q = 5, M = 4, theta = asin(3/5); S = 4 (cos, sin)(-+theta).
    # A static disc: the via-points are the tangent points themselves, met at M / r.
    right, left = candidate_pair(0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 3.0, 2.0)
    assert right == pytest.approx((3.2, -2.4, 2.0), abs=1e-12)  # alpha - theta
    assert left == pytest.approx((3.2, 2.4, 2.0), abs=1e-12)  # alpha + theta


def test_tangent_points_of_an_obstacle_behind_follow_eq10_and_eq11():
    # alpha = pi: RIGHT at pi - theta is (-3.2, +2.4), LEFT at pi + theta is (-3.2, -2.4).
    right, left = candidate_pair(1.0, 1.0, -4.0, 1.0, 0.0, 0.0, 3.0, 1.0)
    assert right[:2] == pytest.approx((1 - 3.2, 1 + 2.4), abs=1e-12)
    assert left[:2] == pytest.approx((1 - 3.2, 1 - 2.4), abs=1e-12)


def test_inside_or_on_the_disc_there_is_no_candidate():
    assert candidate_pair(0, 0, 0.5, 0, 0, 0, 1.0, 1.0) is None  # Q < L
    assert candidate_pair(0, 0, 0, 0, 0, 0, 1.0, 1.0) is None  # Q = 0
    assert candidate_pair(0, 0, 3, 0, 0, 0, 3.0, 1.0) is None  # Q = L


# --- the velocity cone ----------------------------------------------------------------


def test_head_on_obstacle_root_by_hand():
    # S = (3.2, -2.4) moves with v = (-1, 0); cone r = 2:
    # (1 - 4) lam^2 + 2 (S.v) lam + |S|^2 = -3 lam^2 - 6.4 lam + 16 = 0.
    lam = (-6.4 + math.sqrt(6.4**2 + 4 * 3 * 16)) / (2 * 3)
    (x, y, t), _ = candidate_pair(0.0, 0.0, 5.0, 0.0, -1.0, 0.0, 3.0, 2.0)
    assert t == pytest.approx(lam, rel=1e-12)
    assert (x, y) == pytest.approx((3.2 - lam, -2.4), abs=1e-12)
    # The robot reaches it at full speed exactly at lam.
    assert math.hypot(x, y) == pytest.approx(2.0 * lam, rel=1e-12)


def test_obstacle_as_fast_as_the_cone_is_the_linear_case():
    # |v_o| = r = 1: -6.4 lam + 16 = 0 -> lam = 2.5, via (0.7, -2.4), |via| = 2.5.
    (x, y, t), _ = candidate_pair(0.0, 0.0, 5.0, 0.0, -1.0, 0.0, 3.0, 1.0)
    assert t == pytest.approx(2.5, rel=1e-12)
    assert (x, y) == pytest.approx((0.7, -2.4), abs=1e-12)
    # Receding at exactly r: the linear root is negative -> dropped.
    away = candidate_pair(0.0, 0.0, 5.0, 0.0, 1.0, 0.0, 3.0, 1.0)
    assert all(math.isinf(t) for _, _, t in away)


def test_a_point_sliding_across_the_line_of_sight_at_the_robots_speed_is_never_met():
    # RIGHT's tangent point (3.2, -2.4) moves at r = 1 perpendicular to P -> S:
    # a = |v|^2 - r^2 = 0 and b = 2 S.v = 0, so |S|^2 = 0 has no root.
    (x, y, t), _ = candidate_pair(0.0, 0.0, 5.0, 0.0, 0.6, 0.8, 3.0, 1.0)
    assert math.isinf(t) and (x, y) == pytest.approx((3.2, -2.4), abs=1e-12)


def test_receding_faster_than_the_cone_is_dropped():
    pair = candidate_pair(0.0, 0.0, 5.0, 0.0, 3.0, 0.0, 3.0, 1.0)
    assert all(math.isinf(t) for _, _, t in pair)
    assert pair[RIGHT][:2] == pytest.approx((3.2, -2.4), abs=1e-12)  # the raw tangent point


def test_fast_obstacle_with_no_real_root_is_dropped():
    # A slow robot (r = 0.1) cannot meet tangent points sweeping past at 2 m/s.
    pair = candidate_pair(0.0, 0.0, 5.0, 0.0, -2.0, 0.0, 0.7, 0.1)
    assert all(math.isinf(t) for _, _, t in pair)


def test_margin_pushes_the_via_point_radially_out_of_the_moving_disc():
    # Static: the tangent point (3.2, -2.4) of the disc at (5, 0), L = 3, moved to L + 0.5.
    (x, y, t), _ = candidate_pair(0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 3.0, 2.0, margin_m=0.5)
    assert (x, y) == pytest.approx((5 - 1.8 * 3.5 / 3, -2.4 * 3.5 / 3), abs=1e-12)
    assert t == pytest.approx(2.0)  # lambda* is unchanged
    # Moving: pushed away from the centre where the disc is at lambda*.
    _, (x, y, lam) = candidate_pair(0.0, 0.0, 5.0, 0.0, -1.0, 0.0, 3.0, 2.0, margin_m=0.5)
    assert math.dist((x, y), (5 - lam, 0.0)) == pytest.approx(3.5)


def test_max_time_drops_a_tangent_point_that_recedes_almost_as_fast_as_the_robot():
    # A neighbour converging from the left at nearly the robot's speed (|v_o| = 1.10 of
    # 1.1 m/s, a = |v_o|^2 - r^2 = -0.0075 m^2/s^2): its RIGHT tangent point recedes along
    # its track and the cone meets it only at the far root, c / q ~ -b / a, hundreds of
    # seconds out; the LEFT one comes towards the robot and is met within 3 s.
    p, c, v, radius, speed, margin = (0.0, 0.0), (1.5, 2.5), (1.0, -0.45), 1.6, 1.1, 0.3
    assert v[0] ** 2 + v[1] ** 2 - speed**2 == pytest.approx(-0.0075)
    right, left = paper_via_points(p, c, v, radius, speed, margin)
    t_right, t_left = right.lam, left.lam
    assert t_right > 400.0 and t_left < 3.0
    (xr, yr, tr), (xl, yl, tl) = candidate_pair(*p, *c, *v, radius, speed, margin)
    assert tr == pytest.approx(t_right, rel=1e-9) and math.hypot(xr, yr) > 400.0
    assert tl == pytest.approx(t_left, rel=1e-12)
    (xr8, yr8, tr8), left8 = candidate_pair(*p, *c, *v, radius, speed, margin, max_time_s=8.0)
    assert math.isinf(tr8)
    assert math.hypot(xr8, yr8) < 3.0  # the raw tangent point, as for any infeasible one
    assert left8 == (xl, yl, tl)  # under the cap: unchanged
    (_, _, tr2), (_, _, tl2) = candidate_pair(*p, *c, *v, radius, speed, margin, max_time_s=2.0)
    assert math.isinf(tr2) and math.isinf(tl2)


coord = st.floats(-20, 20, allow_nan=False)
velocity = st.tuples(st.floats(-3, 3), st.floats(-3, 3))


@settings(max_examples=examples(500), deadline=None)
@given(
    p=st.tuples(coord, coord),
    c=st.tuples(coord, coord),
    v=velocity,
    radius=st.floats(0.05, 3.0),
    speed=st.floats(0.05, 3.0),
    margin=st.one_of(st.just(0.0), st.floats(0.0, 0.5)),
    max_time=st.one_of(st.just(math.inf), st.floats(0.1, 20.0)),
)
def test_property_candidate_pair_is_the_papers_construction(p, c, v, radius, speed, margin,
                                                            max_time):
    pair = candidate_pair(*p, *c, *v, radius, speed, margin, max_time)
    q = math.dist(p, c)
    if q <= radius:
        assert pair is None
        return
    # Away from where the textbook form loses digits: grazing (M ~ 0), a nearly linear
    # quadratic (|v_o| ~ r), a nearly double root, or lambda* at the cap.
    assume(q > radius * (1.0 + 1e-3))
    assume(abs(v[0] ** 2 + v[1] ** 2 - speed**2) > 1e-3 * speed**2)
    for uncapped in paper_via_points(p, c, v, radius, speed, margin, math.inf):
        assume(abs(uncapped.rel_disc) > 1e-9)
        assume(math.isinf(uncapped.lam) or uncapped.lam < 1e3)
        assume(math.isinf(uncapped.lam) or abs(uncapped.lam - max_time) > 1e-6 * max_time)
    paper = paper_via_points(p, c, v, radius, speed, margin, max_time)
    assert pair is not None
    scale = 1.0 + q + math.hypot(*v) * max((s.lam for s in paper if math.isfinite(s.lam)),
                                           default=0.0)
    for (x, y, lam), expected in zip(pair, paper, strict=True):
        if math.isinf(expected.lam):
            assert math.isinf(lam)
        else:
            assert lam == pytest.approx(expected.lam, rel=1e-6)
        assert (x, y) == pytest.approx((expected.x, expected.y), abs=1e-6 * scale)


@settings(max_examples=examples(300), deadline=None)
@given(st.tuples(coord, coord), st.tuples(coord, coord), velocity, st.floats(0.05, 3.0),
       st.floats(0.05, 3.0))
def test_property_feasible_candidates_are_on_the_cone_and_the_moving_disc(p, c, v, radius, speed):
    pair = candidate_pair(*p, *c, *v, radius, speed)
    if pair is None:
        return
    for x, y, lam in pair:
        assert math.isfinite(x) and math.isfinite(y) and not math.isnan(lam)
        if math.isinf(lam):
            continue
        scale = 1.0 + math.hypot(x, y) + speed * lam
        # Reached at full speed at lam ...
        assert math.dist((x, y), p) == pytest.approx(speed * lam, abs=1e-7 * scale)
        # ... exactly when the moving disc's boundary is there.
        centre = (c[0] + lam * v[0], c[1] + lam * v[1])
        assert math.dist((x, y), centre) == pytest.approx(radius, abs=1e-7 * scale)


@settings(max_examples=examples(200), deadline=None)
@given(st.tuples(coord, coord), st.tuples(coord, coord), st.floats(0.05, 3.0))
def test_property_tangent_points_touch_the_disc_at_right_angles(p, c, radius):
    q = math.dist(p, c)
    assume(q > radius * (1 + 1e-6))  # grazing: M ~ 0, the right angle is numerically meaningless
    # A static disc: the via-points are the tangent points.
    for x, y, _ in candidate_pair(*p, *c, 0.0, 0.0, radius, 1.0):
        assert math.dist((x, y), c) == pytest.approx(radius, rel=1e-7, abs=1e-9)
        radial, chord = np.subtract((x, y), c), np.subtract((x, y), p)
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


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_escape_input_raises(bad):
    with pytest.raises(ValueError):
        escape_point([0, 0], [bad, 0], 1.0, 0.0)


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
