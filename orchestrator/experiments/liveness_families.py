"""Scenario families of the liveness benchmark (issue 39): static maps, dense crowds,
platoons and mixed speeds.

Walls with one and two doorways and a corridor (where a purely local planner meets local
minima), a dense grid of mirror swaps, an antipodal circle round a central pillar, a large
random scene, two platoons meeting head-on and a mixed-speed crossing at 60 deg.

Everything here is pure, like `families`: a generator takes the robot count and a
`numpy.random.Generator` and returns a validated `Scenario` at the families' scale (robot
radius 0.5 m, v_max 1.1 m/s, d_safety 0.3 m) with the benchmark time limit
(`scenario_blocks.benchmark_time_limit_s`: 3x the straight-line ideal time + 30 s). `GENERATORS`
is what `families.resolve` dispatches to; `families.FAMILIES` lists the names.

Walls and corridor walls are rows of static discs (radius 0.6 m, centres at most 1.2 m
apart: neighbouring discs touch or overlap, so nothing passes between them); a doorway is
a gap of exactly `DOORWAY_WIDTH_M` between the edges of the discs on either side.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from agent.core.scenario import ObstacleSpec, RobotSpec, Scenario
from orchestrator.experiments.scenario_blocks import (
    COORD_DECIMALS,
    MIN_CIRCLE_RADIUS_M,
    MIN_START_SPACING_M,
    MIXED_V_MAX_MPS,
    SHORT_RUN_M,
    angled_lanes,
    benchmark_time_limit_s,
    circle_radius_m,
    crossing_half_run_m,
    lane_offsets,
    make_scenario,
    mixed_values,
    random_scenario,
    require,
    robot_spec,
)

WALL_DISC_RADIUS_M = 0.6
WALL_DISC_SPACING_M = 1.2
"""Largest centre distance of neighbouring wall discs (2 x radius: they touch)."""
DOORWAY_WIDTH_M = 4.4
"""Clear width of a doorway, between the edges of the discs on either side [m]."""
DOOR_OFFSET_M = 0.6
"""Each doorway is moved along its wall by a seeded amount, uniform in +-this [m]."""
WALL_END_MARGIN_M = 10.0
WALL_END_DEPTH_FACTOR = 1.5
"""A wall reaches beyond the outermost lane of robots by this many times the deepest row's
distance from the wall, and at least `WALL_END_MARGIN_M`: going round one of its ends is
at least 1.5 times as long as going through a doorway, for every robot."""
WALL_FIRST_ROW_M = 6.0
"""Distance from the wall's centre line to the nearest row of robots [m]."""
ROW_SPACING_M = 3.0
"""Distance between rows of robots (walls, corridor) [m]."""
WALL_DOOR_LANES = 3
"""Lanes per doorway in `wall_door` (3 m apart, the middle one on the doorway's centre)."""
WALL_DOORS_X_M = (-5.0, 5.0)
"""Doorway centres of `wall_doors` before their seeded offsets [m]."""
WALL_DOORS_LANES = 2
"""Lanes per doorway in `wall_doors` (3 m apart, either side of the doorway's centre)."""

CORRIDOR_LENGTH_M = 18.0
"""Length of the corridor's walls, disc edge to disc edge [m]."""
CORRIDOR_WIDTH_M = 4.6
"""Clear width between the corridor walls' disc edges [m]: two robots (1 m discs) pass
each other with more than twice d_safety between them and the walls."""
CORRIDOR_LANE_SPACING_M = 2.5
"""The two lanes of a corridor group, symmetric about the corridor's axis [m]."""
CORRIDOR_LANE_OFFSET_M = 0.2
"""Each group's lanes are moved across the corridor by a seeded amount in +-this [m]."""
CORRIDOR_ENTRY_M = 3.0
"""Distance from the corridor's mouth to a group's first row [m]."""

GRID_DENSE_SPACING_M = {4: 3.0}
"""Centre spacing of a `grid_dense` grid by side k [m]; other sides use
`GRID_DENSE_DEFAULT_SPACING_M` (the 4x4 and 5x5 grids of issue 39)."""
GRID_DENSE_DEFAULT_SPACING_M = 2.6

