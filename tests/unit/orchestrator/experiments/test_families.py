"""Setups A-G, families, scaling, start jitter and `resolve`."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.scenario import Scenario
from orchestrator.experiments import families, scenario_blocks
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
    assert s.planner_config.safety.d_safety_m == 0.3
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
        assert closest < s.planner_config.threats.sensing_radius_m


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


# --------------------------------------------------------------------------------------
# Benchmark families
# --------------------------------------------------------------------------------------

def disc_gaps(xy: np.ndarray, radius: np.ndarray) -> float:
    """Smallest gap between two discs (centre distance minus both radii)."""
    i, j = np.triu_indices(len(xy), k=1)
    return float((np.hypot(*(xy[i] - xy[j]).T) - radius[i] - radius[j]).min())


def radii(s: Scenario) -> np.ndarray:
    return np.array([r.radius_m for r in s.robots])


BENCH_CASES = [("circle_mixed", 8), ("circle_mixed", 32), ("crossing_45", 16),
               ("crossing_90", 16), ("crossing_135", 16), ("swap_pairs", 6),
               ("swap_pairs", 12), ("swap_grid", 4), ("swap_grid", 16),
               ("random_sparse", 20), ("random_medium", 20), ("random_dense", 20),
               ("obstacles_circle", 12), ("obstacles_circle", 24)]


@pytest.mark.parametrize(("family", "n"), BENCH_CASES)
def test_benchmark_families_have_their_size_spacing_and_a_generous_limit(family, n):
    s = resolve(family, agents=n, seed=3)
    assert len(s.robots) == n and s.name.endswith(f"_{n}")
    assert [r.id for r in s.robots] == list(range(n))
    # Starts (and goals) keep at least the 2.5 m spacing of 0.5 m discs: a 1.5 m gap.
    assert disc_gaps(starts(s), radii(s)) >= 1.5 - 1e-6
    assert disc_gaps(goals(s), radii(s)) >= 1.5 - 1e-6
    assert np.all(straight(s) > 1.0)  # every robot has somewhere to go
    ideal = scenario_blocks.ideal_time_s(s.robots)
    assert s.time_limit_s >= 3.0 * ideal + 30.0 - 1e-9
    assert s.time_limit_s <= 3.0 * ideal + 40.0  # rounded up to 10 s, no more
    for r in s.robots:  # headings point at the goals
        want = math.atan2(r.goal[1] - r.start[1], r.goal[0] - r.start[0])
        assert abs(math.remainder(r.start[2] - want, 2 * math.pi)) < 1e-5


@pytest.mark.parametrize(("family", "n"), BENCH_CASES)
def test_benchmark_families_are_deterministic_per_seed(family, n):
    assert resolve(family, agents=n, seed=7) == resolve(family, agents=n, seed=7)


def test_seeded_benchmark_families_change_with_the_seed():
    for family, n in (("circle_mixed", 16), ("random_dense", 20), ("obstacles_circle", 12)):
        assert resolve(family, agents=n, seed=0) != resolve(family, agents=n, seed=1)


def test_circle_mixed_has_every_radius_and_speed_and_the_slowest_sets_the_limit():
    s = resolve("circle_mixed", agents=16, seed=0)
    speeds = np.array([r.limits.v_max_mps for r in s.robots])
    assert set(radii(s)) == set(families.MIXED_RADII_M)
    assert set(speeds) == set(families.MIXED_V_MAX_MPS)
    # Antipodal: every goal is the negated start.
    np.testing.assert_allclose(goals(s), -starts(s), atol=1e-3)
    np.testing.assert_allclose(scenario_blocks.ideal_time_s(s.robots),
                               np.max(straight(s) / speeds))
    # The slowest robots (0.8 m/s) decide: the ideal time is the diameter over 0.8 m/s.
    assert scenario_blocks.ideal_time_s(s.robots) == pytest.approx(straight(s).max() / 0.8)


@pytest.mark.parametrize("angle", [45.0, 90.0, 135.0])
def test_crossing_cohorts_meet_at_the_angle_and_lanes_cross_the_origin(angle):
    s = crossing(16, angle_deg=angle)
    d = goals(s) - starts(s)
    heading = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    np.testing.assert_allclose(heading[:8], 0.0, atol=1e-3)
    np.testing.assert_allclose(heading[8:], angle, atol=1e-3)
    # Each lane's midpoint is on the line through the origin normal to its direction.
    mid = (goals(s) + starts(s)) / 2.0
    unit = d / np.hypot(*d.T)[:, None]
    np.testing.assert_allclose(np.einsum("ij,ij->i", mid, unit), 0.0, atol=1e-3)
    assert s.name == f"crossing_{angle:g}_16"


def test_crossing_at_90_deg_is_the_perpendicular_crossing():
    a, b = crossing(16), crossing(16, angle_deg=90)
    assert [r.start for r in a.robots] == [r.start for r in b.robots]
    assert [r.goal for r in a.robots] == [r.goal for r in b.robots]


def test_crossing_rejects_bad_angles():
    for angle in (0.0, 180.0, -45.0, math.nan):
        with pytest.raises(ScenarioError, match="angle"):
            crossing(8, angle_deg=angle)
    with pytest.raises(ScenarioError, match="flows=2"):
        crossing(8, flows=4, angle_deg=45)


def test_swap_pairs_partners_swap_places():
    s = resolve("swap_pairs", agents=8)
    st_, gl = starts(s), goals(s)
    for p in range(4):
        a, b = 2 * p, 2 * p + 1
        np.testing.assert_allclose(gl[a], st_[b])
        np.testing.assert_allclose(gl[b], st_[a])
        assert st_[a][1] == st_[b][1]  # head-on along one lane
    lanes = sorted({y for _, y in st_})
    np.testing.assert_allclose(np.diff(lanes), families.SWAP_PAIR_SPACING_M)
    np.testing.assert_allclose(straight(s), families.SWAP_RUN_M)


def test_swap_grid_goes_to_the_mirrored_cell():
    s = resolve("swap_grid", agents=16)
    k, cell = 4, families.SWAP_GRID_SPACING_M
    st_ = starts(s)
    for i in range(k):
        for j in range(k):
            r = s.robots[i * k + j]
            mirror = s.robots[(k - 1 - i) * k + (k - 1 - j)]
            assert r.goal == pytest.approx(mirror.start[:2])
    xs = np.unique(np.round(st_[:, 0], 6))
    assert xs.size == k and np.allclose(np.diff(xs), cell)


@pytest.mark.parametrize("n", [0, 2, 9, 12])
def test_swap_grid_needs_an_even_square(n):
    with pytest.raises(ScenarioError, match="square of an even number"):
        resolve("swap_grid", agents=n) if n else families.swap_grid(n)


def test_swap_pairs_needs_an_even_count():
    with pytest.raises(ScenarioError, match="even"):
        resolve("swap_pairs", agents=5)


@pytest.mark.parametrize("density", ["sparse", "medium", "dense"])
def test_random_densities_set_the_square(density):
    s = resolve(f"random_{density}", agents=20, seed=0)
    side = math.sqrt(20 / families.RANDOM_DENSITIES_PER_M2[density])
    both = np.vstack([starts(s), goals(s)])
    assert np.all(np.abs(both) <= side / 2.0 + 0.01)
    assert np.all(straight(s) >= side / 2.0 - 0.02)
    assert s.name == f"random_{density}_20"


def test_random_densities_are_ordered():
    sides = [math.sqrt(1.0 / families.RANDOM_DENSITIES_PER_M2[d])
             for d in ("sparse", "medium", "dense")]
    assert sides[0] > sides[1] > sides[2]


@pytest.mark.parametrize("seed", range(6))
def test_obstacles_circle_obstacles_are_inside_and_clear_of_starts_and_goals(seed, tmp_path):
    s = resolve("obstacles_circle", agents=12, seed=seed)
    assert 3 <= len(s.obstacles) <= 5
    c = np.array([o.center for o in s.obstacles])
    r = np.array([o.radius_m for o in s.obstacles])
    assert [o.id for o in s.obstacles] == [-(k + 1) for k in range(len(s.obstacles))]
    assert np.all((r >= 1.0) & (r <= 2.0))
    assert np.all(np.array([o.velocity for o in s.obstacles]) == 0.0)  # static
    assert np.hypot(*c[0]) <= 2.0 + 1e-9  # one in the middle, where the paths meet
    for xy in (starts(s), goals(s)):
        gap = np.hypot(xy[:, None, 0] - c[None, :, 0], xy[:, None, 1] - c[None, :, 1])
        assert np.all(gap - r[None, :] - 0.5 >= 2.0)
    if len(c) > 1:
        assert disc_gaps(c, r) >= families.OBSTACLE_GAP_M - 1e-9
    np.testing.assert_allclose(goals(s), -starts(s), atol=1e-3)
    dump_scenario(s, tmp_path / "s.yaml")  # the obstacles survive the file format
    assert load_scenario(tmp_path / "s.yaml") == s


def test_movers_obstacles_enter_from_the_sides_and_cross_the_robots_square():
    from agent.planning.routing import StaticMap

    a = families.movers(20, np.random.default_rng(3))
    b = families.movers(20, np.random.default_rng(3))
    assert a == b  # seeded
    half = max(abs(c) for r in a.robots for c in (*r.start[:2], *r.goal))
    assert len(a.obstacles) == families.MOVERS
    lanes = []
    for o in a.obstacles:
        vx, vy = o.velocity
        speed = math.hypot(vx, vy)
        assert families.MOVER_SPEEDS_MPS[0] <= speed <= families.MOVER_SPEEDS_MPS[1] + 1e-3
        assert abs(o.center[0]) > half  # outside the square at the start
        assert vx * o.center[0] < 0.0  # heading across it
        assert abs(o.center[1]) < half
        lanes.append(o.center[1])
    assert sorted(lanes) == lanes  # one lane per quarter, bottom to top
    # the planners see them as moving: not on the static map every robot is given
    assert len(StaticMap.of_obstacles(a.obstacles).radius_m) == 0


def test_movers_start_clear_of_every_robot_on_their_tracks_on_every_seed():
    # Seeds 6, 23 and 27 were refused (a mover's disc overlapped a start or goal disc at
    # the edge of the square); every seed now resolves, with MOVER_START_GAP_M to spare.
    for seed in range(30):
        s = families.resolve("movers", seed=seed)
        for o in s.obstacles:
            for r in s.robots:
                for x, y in (r.start[:2], r.goal):
                    reach, dy = o.radius_m + r.radius_m, o.center[1] - y
                    assert math.hypot(o.center[0] - x, dy) >= reach  # no overlap at t = 0
                    if abs(dy) < reach:  # on its track: how far it runs before touching
                        run_m = abs(o.center[0] - x) - math.sqrt(reach * reach - dy * dy)
                        assert run_m >= families.MOVER_START_GAP_M - 2e-3
