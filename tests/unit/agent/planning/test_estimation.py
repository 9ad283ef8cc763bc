"""Velocity, linearity and ghost-start estimates from observed poses only."""

import math

import numpy as np
import pytest

from agent.core.types import PoseSnapshot
from agent.planning.estimation import NeighborTracker


def snap(t, tick, rows):
    ids = [r[0] for r in rows]
    pose = [[r[1], r[2], 0.0] for r in rows]
    return PoseSnapshot(stamp_s=t, tick=tick, ids=ids, pose=pose, radius_m=[0.5] * len(rows))


def test_constant_velocity_is_recovered_exactly():
    tr = NeighborTracker(own_id=0, window_s=0.5)
    for k in range(8):
        t = 0.1 * k
        tr.update(snap(t, k, [(0, 0.0, 0.0), (1, 2.0 + 1.5 * t, -0.5 * t), (-1, 5.0, 5.0)]))
    o = tr.others()
    assert o.ids.tolist() == [1, -1]
    np.testing.assert_allclose(o.velocity_mps[0], [1.5, -0.5], atol=1e-9)
    np.testing.assert_allclose(o.velocity_mps[1], [0.0, 0.0], atol=1e-12)
    assert o.linearity[0] == pytest.approx(1.0)
    assert o.linearity[1] == 0.0  # never moved
    # Ghost start s_j is the oldest sample inside the 0.5 s window: t = 0.2.
    np.testing.assert_allclose(o.track_start_m[0], [2.0 + 1.5 * 0.2, -0.1], atol=1e-9)
    assert o.is_robot.tolist() == [True, False]


def test_turning_track_has_lower_linearity():
    tr = NeighborTracker(own_id=0, window_s=1.0, max_samples=12)
    for k in range(11):
        a = 0.3 * k  # a robot circling with radius 1
        tr.update(snap(0.1 * k, k, [(0, 0, 0), (3, math.cos(a), math.sin(a))]))
    o = tr.others()
    assert 0.3 < o.linearity[0] < 0.9


def test_single_sample_gives_zero_velocity():
    tr = NeighborTracker(own_id=0)
    tr.update(snap(0.0, 0, [(0, 0, 0), (1, 1, 1)]))
    o = tr.others()
    np.testing.assert_array_equal(o.velocity_mps, [[0.0, 0.0]])


def test_only_latest_discs_are_reported_and_new_ids_join():
    tr = NeighborTracker(own_id=0)
    tr.update(snap(0.0, 0, [(0, 0, 0), (1, 1, 1)]))
    tr.update(snap(0.1, 1, [(0, 0, 0), (2, 4, 4)]))
    o = tr.others()
    assert o.ids.tolist() == [2]
    assert len(NeighborTracker(own_id=0).others()) == 0


def test_rejects_bad_parameters():
    with pytest.raises(ValueError):
        NeighborTracker(0, window_s=0.0)
    with pytest.raises(ValueError):
        NeighborTracker(0, max_samples=1)


def test_fifty_hz_poses_keep_the_whole_window():
    # A distributed robot observes every world tick (50 Hz); the ring keeps samples about
    # window / (H - 2) apart, so the estimate still spans the 0.5 s window, not 8 ticks.
    tr = NeighborTracker(own_id=0, window_s=0.5, max_samples=8)
    for k in range(101):
        t = 0.02 * k
        tr.update(snap(t, k, [(1, 1.0 * t, 0.0)]))
    o = tr.others()
    age = 2.0 - o.track_start_m[0, 0]  # distance back at 1 m/s = age of the oldest sample
    assert 0.4 <= age <= 0.5 + 1e-9
    np.testing.assert_allclose(o.velocity_mps[0], [1.0, 0.0], atol=1e-9)
    # The newest sample is always the newest snapshot.
    tr.update(snap(2.01, 101, [(1, 5.0, 0.0)]))
    np.testing.assert_allclose(tr.others().position_m[0], [5.0, 0.0])

def test_estimates_only_within_a_distance_match_the_full_estimates():
    tr = NeighborTracker(own_id=0, window_s=0.5)
    for k in range(8):
        t = 0.1 * k
        # Disc 3 is in range, then leaves it; disc 2 is always far; ids change order once.
        rows = [(0, 0.0, 0.0), (1, 2.0 + t, 0.0), (2, 40.0, 0.0), (3, 14.0 + 2.0 * t, 1.0)]
        tr.update(snap(t, k, rows if k != 5 else rows[::-1]))
    full = tr.others()
    near = tr.others(near_m=np.array([0.0, 0.0]), within_m=15.0)
    assert full.ids.tolist() == [1, 2, 3] and near.ids.tolist() == [1]
    np.testing.assert_array_equal(near.velocity_mps[0], full.velocity_mps[0])
    np.testing.assert_array_equal(near.track_start_m[0], full.track_start_m[0])
    assert len(tr.others(near_m=np.array([100.0, 100.0]), within_m=1.0)) == 0
    np.testing.assert_allclose(full.velocity_mps[2], [2.0, 0.0], atol=1e-9)  # reordered ids