PILLAR_RADII_M = (1.5, 2.0)
"""Range of the `pillar_circle` pillar's seeded radius [m]."""
PILLAR_OFFSET_M = 0.5
"""The pillar's centre is drawn uniformly in a disc of this radius round the origin [m]."""

RANDOM_40_SIDE_M = 36.0
RANDOM_40_DENSITY_PER_M2 = 40.0 / RANDOM_40_SIDE_M**2
"""`random_40`: 40 robots in a 36 m square; other counts keep that density."""

PLATOON_COLUMNS = 3
"""Columns (lanes across the direction of travel) of a platoon."""
PLATOON_SPACING_M = MIN_START_SPACING_M
"""Lane and row spacing inside a platoon [m] (a tight formation)."""
PLATOON_GAP_M = 16.0
"""Distance between the two platoons' front rows at t = 0 [m]."""
PLATOON_RUN_M = 32.0
"""Every robot's goal is its start moved this far along its platoon's direction [m]."""

CROSSING_MIXED_ANGLE_DEG = 60.0


# --------------------------------------------------------------------------------------
# Walls of discs
# --------------------------------------------------------------------------------------

def wall_discs(y_m: float, x_from_m: float, x_to_m: float, doors_x_m: Sequence[float],
               first_id: int = -1) -> list[ObstacleSpec]:
    """A straight wall along y = y_m from x_from_m to x_to_m (disc edges) with doorways.

    Every solid stretch between two doorways (or a doorway and an end) is tiled with
    discs of `WALL_DISC_RADIUS_M`, evenly, centres at most `WALL_DISC_SPACING_M` apart,
    the outermost discs' edges on the stretch's ends: each doorway is a clear gap of
    `DOORWAY_WIDTH_M` centred on its x, and the wall is closed everywhere else.

    Args:
        y_m: the wall's centre line.
        x_from_m, x_to_m: its ends (x_from_m < x_to_m).
        doors_x_m: doorway centres, each stretch at least one disc long.
        first_id: id of the first disc; the next ones count down (-1, -2, ...).

    Returns:
        The discs, from x_from_m to x_to_m.
    """
    half_door = DOORWAY_WIDTH_M / 2.0
    edges = [x_from_m, *(x for d in sorted(doors_x_m) for x in (d - half_door, d + half_door)),
             x_to_m]
    discs: list[ObstacleSpec] = []
    for a, b in zip(edges[::2], edges[1::2]):
        for x in tile_stretch(a, b):
            centre = (round(x, COORD_DECIMALS) + 0.0, round(y_m, COORD_DECIMALS) + 0.0)
            discs.append(ObstacleSpec(id=first_id - len(discs), center=centre,
                                      radius_m=WALL_DISC_RADIUS_M))
    return discs


def tile_stretch(lo_m: float, hi_m: float) -> list[float]:
    """Centres of the discs that close the solid stretch [lo_m, hi_m] of a wall: evenly
    spaced, at most `WALL_DISC_SPACING_M` apart, the outer discs' edges on its ends (also
    `structured_families.line_discs`, along a wall of any direction).

    Raises:
        ScenarioError: the stretch is shorter than one disc.
    """
    r = WALL_DISC_RADIUS_M
    require(hi_m - lo_m >= 2.0 * r - 1e-9, f"wall: a stretch of {hi_m - lo_m:g} m between "
            "openings is shorter than one disc")
    count = math.ceil(round((hi_m - lo_m - 2.0 * r) / WALL_DISC_SPACING_M, 9)) + 1
    centres: list[float] = np.linspace(lo_m + r, hi_m - r, count).tolist()
    return centres


def _door_offsets(count: int, rng: np.random.Generator) -> np.ndarray:
    """(count,) seeded shifts of the doorways along their wall [m], rounded to 1 cm."""
    return np.round(rng.uniform(-DOOR_OFFSET_M, DOOR_OFFSET_M, size=count), 2)


