"""Scenario generators: the paper's setups A-G, scenario families, scaling and start jitter.

Everything here is pure: generators take their sizes and a `numpy.random.Generator` and
return a validated `Scenario`; `resolve` is the one entry point the CLI uses (it reads the
setup files in `orchestrator/setups/`).

Scale (the paper's grid units read as metres): robot radius 0.5 m, v_max 1.1 m/s,
d_safety 0.3 m; straight start-goal distance 36 m for setups A-E, 76 m for F and G;
lanes of one cohort 3 m apart (starts >= 2.5 m apart); time limit 4x the ideal time
(longest straight line / v_max), rounded up to 10 s; the benchmark families (circle_mixed,
crossing_<angle>, swap_pairs, swap_grid, random_<density>, obstacles_circle, and the
liveness families of `liveness_families`) 3x + 30 s.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from agent.core.config import PLANNER_NAMES, profile_config
from agent.core.scenario import ObstacleSpec, RobotSpec, Scenario
from eifp_wire import MAX_ROBOTS
from orchestrator.experiments.liveness_families import GENERATORS as LIVENESS_GENERATORS
from orchestrator.experiments.scenario_blocks import (
    LANE_SPACING_M,
    LONG_RUN_M,
    MIN_CIRCLE_RADIUS_M,
    MIN_START_SPACING_M,
    MIXED_RADII_M,
    MIXED_V_MAX_MPS,
    ROBOT_RADIUS_M,
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
from orchestrator.experiments.structured_families import GENERATORS as STRUCTURED_GENERATORS
from world.scenario_file import ScenarioError, load_scenario, validate_scenario

SETUPS_DIR = Path(__file__).resolve().parent.parent / "setups"

# Setup E: five robots, goals near the centre (pairwise >= 2.5 m apart), each start 36 m
# from its goal in a random direction (approach directions >= 35 deg apart). Drawn once
# with numpy.random.default_rng(20240505) and hard-coded so the setup never changes.
_SETUP_E = (
    # start (x, y), goal (x, y)
    ((-31.42, -22.37), (-0.86, -3.34)),
    ((-32.92, 19.28), (-2.85, -0.52)),
    ((-8.52, 34.69), (1.99, 0.26)),
    ((5.42, -34.04), (-0.29, 1.5)),
    ((33.86, -19.33), (1.81, -2.94)),
)


# --------------------------------------------------------------------------------------
# Building blocks
# --------------------------------------------------------------------------------------

# Direction of a cohort -> (start(lane, h), goal(lane, h)).
_FLOWS: dict[str, Callable[[float, float], tuple[tuple[float, float], tuple[float, float]]]] = {
    "left_to_right": lambda s, h: ((-h, s), (h, s)),
    "right_to_left": lambda s, h: ((h, s), (-h, s)),
    "top_to_bottom": lambda s, h: ((s, h), (s, -h)),
    "bottom_to_top": lambda s, h: ((s, -h), (s, h)),
}


def _cohorts(flows: Sequence[tuple[str, np.ndarray]], half_run_m: float) -> list[RobotSpec]:
    robots: list[RobotSpec] = []
    for flow, lanes in flows:
        for s in lanes:
            start, goal = _FLOWS[flow](float(s), half_run_m)
            robots.append(robot_spec(len(robots), start, goal))
    return robots


# --------------------------------------------------------------------------------------
# The paper's setups A-G
# --------------------------------------------------------------------------------------

def setup_a() -> Scenario:
    """Two robots mirrored across the x axis; their paths cross at right angles at (0, 0)."""
    c = SHORT_RUN_M / 2.0 / math.sqrt(2.0)
    robots = [robot_spec(0, (-c, c), (c, -c)), robot_spec(1, (-c, -c), (c, c))]
    return make_scenario("setup_a", "A: two robots mirrored across the x axis, paths crossing at "
                         "right angles at the origin (symmetric conflict)", robots)


def setup_b() -> Scenario:
    """Three robots in a T: one from the top, two head-on from the left and right."""
    h = SHORT_RUN_M / 2.0
    robots = [robot_spec(0, (0.0, h), (0.0, -h)), robot_spec(1, (-h, 0.0), (h, 0.0)),
              robot_spec(2, (h, 0.0), (-h, 0.0))]
    return make_scenario("setup_b", "B: three robots T-shaped, one from the top and two from "
                         "opposite sides, all meeting at the origin", robots)


def setup_c() -> Scenario:
    """Three robots 120 deg apart on a circle, each crossing to the antipodal point."""
    h = SHORT_RUN_M / 2.0
    robots = []
    for k, deg in enumerate((90.0, 210.0, 330.0)):
        a = math.radians(deg)
        start = (h * math.cos(a), h * math.sin(a))
        robots.append(robot_spec(k, start, (-start[0], -start[1])))
    return make_scenario("setup_c", "C: three robots at 120 deg converging through the origin "
                         "(radial symmetry)", robots)


def setup_d() -> Scenario:
    """Four robots on a cross swapping with the antipodal robot (mirrored across both axes)."""
    h = SHORT_RUN_M / 2.0
    starts = [(h, 0.0), (0.0, h), (-h, 0.0), (0.0, -h)]
    robots = [robot_spec(k, s, (-s[0], -s[1])) for k, s in enumerate(starts)]
    return make_scenario("setup_d", "D: four robots in a cross, antipodal swap through the "
                         "origin (mirrored across both axes)", robots)


def setup_e() -> Scenario:
    """Five robots at seeded random places, goals clustered around the centre."""
    robots = [robot_spec(k, s, g) for k, (s, g) in enumerate(_SETUP_E)]
    return make_scenario("setup_e", "E: five robots randomly distributed (seeded), goals "
                         "clustered within 4 m of the origin", robots)


def setup_f(n: int = 12) -> Scenario:
    """Three groups of n/3: left to right, top to bottom and bottom to top (head-on)."""
    require(n >= 3 and n % 3 == 0,
            f"setup_f: --agents must be a positive multiple of 3 (three groups), got {n}")
    k = n // 3
    lanes = lane_offsets(k)
    flows = [("left_to_right", lanes), ("top_to_bottom", lanes), ("bottom_to_top", lanes)]
    robots = _cohorts(flows, crossing_half_run_m(k, LONG_RUN_M / 2.0))
    name = "setup_f" if n == 12 else f"setup_f_{n}"
    return make_scenario(name, f"F: {n} robots in three groups of {k}: left to right, top to "
                         "bottom, bottom to top", robots)


def setup_g(n: int = 16) -> Scenario:
    """Four cohorts of n/4, each crossing to the opposite side (opposing cohorts head-on)."""
    require(n >= 4 and n % 4 == 0,
            f"setup_g: --agents must be a positive multiple of 4 (four cohorts), got {n}")
    k = n // 4
    lanes = lane_offsets(k)
    flows = [("left_to_right", lanes), ("right_to_left", lanes),
             ("top_to_bottom", lanes), ("bottom_to_top", lanes)]
    robots = _cohorts(flows, crossing_half_run_m(k, LONG_RUN_M / 2.0))
    name = "setup_g" if n == 16 else f"setup_g_{n}"
    return make_scenario(name, f"G: {n} robots in four cohorts of {k}, each crossing to the "
                         "opposite side (dense cross-flow)", robots)


SETUPS: dict[str, Callable[..., Scenario]] = {
    "setup_a": setup_a, "setup_b": setup_b, "setup_c": setup_c, "setup_d": setup_d,
    "setup_e": setup_e, "setup_f": setup_f, "setup_g": setup_g,
}
SCALABLE_SETUPS = ("setup_f", "setup_g")


# --------------------------------------------------------------------------------------
# Families
# --------------------------------------------------------------------------------------

def circle(n: int, rng: np.random.Generator | None = None) -> Scenario:
    """n robots on a circle, each swapping with its antipode; exactly point-symmetric.

    The radius is the smallest for which neighbouring starts are >= 2.5 m apart, but at
    least 18 m. For even n the second half of the robots is the exact negation of the
    first half. `rng` is unused (the family is deterministic).
    """
    require(n >= 2, f"circle: --agents must be >= 2, got {n}")
    radius_m = max(MIN_CIRCLE_RADIUS_M, MIN_START_SPACING_M / 2.0 / math.sin(math.pi / n))
    radius_m = math.ceil(radius_m * 10.0) / 10.0
    half = n // 2 if n % 2 == 0 else n
    starts = [(radius_m * math.cos(2.0 * math.pi * k / n),
               radius_m * math.sin(2.0 * math.pi * k / n)) for k in range(half)]
    if n % 2 == 0:
        starts += [(-x, -y) for x, y in starts]
    robots = [robot_spec(k, (x, y), (-x, -y), exact=True) for k, (x, y) in enumerate(starts)]
    return make_scenario(f"circle_{n}", f"{n} robots on a circle of radius {radius_m:g} m, "
                         "antipodal swap", robots)


CIRCLES_GROUP = 8
"""Robots per circle of the `circles` family (the last circles may hold fewer, >= 2)."""
CIRCLES_RADIUS_M = 8.0
CIRCLES_PITCH_M = 19.0
"""Centre distance of neighbouring circles: the outermost robots of two neighbours start
3 m apart, well inside each other's sensing radius, so circles interact at their edges."""
CIRCLES_TIME_LIMIT_S = 120.0
"""An 8-robot antipodal swap through one point takes eIFP-MPC up to ~6x the ideal 14.5 s
(lockstep, 16 robots: all arrived at 83 s), more than the families' 4x rule allows."""


