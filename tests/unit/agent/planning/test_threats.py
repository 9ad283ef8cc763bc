"""TCPA/DCPA (Eqs. 3-5), the threat test and ranking (Eqs. 6-7), the leg check, neighbours."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.types import Others, Threat
from agent.planning.threats import (
    leg_threats,
    legs_threats,
    nearby_others,
    rank_threats,
    tcpa_dcpa,
    threat_records,
)
from tests.examples import examples


def others(pos, vel, ids=None, radius=0.2):
    pos = np.asarray(pos, dtype=float).reshape(-1, 2)
    k = pos.shape[0]
    return Others(
        ids=np.arange(k) if ids is None else ids,
        position_m=pos,
        velocity_mps=np.asarray(vel, dtype=float).reshape(-1, 2),
        radius_m=np.full(k, radius),
        linearity=np.ones(k),
        track_start_m=pos,
        is_robot=np.ones(k, dtype=bool),
    )


def ranked_threats(position_m, velocity_mps, o, d_thresh_m, t_max_s):
    """The threats of Eq. (6) as typed records, most imminent first (Eq. 7), as the planner
    builds them (`ifp`: `rank_threats`, then `threat_records`)."""
    index, tcpa, dcpa = rank_threats(position_m, velocity_mps, o, d_thresh_m, t_max_s)
    return threat_records(index, tcpa, dcpa, o)


# --- Eqs. (3)-(5) ---------------------------------------------------------------------


def test_head_on_at_10m_closing_at_2mps():
    tcpa, dcpa = tcpa_dcpa([0, 0], [1, 0], [[10, 0]], [[-1, 0]])
    assert tcpa[0] == pytest.approx(5.0)
    assert dcpa[0] == pytest.approx(0.0, abs=1e-12)


def test_parallel_offset_keeps_its_lateral_distance():
    tcpa, dcpa = tcpa_dcpa([0, 0], [1, 0], [[10, 3]], [[-1, 0]])
    assert tcpa[0] == pytest.approx(5.0)
    assert dcpa[0] == pytest.approx(3.0)


def test_crossing_at_right_angles_meets_at_the_crossing():
    tcpa, dcpa = tcpa_dcpa([0, 0], [1, 0], [[5, -5]], [[0, 1]])
    assert tcpa[0] == pytest.approx(5.0)
    assert dcpa[0] == pytest.approx(0.0, abs=1e-12)


def test_receding_obstacle_has_negative_tcpa_and_is_no_threat():
    tcpa, dcpa = tcpa_dcpa([0, 0], [1, 0], [[10, 0]], [[2, 0]])
    assert tcpa[0] == pytest.approx(-10.0)
    assert dcpa[0] == pytest.approx(0.0, abs=1e-12)
    assert (
        ranked_threats(np.zeros(2), np.array([1.0, 0.0]), others([[10, 0]], [[2, 0]]), 1.3, 8.0)
        == ()
    )


def test_zero_relative_velocity_gives_tcpa_zero_and_current_distance():
    tcpa, dcpa = tcpa_dcpa([1, 1], [0.5, 0.5], [[4, 5]], [[0.5, 0.5]])
    assert tcpa[0] == 0.0
    assert dcpa[0] == pytest.approx(5.0)
    # Even touching: TCPA = 0 is not inside 0 < TCPA < T_max.
    near = others([[1.1, 1]], [[0.5, 0.5]])
    assert ranked_threats(np.array([1.0, 1.0]), np.array([0.5, 0.5]), near, 1.3, 8.0) == ()


def test_coincident_positions_are_finite():
    tcpa, dcpa = tcpa_dcpa([2, 2], [1, 0], [[2, 2], [2, 2]], [[1, 0], [0, 1]])
    assert np.all(np.isfinite(tcpa)) and np.all(np.isfinite(dcpa))
    assert tcpa.tolist() == [0.0, 0.0]
    assert dcpa == pytest.approx([0.0, 0.0])


def test_vectorised_over_others_matches_one_by_one():
    rng = np.random.default_rng(3)
    p_o, v_o = rng.normal(size=(7, 2)) * 5, rng.normal(size=(7, 2))
    tcpa, dcpa = tcpa_dcpa([0.3, -0.2], [0.8, 0.1], p_o, v_o)
    for j in range(7):
        t1, d1 = tcpa_dcpa([0.3, -0.2], [0.8, 0.1], p_o[j : j + 1], v_o[j : j + 1])
        assert t1[0] == pytest.approx(tcpa[j]) and d1[0] == pytest.approx(dcpa[j])


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_input_raises(bad):
    with pytest.raises(ValueError, match="non-finite"):
        tcpa_dcpa([0, bad], [1, 0], [[10, 0]], [[-1, 0]])
    with pytest.raises(ValueError, match="non-finite"):
        tcpa_dcpa([0, 0], [1, 0], [[10, 0]], [[-1, bad]])
    with pytest.raises(ValueError, match="non-finite"):
        ranked_threats(
            np.array([bad, 0.0]), np.array([1.0, 0.0]), others([[5, 0]], [[0, 0]]), 1.3, 8.0
        )
    with pytest.raises(ValueError, match="non-finite"):
        ranked_threats(np.zeros(2), np.array([1.0, 0.0]), others([[5, 0]], [[0, 0]]), bad, 8.0)


# --- Eqs. (6)-(7) ---------------------------------------------------------------------


def test_threat_condition_and_ranking_by_tcpa():
    o = others(
        [[10, 0], [4, 0.5], [6, 5], [30, 0], [-5, 0]],
        [[-1, 0], [0, 0], [0, 0], [0, 0], [0, 0]],
        ids=[10, 11, 12, 13, 14],
    )
    threats = ranked_threats(np.zeros(2), np.array([1.0, 0.0]), o, d_thresh_m=1.3, t_max_s=8.0)
    # 11: TCPA 4, DCPA 0.5 -> first; 10: TCPA 5, DCPA 0 -> second;
    # 12: DCPA 5 > 1.3; 13: TCPA 30 >= T_max; 14: behind, TCPA < 0.
    assert [t.other_id for t in threats] == [11, 10]
    assert threats[0] == Threat(other_id=11, tcpa_s=pytest.approx(4.0), dcpa_m=pytest.approx(0.5))
    assert threats[1].tcpa_s == pytest.approx(5.0)


def test_threshold_edges_dcpa_inclusive_tcpa_exclusive():
    o = others([[5, 1.3], [8, 0]], [[0, 0], [0, 0]])
    threats = ranked_threats(np.zeros(2), np.array([1.0, 0.0]), o, d_thresh_m=1.3, t_max_s=8.0)
    assert [t.other_id for t in threats] == [0]  # DCPA == D_thresh counts, TCPA == T_max not


def test_equal_tcpa_ties_break_by_id_whatever_the_order():
    pos = [[5, 0.5], [5, -0.5], [5, 0.0]]
    vel = [[0, 0]] * 3
    a = ranked_threats(np.zeros(2), np.array([1.0, 0]), others(pos, vel, ids=[9, 4, 7]), 1.3, 8.0)
    b = ranked_threats(
        np.zeros(2), np.array([1.0, 0]), others(pos[::-1], vel, ids=[7, 4, 9]), 1.3, 8.0
    )
    assert [t.other_id for t in a] == [4, 7, 9]
    assert a == b


def test_rank_threats_returns_indices_and_all_values():
    o = others([[10, 0], [0, 10]], [[-1, 0], [0, 0]])
    index, tcpa, dcpa = rank_threats(np.zeros(2), np.array([1.0, 0.0]), o, 1.3, 8.0)
    assert index.tolist() == [0]
    assert tcpa.shape == (2,) and dcpa.shape == (2,)
    assert tcpa[1] == pytest.approx(0.0) and dcpa[1] == pytest.approx(10.0)


def test_no_others_no_threats():
    assert ranked_threats(np.zeros(2), np.array([1.0, 0.0]), Others.empty(), 1.3, 8.0) == ()


finite = st.floats(-50, 50, allow_nan=False)


@settings(max_examples=examples(200), deadline=None)
@given(
    st.tuples(finite, finite),
    st.tuples(finite, finite),
    st.lists(st.tuples(finite, finite, finite, finite), min_size=1, max_size=8),
)
def test_property_finite_in_finite_out(p_r, v_r, rows):
    arr = np.array(rows)
    tcpa, dcpa = tcpa_dcpa(p_r, v_r, arr[:, :2], arr[:, 2:])
    assert np.all(np.isfinite(tcpa)) and np.all(np.isfinite(dcpa))
    assert np.all(dcpa >= 0.0)
    # The closest approach in the future is no farther than the current distance.
    now = np.hypot(*(arr[:, :2] - np.array(p_r)).T)
    ahead = tcpa > 0
    assert np.all(dcpa[ahead] <= now[ahead] + 1e-9 * (1 + now[ahead]))


grid = st.integers(-200, 200).map(lambda i: 0.25 * i)  # exact under shifts


@settings(max_examples=examples(100), deadline=None)
@given(
    st.tuples(grid, grid),
    st.lists(st.tuples(grid, grid, grid, grid), min_size=1, max_size=6),
    st.randoms(use_true_random=False),
)
def test_property_translation_and_permutation_invariant(shift, rows, rnd):
    arr = np.array(rows)
    o = others(arr[:, :2], arr[:, 2:])
    base = ranked_threats(np.zeros(2), np.array([0.75, 0.25]), o, 2.0, 8.0)
    order = list(range(len(rows)))
    rnd.shuffle(order)
    moved = others(arr[order, :2] + np.array(shift), arr[order, 2:], ids=np.array(order))
    other = ranked_threats(np.array(shift), np.array([0.75, 0.25]), moved, 2.0, 8.0)
    assert base == other


# --- the leg check --------------------------------------------------------------------


def test_leg_hits_a_static_obstacle_near_the_leg():
    o = others([[5, 0.5], [5, 1.0]], [[0, 0], [0, 0]])
    index, tcpa = leg_threats([0, 0], [10, 0], 1.0, 0.0, o, np.array([0.7, 0.7]), 8.0)
    assert index.tolist() == [0]  # 0.5 < 0.7; 1.0 is clear
    assert tcpa[0] == pytest.approx(5.0)


def test_leg_tcpa_is_limited_to_the_leg():
    # Dead ahead but 2 m past the leg's end: the closest point on the leg is 2 m away.
    o = others([[12, 0]], [[0, 0]])
    index, _ = leg_threats([0, 0], [10, 0], 1.0, 0.0, o, np.array([0.7]), 20.0)
    assert index.size == 0
    index, _ = leg_threats([0, 0], [10, 0], 1.0, 0.0, o, np.array([2.5]), 20.0)
    assert index.tolist() == [0]


def test_leg_start_time_advances_the_others():
    # Crossing at (5, 0): it is there at t = 7 s. A leg starting at t0 = 2 s passes
    # (5, 0) at t = 7 s; the same leg started now passes 2 m before it arrives.
    o = others([[5, -7]], [[0, 1]])
    hit, _ = leg_threats([0, 0], [10, 0], 1.0, 2.0, o, np.array([0.7]), 20.0)
    miss, _ = leg_threats([0, 0], [10, 0], 1.0, 0.0, o, np.array([0.7]), 20.0)
    assert hit.tolist() == [0] and miss.size == 0


def test_leg_horizon_exclusion_and_degenerate_legs():
    o = others([[5, 0]], [[0, 0]])
    clear = np.array([0.7])
    assert leg_threats([0, 0], [10, 0], 1.0, 0.0, o, clear, 8.0)[0].tolist() == [0]
    assert leg_threats([0, 0], [10, 0], 1.0, 0.0, o, clear, 4.0)[0].size == 0  # after T_max
    assert leg_threats([0, 0], [10, 0], 1.0, 9.0, o, clear, 8.0)[0].size == 0  # starts late
    assert leg_threats([0, 0], [10, 0], 1.0, 0.0, o, clear, 8.0, np.array([True]))[0].size == 0
    assert leg_threats([0, 0], [0, 0], 1.0, 0.0, o, clear, 8.0)[0].size == 0  # no length
    assert leg_threats([0, 0], [10, 0], 0.0, 0.0, o, clear, 8.0)[0].size == 0  # no speed
    with pytest.raises(ValueError):
        leg_threats([0, math.nan], [10, 0], 1.0, 0.0, o, clear, 8.0)


def test_leg_grazing_tangent_is_not_a_threat():
    # A leg tangent to the disc of radius 1 around (5, 1): closest approach exactly 1.
    o = others([[5, 1]], [[0, 0]])
    assert leg_threats([0, 0], [10, 0], 1.0, 0.0, o, np.array([1.0]), 20.0)[0].size == 0
    assert leg_threats([0, 0], [10, 0], 1.0, 0.0, o, np.array([1.0001]), 20.0)[0].size == 1


# --- neighbours -----------------------------------------------------------------------


def test_nearby_others_filters_caps_and_orders():
    o = others([[9, 0], [1, 0], [0, 11], [0, -1], [3, 0]], [[0, 0]] * 5, ids=[5, 6, 7, 8, 9])
    assert nearby_others(np.zeros(2), o, 10.0, 10).ids.tolist() == [6, 8, 9, 5]
    # Capped at 2 nearest; the tie between ids 6 and 8 (both at 1 m) is broken by id.
    assert nearby_others(np.zeros(2), o, 10.0, 2).ids.tolist() == [6, 8]


def test_nearby_others_returns_the_same_object_when_nothing_is_dropped():
    o = others([[1, 0], [2, 0]], [[0, 0]] * 2)
    assert nearby_others(np.zeros(2), o, 10.0, 5) is o
    assert len(nearby_others(np.zeros(2), Others.empty(), 10.0, 5)) == 0


def test_a_denormal_leg_gives_no_nan_and_no_warning():
    # Found by hypothesis in tests/agent/test_ifp.py: a goal 2.2e-313 m away made
    # speed / length overflow, and (b - a) * inf put 0 * inf = NaN into the relative velocity.
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        hit, tcpa = legs_threats(
            np.array([0j]), np.array([2.2250738585e-313j]), np.array([0.0]), 1.1,
            np.array([1.0 + 0j]), np.array([0j]), np.array([1.3]), 8.0)
    assert np.isfinite(tcpa).all()
    assert hit.shape == (1, 1)
