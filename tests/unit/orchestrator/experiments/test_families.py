"""Setups A-G, families, scaling, start jitter and `resolve`."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.scenario import Scenario
from orchestrator.experiments import families
from orchestrator.experiments.families import (
    CIRCLES_GROUP,
    CIRCLES_RADIUS_M,
    SETUPS,
    circle,
    circles,
    crossing,
    jitter_starts,
    random_scenario,
    resolve,
    setup_g,
    setup_path,
)
from world.scenario_file import ScenarioError, dump_scenario, load_scenario

SIZES = {"setup_a": 2, "setup_b": 3, "setup_c": 3, "setup_d": 4, "setup_e": 5,
         "setup_f": 12, "setup_g": 16}


def starts(s: Scenario) -> np.ndarray:
    return np.array([r.start[:2] for r in s.robots])


def goals(s: Scenario) -> np.ndarray:
    return np.array([r.goal for r in s.robots])


def min_pair_distance(xy: np.ndarray) -> float:
    i, j = np.triu_indices(len(xy), k=1)
    return float(np.hypot(*(xy[i] - xy[j]).T).min())


def straight(s: Scenario) -> np.ndarray:
    return np.hypot(*(goals(s) - starts(s)).T)


@pytest.mark.parametrize("name", list(SETUPS))
def test_setup_files_match_their_generators_and_the_paper_scale(name):
    s = load_scenario(setup_path(name))
    assert s == SETUPS[name]()
    assert s.name == name and s.description
    assert len(s.robots) == SIZES[name]
    expected = 76.0 if name in ("setup_f", "setup_g") else 36.0
    np.testing.assert_allclose(straight(s), expected, atol=0.02)
    assert all(r.radius_m == 0.5 and r.limits.v_max_mps == 1.1 for r in s.robots)
    assert s.planner_config.d_safety_m == 0.3
    assert s.time_limit_s >= 4.0 * expected / 1.1
    assert min_pair_distance(starts(s)) >= 2.5
    # Headings point at the goals.
    for r in s.robots:
        want = math.atan2(r.goal[1] - r.start[1], r.goal[0] - r.start[0])
        assert abs(math.remainder(r.start[2] - want, 2 * math.pi)) < 1e-5


def test_setup_a_is_mirrored_across_the_x_axis_and_paths_meet_at_the_centre():
    s = SETUPS["setup_a"]()
    a, b = s.robots
    assert (b.start[0], -b.start[1], -b.start[2]) == a.start
    assert (b.goal[0], -b.goal[1]) == a.goal
    # Both straight paths pass through the origin at the same distance from the start.
    for r in s.robots:
        assert abs(r.start[0] * r.goal[1] - r.start[1] * r.goal[0]) < 1e-9
    np.testing.assert_allclose(np.hypot(*starts(s).T), 18.0, atol=1e-3)


def test_setup_b_is_a_t_top_and_two_opposite_sides():
    s = SETUPS["setup_b"]()
    dirs = {tuple(np.sign(np.round(g - st_, 6))) for st_, g in zip(starts(s), goals(s))}
    assert dirs == {(0.0, -1.0), (1.0, 0.0), (-1.0, 0.0)}  # down, right, left; none up


def test_setup_c_has_radial_symmetry():
    s = SETUPS["setup_c"]()
    angles = np.sort(np.degrees(np.arctan2(starts(s)[:, 1], starts(s)[:, 0])) % 360)
    np.testing.assert_allclose(np.diff(angles), 120.0, atol=1e-3)
    np.testing.assert_allclose(goals(s), -starts(s), atol=1e-9)


def test_setup_d_is_mirrored_across_both_axes():
    s = SETUPS["setup_d"]()
    pairs = {(tuple(a), tuple(b)) for a, b in zip(starts(s), goals(s))}
    for flip in (np.array([1.0, -1.0]), np.array([-1.0, 1.0])):
        mirrored = {(tuple(np.array(a) * flip + 0.0), tuple(np.array(b) * flip + 0.0))
                    for a, b in pairs}
        assert mirrored == pairs


def test_setup_e_goals_are_central_distinct_and_spaced():
    s = SETUPS["setup_e"]()
    assert np.all(np.hypot(*goals(s).T) <= 4.0)
    assert min_pair_distance(goals(s)) >= 2.0


def test_setup_f_has_three_groups_of_four():
    s = SETUPS["setup_f"]()
    d = np.sign(np.round(goals(s) - starts(s), 6))
    dirs = [tuple(x) for x in d]
    assert dirs.count((1.0, 0.0)) == 4 and dirs.count((0.0, -1.0)) == 4
    assert dirs.count((0.0, 1.0)) == 4


def test_setup_g_scales_to_four_cohorts_of_eight():
    s = resolve("setup_g", agents=32)
    assert len(s.robots) == 32 and s.name == "setup_g_32"
    dirs = [tuple(x) for x in np.sign(np.round(goals(s) - starts(s), 6))]
    for d in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
        assert dirs.count(d) == 8
    assert min_pair_distance(starts(s)) >= 2.5
    assert len({r.id for r in s.robots}) == 32
    # Very wide cohorts widen the field so that cohorts never start on top of each other.
    wide = setup_g(4 * 40)
    assert min_pair_distance(starts(wide)) >= 2.5


def test_setup_f_scales_to_groups_of_n_over_3():
    assert len(resolve("setup_f", agents=24).robots) == 24
    with pytest.raises(ScenarioError, match="multiple of 3"):
        resolve("setup_f", agents=10)


def test_fixed_size_setups_reject_other_sizes_clearly():
    with pytest.raises(ScenarioError, match=r"setup_a: has a fixed size of 2 robots; "
                                            r"--agents 5 is only supported"):
        resolve("setup_a", agents=5)
    assert len(resolve("setup_a", agents=2).robots) == 2
    with pytest.raises(ScenarioError, match="multiple of 4"):
        resolve("setup_g", agents=30)


@pytest.mark.parametrize("n", [2, 3, 8, 16, 64])
def test_circle_is_an_antipodal_swap_with_spacing(n):
    s = circle(n)
    radius = np.hypot(*starts(s).T)
    assert np.all(radius >= 18.0 - 1e-9) and np.ptp(radius) < 1e-9
    np.testing.assert_array_equal(goals(s), -starts(s))
    assert min_pair_distance(starts(s)) >= 2.5
    if n % 2 == 0:  # exact point symmetry, bit for bit
        np.testing.assert_array_equal(starts(s)[n // 2:], -starts(s)[: n // 2])


@pytest.mark.parametrize("n", [2, 9, 16, 64, 128])
def test_circles_tile_small_antipodal_swaps(n):
    s = circles(n)
    assert len(s.robots) == n and s.time_limit_s == 120.0
    st, gl = starts(s), goals(s)
    centre = (st + gl) / 2.0  # each robot swaps through its circle's centre
    assert np.allclose(np.hypot(*(st - centre).T), CIRCLES_RADIUS_M, atol=1e-3)
    centres = np.unique(np.round(centre, 2), axis=0)
    groups = math.ceil(n / CIRCLES_GROUP)
    assert len(centres) == groups
    sizes = [int(np.sum(np.all(np.round(centre, 2) == c, axis=1))) for c in centres]
    assert max(sizes) <= CIRCLES_GROUP and min(sizes) >= min(n, 2)
    assert min_pair_distance(st) >= 2.5 and min_pair_distance(gl) >= 2.5
    if groups > 1:  # rim robots of neighbouring circles start within sensing range
        i, j = np.triu_indices(n, k=1)
        other = np.any(np.round(centre[i], 2) != np.round(centre[j], 2), axis=1)
        closest = np.hypot(*(st[i] - st[j]).T)[other].min()
        assert closest < s.planner_config.sensing_radius_m


def test_circle_grows_when_crowded():
    assert np.hypot(*starts(circle(64))[0]) > 18.0


@pytest.mark.parametrize(("flows", "n"), [(2, 8), (4, 16), (4, 4)])
def test_crossing_has_perpendicular_flows(flows, n):
    s = crossing(n, flows=flows)
    d = {tuple(x) for x in np.sign(np.round(goals(s) - starts(s), 6))}
    assert len(d) == flows
    assert {(1.0, 0.0), (0.0, 1.0)} <= d
    assert min_pair_distance(starts(s)) >= 2.5
    with pytest.raises(ScenarioError):
        crossing(n + 1, flows=flows)


def test_random_is_seeded_and_spaced():
    a = random_scenario(12, np.random.default_rng(7))
    b = random_scenario(12, np.random.default_rng(7))
    c = random_scenario(12, np.random.default_rng(8))
    assert a == b and a != c
    assert min_pair_distance(starts(a)) >= 2.5 and min_pair_distance(goals(a)) >= 2.5
    assert resolve("random", seed=3) == resolve("random", seed=3)
    assert resolve("random", seed=3) != resolve("random", seed=4)


def test_jitter_moves_starts_within_the_disc_and_keeps_them_valid():
    s = SETUPS["setup_g"]()
    j = jitter_starts(s, 1.0, np.random.default_rng(1))
    moved = np.hypot(*(starts(j) - starts(s)).T)
    assert np.all(moved <= 1.0 + 1e-12) and np.all(moved > 0.0)
    assert [r.start[2] for r in j.robots] == [r.start[2] for r in s.robots]
    assert goals(j).tolist() == goals(s).tolist()
    assert jitter_starts(s, 1.0, np.random.default_rng(1)) == j
    assert jitter_starts(s, 0.0, np.random.default_rng(1)) is s
    with pytest.raises(ScenarioError, match="jitter"):
        jitter_starts(s, -1.0, np.random.default_rng(1))


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 40), st.floats(0.0, 6.0), st.integers(0, 2**16))
def test_jitter_of_a_crowded_circle_never_overlaps(n, d, seed):
    s = circle(n)
    j = jitter_starts(s, d, np.random.default_rng(seed))
    xy = starts(j)
    assert min_pair_distance(xy) >= 1.0  # two radii: discs never overlap
    assert np.all(np.hypot(*(xy - starts(s)).T) <= d + 1e-9)


def test_resolve_names_paths_aliases_and_planner_override(tmp_path):
    assert resolve("d") == resolve("setup_d")
    s = resolve("setup_b", planner="orca", start_jitter_m=0.5, seed=2)
    assert {r.planner for r in s.robots} == {"orca"}
    assert s != resolve("setup_b", planner="orca", start_jitter_m=0.5, seed=3)
    path = tmp_path / "mine.yaml"
    dump_scenario(SETUPS["setup_c"](), path)
    assert resolve(str(path)) == SETUPS["setup_c"]()
    with pytest.raises(ScenarioError, match="cannot resize"):
        resolve(str(path), agents=4)
    with pytest.raises(ScenarioError, match="unknown setup or family"):
        resolve("setup_z")
    with pytest.raises(ScenarioError, match="unknown planner 'rrt'"):
        resolve("setup_a", planner="rrt")
    with pytest.raises(ScenarioError, match=r"nope\.yaml: cannot read"):
        resolve(str(tmp_path / "nope.yaml"))
    for name, (default_n, _what) in families.FAMILIES.items():
        assert len(resolve(name).robots) == default_n