def circle_tile(centre_xy: tuple[float, float], size: int, g: int, *, first_id: int
                ) -> list[RobotSpec]:
    """Circle g of the `circles` family: `size` robots on a circle of `CIRCLES_RADIUS_M`
    around `centre_xy` [m], each swapping to the antipodal point, rotated by
    g * 22.5 deg / 3; ids from `first_id` on."""
    cx, cy = centre_xy
    turn = g * math.pi / CIRCLES_GROUP / 3.0
    robots = []
    for k in range(size):
        a = turn + 2.0 * math.pi * k / size
        dx, dy = CIRCLES_RADIUS_M * math.cos(a), CIRCLES_RADIUS_M * math.sin(a)
        robots.append(robot_spec(first_id + k, (cx + dx, cy + dy), (cx - dx, cy - dy)))
    return robots


def circles(n: int, rng: np.random.Generator | None = None) -> Scenario:
    """n robots in antipodal circles of up to 8 (radius 8 m), circles on a 19 m grid.

    The scaling family: every circle is the `circle` swap at a small radius, so the
    density around a robot and the run's duration stay the same for any n, while robots
    on the rims of neighbouring circles meet each other. Circle g is rotated by
    g * 22.5 deg / 3 (neighbouring circles are not mirror images). `rng` is unused.
    """
    require(n >= 2, f"circles: --agents must be >= 2, got {n}")
    groups = math.ceil(n / CIRCLES_GROUP)
    sizes = [n // groups + (1 if g < n % groups else 0) for g in range(groups)]
    cols = math.ceil(math.sqrt(groups))
    rows = math.ceil(groups / cols)
    robots: list[RobotSpec] = []
    for g, size in enumerate(sizes):
        centre = ((g % cols - (cols - 1) / 2.0) * CIRCLES_PITCH_M,
                  (g // cols - (rows - 1) / 2.0) * CIRCLES_PITCH_M)
        robots += circle_tile(centre, size, g, first_id=len(robots))
    scenario = make_scenario(f"circles_{n}", f"{n} robots in {groups} antipodal circles of "
                             f"radius {CIRCLES_RADIUS_M:g} m, {CIRCLES_PITCH_M:g} m apart", robots)
    return dataclasses.replace(scenario, time_limit_s=CIRCLES_TIME_LIMIT_S)


def crossing(n: int, rng: np.random.Generator | None = None, *, flows: int = 2,
             angle_deg: float | None = None) -> Scenario:
    """Flows of n/flows robots crossing a square (36 m across, wider for wide cohorts).

    flows=2: left to right and bottom to top. flows=4: all four directions, opposing
    flows on interleaved lanes (half a lane apart). `rng` is unused.

    angle_deg (flows=2 only): the second cohort's direction of travel at this angle to the
    first's (counter-clockwise, 0 < angle < 180): 90 is the perpendicular crossing (the
    same robots as without an angle), 45 two cohorts merging at a shallow angle, 135
    nearly head-on. Both cohorts' lanes cross at the origin; for shallow angles the run is
    lengthened (in 1 m steps) until the two cohorts' starts, and their goals, keep the
    generators' 2.5 m spacing. The scenario is then named `crossing_<angle>_<n>` and has
    the benchmark time limit (`benchmark_time_limit_s`).
    """
    require(flows in (2, 4), f"crossing: flows must be 2 or 4, got {flows}")
    require(n >= flows and n % flows == 0,
            f"crossing: --agents must be a positive multiple of {flows}, got {n}")
    k = n // flows
    # k + 1: interleaved lanes reach half a lane out.
    h = crossing_half_run_m(k + 1, SHORT_RUN_M / 2.0)
    lanes = lane_offsets(k)
    if angle_deg is not None:
        require(flows == 2, "crossing: an angle needs flows=2")
        return _angled_crossing(k, lanes, h, float(angle_deg))
    if flows == 2:
        spec = [("left_to_right", lanes), ("bottom_to_top", lanes)]
        name = f"crossing_{n}"
    else:
        shifted = lane_offsets(k, offset_m=LANE_SPACING_M / 2.0)
        spec = [("left_to_right", lanes), ("bottom_to_top", lanes),
                ("right_to_left", shifted), ("top_to_bottom", shifted)]
        name = f"crossing4_{n}"
    return make_scenario(name, f"{flows} perpendicular flows of {k} robots", _cohorts(spec, h))


def _angled_crossing(k: int, lanes: np.ndarray, h: float, angle_deg: float) -> Scenario:
    starts, goals, h = angled_lanes(lanes, h, angle_deg)
    robots = [robot_spec(i, s, g) for i, (s, g) in enumerate(zip(starts, goals))]
    n = 2 * k
    label = f"{angle_deg:g}"
    return make_scenario(f"crossing_{label}_{n}", f"two cohorts of {k} crossing at {label} deg "
                         f"({2.0 * h:g} m runs)", robots,
                         time_limit_s=benchmark_time_limit_s(robots))


# --------------------------------------------------------------------------------------
# Benchmark families (orchestrator benchmark): scenarios the planners were not tuned on
# --------------------------------------------------------------------------------------

def circle_mixed(n: int, rng: np.random.Generator) -> Scenario:
    """The antipodal circle with mixed robots: radii 0.3/0.5/0.7 m, v_max 0.8/1.1/1.4 m/s.

    Each value is used by about a third of the robots (n >= 3: all three appear), the
    assignment seeded by `rng` (radii and speeds independently). Neighbouring starts keep a
    2.5 m centre spacing plus what the largest disc adds over 0.5 m (2.9 m). Ideal time
    and time limit follow from each robot's own v_max (the slowest robot decides).
    """
    require(n >= 2, f"circle_mixed: --agents must be >= 2, got {n}")
    spacing_m = MIN_START_SPACING_M + 2.0 * (max(MIXED_RADII_M) - ROBOT_RADIUS_M)
    radius_m = circle_radius_m(n, spacing_m, MIN_CIRCLE_RADIUS_M)
    radii = mixed_values(MIXED_RADII_M, n, rng)
    speeds = mixed_values(MIXED_V_MAX_MPS, n, rng)
    robots = []
    for k in range(n):
        a = 2.0 * math.pi * k / n
        x, y = radius_m * math.cos(a), radius_m * math.sin(a)
        robots.append(robot_spec(k, (x, y), (-x, -y), radius_m=radii[k], v_max_mps=speeds[k]))
    return make_scenario(f"circle_mixed_{n}", f"{n} mixed robots (radius 0.3-0.7 m, v_max "
                         f"0.8-1.4 m/s) on a circle of radius {radius_m:g} m, antipodal swap",
                         robots, time_limit_s=benchmark_time_limit_s(robots))


SWAP_RUN_M = 12.0
"""Distance the two robots of a `swap_pairs` pair travel (head-on)."""
SWAP_PAIR_SPACING_M = LANE_SPACING_M
"""Distance between neighbouring pairs of `swap_pairs`."""


def swap_pairs(n: int, rng: np.random.Generator | None = None) -> Scenario:
    """n/2 pairs side by side, the two robots of a pair swapping places head-on.

    Pair p: robots at (-6 m, y_p) and (+6 m, y_p), lanes 3 m apart (so neighbouring pairs
    interact while they dodge); robot 2p starts on the left. `rng` is unused.
    """
    require(n >= 2 and n % 2 == 0, f"swap_pairs: --agents must be a positive even number, "
            f"got {n}")
    half = SWAP_RUN_M / 2.0
    robots: list[RobotSpec] = []
    for y in lane_offsets(n // 2, SWAP_PAIR_SPACING_M):
        robots.append(robot_spec(len(robots), (-half, y), (half, y)))
        robots.append(robot_spec(len(robots), (half, y), (-half, y)))
    return make_scenario(f"swap_pairs_{n}", f"{n // 2} pairs side by side "
                         f"({SWAP_PAIR_SPACING_M:g} m apart), each swapping places head-on "
                         f"over {SWAP_RUN_M:g} m", robots,
                         time_limit_s=benchmark_time_limit_s(robots))


SWAP_GRID_SPACING_M = 4.0
"""Cell size of `swap_grid`."""


def swap_grid(n: int, rng: np.random.Generator | None = None) -> Scenario:
    """A k x k grid (n = k^2, k even), every robot going to the mirrored cell.

    Cells are 4 m apart, centred on the origin; robot (i, j) goes to cell (k-1-i, k-1-j),
    i.e. its goal is its start mirrored through the centre (k even: nobody stays). Every
    straight line passes through the centre. `rng` is unused.
    """
    k = math.isqrt(max(n, 0))
    require(n >= 4 and k * k == n and k % 2 == 0,
            f"swap_grid: --agents must be the square of an even number (4, 16, 36, ...), "
            f"got {n}")
    lanes = lane_offsets(k, SWAP_GRID_SPACING_M)
    robots = [robot_spec(i * k + j, (x, y), (-x, -y))
              for i, y in enumerate(lanes) for j, x in enumerate(lanes)]
    return make_scenario(f"swap_grid_{n}", f"{k}x{k} grid ({SWAP_GRID_SPACING_M:g} m cells), every "
                         "robot to the cell mirrored through the centre", robots,
                         time_limit_s=benchmark_time_limit_s(robots))


RANDOM_DENSITIES_PER_M2 = {"sparse": 0.01, "medium": 0.025, "dense": 0.05}
"""Robots per square metre of the `random_<density>` families (1, 2.5, 5 per 100 m^2)."""


def random_density(n: int, rng: np.random.Generator, density: str) -> Scenario:
    """`random_scenario` in a square sized for a named density (`RANDOM_DENSITIES_PER_M2`)."""
    require(density in RANDOM_DENSITIES_PER_M2,
            f"random: density must be one of {', '.join(RANDOM_DENSITIES_PER_M2)}, "
            f"got {density!r}")
    return random_scenario(n, rng, density_per_m2=RANDOM_DENSITIES_PER_M2[density],
                           name=f"random_{density}_{n}")


MOVERS = 4
"""Moving obstacles of the `movers` family."""
MOVER_SPEEDS_MPS = (0.4, 1.0)
"""Range of the `movers` obstacles' speeds [m/s]."""
MOVER_RADIUS_M = 0.6
"""Radius of the `movers` obstacles [m]."""


def movers(n: int, rng: np.random.Generator) -> Scenario:
    """`random_medium`'s robots, with `MOVERS` blind obstacles crossing their square.

    The obstacles keep a constant velocity whatever happens (a scenario obstacle does
    not plan): each enters from a side edge (alternately left and right) at the start,
    on a lane across the square (lanes at 1/8, 3/8, 5/8 and 7/8 of the side, moved by up
    to an eighth of it), at a seeded speed in 0.4-1.0 m/s and a heading within 0.15 rad
    of straight across. They cross the goals of robots that have arrived: the scene for
    `agent.planning.goal_guard`.
    """
    base = random_density(n, rng, "medium")
    half_m = max(max(abs(c) for r in base.robots for c in (*r.start[:2], *r.goal)), 1.0)
    obstacles = []
    for k in range(MOVERS):
        direction = 1.0 if k % 2 else -1.0
        lane = half_m * (-1.0 + (2 * k + 1) / MOVERS + float(rng.uniform(-0.25, 0.25)) / 2.0)
        speed = float(rng.uniform(*MOVER_SPEEDS_MPS))
        angle = float(rng.uniform(-0.15, 0.15))
        x_m = -direction * _clear_of_robots(half_m + 1.0, direction, lane, base.robots)
        obstacles.append(ObstacleSpec(
            id=-(k + 1), center=(round(x_m, 3), round(lane, 3)),
            radius_m=MOVER_RADIUS_M,
            velocity=(round(direction * speed * math.cos(angle), 3),
                      round(speed * math.sin(angle), 3))))
    return make_scenario(f"movers_{n}", f"{base.description}, {MOVERS} obstacles crossing "
                         f"it at 0.4-1.0 m/s", base.robots, obstacles=obstacles,
                         time_limit_s=base.time_limit_s)


MOVER_START_GAP_M = 0.3
"""Smallest gap at t = 0 between a mover and a robot's start or goal disc its track runs
through (`_clear_of_robots`): a robot standing in its way has 0.3-0.75 s to start moving."""


def _clear_of_robots(out_m: float, direction: float, lane_m: float,
                     robots: Sequence[RobotSpec]) -> float:
    """How far out (|x|) a mover entering on `lane_m` from the side -`direction` starts: at
    `out_m`, or further out where it would come within `MOVER_START_GAP_M` of a robot's
    start or goal disc at the edge of the square (run seeds 6, 23 and 27 of `movers` 20
    overlapped one, and the scenario was refused)."""
    for r in robots:
        for x, y in (r.start[:2], r.goal):
            dy = lane_m - y
            reach = MOVER_RADIUS_M + r.radius_m
            if abs(dy) < reach:  # the mover's track runs through this disc
                touch = -direction * x + math.sqrt(reach * reach - dy * dy)
                out_m = max(out_m, touch + MOVER_START_GAP_M)
    return out_m


OBSTACLE_RADII_M = (1.0, 2.0)
"""Range of the static obstacles' radii in `obstacles_circle`."""
OBSTACLE_GAP_M = 2.5
"""Smallest gap between two obstacles of `obstacles_circle` (a robot fits through)."""
OBSTACLE_CIRCLE_MIN_RADIUS_M = 12.0


def obstacles_circle(n: int, rng: np.random.Generator, *, max_tries: int = 10_000
                     ) -> Scenario:
    """The antipodal circle (radius >= 12 m) with 3-5 static disc obstacles inside.

    Obstacles: seeded count, radii uniform in 1-2 m, centres uniform in the disc of half
    the circle's radius (one of them within 2 m of the centre, where every straight path
    meets); pairwise gaps >= 2.5 m. Starts and goals are on the circle, so the obstacles
    never overlap them (and `validate_scenario` checks it).
    """
    require(n >= 2, f"obstacles_circle: --agents must be >= 2, got {n}")
    radius_m = circle_radius_m(n, MIN_START_SPACING_M, OBSTACLE_CIRCLE_MIN_RADIUS_M)
    count = int(rng.integers(3, 6))
    obstacles: list[ObstacleSpec] = []
    tries = 0
    while len(obstacles) < count:
        tries += 1
        if tries > max_tries:  # pragma: no cover - the disc is far from full
            raise ScenarioError(f"obstacles_circle: could not place {count} obstacles")
        reach = 2.0 if not obstacles else radius_m / 2.0
        rho = reach * math.sqrt(rng.uniform())
        phi = rng.uniform(0.0, 2.0 * math.pi)
        c = (round(rho * math.cos(phi), 2) + 0.0, round(rho * math.sin(phi), 2) + 0.0)
        r = round(float(rng.uniform(*OBSTACLE_RADII_M)), 2)
        if any(math.dist(c, o.center) - r - o.radius_m < OBSTACLE_GAP_M for o in obstacles):
            continue
        obstacles.append(ObstacleSpec(id=-(len(obstacles) + 1), center=c, radius_m=r))
    robots = []
    for k in range(n):
        a = 2.0 * math.pi * k / n
        x, y = radius_m * math.cos(a), radius_m * math.sin(a)
        robots.append(robot_spec(k, (x, y), (-x, -y)))
    return make_scenario(f"obstacles_circle_{n}", f"{n} robots on a circle of radius "
                         f"{radius_m:g} m, antipodal swap around {count} static obstacles",
                         robots, obstacles=obstacles, time_limit_s=benchmark_time_limit_s(robots))


FAMILIES: dict[str, tuple[int, str]] = {
    # name -> (default robot count, what it is)
    "circle": (8, "N robots on a circle (radius >= 18 m), antipodal swap"),
    "crossing": (8, "two perpendicular flows of N/2 (left->right, bottom->top)"),
    "crossing4": (16, "four perpendicular flows of N/4, opposing flows on interleaved lanes"),
    "random": (8, "N seeded random starts and goals in a square, >= 2.5 m spacing"),
    "circles": (16, "antipodal circles of 8 (radius 8 m) on a 19 m grid: the scaling family"),
    "circle_mixed": (16, "antipodal circle, mixed radii 0.3-0.7 m and v_max 0.8-1.4 m/s"),
    "crossing_45": (16, "two cohorts of N/2 crossing at 45 deg (shallow merge)"),
    "crossing_90": (16, "two cohorts of N/2 crossing at 90 deg"),
    "crossing_135": (16, "two cohorts of N/2 crossing at 135 deg (nearly head-on)"),
    "swap_pairs": (6, "N/2 pairs side by side, 3 m apart, each swapping places head-on"),
    "swap_grid": (16, "k x k grid (N = k^2, k even), each robot to the mirrored cell"),
    "random_sparse": (20, "N seeded random starts and goals, 1 robot per 100 m^2"),
    "random_medium": (20, "N seeded random starts and goals, 2.5 robots per 100 m^2"),
    "random_dense": (20, "N seeded random starts and goals, 5 robots per 100 m^2"),
    "obstacles_circle": (12, "antipodal circle (radius >= 12 m) around 3-5 static obstacles"),
    "movers": (20, "random_medium's N robots, 4 blind obstacles crossing at 0.4-1.0 m/s"),
    # The liveness families (issue 39); generators: `liveness_families.GENERATORS`.
    "wall_door": (12, "two groups of N/2 swap sides through one 4.4 m doorway in a disc wall"),
    "wall_doors": (16, "two groups of N/2 swap sides of a disc wall with two doorways"),
    "corridor": (8, "two groups of N/2 pass head-on through an 18 m corridor, 4.6 m wide"),
    "grid_dense": (25, "k x k grid (N = k^2) 2.6-3 m apart, each robot to its mirror point"),
    "pillar_circle": (24, "antipodal circle (radius >= 18 m) round a central pillar"),
    "random_40": (40, "N seeded random starts and goals, 40 robots per 36 m square"),
    "platoons": (16, "two platoons of N/2 (3 columns, 2.5 m apart) meeting head-on"),
    "crossing_60_mixed": (16, "two cohorts of N/2 crossing at 60 deg, v_max 0.8-1.4 m/s"),
    # Structured scenes, not in the default suite; generators: `structured_families`.
    "rooms": (10, "N robots in a 3x3 block of rooms with doors 1.6-3.0 m, each to another room"),
    "evacuate": (18, "N robots leave a 14 m room through one door 2.8-3.4 m wide"),
    "cross_corridors": (12, "four corridors 2.6-3.2 m clear meet; N/4 per arm to other arms"),
    "dead_end": (6, "N robots to goals along a dead-end corridor 2.6-3.2 m, random order"),
    "parking": (12, "N robots from a ring to goals packed 1.5 m apart"),
    "pocket": (6, "N robots start in U-shaped pockets open away from their goals"),
    "random_walls": (14, "N random starts and goals among six random walls, 26 m square"),
    "maze": (12, "N/2 each way through three walls 2.8-3.6 m apart, a 2.8-3.2 m door each"),
}


def _family(name: str, n: int, rng: np.random.Generator) -> Scenario:
    if name in LIVENESS_GENERATORS:
        return LIVENESS_GENERATORS[name](n, rng)
    if name in STRUCTURED_GENERATORS:
        return STRUCTURED_GENERATORS[name](n, rng)
    if name == "circle":
        return circle(n, rng)
    if name == "crossing":
        return crossing(n, rng, flows=2)
    if name == "circles":
        return circles(n, rng)
    if name == "crossing4":
        return crossing(n, rng, flows=4)
    if name == "circle_mixed":
        return circle_mixed(n, rng)
    if name.startswith("crossing_"):
        return crossing(n, rng, flows=2, angle_deg=float(name.removeprefix("crossing_")))
    if name == "movers":
        return movers(n, rng)
    if name == "swap_pairs":
        return swap_pairs(n, rng)
    if name == "swap_grid":
        return swap_grid(n, rng)
    if name.startswith("random_"):
        return random_density(n, rng, name.removeprefix("random_"))
    if name == "obstacles_circle":
        return obstacles_circle(n, rng)
    return random_scenario(n, rng)


# --------------------------------------------------------------------------------------
# Perturbation and resolution
# --------------------------------------------------------------------------------------

def jitter_starts(scenario: Scenario, d_m: float, rng: np.random.Generator, *,
                  min_gap_m: float = 0.2, tries: int = 100) -> Scenario:
    """Move every start by up to d_m metres (uniform in a disc); headings are kept.

    Robots are moved one after another; a draw is accepted when the moved disc keeps a
    gap of at least min_gap_m to every other start (moved or not) and every obstacle at
    t = 0. After `tries` rejected draws the robot keeps its start, which is always valid
    because the robots moved before it were checked against it.
    """
    if not (math.isfinite(d_m) and d_m >= 0.0):
        raise ScenarioError(f"{scenario.name}: start jitter must be >= 0 m, got {d_m!r}")
    if d_m == 0.0:
        return scenario
    xy = np.array([r.start[:2] for r in scenario.robots], dtype=float)
    radius = np.array([r.radius_m for r in scenario.robots], dtype=float)
    ob_c = np.array([o.center for o in scenario.obstacles], dtype=float).reshape(-1, 2)
    ob_r = np.array([o.radius_m for o in scenario.obstacles], dtype=float)
    others = np.ones(len(xy), dtype=bool)
    for k in range(len(xy)):
        others[:] = True
        others[k] = False
        for _ in range(tries):
            rho = d_m * math.sqrt(rng.uniform())  # sqrt: uniform over the disc's area
            phi = rng.uniform(0.0, 2.0 * math.pi)
            cand = xy[k] + rho * np.array([math.cos(phi), math.sin(phi)])
            gap_r = np.hypot(*(xy[others] - cand).T) - radius[others] - radius[k]
            gap_o = np.hypot(*(ob_c - cand).T) - ob_r - radius[k]
            if np.all(gap_r >= min_gap_m) and np.all(gap_o >= min_gap_m):
                xy[k] = cand
                break
    robots = tuple(
        dataclasses.replace(r, start=(float(x), float(y), r.start[2]))
        for r, (x, y) in zip(scenario.robots, xy)
    )
    jittered = dataclasses.replace(
        scenario, robots=robots,
        description=f"{scenario.description} (starts jittered by up to {d_m:g} m)")
    return validate_scenario(jittered, scenario.name)


def with_planner(scenario: Scenario, planner: str) -> Scenario:
    """Every robot uses `planner`."""
    if planner not in PLANNER_NAMES:
        raise ScenarioError(f"--planner: unknown planner {planner!r}; expected one of "
                            f"{', '.join(PLANNER_NAMES)}")
    robots = tuple(dataclasses.replace(r, planner=planner) for r in scenario.robots)
    return dataclasses.replace(scenario, robots=robots)


def setup_path(name: str) -> Path:
    """The file of a named setup (`setup_a` ... `setup_g`)."""
    return SETUPS_DIR / f"{name}.yaml"


def known_names() -> tuple[str, ...]:
    """Every name `resolve` accepts besides a file path."""
    return (*SETUPS, *FAMILIES)


def resolve(name_or_path: str, agents: int | None = None, seed: int = 0,
            start_jitter_m: float = 0.0, planner: str | None = None,
            profile: str | None = None, without: str | None = None) -> Scenario:
    """The scenario the CLI runs.

    Args:
        name_or_path: `setup_a` ... `setup_g` (also `a` ... `g`), a family (`FAMILIES`:
            `circle`, `crossing`, `crossing4`, `random`, the benchmark families) or a
            scenario file path.
        agents: robot count; setups F and G scale (groups of agents/3, cohorts of
            agents/4), families take any valid count, other setups and files only
            their own size.
        seed: seeds the random family and the start jitter (independent streams).
        start_jitter_m: move starts by up to this much (see `jitter_starts`).
        planner: if given, every robot uses it.
        profile: if given, the planner configuration of that profile
            (`agent.core.config.PROFILES`; ``paper``: the paper's method as written, built
            on the scenario's own weights and sizes).
        without: if given, mechanisms of the default profile to switch off, comma-separated
            (`agent.core.config.PlannerConfig.without`): ablations.

    Raises:
        ScenarioError: unknown name, bad size, invalid file or parameters.
    """
    family_rng, jitter_rng = np.random.default_rng(seed).spawn(2)
    key = name_or_path.strip()
    if len(key) == 1 and f"setup_{key.lower()}" in SETUPS:
        key = f"setup_{key.lower()}"
    if agents is not None and not 1 <= agents <= MAX_ROBOTS:
        raise ScenarioError(f"--agents: must be in [1, {MAX_ROBOTS}], got {agents}")
    if key in SETUPS:
        scenario = load_scenario(setup_path(key))
        if agents is not None and agents != len(scenario.robots):
            if key not in SCALABLE_SETUPS:
                raise ScenarioError(
                    f"{key}: has a fixed size of {len(scenario.robots)} robots; "
                    f"--agents {agents} is only supported for {', '.join(SCALABLE_SETUPS)} "
                    "and the families")
            scenario = SETUPS[key](agents)
    elif key in FAMILIES:
        scenario = _family(key, FAMILIES[key][0] if agents is None else agents, family_rng)
    elif key.endswith((".yaml", ".yml")) or Path(key).is_file():
        scenario = load_scenario(key)
        if agents is not None and agents != len(scenario.robots):
            raise ScenarioError(f"{key}: has {len(scenario.robots)} robots; --agents "
                                f"{agents} cannot resize a scenario file")
    else:
        raise ScenarioError(f"{key}: unknown setup or family; expected one of "
                            f"{', '.join(known_names())} or a .yaml file")
    if planner is not None:
        scenario = with_planner(scenario, planner)
    if profile is not None:
        try:
            config = profile_config(profile, scenario.planner_config)
        except ValueError as exc:
            raise ScenarioError(f"--profile: {exc}") from None
        scenario = dataclasses.replace(scenario, planner_config=config)
    if without is not None:
        try:
            config = scenario.planner_config.with_settings(without=without)
        except ValueError as exc:
            raise ScenarioError(f"--{exc}") from None
        scenario = dataclasses.replace(scenario, planner_config=config)
    return jitter_starts(scenario, start_jitter_m, jitter_rng)
