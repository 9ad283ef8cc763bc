"""Crossing encounters on hand-made trajectories with known answers, and against a direct
pair-by-pair reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from orchestrator.analysis import encounters
from orchestrator.analysis.encounters import (
    ENCOUNTER_DISTANCE_M,
    ENCOUNTER_HEADING_RAD,
    closest_approach,
    crossing_encounters,
    near_pairs,
)

DT = 0.1
T = np.arange(0.0, 10.0 + DT / 2, DT)  # 101 samples, 10 s


def straight(start_xy: tuple[float, float], heading: float, speed: float = 1.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """(xy (T, 2), heading (T,)) of a robot driving straight from start_xy."""
    direction = np.array([math.cos(heading), math.sin(heading)])
    xy = np.asarray(start_xy, dtype=float) + speed * T[:, None] * direction
    return xy, np.full(T.size, heading)


def robots(*runs: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(xy (T, n, 2), heading (T, n)) of the runs side by side."""
    return np.stack([r[0] for r in runs], axis=1), np.stack([r[1] for r in runs], axis=1)


def test_a_head_on_pass_counts_one_for_each():
    # They meet at t = 5 s, 0.5 m apart sideways.
    xy, h = robots(straight((-5.0, 0.0), 0.0), straight((5.0, 0.5), math.pi))
    assert crossing_encounters(xy, h).tolist() == [1, 1]


def test_two_robots_side_by_side_do_not_count():
    xy, h = robots(straight((0.0, 0.0), 0.0), straight((0.0, 1.5), 0.0))
    assert crossing_encounters(xy, h).tolist() == [0, 0]
    # Headings 2 pi apart are the same heading.
    xy, h = robots(straight((0.0, 0.0), 0.0), straight((0.0, 1.5), 2.0 * math.pi))
    assert crossing_encounters(xy, h).tolist() == [0, 0]


def test_a_pair_that_never_comes_within_the_distance_does_not_count():
    xy, h = robots(straight((-5.0, 0.0), 0.0), straight((5.0, 3.0), math.pi))
    assert crossing_encounters(xy, h).tolist() == [0, 0]
    # Exactly at the distance at the closest approach: not below it.
    xy, h = robots(straight((-5.0, 0.0), 0.0),
                   straight((5.0, ENCOUNTER_DISTANCE_M), math.pi))
    assert crossing_encounters(xy, h).tolist() == [0, 0]
    xy, h = robots(straight((-5.0, 0.0), 0.0),
                   straight((5.0, ENCOUNTER_DISTANCE_M - 0.01), math.pi))
    assert crossing_encounters(xy, h).tolist() == [1, 1]


def test_a_crossing_at_90_degrees_counts_one_for_each():
    # Robot 0 crosses the origin at t = 5 s, robot 1 at t = 6 s: 1.41 m apart at best.
    xy, h = robots(straight((-5.0, 0.0), 0.0), straight((0.0, -6.0), math.pi / 2))
    assert crossing_encounters(xy, h).tolist() == [1, 1]


def test_the_heading_threshold_is_45_degrees_at_the_closest_approach():
    assert math.isclose(ENCOUNTER_HEADING_RAD, math.pi / 4)
    for angle, expected in ((math.radians(44.0), 0), (math.radians(46.0), 1)):
        # Robot 1 drives through robot 0's position at t = 5 s at that angle.
        r0 = straight((-5.0, 0.0), 0.0)
        r1 = straight((-5.0 * math.cos(angle), -5.0 * math.sin(angle)), angle)
        assert crossing_encounters(*robots(r0, r1)).tolist() == [expected, expected]


def test_only_the_headings_at_the_closest_approach_matter():
    xy, h = robots(straight((0.0, 0.0), 0.0), straight((0.0, 1.5), 0.0))
    xy[:, 1, 1] += np.abs(T - 5.0)  # nearest (1.5 m) at t = 5 s
    turned = h.copy()
    turned[:40, 1] = math.pi / 2  # crossing headings, but far from the closest approach
    assert crossing_encounters(xy, turned).tolist() == [0, 0]
    turned[50, 1] = math.pi / 2  # at the closest approach
    assert crossing_encounters(xy, turned).tolist() == [1, 1]


def test_a_stream_meeting_a_robot_head_on_counts_each_crossing_pair():
    xy, h = robots(straight((-5.0, 0.0), 0.0), straight((-5.0, 1.5), 0.0),
                   straight((5.0, 0.75), math.pi))
    assert crossing_encounters(xy, h).tolist() == [1, 1, 2]


def test_a_robot_alone_or_no_samples_count_zero():
    xy, h = robots(straight((0.0, 0.0), 0.0))
    assert crossing_encounters(xy, h).tolist() == [0]
    assert crossing_encounters(np.zeros((0, 3, 2)), np.zeros((0, 3))).tolist() == [0, 0, 0]


def test_shapes_are_checked():
    with pytest.raises(ValueError, match="heading_rad"):
        crossing_encounters(np.zeros((5, 2, 2)), np.zeros((2, 5)))


