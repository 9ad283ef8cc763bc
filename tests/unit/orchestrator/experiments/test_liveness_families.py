"""The liveness families: geometry of walls, doorways and corridor, counts, spacing,
seeding, and that every goal can be reached round the static obstacles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from agent.core.scenario import Scenario
from orchestrator.experiments import families, scenario_blocks
from orchestrator.experiments import liveness_families as lf
from orchestrator.experiments.families import resolve
from world.scenario_file import ScenarioError, dump_scenario, load_scenario

ROBOT_R = 0.5
CASES = [("wall_door", 12), ("wall_door", 24), ("wall_doors", 16), ("corridor", 8),
         ("corridor", 6), ("grid_dense", 16), ("grid_dense", 25), ("grid_dense", 9),
         ("pillar_circle", 24), ("pillar_circle", 40), ("random_40", 40),
         ("platoons", 16), ("platoons", 18), ("crossing_60_mixed", 16)]
SEEDED = ("wall_door", "wall_doors", "corridor", "pillar_circle", "random_40", "platoons",
          "crossing_60_mixed")


def starts(s: Scenario) -> np.ndarray:
    return np.array([r.start[:2] for r in s.robots])


def goals(s: Scenario) -> np.ndarray:
    return np.array([r.goal for r in s.robots])


def centres(s: Scenario) -> np.ndarray:
    return np.array([o.center for o in s.obstacles]).reshape(-1, 2)


def min_pair_distance(xy: np.ndarray) -> float:
    i, j = np.triu_indices(len(xy), k=1)
    return float(np.hypot(*(xy[i] - xy[j]).T).min())


def free_space(s: Scenario, step_m: float = 0.1, margin_m: float = 4.0):
    """Connected components of the cells a robot's centre may occupy (obstacles grown by
    the robot radius), on a grid covering every start, goal and obstacle."""
    pts = np.vstack([starts(s), goals(s), centres(s)])
    lo, hi = pts.min(axis=0) - margin_m, pts.max(axis=0) + margin_m
    xs, ys = np.arange(lo[0], hi[0], step_m), np.arange(lo[1], hi[1], step_m)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    free = np.ones(gx.shape, dtype=bool)
    for o in s.obstacles:
        free &= np.hypot(gx - o.center[0], gy - o.center[1]) > o.radius_m + ROBOT_R
    labels, _ = ndimage.label(free)

    def label_at(xy: np.ndarray) -> int:
        i, j = np.round((np.asarray(xy) - lo) / step_m).astype(int)
        return int(labels[i, j])

    return label_at


@pytest.mark.parametrize(("family", "n"), CASES)
def test_each_family_is_valid_sized_spaced_and_at_the_families_scale(family, n, tmp_path):
    s = resolve(family, agents=n, seed=4)
    assert len(s.robots) == n and s.name == f"{family}_{n}"
    assert [r.id for r in s.robots] == list(range(n))
    assert min_pair_distance(starts(s)) >= scenario_blocks.MIN_START_SPACING_M - 1e-9
    assert min_pair_distance(goals(s)) >= scenario_blocks.MIN_START_SPACING_M - 1e-9
    assert all(r.radius_m == 0.5 for r in s.robots)
    assert s.planner_config.safety.d_safety_m == 0.3
    assert s.time_limit_s == scenario_blocks.benchmark_time_limit_s(s.robots)
    assert np.all(np.hypot(*(goals(s) - starts(s)).T) > 3.0)  # everyone has to travel
    for r in s.robots:  # headings point at the goals
        want = math.atan2(r.goal[1] - r.start[1], r.goal[0] - r.start[0])
        assert abs(math.remainder(r.start[2] - want, 2 * math.pi)) < 1e-5
    dump_scenario(s, tmp_path / "s.yaml")  # the obstacles survive the file format
    assert load_scenario(tmp_path / "s.yaml") == s


@pytest.mark.parametrize(("family", "n"), CASES)
def test_every_goal_is_reachable_round_the_static_obstacles(family, n):
    s = resolve(family, agents=n, seed=2)
    label_at = free_space(s)
    for r in s.robots:
        assert label_at(r.start[:2]) != 0, f"robot {r.id} starts inside an obstacle"
        assert label_at(r.start[:2]) == label_at(r.goal), f"robot {r.id} cannot reach its goal"
    # Starts and goals keep d_safety from every obstacle (robot disc edge to disc edge).
    for xy in (starts(s), goals(s)):
        for o in s.obstacles:
            gap = np.hypot(*(xy - np.array(o.center)).T) - o.radius_m - ROBOT_R
            assert gap.min() >= 0.3


def test_the_families_are_registered_and_resolve_at_their_default_size():
    assert set(lf.GENERATORS) <= set(families.FAMILIES)
    for name in lf.GENERATORS:
        default_n = families.FAMILIES[name][0]
        assert len(resolve(name).robots) == default_n
        assert resolve(name, seed=5) == lf.GENERATORS[name](default_n,
                                                           np.random.default_rng(5).spawn(2)[0])


@pytest.mark.parametrize("family", SEEDED)
def test_seeded_families_vary_with_the_seed_and_repeat_with_it(family):
    n = families.FAMILIES[family][0]
    assert resolve(family, agents=n, seed=3) == resolve(family, agents=n, seed=3)
    assert len({resolve(family, agents=n, seed=seed) for seed in range(4)}) > 1


# --------------------------------------------------------------------------------------
# Walls and doorways
# --------------------------------------------------------------------------------------

def wall_gaps(s: Scenario, y_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(x of the discs on the line y_m, sorted; clear gaps between neighbours)."""
    c = centres(s)
    x = np.sort(c[np.isclose(c[:, 1], y_m)][:, 0])
    return x, np.diff(x) - 2.0 * lf.WALL_DISC_RADIUS_M


