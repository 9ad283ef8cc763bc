"""The reference: natural cubic spline by chord length, timed by the speed profile."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

from agent.planning.spline import (
    NaturalCubicSpline,
    build_reference,
    dedup_waypoints,
    distance_profile,
    polyline_point_ahead,
    reference_point_ahead,
)
from tests.examples import examples

V_MAX, ACCEL, DT, N = 1.1, 1.5, 0.1, 20


def steps(ref):
    return np.hypot(np.diff(ref.x_m), np.diff(ref.y_m))


def test_spline_matches_scipy_natural_cubic_spline():
    pts = np.array([[0, 0], [2, -1], [4, -1.2], [6, 0.5], [10, 0.0]])
    spline = NaturalCubicSpline([complex(x, y) for x, y in pts])
    u = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))))
    np.testing.assert_allclose(spline.knots, u, atol=1e-12)
    ref = CubicSpline(u, pts, bc_type="natural")
    grid = np.linspace(0, u[-1], 97)
    p, dp, ddp = spline.evaluate(grid)
    np.testing.assert_allclose(np.c_[p.real, p.imag], ref(grid), atol=1e-10)
    np.testing.assert_allclose(np.c_[dp.real, dp.imag], ref(grid, 1), atol=1e-10)
    np.testing.assert_allclose(np.c_[ddp.real, ddp.imag], ref(grid, 2), atol=1e-9)


def test_spline_passes_through_the_waypoints():
    pts = [0j, 1 + 2j, 3 + 2j, 4 - 1j]
    spline = NaturalCubicSpline(pts)
    p, _, ddp = spline.evaluate(spline.knots)
    np.testing.assert_allclose(p, pts, atol=1e-12)
    assert abs(ddp[0]) < 1e-12 and abs(ddp[-1]) < 1e-12  # natural ends


def test_straight_line_from_two_waypoints():
    ref = build_reference(np.array([[1.0, 1.0], [11.0, 1.0]]), 0.0, V_MAX, ACCEL, DT, N)
    assert ref.t_s.shape == (N + 1,) and ref.n_steps == N
    np.testing.assert_allclose(ref.t_s, DT * np.arange(N + 1))
    np.testing.assert_allclose(ref.x_m, 1.0 + V_MAX * ref.t_s, atol=1e-12)
    np.testing.assert_allclose(ref.y_m, 1.0)
    np.testing.assert_allclose(ref.heading_rad, 0.0, atol=1e-12)
    np.testing.assert_allclose(ref.v_mps, V_MAX)
    np.testing.assert_allclose(ref.omega_radps, 0.0, atol=1e-12)
    assert ref.length_m == pytest.approx(10.0)
    np.testing.assert_allclose(ref.states()[:, 0], ref.x_m)


def test_curved_path_passes_the_waypoints_at_the_requested_speed():
    wps = np.array([[0, 0], [1.0, 0.6], [2.0, 0.6], [3.0, 0.0]])
    ref = build_reference(wps, 0.3, V_MAX, ACCEL, DT, 60)
    # Every waypoint is visited (within one step's length).
    for w in wps:
        assert np.min(np.hypot(ref.x_m - w[0], ref.y_m - w[1])) < V_MAX * DT / 2 + 1e-9
    # Distance between samples follows the profile: the mean speed over each step
    # (chord vs arc: curvature ~1/m, steps 0.11 m -> well under 1 %).
    mean_v = 0.5 * (ref.v_mps[1:] + ref.v_mps[:-1])
    moving = mean_v > 0.2
    np.testing.assert_allclose(steps(ref)[moving], mean_v[moving] * DT, rtol=1e-2)
    assert np.all(ref.v_mps <= V_MAX + 1e-12) and ref.v_mps[0] == pytest.approx(V_MAX)
    # Heading follows the direction of travel; the arch over the top is a right turn.
    travel = np.arctan2(np.diff(ref.y_m), np.diff(ref.x_m))
    np.testing.assert_allclose(ref.heading_rad[1:25], travel[1:25], atol=0.06)
    assert np.all(ref.omega_radps[3:25] < 0.0)


def test_omega_sign_and_size_on_a_left_turn():
    # Nine points on a half circle of radius 2, driven counter-clockwise at 1 m/s: away
    # from the natural (straight) ends, omega = v / radius = 0.5 rad/s.
    a = np.linspace(-math.pi / 2, math.pi / 2, 9)
    wps = np.c_[2 * np.cos(a), 2 + 2 * np.sin(a)]
    ref = build_reference(wps, 0.0, 1.0, ACCEL, DT, 60)
    mid = slice(20, 41)  # 2 m .. 4 m along a 6.3 m arc
    np.testing.assert_allclose(ref.omega_radps[mid], 0.5, rtol=0.03)
    mirrored = build_reference(wps * [1, -1], 0.0, 1.0, ACCEL, DT, 60)  # clockwise
    np.testing.assert_allclose(mirrored.omega_radps, -ref.omega_radps, atol=1e-12)


def test_goal_inside_the_horizon_stops_there_and_holds():
    ref = build_reference(np.array([[0.0, 0.0], [0.5, 0.0]]), 0.0, V_MAX, ACCEL, DT, N)
    assert ref.x_m[-1] == pytest.approx(0.5) and ref.v_mps[-1] == 0.0
    stopped = ref.v_mps == 0.0
    assert stopped[-5:].all()
    np.testing.assert_allclose(ref.x_m[stopped], 0.5, atol=1e-12)
    assert np.all(np.diff(ref.v_mps) <= 1e-12)  # slows down monotonically
    # Never faster than the stopping profile sqrt(2 a d_remaining).
    assert np.all(ref.v_mps <= np.sqrt(2 * ACCEL * (0.5 - ref.s_m)) + 1e-9)
    assert np.all(np.diff(ref.s_m) >= 0.0)


def test_distance_profile_closed_form():
    t = np.arange(41) * 0.05
    s, v = distance_profile(t, 3.0, 1.0, 1.0, v_start_mps=0.0)  # ramp, cruise, brake
    assert v[0] == 0.0 and v[10] == pytest.approx(0.5)  # accelerating at 1 m/s^2
    assert s[10] == pytest.approx(0.125)  # a t^2 / 2
    assert v[30] == pytest.approx(1.0) and s[30] == pytest.approx(0.5 + 0.5)
    # Stops at S = 3 at t = 1 + 1 + 1 = 3 s (beyond this window); s stays below S.
    assert np.all(s <= 3.0)
    s, v = distance_profile(np.arange(60) * 0.1, 1.0, 1.0, 1.0, v_start_mps=0.0)
    # Triangle: peak 1 m/s at s = 0.5 (t = 1 s), stop at t = 2 s, S = 1.
    assert v.max() == pytest.approx(1.0)
    assert s[20:].tolist() == pytest.approx([1.0] * 40)
    assert v[20:].tolist() == [0.0] * 40
    s, v = distance_profile(np.arange(5) * 0.1, 0.0, 1.0, 1.0)  # already there
    assert s.tolist() == [0.0] * 5 and v.tolist() == [0.0] * 5


def test_ramp_from_the_current_speed():
    ref = build_reference(np.array([[0, 0], [20.0, 0]]), 0.0, V_MAX, ACCEL, DT, N, v_start_mps=0.2)
    assert ref.v_mps[0] == pytest.approx(0.2)
    np.testing.assert_allclose(np.diff(ref.v_mps[:6]), ACCEL * DT)
    assert ref.v_mps[-1] == pytest.approx(V_MAX)


def test_duplicate_and_near_duplicate_waypoints_are_dropped():
    clean = np.array([[0.0, 0.0], [3.0, 0.0], [6.0, 1.0]])
    messy = np.array([[0.0, 0.0], [0.0, 0.0], [3.0, 0.0], [3.0, 1e-7], [6.0, 1.0], [6.0, 1.0]])
    np.testing.assert_array_equal(dedup_waypoints(messy), [[0, 0], [3, 0], [6, 1]])
    a = build_reference(clean, 0.0, V_MAX, ACCEL, DT, N)
    b = build_reference(messy, 0.0, V_MAX, ACCEL, DT, N)
    np.testing.assert_allclose(a.x_m, b.x_m)
    np.testing.assert_allclose(a.y_m, b.y_m, atol=1e-12)
    # A near-duplicate goal replaces the last via-point, the robot is always kept.
    np.testing.assert_array_equal(
        dedup_waypoints(np.array([[0, 0], [2, 0], [2, 5e-4]])), [[0, 0], [2, 5e-4]]
    )
    np.testing.assert_array_equal(dedup_waypoints(np.array([[0, 0], [1e-4, 0]])), [[0, 0]])


def test_robot_at_goal_holds_still_with_its_heading():
    ref = build_reference(np.array([[1.0, 2.0], [1.0, 2.0]]), 0.7, V_MAX, ACCEL, DT, N)
    np.testing.assert_allclose(ref.x_m, 1.0)
    np.testing.assert_allclose(ref.y_m, 2.0)
    np.testing.assert_allclose(ref.heading_rad, 0.7)
    assert np.all(ref.v_mps == 0.0) and np.all(ref.omega_radps == 0.0)
    assert ref.length_m == 0.0


def test_heading_is_unwrapped_and_starts_near_the_robot_heading():
    # Driving towards -x (heading pi) with the robot's heading reported as 3 pi - 0.1.
    ref = build_reference(np.array([[0, 0], [-5.0, 0.0]]), 3 * math.pi - 0.1, V_MAX, ACCEL, DT, N)
    np.testing.assert_allclose(ref.heading_rad, 3 * math.pi, atol=1e-9)
    # A path that turns through +-pi stays continuous.
    wps = np.array([[0, 0], [2, 0], [3, 1], [2, 2], [0, 2], [-1, 1]])
    ref = build_reference(wps, 0.0, V_MAX, ACCEL, DT, 80)
    assert np.max(np.abs(np.diff(ref.heading_rad))) < 0.5
    assert ref.heading_rad.max() > math.pi  # went past pi without wrapping to -pi


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_input_raises(bad):
    with pytest.raises(ValueError):
        build_reference(np.array([[0, 0], [bad, 1.0]]), 0.0, V_MAX, ACCEL, DT, N)
    with pytest.raises(ValueError):
        build_reference(np.array([[0, 0], [1.0, 1.0]]), bad, V_MAX, ACCEL, DT, N)
    with pytest.raises(ValueError):
        build_reference(np.array([[0, 0], [1.0, 1.0]]), 0.0, V_MAX, ACCEL, DT, N, v_start_mps=bad)


def test_bad_shapes_and_limits_raise():
    with pytest.raises(ValueError):
        build_reference(np.zeros((3, 3)), 0.0, V_MAX, ACCEL, DT, N)
    with pytest.raises(ValueError):
        build_reference(np.zeros((0, 2)), 0.0, V_MAX, ACCEL, DT, N)
    with pytest.raises(ValueError):
        build_reference(np.array([[0, 0], [1.0, 0]]), 0.0, 0.0, ACCEL, DT, N)
    with pytest.raises(ValueError):
        build_reference(np.array([[0, 0], [1.0, 0]]), 0.0, V_MAX, ACCEL, DT, 0)


def test_points_ahead():
    ref = build_reference(np.array([[0, 0], [10.0, 0]]), 0.0, 1.0, ACCEL, DT, N)
    np.testing.assert_allclose(reference_point_ahead(ref, 0.55), [0.55, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(reference_point_ahead(ref, 99.0), [2.0, 0.0, 0.0], atol=1e-12)
    wps = np.array([[0, 0], [3.0, 0], [3.0, 4.0]])
    np.testing.assert_allclose(polyline_point_ahead(wps, 5.0), [3.0, 2.0])
    np.testing.assert_allclose(polyline_point_ahead(wps, 50.0), [3.0, 4.0])
    np.testing.assert_allclose(polyline_point_ahead(wps, -1.0), [0.0, 0.0])
    np.testing.assert_allclose(polyline_point_ahead(wps[:1], 2.0), [0.0, 0.0])


coord = st.floats(-20, 20, allow_nan=False)


@settings(max_examples=examples(150), deadline=None)
@given(
    st.lists(st.tuples(coord, coord), min_size=1, max_size=6),
    st.floats(-10, 10),
    st.floats(0.1, 2.0),
    st.one_of(st.none(), st.floats(0, 3)),
)
def test_property_finite_waypoints_give_a_finite_reference(wps, heading, v_max, v_start):
    wps = np.array(wps)
    ref = build_reference(wps, heading, v_max, ACCEL, DT, N, v_start_mps=v_start)
    for arr in (ref.x_m, ref.y_m, ref.heading_rad, ref.v_mps, ref.omega_radps, ref.s_m):
        assert arr.shape == (N + 1,) and np.all(np.isfinite(arr))
    assert ref.x_m[0] == pytest.approx(wps[0, 0], abs=1e-9)
    assert ref.y_m[0] == pytest.approx(wps[0, 1], abs=1e-9)
    assert np.all(ref.v_mps >= 0.0) and np.all(ref.v_mps <= v_max + 1e-12)
    assert np.all(np.diff(ref.s_m) >= -1e-12) and ref.s_m[-1] <= ref.length_m + 1e-9
    assert abs(ref.heading_rad[0] - heading) <= math.pi + 1e-9


def test_clamped_start_matches_scipy_and_leaves_along_the_heading():
    from scipy.interpolate import CubicSpline

    from agent.planning.spline import NaturalCubicSpline

    pts = [0j, 3 + 1j, 5 - 2j, 9 + 0.5j]
    tangent = complex(math.cos(0.3), math.sin(0.3))
    ours = NaturalCubicSpline(pts, tangent)
    ref = CubicSpline(ours.knots, np.array(pts), bc_type=((1, tangent), (2, 0.0)))
    u = np.linspace(0.0, ours.knots[-1], 57)
    p, dp, _ = ours.evaluate(u)
    np.testing.assert_allclose(p, ref(u), atol=1e-10)
    np.testing.assert_allclose(dp, ref(u, 1), atol=1e-10)
    assert dp[0] == pytest.approx(tangent)


def test_clamp_heading_only_with_a_via_point_ahead():
    from agent.planning.spline import build_reference

    wp = np.array([[0.0, 0.0], [4.0, 1.0], [10.0, 0.0]])  # 14 degrees off the heading
    natural = build_reference(wp, 0.0, 1.0, 1.0, 0.1, 20)
    clamped = build_reference(wp, 0.0, 1.0, 1.0, 0.1, 20, clamp_heading=True)
    assert abs(clamped.heading_rad[0]) < 1e-9 < abs(natural.heading_rad[0])
    # A via-point 45 degrees off the heading, or behind: a sharp turn starts natural.
    for heading in (-0.25 * math.pi + math.atan2(1.0, 4.0), math.pi):
        sharp = build_reference(wp, heading, 1.0, 1.0, 0.1, 20, clamp_heading=True)
        np.testing.assert_allclose(sharp.heading_rad[0] - 2 * math.pi * round(
            sharp.heading_rad[0] / (2 * math.pi)), natural.heading_rad[0], atol=1e-12)


# --- lines and arcs (`LineArcPath`, `build_reference(lines_arcs=True)`) -------------------


def dense(path, step_m=0.01):
    s = np.arange(0.0, path.length_m + step_m, step_m)
    p, heading = path.evaluate(s)
    return s, p, np.unwrap(heading)


def test_line_arc_path_runs_along_the_legs_and_rounds_the_corner():
    from agent.planning.spline import LineArcPath

    # Robot heading along its first leg (no start arc), via-point (6, 1.5), goal (40, 0).
    pts = [0j, 6 + 1.5j, 40 + 0j]
    leg_in, leg_out = pts[1] / abs(pts[1]), (pts[2] - pts[1]) / abs(pts[2] - pts[1])
    path = LineArcPath(pts, math.atan2(1.5, 6.0), corner_radius_m=1.0, start_radius_m=5.0)
    delta = abs(np.angle(leg_out / leg_in))
    cut = math.tan(0.5 * delta)  # R tan(delta / 2), R = 1
    s, p, heading = dense(path)
    # On the legs the path is the leg itself, up to the corner's arc.
    first = s < abs(pts[1]) - cut
    assert np.abs((p[first] * leg_in.conjugate()).imag).max() < 1e-9
    last = s > path.length_m - (abs(pts[2] - pts[1]) - cut)
    assert np.abs(((p[last] - pts[1]) * leg_out.conjugate()).imag).max() < 1e-9
    # The arc is tangent to both legs: it passes the via-point at R (1 / cos(delta/2) - 1).
    assert np.abs(p - pts[1]).min() == pytest.approx(1.0 / math.cos(0.5 * delta) - 1.0, abs=1e-3)
    # Continuous in position and heading; it ends at the goal, shorter than the polyline.
    assert np.abs(np.diff(p)).max() < 0.0101 and np.abs(np.diff(heading)).max() < 0.011
    assert p[-1] == pytest.approx(pts[2])
    assert path.length_m < abs(pts[1]) + abs(pts[2] - pts[1])


def test_line_arc_path_with_zero_corner_radius_is_the_polyline():
    from agent.planning.spline import LineArcPath

    wp = np.array([[0.0, 0.0], [3.0, 2.0], [5.0, -1.0], [9.0, 0.0]])
    path = LineArcPath([complex(x, y) for x, y in wp], math.atan2(2.0, 3.0), 0.0, 0.0)
    for d in (0.5, 3.6, 4.0, 7.0, path.length_m):
        p, _ = path.evaluate(np.array([d]))
        np.testing.assert_allclose([p[0].real, p[0].imag], polyline_point_ahead(wp, d),
                                   atol=1e-12)


def test_line_arc_corners_between_short_legs_share_them():
    from agent.planning.spline import LineArcPath

    # A short polygon round a disc (legs of 0.6 m turning by 40 degrees): each corner may
    # use at most half of a leg between two via-points, so the arcs join into a curve.
    turn = np.exp(1j * np.radians(40.0))
    pts = [0j, 4 + 0j]
    for _ in range(3):
        step = (pts[-1] - pts[-2]) / abs(pts[-1] - pts[-2]) * turn * 0.6
        pts.append(pts[-1] + step)
    pts.append(pts[-1] + (pts[-1] - pts[-2]) / 0.6 * 5.0)
    path = LineArcPath(pts, 0.0, corner_radius_m=5.0, start_radius_m=0.0)
    s, p, heading = dense(path, 0.005)
    assert np.abs(np.diff(p)).max() < 0.0051  # no gap where two corners meet
    assert np.abs(np.diff(heading)).max() < 0.03  # and no kink
    assert heading[-1] - heading[0] == pytest.approx(3 * np.angle(turn), abs=1e-9)
    assert p[-1] == pytest.approx(pts[-1])


@pytest.mark.parametrize("off_deg", [10.0, -20.0])
def test_line_arc_start_arc_leaves_along_the_heading(off_deg):
    from agent.planning.spline import LineArcPath

    # Via-point ahead on the x axis, robot heading off_deg off it: the path starts along
    # the heading (like the clamped spline), turns towards the leg on a 5 m arc, runs
    # straight back onto the leg and meets it where the corner's arc begins.
    pts = [0j, 12 + 0j, 30 + 6j]
    heading = math.radians(off_deg)
    toward = -math.copysign(1.0, heading)  # the sense of the turn back to the leg
    path = LineArcPath(pts, heading, corner_radius_m=1.0, start_radius_m=5.0)
    s, p, h = dense(path, 0.001)
    assert h[0] == pytest.approx(heading, abs=1e-12)
    assert (h[1] - h[0]) / 0.001 == pytest.approx(toward / 5.0)  # radius 5 m
    corner_start = 12.0 - math.tan(0.5 * math.atan2(6.0, 18.0))
    back = np.argmax(p.real >= corner_start)
    assert abs(p[back].imag) < 2e-3  # back on the leg before the corner
    start_part = h[:back]
    assert np.all(toward * np.diff(start_part) >= -1e-12)  # one sense of turn, then straight
    assert toward * (start_part[-1] - start_part[0]) > abs(heading)  # past the leg's direction
    assert abs(start_part[-1]) < 0.25 * abs(heading)  # and back to it at a small kink
    assert np.abs(np.diff(p)).max() < 0.00101  # continuous


def test_line_arc_reference_times_the_path_without_turn_feed_forward():
    wp = np.array([[0.0, 0.0], [12.0, 0.0], [30.0, 6.0]])
    ref = build_reference(wp, 0.1, V_MAX, ACCEL, DT, 60, v_start_mps=V_MAX,
                          lines_arcs=True, corner_radius_m=1.0, start_radius_m=5.0)
    assert ref.heading_rad[0] == pytest.approx(0.1, abs=1e-12)
    np.testing.assert_array_equal(ref.omega_radps, 0.0)
    np.testing.assert_allclose(steps(ref), V_MAX * DT, atol=1e-5)  # the speed profile (chords)
    # 45 degrees off (or behind) is a sharp turn: the path starts along the leg.
    for sharp in (math.radians(45.0), math.pi):
        ref = build_reference(wp, sharp, V_MAX, ACCEL, DT, 20, lines_arcs=True)
        assert math.remainder(ref.heading_rad[0], 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
        assert abs(ref.heading_rad[0] - sharp) <= math.pi
    # The path ends at the goal and the reference stops there.
    long = build_reference(wp, 0.1, V_MAX, ACCEL, DT, 600, lines_arcs=True)
    assert (long.x_m[-1], long.y_m[-1], long.v_mps[-1]) == pytest.approx((30.0, 6.0, 0.0))


def test_line_arc_reference_without_via_points_is_the_straight_line():
    two = np.array([[0.0, 0.0], [10.0, 2.0]])
    a = build_reference(two, 0.3, V_MAX, ACCEL, DT, N, lines_arcs=True)
    b = build_reference(two, 0.3, V_MAX, ACCEL, DT, N)
    np.testing.assert_array_equal(a.x_m, b.x_m)
    np.testing.assert_array_equal(a.heading_rad, b.heading_rad)
    with pytest.raises(ValueError, match="radii"):
        build_reference(two, 0.0, V_MAX, ACCEL, DT, N, lines_arcs=True, corner_radius_m=-1.0)


@settings(max_examples=examples(300), deadline=None)
@given(steps=st.lists(st.floats(-20.0, 20.0) | st.sampled_from([math.pi, -math.pi,
                                                                  2 * math.pi, 0.0]),
                      min_size=0, max_size=30),
       start=st.floats(-100.0, 100.0))
def test_unwrap_is_numpys_bit_for_bit(steps: list[float], start: float) -> None:
    """The spline's own unwrap (`spline._unwrap`) gives exactly numpy's floats, steps of
    exactly +-pi included."""
    from agent.planning.spline import _unwrap

    heading = np.cumsum([start, *steps])
    assert _unwrap(heading).tobytes() == np.unwrap(heading).tobytes()


# --- stored samples (data/spline_reference.json) ------------------------------------------

SAMPLES = json.loads((Path(__file__).parent / "data" / "spline_reference.json").read_text())
"""`build_reference` on fixed inputs, every path (written by data/make_spline_reference.py)."""


@pytest.mark.parametrize("name", sorted(SAMPLES["cases"]))
def test_build_reference_reproduces_the_stored_samples(name: str) -> None:
    case = SAMPLES["cases"][name]
    inputs, expected = dict(case["inputs"]), case["expected"]
    ref = build_reference(np.array(inputs.pop("waypoints_m")), v_max_mps=SAMPLES["v_max_mps"],
                          accel_mps2=SAMPLES["accel_mps2"], dt_s=SAMPLES["dt_s"], **inputs)
    atol = SAMPLES["tolerance"]["atol"]
    for field in ("t_s", "x_m", "y_m", "heading_rad", "v_mps", "omega_radps", "s_m"):
        np.testing.assert_allclose(getattr(ref, field), expected[field], rtol=0, atol=atol,
                                   err_msg=f"{name}: {field}")
    assert ref.length_m == pytest.approx(expected["length_m"], rel=0, abs=atol)