def test_closest_approach_keeps_the_first_sample_of_a_tie(monkeypatch):
    xy = np.zeros((6, 2, 2))
    xy[:, 1, 0] = [3.0, 1.0, 2.0, 1.0, 1.0, 4.0]  # nearest at samples 1, 3 and 4
    for block in (1, 2, 1 << 21):
        monkeypatch.setattr(encounters, "_BLOCK_PAIR_SAMPLES", block)
        i, j, dist, sample = closest_approach(xy)
        assert (i.tolist(), j.tolist(), dist.tolist(), sample.tolist()) == \
            ([0], [1], [1.0], [1])


def reference_encounters(xy: np.ndarray, heading: np.ndarray) -> list[int]:
    """The definition, one robot and one other at a time."""
    n = xy.shape[1]
    counts = []
    for a in range(n):
        count = 0
        for b in range(n):
            if b == a:
                continue
            d = np.hypot(*(xy[:, b] - xy[:, a]).T)
            k = int(np.argmin(d))
            diff = abs(math.remainder(heading[k, b] - heading[k, a], 2.0 * math.pi))
            count += bool(d[k] < ENCOUNTER_DISTANCE_M and diff > ENCOUNTER_HEADING_RAD)
        counts.append(count)
    return counts


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7), samples=st.integers(1, 30),
       block=st.sampled_from([1, 7, 1 << 21]))
def test_matches_the_pair_by_pair_reference(seed, n, samples, block):
    rng = np.random.default_rng(seed)
    # Random walks in a 6 m square: some pairs come close, some do not.
    xy = rng.uniform(0.0, 6.0, (1, n, 2)) + np.cumsum(rng.normal(0.0, 0.3, (samples, n, 2)),
                                                      axis=0)
    heading = rng.uniform(-2.0 * math.pi, 2.0 * math.pi, (samples, n))
    original = encounters._BLOCK_PAIR_SAMPLES
    try:
        encounters._BLOCK_PAIR_SAMPLES = block
        counts = crossing_encounters(xy, heading)
    finally:
        encounters._BLOCK_PAIR_SAMPLES = original
    assert counts.tolist() == reference_encounters(xy, heading)
    assert counts.sum() % 2 == 0  # each crossing counts for both robots


def test_a_sample_without_a_pose_does_not_hide_the_encounter():
    # One NaN pose early in the run, in the same block as the closest approach: the
    # head-on pass still counts for both.
    xy, h = robots(straight((-5.0, 0.0), 0.0), straight((5.0, 0.5), math.pi))
    xy[3, 1] = np.nan
    assert crossing_encounters(xy, h).tolist() == [1, 1]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 9), samples=st.integers(1, 80),
       stride=st.sampled_from([1, 3, 25, 100]), holes=st.booleans())
def test_near_pairs_keeps_every_pair_that_comes_close(seed, n, samples, stride, holes):
    rng = np.random.default_rng(seed)
    # Fast random walks in a 30 m square: most pairs stay apart, some meet.
    xy = rng.uniform(0.0, 30.0, (1, n, 2)) + np.cumsum(rng.normal(0.0, 0.8, (samples, n, 2)),
                                                       axis=0)
    if holes:
        xy[rng.random((samples, n)) < 0.1] = np.nan
    kept = set(zip(*(a.tolist() for a in near_pairs(xy, ENCOUNTER_DISTANCE_M, stride))))
    i, j, dist, _ = closest_approach(xy)
    close = {(a, b) for a, b, d in zip(i.tolist(), j.tolist(), dist.tolist())
             if d < ENCOUNTER_DISTANCE_M}
    assert close <= kept
    # and the pairs come back in the order of np.triu_indices
    pairs = list(zip(*(a.tolist() for a in near_pairs(xy, ENCOUNTER_DISTANCE_M, stride))))
    assert pairs == sorted(pairs)


def test_near_pairs_drops_pairs_that_stay_apart_and_keeps_a_fast_one():
    # Robots 0 and 1 drive side by side 10 m apart; robot 2 starts 20 m from robot 0 and
    # drives at it at 4 m/s, reaching it within one window of 25 samples (2.5 s).
    xy, h = robots(straight((0.0, 0.0), 0.0), straight((0.0, 10.0), 0.0),
                   straight((20.0, 0.0), math.pi, speed=3.0))
    kept = list(zip(*(a.tolist() for a in near_pairs(xy, ENCOUNTER_DISTANCE_M, 25))))
    assert (0, 1) not in kept
    assert (0, 2) in kept
    assert crossing_encounters(xy, h).tolist() == [1, 0, 1]


def test_near_pairs_with_a_missing_anchor_pose_keeps_the_pair():
    xy, _ = robots(straight((0.0, 0.0), 0.0), straight((0.0, 10.0), 0.0))
    xy[0, 1] = np.nan  # no pose at the first window's first sample
    kept = list(zip(*(a.tolist() for a in near_pairs(xy, ENCOUNTER_DISTANCE_M, 25))))
    assert kept == [(0, 1)]
    # the exact pass still finds them 10 m apart: no encounter
    assert crossing_encounters(xy, np.zeros(xy.shape[:2])).tolist() == [0, 0]