def test_dense_fast_path_matches_the_weighted_fit():
    """Every disc in every sample takes the shared-weights path; it must equal the general
    weighted least squares with all weights one (the path used when a disc is missing)."""
    rng = np.random.default_rng(3)
    pos = rng.normal(size=(6, 4, 2))
    tt = np.array([-0.5, -0.41, -0.3, -0.2, -0.12, 0.0])
    dense = NeighborTracker._estimate_dense(pos, tt)
    sparse = NeighborTracker._estimate_sparse(pos, np.ones((6, 4), dtype=bool), tt)
    for a, b in zip(dense, sparse, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_a_disc_missing_from_one_sample_is_fitted_on_the_samples_it_was_in():
    tr = NeighborTracker(own_id=0, window_s=0.5, max_samples=8)
    for k in range(7):
        t = 0.1 * k
        rows = [(1, 1.0 * t, 0.0)] + ([(2, 3.0, 2.0 * t)] if k != 5 else [])
        tr.update(snap(t, k, rows))
    o = tr.others()
    assert o.ids.tolist() == [1, 2]
    np.testing.assert_allclose(o.velocity_mps, [[1.0, 0.0], [0.0, 2.0]], atol=1e-9)
    assert o.linearity.tolist() == pytest.approx([1.0, 1.0])


def test_the_latest_observed_heading_is_reported_and_follows_subsets():
    tr = NeighborTracker(own_id=0)
    rows = [(0, 0.0, 0.0, 0.0), (1, 2.0, 0.0, 0.5), (2, 4.0, 1.0, -2.0)]
    for k, turn in enumerate((0.0, 0.1)):
        tr.update(PoseSnapshot(stamp_s=0.1 * k, tick=k, ids=[r[0] for r in rows],
                               pose=[[r[1], r[2], r[3] + turn] for r in rows],
                               radius_m=[0.5] * 3))
    o = tr.others()
    np.testing.assert_allclose(o.heading_rad, [0.6, -1.9])
    np.testing.assert_allclose(o.subset(np.array([1])).heading_rad, [-1.9])
    np.testing.assert_allclose(tr.others(near_m=np.zeros(2), within_m=3.0).heading_rad, [0.6])


def test_recent_speed_is_the_newest_interval_and_shows_a_braking_the_slope_trails():
    # Robot 1 cruises at 1.0 m/s, then brakes at 1.5 m/s^2 from t = 0.5 s; robot 2 joins
    # in the newest sample only.
    tr = NeighborTracker(own_id=0, window_s=0.5)
    x, v = 0.0, 1.0
    for k in range(9):
        t = 0.1 * k
        rows = [(1, x, 0.0)] + ([(2, 5.0, 5.0)] if k == 8 else [])
        tr.update(snap(t, k, rows))
        v_next = v - 1.5 * 0.1 if t >= 0.5 else v
        x += 0.5 * (v + v_next) * 0.1
        v = v_next
    o = tr.others()
    assert o.ids.tolist() == [1, 2]
    # from t = 0.7 to 0.8 it slowed from 0.70 to 0.55 m/s: 0.5 (0.70 + 0.55) 0.1 = 0.0625 m
    assert o.recent_speed_mps[0] == pytest.approx(0.625)
    assert o.recent_interval_s[0] == pytest.approx(0.1)
    assert math.isnan(o.recent_speed_mps[1]) and math.isnan(o.recent_interval_s[1])
    # the least-squares slope still shows more: it trails the braking
    assert np.hypot(*o.velocity_mps[0]) > o.recent_speed_mps[0] + 0.1
    np.testing.assert_allclose(o.subset(np.array([0])).recent_speed_mps, [0.625])


def test_recent_speed_skips_a_sample_the_disc_was_missing_from():
    tr = NeighborTracker(own_id=0, window_s=0.5, max_samples=8)
    for k in range(7):
        rows = [(1, 1.0 * 0.1 * k, 0.0)] + ([(2, 3.0, 2.0 * 0.1 * k)] if k != 5 else [])
        tr.update(snap(0.1 * k, k, rows))
    o = tr.others()
    np.testing.assert_allclose(o.recent_speed_mps, [1.0, 2.0])
    np.testing.assert_allclose(o.recent_interval_s, [0.1, 0.2])


def test_recent_motion_dense_path_equals_the_per_disc_path():
    # The usual case (every disc in the sample before the newest) takes a shortcut; a disc
    # missing there sends the whole call down the per-disc path, which must agree on the
    # others to the last bit.
    from agent.planning.estimation import _recent_motion

    rng = np.random.default_rng(3)
    for h in (2, 4, 7):
        pos = rng.uniform(-5.0, 5.0, (h, 6, 2))
        hdg = rng.uniform(-4.0, 4.0, (h, 6))
        tt = np.sort(rng.uniform(-0.5, 0.0, h))
        tt -= tt[-1]
        use = np.ones((h, 6), dtype=bool)
        dense = _recent_motion(pos[:, :5], hdg[:, :5], use[:, :5], tt)
        use[-2, 5] = False
        general = _recent_motion(pos, hdg, use, tt)
        for got, want in zip(general, dense, strict=True):
            np.testing.assert_array_equal(got[:5], want)
        assert math.isnan(general[0][5]) == (h == 2)  # with h > 2 an older sample serves
        assert math.isnan(general[1][5]) == (h == 2)


def test_recent_turn_rate_is_the_wrapped_heading_change_over_the_newest_interval():
    # Robot 1 turns left at 1.2 rad/s across the +-pi seam; robot 2 turns right at
    # 0.5 rad/s; robot 3 joins in the newest sample only.
    tr = NeighborTracker(own_id=0, window_s=0.5)
    for k in range(8):
        t = 0.1 * k
        rows = [(1, 0.0, 0.0, 2.8 + 1.2 * t), (2, 4.0, 0.0, 0.3 - 0.5 * t)]
        rows += [(3, 0.0, 4.0, 1.0)] if k == 7 else []
        tr.update(PoseSnapshot(stamp_s=t, tick=k, ids=[r[0] for r in rows],
                               pose=[list(r[1:]) for r in rows], radius_m=[0.5] * len(rows)))
    o = tr.others()
    np.testing.assert_allclose(o.recent_turn_rate_radps[:2], [1.2, -0.5], atol=1e-9)
    assert math.isnan(o.recent_turn_rate_radps[2])
    np.testing.assert_allclose(o.subset(np.array([1])).recent_turn_rate_radps, [-0.5],
                               atol=1e-9)


@pytest.mark.parametrize("rate_hz", [10.0, 50.0])
def test_the_default_window_spans_about_the_same_at_10_and_50_hz(rate_hz):
    # The 0.75 s window (`ESTIMATION_WINDOW_S`). Poses 0.1 s apart: every pose is kept and
    # the 8-sample history holds 0.7 s. Poses 0.02 s apart: samples are kept about
    # window / 6 apart and the fit reaches back to the oldest one inside the window (0.72 s
    # here). The ghost
    # start is the oldest sample fitted; at 1 m/s its distance back is its age.
    from agent.planning.estimation import ESTIMATION_WINDOW_S

    window_s = ESTIMATION_WINDOW_S
    assert window_s == 0.75
    assert NeighborTracker(own_id=0).window_s == window_s  # the default
    tr = NeighborTracker(own_id=0, window_s=window_s)
    dt = 1.0 / rate_hz
    n = round(3.0 / dt)
    for k in range(n + 1):
        t = k * dt
        tr.update(snap(t, k, [(0, 0.0, 0.0), (1, 1.0 * t, 0.0)]))
    o = tr.others()
    np.testing.assert_allclose(o.velocity_mps[0], [1.0, 0.0], atol=1e-9)
    reach_s = n * dt - o.track_start_m[0, 0]
    if rate_hz == 10.0:
        assert reach_s == pytest.approx(0.7, abs=1e-9)
    else:
        assert window_s - window_s / 6.0 < reach_s <= window_s + 1e-9, reach_s


def _read_only(arr: list[int]) -> np.ndarray:
    arr = np.array(arr, dtype=np.int64)
    arr.flags.writeable = False
    return arr


@pytest.mark.parametrize("ids", [[0, 1, 2, 3, -1], [2, 0, 3, 1, -1], [1, 2, 3, -1]])
def test_a_repeated_read_only_id_array_gives_the_same_estimates(ids: list[int]) -> None:
    """The shortcut for the same read-only id array (a robot's `PoseDecoder`) leaves the
    tracker exactly as fresh arrays do, discs joining and leaving in between."""
    rng = np.random.default_rng(5)
    shared = _read_only(ids)
    joined = _read_only([*ids, 9])
    fast, slow = NeighborTracker(own_id=0), NeighborTracker(own_id=0)
    for k in range(30):
        use = shared if k % 7 else joined  # a disc joins now and then, and leaves
        pose = rng.uniform(-5, 5, (use.shape[0], 3))
        radius = rng.uniform(0.2, 0.6, use.shape[0])
        fast.update(PoseSnapshot.trusted(stamp_s=0.1 * k, tick=k, ids=use, pose=pose,
                                         radius_m=radius))
        slow.update(PoseSnapshot(stamp_s=0.1 * k, tick=k, ids=np.array(use), pose=pose,
                                 radius_m=radius))
        a, b = fast.others(), slow.others()
        for name in ("ids", "position_m", "velocity_mps", "radius_m", "linearity",
                     "heading_rad", "recent_speed_mps"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert fast._same_ids is shared  # the shortcut was taken