@pytest.mark.parametrize(("family", "doors"), [("wall_door", 1), ("wall_doors", 2)])
@pytest.mark.parametrize("seed", range(4))
def test_a_wall_has_its_doorways_of_the_stated_width_and_is_closed_elsewhere(family, doors,
                                                                              seed):
    s = resolve(family, seed=seed)
    assert all(o.radius_m == lf.WALL_DISC_RADIUS_M and o.velocity == (0.0, 0.0)
               for o in s.obstacles)
    x, gaps = wall_gaps(s)
    assert len(x) == len(s.obstacles)  # every disc is on the wall
    is_door = gaps > 0.0
    assert int(is_door.sum()) == doors
    np.testing.assert_allclose(gaps[is_door], lf.DOORWAY_WIDTH_M, atol=2e-4)
    # Closed elsewhere: neighbouring discs touch or overlap (a robot needs 1 m).
    assert gaps[~is_door].max() <= 1e-4
    # The doorways sit within the seeded offset of their nominal places.
    door_x = (x[:-1][is_door] + x[1:][is_door]) / 2.0
    nominal = (0.0,) if doors == 1 else lf.WALL_DOORS_X_M
    assert np.all(np.abs(door_x - np.array(nominal)) <= lf.DOOR_OFFSET_M + 1e-4)
    # The wall reaches 1.5 x the deepest row's distance beyond the outermost lane.
    reach = np.abs(starts(s)[:, 0]).max() + 1.5 * np.abs(starts(s)[:, 1]).max()
    np.testing.assert_allclose([x[0] - lf.WALL_DISC_RADIUS_M, x[-1] + lf.WALL_DISC_RADIUS_M],
                               [-reach, reach], atol=1e-4)


@pytest.mark.parametrize(("family", "n"), [("wall_door", 12), ("wall_door", 30),
                                         ("wall_doors", 16), ("wall_doors", 4)])