def _swap_across_wall(doors_x_m: Sequence[float], lanes_per_door: int, k: int
                      ) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """(start, goal) of two groups of k swapping sides of the wall y = 0.

    Lanes: `lanes_per_door` per doorway, 3 m apart, centred on the doorway's nominal
    centre. A group fills rows parallel to the wall, lane by lane (the last row may be
    short); row r is `WALL_FIRST_ROW_M` + r x `ROW_SPACING_M` from the wall. A robot's
    goal is its start mirrored across the wall: the group below (first) goes up, the
    group above comes down, head-on in every lane.
    """
    lanes = sorted(float(d + s) for d in doors_x_m for s in lane_offsets(lanes_per_door))
    pairs = []
    for side in (-1.0, 1.0):
        for j in range(k):
            y = side * (WALL_FIRST_ROW_M + (j // len(lanes)) * ROW_SPACING_M)
            x = lanes[j % len(lanes)]
            pairs.append(((x, y), (x, -y)))
    return pairs


def _wall_scenario(name: str, n: int, rng: np.random.Generator, doors_x_m: Sequence[float],
                   lanes_per_door: int) -> Scenario:
    require(n >= 2 and n % 2 == 0, f"{name}: --agents must be a positive even number "
            f"(two groups), got {n}")
    pairs = _swap_across_wall(doors_x_m, lanes_per_door, n // 2)
    depth = max(abs(s[1]) for s, _ in pairs)
    reach = (max(abs(s[0]) for s, _ in pairs) +
             max(WALL_END_MARGIN_M, WALL_END_DEPTH_FACTOR * depth))
    doors = np.asarray(doors_x_m, dtype=float) + _door_offsets(len(doors_x_m), rng)
    walls = wall_discs(0.0, -reach, reach, doors.tolist())
    robots = [robot_spec(i, s, g) for i, (s, g) in enumerate(pairs)]
    where = ", ".join(f"{d:g}" for d in doors)
    return make_scenario(f"{name}_{n}", f"two groups of {n // 2} swap sides of a {2 * reach:g} m "
                         f"wall of {len(walls)} discs through {len(doors)} "
                         f"doorway{'s' if len(doors) > 1 else ''} of {DOORWAY_WIDTH_M:g} m at "
                         f"x = {where} m", robots, obstacles=walls,
                         time_limit_s=benchmark_time_limit_s(robots))


def wall_door(n: int, rng: np.random.Generator) -> Scenario:
    """Two groups of n/2 swap sides through one doorway in a straight wall of discs.

    Geometry: the wall lies on y = 0 from -L to L, L = outermost lane + max(10 m, 1.5 x
    the deepest row's distance) (16.5 m for two rows: n <= 12); the doorway (4.4 m clear)
    is centred at x = u, u seeded uniform in +-0.6 m. Three lanes at x = -3, 0, 3 m; rows
    6, 9, ... m from the wall on either side, each robot going to its start mirrored
    across the wall (the outer lanes' straight lines meet the wall beside the doorway).
    """
    return _wall_scenario("wall_door", n, rng, (0.0,), WALL_DOOR_LANES)


def wall_doors(n: int, rng: np.random.Generator) -> Scenario:
    """`wall_door` with two doorways, nominally at x = -5 and 5 m, each moved by its own
    seeded offset (+-0.6 m); two lanes per doorway (x = -6.5, -3.5, 3.5, 6.5 m), the wall
    reaching as far beyond the outer lanes as in `wall_door` (L = 20 m for two rows:
    n <= 16)."""
    return _wall_scenario("wall_doors", n, rng, WALL_DOORS_X_M, WALL_DOORS_LANES)


def corridor(n: int, rng: np.random.Generator) -> Scenario:
    """Two groups of n/2 pass each other head-on through a corridor of two disc walls.

    Geometry: walls on y = +-(2.3 + 0.6) m from x = -9 to 9 m (disc edges), 4.6 m clear
    between them. Each group has two lanes 2.5 m apart, symmetric about the axis and
    moved across it by a seeded offset (+-0.2 m, per group); rows start 3 m outside a
    mouth, 3 m apart. A robot's goal is its start mirrored across x = 0 (the other
    group's start area), so the groups meet head-on inside the corridor.
    """
    require(n >= 2 and n % 2 == 0, f"corridor: --agents must be a positive even number "
            f"(two groups), got {n}")
    half_length = CORRIDOR_LENGTH_M / 2.0
    wall_y = CORRIDOR_WIDTH_M / 2.0 + WALL_DISC_RADIUS_M
    walls = wall_discs(-wall_y, -half_length, half_length, ())
    walls += wall_discs(wall_y, -half_length, half_length, (), first_id=-len(walls) - 1)
    lanes = lane_offsets(2, CORRIDOR_LANE_SPACING_M)
    robots: list[RobotSpec] = []
    for side, offset in zip((-1.0, 1.0), rng.uniform(-CORRIDOR_LANE_OFFSET_M,
                                                     CORRIDOR_LANE_OFFSET_M, size=2)):
        for j in range(n // 2):
            x = side * (half_length + CORRIDOR_ENTRY_M + (j // 2) * ROW_SPACING_M)
            y = float(lanes[j % 2]) + round(float(offset), 2)
            robots.append(robot_spec(len(robots), (x, y), (-x, y)))
    return make_scenario(f"corridor_{n}", f"two groups of {n // 2} pass head-on through a "
                         f"{CORRIDOR_LENGTH_M:g} m corridor, {CORRIDOR_WIDTH_M:g} m wide",
                         robots, obstacles=walls, time_limit_s=benchmark_time_limit_s(robots))


def grid_dense(n: int, rng: np.random.Generator) -> Scenario:
    """A k x k grid (n = k^2, k >= 2) of robots, each to its start mirrored through the
    centre.

    Centre spacing 3.0 m for k = 4, else 2.6 m (2.6-3 robot diameters, the grids of
    issue 39); the grid is centred on the origin and every straight line passes through
    it. Odd k: the centre robot's mirror point is its own start, so it leaves instead, to
    the point one spacing beyond the middle of a side of the grid, the side seeded.
    Even k: `rng` is unused.
    """
    k = math.isqrt(max(n, 0))
    require(n >= 4 and k * k == n, f"grid_dense: --agents must be a square (4, 9, 16, 25, "
            f"...), got {n}")
    spacing_m = GRID_DENSE_SPACING_M.get(k, GRID_DENSE_DEFAULT_SPACING_M)
    lanes = lane_offsets(k, spacing_m)
    starts = [(float(x), float(y)) for y in lanes for x in lanes]
    goals = [(-x + 0.0, -y + 0.0) for x, y in starts]
    if k % 2 == 1:
        exit_m = ((k - 1) / 2.0 + 1.0) * spacing_m
        angle = math.pi / 2.0 * int(rng.integers(4))
        goals[n // 2] = (round(exit_m * math.cos(angle), COORD_DECIMALS) + 0.0,
                         round(exit_m * math.sin(angle), COORD_DECIMALS) + 0.0)
    robots = [robot_spec(i, s, g) for i, (s, g) in enumerate(zip(starts, goals))]
    return make_scenario(f"grid_dense_{n}", f"{k}x{k} grid, {spacing_m:g} m apart, every robot to "
                         "its start mirrored through the centre" +
                         (" (the centre robot leaves the grid)" if k % 2 else ""), robots,
                         time_limit_s=benchmark_time_limit_s(robots))


def pillar_circle(n: int, rng: np.random.Generator) -> Scenario:
    """The antipodal circle (radius >= 18 m, starts >= 2.5 m apart) round one pillar.

    The pillar is a static disc of seeded radius (uniform 1.5-2 m), its centre seeded
    uniform in the disc of 0.5 m round the origin: every straight line meets it.
    """
    require(n >= 2, f"pillar_circle: --agents must be >= 2, got {n}")
    radius_m = circle_radius_m(n, MIN_START_SPACING_M, MIN_CIRCLE_RADIUS_M)
    pillar_r = round(float(rng.uniform(*PILLAR_RADII_M)), 2)
    rho = PILLAR_OFFSET_M * math.sqrt(rng.uniform())  # sqrt: uniform over the disc
    phi = rng.uniform(0.0, 2.0 * math.pi)
    centre = (round(rho * math.cos(phi), 2) + 0.0, round(rho * math.sin(phi), 2) + 0.0)
    robots = []
    for k in range(n):
        a = 2.0 * math.pi * k / n
        x, y = radius_m * math.cos(a), radius_m * math.sin(a)
        robots.append(robot_spec(k, (x, y), (-x, -y)))
    pillar = ObstacleSpec(id=-1, center=centre, radius_m=pillar_r)
    return make_scenario(f"pillar_circle_{n}", f"{n} robots on a circle of radius {radius_m:g} m, "
                         f"antipodal swap round a pillar of radius {pillar_r:g} m", robots,
                         obstacles=(pillar,), time_limit_s=benchmark_time_limit_s(robots))


def random_40(n: int, rng: np.random.Generator) -> Scenario:
    """`random_scenario` at 40 robots per 36 m square (n = 40: that square)."""
    return random_scenario(n, rng, density_per_m2=RANDOM_40_DENSITY_PER_M2,
                           name=f"random_40_{n}")


def platoons(n: int, rng: np.random.Generator) -> Scenario:
    """Two platoons of n/2 meet head-on, each keeping its formation to its goals.

    A platoon has 3 columns (fewer for n/2 < 3) and as many rows as it needs (the last
    may be short), 2.5 m apart both ways. The first drives in +x with its front row at
    x = -8 m, the second in -x with its front row at x = 8 m, its lanes moved sideways
    by a seeded offset (uniform in +-1.25 m, half a lane); every goal is the robot's start
    moved 32 m along its platoon's direction.
    """
    require(n >= 2 and n % 2 == 0, f"platoons: --agents must be a positive even number "
            f"(two platoons), got {n}")
    k = n // 2
    columns = min(PLATOON_COLUMNS, k)
    offsets = (0.0, round(float(rng.uniform(-0.5, 0.5)) * PLATOON_SPACING_M, 2))
    robots: list[RobotSpec] = []
    for direction, offset in zip((1.0, -1.0), offsets):
        lanes = lane_offsets(columns, PLATOON_SPACING_M, offset)
        for j in range(k):
            x = -direction * (PLATOON_GAP_M / 2.0 + (j // columns) * PLATOON_SPACING_M)
            y = float(lanes[j % columns])
            robots.append(robot_spec(len(robots), (x, y), (x + direction * PLATOON_RUN_M, y)))
    return make_scenario(f"platoons_{n}", f"two platoons of {k} ({columns} columns, "
                         f"{PLATOON_SPACING_M:g} m apart) meet head-on, each moving "
                         f"{PLATOON_RUN_M:g} m", robots,
                         time_limit_s=benchmark_time_limit_s(robots))


def crossing_60_mixed(n: int, rng: np.random.Generator) -> Scenario:
    """`crossing` at 60 deg (two cohorts of n/2) with mixed speeds.

    Lanes and runs as `crossing_60`; every robot's v_max is one of 0.8, 1.1 and 1.4 m/s,
    each used by about a third of the robots, the assignment seeded (as in
    `circle_mixed`); radii stay 0.5 m. The ideal time and the limit follow from each
    robot's own v_max.
    """
    require(n >= 2 and n % 2 == 0, f"crossing_60_mixed: --agents must be a positive even "
            f"number, got {n}")
    k = n // 2
    starts, goals, h = angled_lanes(lane_offsets(k), crossing_half_run_m(k + 1, SHORT_RUN_M / 2.0),
                                    CROSSING_MIXED_ANGLE_DEG)
    speeds = mixed_values(MIXED_V_MAX_MPS, n, rng)
    robots = [robot_spec(i, s, g, v_max_mps=v)
              for i, (s, g, v) in enumerate(zip(starts, goals, speeds))]
    return make_scenario(f"crossing_60_mixed_{n}", f"two cohorts of {k} crossing at 60 deg "
                         f"({2.0 * h:g} m runs), v_max 0.8-1.4 m/s", robots,
                         time_limit_s=benchmark_time_limit_s(robots))


GENERATORS: dict[str, Callable[[int, np.random.Generator], Scenario]] = {
    "wall_door": wall_door, "wall_doors": wall_doors, "corridor": corridor,
    "grid_dense": grid_dense, "pillar_circle": pillar_circle, "random_40": random_40,
    "platoons": platoons, "crossing_60_mixed": crossing_60_mixed,
}
"""Family name -> generator (`families.FAMILIES` has their default sizes and summaries)."""
