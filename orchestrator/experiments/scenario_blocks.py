"""Building blocks of the scenario generators (`families`, `liveness_families`): the
families' scale, robots heading at their goals, validated scenarios, lanes, time limits,
and the generators both modules build on (`random_scenario`, `angled_lanes`).

Pure: sizes and a `numpy.random.Generator` in, validated `Scenario` out.

Scale (the paper's grid units read as metres): robot radius 0.5 m, v_max 1.1 m/s,
d_safety 0.3 m; lanes of one cohort 3 m apart (starts >= 2.5 m apart); time limit 4x the
ideal time (longest straight line / v_max), rounded up to 10 s, or for the benchmark
families (`benchmark_time_limit_s`) 3x + 30 s.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from agent.core.config import PlannerConfig, RobotLimits, SafetyConfig
from agent.core.scenario import ObstacleSpec, RobotSpec, Scenario
from world.scenario_file import ScenarioError, validate_scenario

ROBOT_RADIUS_M = 0.5
V_MAX_MPS = 1.1
OMEGA_MAX_RADPS = 1.5
D_SAFETY_M = 0.3
SHORT_RUN_M = 36.0
"""Straight start-goal distance of setups A-E."""
LONG_RUN_M = 76.0
"""Straight start-goal distance of setups F and G."""
LANE_SPACING_M = 3.0
"""Distance between neighbouring lanes of one cohort."""
MIN_START_SPACING_M = 2.5
"""Smallest centre distance between two starts (or two goals) a generator produces."""
MIN_CIRCLE_RADIUS_M = 18.0
TIME_LIMIT_FACTOR = 4.0
"""Time limit = this many times the ideal time, rounded up to 10 s."""
BENCH_TIME_LIMIT_FACTOR = 3.0
BENCH_TIME_MARGIN_S = 30.0
"""Benchmark families (`benchmark_time_limit_s`): 3x the ideal time + 30 s."""
COORD_DECIMALS = 4
HEADING_DECIMALS = 6


def robot_spec(robot_id: int, start_xy: Iterable[float], goal_xy: Iterable[float], *,
               exact: bool = False, radius_m: float = ROBOT_RADIUS_M,
               v_max_mps: float = V_MAX_MPS) -> RobotSpec:
    """A robot at the setups' scale, heading straight at its goal (`start_xy`, `goal_xy`:
    x, y [m]).

    Coordinates are rounded to 0.1 mm and headings to 1 urad (short, readable files)
    unless `exact`. The `+ 0.0` turns -0.0 into 0.0.
    """
    def r(value: float, decimals: int) -> float:
        return float(value) + 0.0 if exact else round(float(value), decimals) + 0.0

    sx, sy = (r(c, COORD_DECIMALS) for c in start_xy)
    gx, gy = (r(c, COORD_DECIMALS) for c in goal_xy)
    heading = r(math.atan2(gy - sy, gx - sx), HEADING_DECIMALS)
    return RobotSpec(
        id=robot_id,
        start=(sx, sy, heading),
        goal=(gx, gy),
        radius_m=float(radius_m),
        limits=RobotLimits(v_max_mps=float(v_max_mps), omega_max_radps=OMEGA_MAX_RADPS),
    )


def ideal_time_s(robots: Sequence[RobotSpec]) -> float:
    """Longest straight start-goal line over v_max (the best any planner can do)."""
    return max(
        math.hypot(r.goal[0] - r.start[0], r.goal[1] - r.start[1]) / r.limits.v_max_mps
        for r in robots
    )


def benchmark_time_limit_s(robots: Sequence[RobotSpec]) -> float:
    """The benchmark families' limit: 3x the ideal time + 30 s, rounded up to 10 s.

    Generous, so a slow planner fails by time rather than by a tight limit; short runs
    (a swap over 12 m, ideal 11 s) get the margin, long ones the factor.
    """
    ideal = ideal_time_s(robots)
    return math.ceil((BENCH_TIME_LIMIT_FACTOR * ideal + BENCH_TIME_MARGIN_S) / 10.0) * 10.0


def make_scenario(name: str, description: str, robots: Sequence[RobotSpec], *,
                  obstacles: Sequence[ObstacleSpec] = (),
                  time_limit_s: float | None = None) -> Scenario:
    """The validated scenario at the families' scale (d_safety 0.3 m, goal tolerance
    0.25 m); time limit `time_limit_s`, else 4x the ideal time rounded up to 10 s.

    Raises:
        ScenarioError: `validate_scenario` refuses it (named by `name`).
    """
    limit = time_limit_s if time_limit_s is not None else \
        math.ceil(TIME_LIMIT_FACTOR * ideal_time_s(robots) / 10.0) * 10.0
    scenario = Scenario(
        name=name,
        description=description,
        time_limit_s=float(limit),
        goal_tolerance_m=0.25,
        planner_config=PlannerConfig(safety=SafetyConfig(d_safety_m=D_SAFETY_M)),
        robots=tuple(robots),
        obstacles=tuple(obstacles),
    )
    return validate_scenario(scenario, name)


def lane_offsets(k: int, spacing_m: float = LANE_SPACING_M, offset_m: float = 0.0) -> np.ndarray:
    """(k,) lane offsets centred on 0 (plus offset_m), spacing_m apart."""
    return (np.arange(k) - (k - 1) / 2.0) * spacing_m + offset_m


def crossing_half_run_m(k: int, minimum_m: float) -> float:
    """Half the crossing distance: the requested one, or more when cohorts are wide."""
    lanes_half_width = (k - 1) / 2.0 * LANE_SPACING_M
    return max(minimum_m, lanes_half_width + 2.0 * MIN_START_SPACING_M)


def require(condition: bool, message: str) -> None:
    """Raise `ScenarioError(message)` unless `condition` (a generator's size checks)."""
    if not condition:
        raise ScenarioError(message)


def angled_lanes(lanes: np.ndarray, h: float, angle_deg: float
                 ) -> tuple[np.ndarray, np.ndarray, float]:
    """Starts and goals of two cohorts on `lanes` crossing at angle_deg (`crossing`).

    Args:
        lanes: (k,) lane offsets [m] of each cohort.
        h: the smallest half run [m]; lengthened in 1 m steps until starts, and goals,
            keep the 2.5 m spacing.
        angle_deg: the second cohort's direction to the first's, in (0, 180).

    Returns:
        (starts (2k, 2), goals (2k, 2), the half run used [m]); the first cohort first.
    """
    require(math.isfinite(angle_deg) and 0.0 < angle_deg < 180.0,
            f"crossing: the angle must be in (0, 180) deg, got {angle_deg!r}")
    phi = math.radians(angle_deg)
    directions = (np.array([1.0, 0.0]), np.array([math.cos(phi), math.sin(phi)]))
    # Lane offsets along the left normal of the first cohort and the right normal of the
    # second: at 90 deg these are exactly the `left_to_right` and `bottom_to_top` flows.
    normals = (np.array([0.0, 1.0]), np.array([math.sin(phi), -math.cos(phi)]))
    for _ in range(200):
        starts = np.array([-h * d + s * nrm for d, nrm in zip(directions, normals)
                           for s in lanes])
        goals = np.array([h * d + s * nrm for d, nrm in zip(directions, normals)
                          for s in lanes])
        if min(min_spacing_m(starts), min_spacing_m(goals)) >= MIN_START_SPACING_M:
            break
        h += 1.0
    else:  # pragma: no cover - 200 m more always separates the cohorts
        raise ScenarioError(f"crossing: could not separate the cohorts at {angle_deg:g} deg")
    return starts, goals, h


def min_spacing_m(xy: np.ndarray) -> float:
    """Smallest centre distance between two rows of (m, 2) points (inf for fewer than 2)."""
    if len(xy) < 2:
        return math.inf
    i, j = np.triu_indices(len(xy), k=1)
    return float(np.hypot(*(xy[i] - xy[j]).T).min())


def random_scenario(n: int, rng: np.random.Generator, *, max_tries: int = 20_000,
                    density_per_m2: float | None = None, name: str | None = None) -> Scenario:
    """n robots with seeded random starts and goals in a square.

    The square's side is max(20 m, 4 m * sqrt(n)), or sqrt(n / density_per_m2) when a
    density (robots per square metre) is given; starts are pairwise >= 2.5 m apart, goals
    too, and each goal is at least half the side away from its start. With a density the
    scenario has the benchmark time limit (`benchmark_time_limit_s`).
    """
    require(n >= 1, f"random: --agents must be >= 1, got {n}")
    if density_per_m2 is None:
        side_m = max(20.0, 4.0 * math.sqrt(n))
    else:
        require(math.isfinite(density_per_m2) and density_per_m2 > 0.0,
                f"random: the density must be > 0, got {density_per_m2!r}")
        side_m = round(math.sqrt(n / density_per_m2), 2)
    starts: list[np.ndarray] = []
    goals: list[np.ndarray] = []
    tries = 0
    while len(starts) < n:
        tries += 1
        if tries > max_tries:
            raise ScenarioError(f"random: could not place {n} robots in {side_m:g} m square")
        s, g = rng.uniform(-side_m / 2.0, side_m / 2.0, size=(2, 2))
        s, g = np.round(s, 2), np.round(g, 2)
        if np.hypot(*(g - s)) < side_m / 2.0:
            continue
        if any(np.hypot(*(s - o)) < MIN_START_SPACING_M for o in starts):
            continue
        if any(np.hypot(*(g - o)) < MIN_START_SPACING_M for o in goals):
            continue
        starts.append(s)
        goals.append(g)
    robots = [robot_spec(k, s, g) for k, (s, g) in enumerate(zip(starts, goals))]
    if density_per_m2 is None:
        return make_scenario(name or f"random_{n}", f"{n} robots, random starts and goals in a "
                             f"{side_m:g} m square", robots)
    return make_scenario(name or f"random_{n}", f"{n} robots, random starts and goals in a "
                         f"{side_m:g} m square ({100.0 * density_per_m2:g} robots per 100 m^2)",
                         robots, time_limit_s=benchmark_time_limit_s(robots))


MIXED_RADII_M = (0.3, 0.5, 0.7)
"""Disc radii of `circle_mixed`, each used by about a third of the robots."""
MIXED_V_MAX_MPS = (0.8, 1.1, 1.4)
"""v_max of `circle_mixed`, each used by about a third of the robots (drawn independently
of the radii)."""


def mixed_values(values: Sequence[float], n: int, rng: np.random.Generator) -> np.ndarray:
    """(n,) values cycled so each appears n // len or one more times, in seeded order."""
    return rng.permutation(np.resize(np.asarray(values, dtype=float), n))


def circle_radius_m(n: int, spacing_m: float, minimum_m: float) -> float:
    """The smallest radius (0.1 m steps, >= minimum_m) with neighbours spacing_m apart."""
    radius_m = max(minimum_m, spacing_m / 2.0 / math.sin(math.pi / n))
    return math.ceil(radius_m * 10.0) / 10.0