def test_groups_swap_across_the_wall_and_the_ends_are_a_long_way_round(family, n):
    s = resolve(family, agents=n, seed=0)
    st, gl = starts(s), goals(s)
    half = len(st) // 2
    assert np.all(st[:half, 1] < 0) and np.all(st[half:, 1] > 0)  # half each side
    np.testing.assert_allclose(gl, st * np.array([1.0, -1.0]))  # mirrored across the wall
    x, gaps = wall_gaps(s)
    door_x = (x[:-1][gaps > 0] + x[1:][gaps > 0]) / 2.0
    end = x[-1] + lf.WALL_DISC_RADIUS_M + ROBOT_R
    for a, b in zip(st, gl):
        door = np.array([door_x[np.argmin(np.abs(door_x - a[0]))], 0.0])
        via_door = np.hypot(*(door - a)) + np.hypot(*(b - door))
        via_end = min(np.hypot(*(np.array([sx * end, 0.0]) - a)) +
                      np.hypot(*(b - np.array([sx * end, 0.0]))) for sx in (-1.0, 1.0))
        assert via_end >= 1.5 * via_door


def test_wall_discs_tile_a_stretch_exactly():
    discs = lf.wall_discs(2.0, -5.0, 5.0, (0.0,), first_id=-3)
    assert [o.id for o in discs] == list(range(-3, -3 - len(discs), -1))
    x = np.array([o.center[0] for o in discs])
    assert x[0] == pytest.approx(-4.4) and x[-1] == pytest.approx(4.4)
    assert all(o.center[1] == 2.0 for o in discs)
    spacing = np.diff(x)
    assert spacing.max() == pytest.approx(lf.DOORWAY_WIDTH_M + 1.2)
    assert np.sort(spacing)[-2] <= lf.WALL_DISC_SPACING_M + 1e-9
    with pytest.raises(ScenarioError, match="shorter than one disc"):
        lf.wall_discs(0.0, -3.0, 3.0, (-2.0, 2.0))


@pytest.mark.parametrize("seed", range(4))
def test_corridor_is_two_closed_walls_wide_enough_for_two_robots_to_pass(seed):
    s = resolve("corridor", agents=8, seed=seed)
    wall_y = lf.CORRIDOR_WIDTH_M / 2.0 + lf.WALL_DISC_RADIUS_M
    for y in (-wall_y, wall_y):
        x, gaps = wall_gaps(s, y)
        assert len(x) == len(s.obstacles) // 2 and gaps.max() <= 1e-4
        np.testing.assert_allclose([x[0] - 0.6, x[-1] + 0.6], [-9.0, 9.0], atol=1e-4)
    clear = 2.0 * wall_y - 2.0 * lf.WALL_DISC_RADIUS_M
    assert clear >= 2 * 2 * ROBOT_R + 3 * 0.3  # two robots, d_safety to the walls and each other
    st, gl = starts(s), goals(s)
    np.testing.assert_allclose(gl, st * np.array([-1.0, 1.0]))  # mirrored across x = 0
    assert np.all(np.abs(st[:, 0]) >= 9.0 + lf.CORRIDOR_ENTRY_M - 1e-9)  # outside the mouths
    assert np.sum(st[:, 0] < 0) == 4
    # Every lane runs inside the corridor with d_safety to the walls' disc edges.
    assert np.all(np.abs(st[:, 1]) + ROBOT_R + 0.3 <= lf.CORRIDOR_WIDTH_M / 2.0 + 1e-9)


# --------------------------------------------------------------------------------------
# Crowds
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize(("n", "spacing"), [(16, 3.0), (25, 2.6), (36, 2.6)])
def test_grid_dense_mirrors_every_robot_through_the_centre(n, spacing):
    s = resolve("grid_dense", agents=n, seed=0)
    st, gl = starts(s), goals(s)
    k = math.isqrt(n)
    xs = np.unique(np.round(st[:, 0], 6))
    assert xs.size == k and np.allclose(np.diff(xs), spacing)
    assert 2.5 <= spacing / (2 * ROBOT_R) <= 3.0
    movers = np.ones(n, dtype=bool)
    if k % 2:
        movers[n // 2] = False
    np.testing.assert_allclose(gl[movers], -st[movers], atol=1e-9)


def test_grid_dense_odd_centre_robot_leaves_by_a_seeded_side():
    exits = set()
    for seed in range(12):
        s = resolve("grid_dense", agents=25, seed=seed)
        centre = s.robots[12]
        assert centre.start[:2] == (0.0, 0.0)
        assert np.hypot(*centre.goal) == pytest.approx(3 * 2.6)
        exits.add(centre.goal)
    assert len(exits) > 1
    with pytest.raises(ScenarioError, match="square"):
        resolve("grid_dense", agents=12)


@pytest.mark.parametrize("seed", range(4))
def test_pillar_circle_swaps_antipodally_round_one_pillar_every_line_meets(seed):
    s = resolve("pillar_circle", agents=40, seed=seed)
    (pillar,) = s.obstacles
    assert lf.PILLAR_RADII_M[0] <= pillar.radius_m <= lf.PILLAR_RADII_M[1]
    assert np.hypot(*pillar.center) <= lf.PILLAR_OFFSET_M + 1e-9
    np.testing.assert_allclose(goals(s), -starts(s), atol=1e-3)
    np.testing.assert_allclose(np.hypot(*starts(s).T), 18.0, atol=1e-3)


def test_random_40_is_40_robots_in_a_36_m_square():
    s = resolve("random_40", seed=0)
    assert len(s.robots) == 40
    both = np.vstack([starts(s), goals(s)])
    assert np.all(np.abs(both) <= 18.0 + 1e-9) and np.ptp(both[:, 0]) > 30.0


@pytest.mark.parametrize("n", [16, 18, 2])
def test_platoons_meet_head_on_in_formation(n):
    s = resolve("platoons", agents=n, seed=1)
    st, gl = starts(s), goals(s)
    half = n // 2
    np.testing.assert_allclose(gl[:half] - st[:half], [[lf.PLATOON_RUN_M, 0.0]] * half)
    np.testing.assert_allclose(gl[half:] - st[half:], [[-lf.PLATOON_RUN_M, 0.0]] * half)
    assert st[:half, 0].max() == pytest.approx(-lf.PLATOON_GAP_M / 2.0)
    assert st[half:, 0].min() == pytest.approx(lf.PLATOON_GAP_M / 2.0)
    # The platoons overlap sideways: they must pass through each other.
    a, b = st[:half, 1], st[half:, 1]
    assert max(a.min(), b.min()) < min(a.max(), b.max()) + 2 * ROBOT_R
    assert len(np.unique(np.round(a, 6))) == min(3, half)


def test_crossing_60_mixed_has_every_speed_and_the_60_deg_geometry():
    s = resolve("crossing_60_mixed", agents=16, seed=0)
    speeds = np.array([r.limits.v_max_mps for r in s.robots])
    assert set(speeds) == set(scenario_blocks.MIXED_V_MAX_MPS)
    d = goals(s) - starts(s)
    heading = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    np.testing.assert_allclose(heading[:8], 0.0, atol=1e-3)
    np.testing.assert_allclose(heading[8:], 60.0, atol=1e-3)
    plain = families.crossing(16, angle_deg=60.0)
    assert [r.start for r in s.robots] == [r.start for r in plain.robots]
    assert scenario_blocks.ideal_time_s(s.robots) == pytest.approx(np.max(np.hypot(*d.T) / speeds))


@pytest.mark.parametrize("family", ["wall_door", "wall_doors", "corridor", "platoons",
                                    "crossing_60_mixed"])
def test_two_group_families_need_an_even_count(family):
    with pytest.raises(ScenarioError, match="even"):
        resolve(family, agents=7)
