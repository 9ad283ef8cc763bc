"""Scenario description: robots, goals, obstacles, limits and planner parameters.

The dataclasses here are what the world, the robots and the orchestrator share. The YAML
file format maps onto them one key to one field; loading and validation live below and
raise `ScenarioError`, which names the file and the field.

File format (YAML, SI units: metres, seconds, radians)::

    name: setup_d                # required, non-empty string
    description: four robots ... # optional, default ""
    profile: default             # optional: default | paper (the paper's method as written;
                                 #   the keys under `defaults` still override it) | lanes
    without: [routing, liveness] # optional: mechanisms of the default profile switched off
                                 #   (ablations; agent.core.config.MECHANISM_NAMES)
    time_limit: 140              # required [s], > 0: the run fails if not all arrived by then
    goal_tolerance: 0.25         # optional [m], > 0, default 0.25
    defaults:                    # optional; every key optional
      radius: 0.5                # robot disc radius [m]
      planner: eifp-mpc          # default planner: eifp-mpc | eifp | ifp | orca
      v_max: 1.1                 # RobotLimits, by field name without its unit suffix:
      omega_max: 1.5             #   v_max, v_min, omega_max, accel_max, alpha_max
      safety:                    # PlannerConfig's sub-configs, each a mapping of its
        d_safety: 0.3            #   fields without their unit suffix (agent.core.config):
      threats:                   #   safety: d_safety, braking_margin
        t_max: 8.0               #   threats: t_max, sensing_radius, max_neighbors
      cost:                      #   cost: w_length, w_distance, w_angle, side_hysteresis
        w_angle: 0.3             #   reference: max_depth, corner_radius
      mpc:                       #   mpc: horizon_steps, dt, clearance_margin
        horizon_steps: 20        #   orca: time_horizon
    robots:                      # required, at least one
      - id: 0                    # required, int in [0, 2^31 - 1], unique
        start: [-18.0, 0.0, 0.0] # required, [x, y, theta]
        goal: [18.0, 0.0]        # required, [x, y]
        radius: 0.5              # optional per-robot overrides: radius, planner and any
        v_max: 1.1               #   RobotLimits key (v_max, v_min, omega_max, ...)
    obstacles:                   # optional; ids -1, -2, ... in file order
      - center: [0.0, 5.0]       # required, [x, y] at t = 0
        radius: 1.0              # required [m], > 0
        velocity: [0.0, 0.0]     # optional [vx, vy] in m/s, default [0, 0]

The key of a dataclass field is its name with the unit suffix (`_m`, `_s`, `_mps`,
`_mps2`, `_radps`, `_radps2`) stripped: `safety.d_safety` -> `SafetyConfig.d_safety_m`,
`mpc.dt` -> `MpcConfig.dt_s`, `v_max` -> `RobotLimits.v_max_mps`. The top-level
`profile` sets `PlannerConfig.profile`; the settings under `defaults` apply on top of it.

Validation rejects, with `<file>: <field path>: <problem>` (e.g.
`setup_x.yaml: robots[2].start: expected [x, y, theta], got [1.0, 2.0]`): YAML syntax
errors and duplicate mapping keys; unknown keys at every level; missing required keys;
wrong types (booleans are not numbers, floats are not ints); non-finite numbers; zero or
negative sizes, speeds and horizons (weights and margins may be zero; `v_min` may be
negative but not above `v_max`); unknown planner names; duplicate robot ids; robot discs
that overlap each other or an obstacle at their starts; goal discs (robot radius around
the goal) that overlap an obstacle disc at t = 0 or another robot's goal disc; goals that
no path round the static obstacles reaches (enclosed, or behind gaps narrower than the
robot: `robots[0].goal: robot 0 cannot reach its goal: ...`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import reprlib
import typing
from collections.abc import Hashable, Mapping
from pathlib import Path
from typing import Any, TypeGuard, overload

import numpy as np

from agent.core.config import (
    MECHANISM_NAMES,
    PLANNER_NAMES,
    POSITIVE_FIELDS,
    PROFILES,
    SIGNED_FIELDS,
    SUB_CONFIGS,
    RobotLimits,
    file_key,
    profile_config,
)
from agent.core.scenario import ObstacleSpec, RobotSpec, Scenario
from agent.files import replace_file
from agent.planning.routing import StaticMap, unreachable_reason
from eifp_wire import (
    MAX_COORD_M,
    MAX_OBSTACLES,
    MAX_RADIUS_M,
    MAX_ROBOTS,
    MAX_SPEED,
    MAX_TIME_S,
)


class ScenarioError(ValueError):
    """A scenario file or dict is invalid; the message names the source and the field."""


# --------------------------------------------------------------------------------------
# Loading, validation and dumping (the file format is in the module docstring).
# --------------------------------------------------------------------------------------

DEFAULT_GOAL_TOLERANCE_M = 0.25
DEFAULT_RADIUS_M = 0.5
DEFAULT_PLANNER = "eifp-mpc"
MAX_ROBOT_ID = 2**31 - 1
"""Robot ids travel as int32 on the wire."""

# Range rules of the config fields: agent.core.config (POSITIVE_FIELDS must be > 0, SIGNED_FIELDS
# any sign, every other number >= 0); `v_min` may be negative (reversing) but not above v_max.

_TOP_KEYS = ("name", "description", "profile", "without", "time_limit", "goal_tolerance",
             "defaults", "robots", "obstacles")
_TOP_REQUIRED = ("name", "time_limit", "robots")
_ROBOT_REQUIRED = ("id", "start", "goal")
_OBSTACLE_KEYS = ("center", "radius", "velocity")
_OBSTACLE_REQUIRED = ("center", "radius")


@functools.cache
def _key_map(cls: type) -> dict[str, tuple[str, object]]:
    """file key -> (field name, resolved type) for a config dataclass."""
    hints = typing.get_type_hints(cls)
    out: dict[str, tuple[str, object]] = {}
    for f in dataclasses.fields(cls):
        key = file_key(f.name)
        if key in out:  # two fields differing only by unit: the format would be ambiguous
            raise TypeError(f"{cls.__name__}: fields {out[key][0]} and {f.name} share key {key}")
        out[key] = (f.name, hints[f.name])
    return out


def _join(path: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else key


MAX_SCENARIO_BYTES = 4 << 20
"""Largest scenario file read [bytes] (4 MiB): `MAX_ROBOTS` robots with every override fit
in about a quarter of it; anything larger is refused before it is parsed."""
MAX_SHOWN_CHARS = 80
"""Values in error messages are cut to this many characters."""
_SHORT_REPR = reprlib.Repr()
_SHORT_REPR.maxlevel = 2
_SHORT_REPR.maxdict = _SHORT_REPR.maxlist = _SHORT_REPR.maxtuple = _SHORT_REPR.maxset = 4
_SHORT_REPR.maxstring = _SHORT_REPR.maxother = _SHORT_REPR.maxlong = MAX_SHOWN_CHARS


def shown(value: object) -> str:
    """A bounded `repr` of `value` for an error message: depth, items and length capped
    before anything is formatted, so a huge value (a YAML alias bomb) costs nothing."""
    text = _SHORT_REPR.repr(value)
    return text if len(text) <= MAX_SHOWN_CHARS else text[:MAX_SHOWN_CHARS - 3] + "..."


def _got(value: object) -> str:
    return f"got {shown(value)} ({type(value).__name__})"


class _Ctx:
    """Where errors come from: the source (file name) for every message."""

    def __init__(self, source: str) -> None:
        self.source = source

    def error(self, path: str, message: str) -> ScenarioError:
        where = path or "(top level)"
        return ScenarioError(f"{self.source}: {where}: {message}")


def _is_number(value: object) -> TypeGuard[int | float]:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _number(ctx: _Ctx, path: str, value: object, *, lower: str = "none") -> float:
    """A finite float; `lower` is "positive", "nonneg" or "none"."""
    if not _is_number(value):
        raise ctx.error(path, f"expected a number, {_got(value)}")
    out = float(value)
    if not math.isfinite(out):
        raise ctx.error(path, f"expected a finite number, {_got(value)}")
    if lower == "positive" and out <= 0.0:
        raise ctx.error(path, f"must be > 0, got {out!r}")
    if lower == "nonneg" and out < 0.0:
        raise ctx.error(path, f"must be >= 0, got {out!r}")
    return out


def _integer(ctx: _Ctx, path: str, value: object, *, minimum: int | None = None,
             maximum: int | None = None) -> int:
    if not isinstance(value, int | np.integer) or isinstance(value, bool):
        raise ctx.error(path, f"expected an integer, {_got(value)}")
    if minimum is not None and value < minimum:
        raise ctx.error(path, f"must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise ctx.error(path, f"must be <= {maximum}, got {value}")
    return int(value)


@overload
def _vector(ctx: _Ctx, path: str, value: object, names: tuple[str, str]
            ) -> tuple[float, float]: ...
@overload
def _vector(ctx: _Ctx, path: str, value: object, names: tuple[str, str, str]
            ) -> tuple[float, float, float]: ...
def _vector(ctx: _Ctx, path: str, value: object, names: tuple[str, ...]) -> tuple[float, ...]:
    shape = "[" + ", ".join(names) + "]"
    if not isinstance(value, list | tuple) or len(value) != len(names):
        raise ctx.error(path, f"expected {shape}, {_got(value)}")
    out = []
    for k, item in enumerate(value):
        if not _is_number(item) or not math.isfinite(float(item)):
            raise ctx.error(path, f"expected {shape} of finite numbers, {names[k]} {_got(item)}")
        out.append(float(item))
    return tuple(out)


def _string(ctx: _Ctx, path: str, value: object, *, nonempty: bool = False) -> str:
    if not isinstance(value, str):
        raise ctx.error(path, f"expected a string, {_got(value)}")
    if nonempty and not value.strip():
        raise ctx.error(path, "must not be empty")
    return value


def _planner_name(ctx: _Ctx, path: str, value: object) -> str:
    name = _string(ctx, path, value)
    if name not in PLANNER_NAMES:
        known = ", ".join(PLANNER_NAMES)
        raise ctx.error(path, f"unknown planner {shown(name)}; expected one of {known}")
    return name


def _mapping(ctx: _Ctx, path: str, value: object, allowed: typing.Iterable[str],
             required: typing.Iterable[str] = ()) -> Mapping[str, Any]:
    """A mapping with string keys, no unknown keys and every required key."""
    if not isinstance(value, Mapping):
        raise ctx.error(path, f"expected a mapping, {_got(value)}")
    allowed = tuple(allowed)
    for key in value:
        if not isinstance(key, str):
            raise ctx.error(path, f"keys must be strings, {_got(key)}")
        if key not in allowed:
            raise ctx.error(_join(path, key[:MAX_SHOWN_CHARS]),
                            f"unknown key; expected one of {', '.join(sorted(allowed))}")
    for key in required:
        if key not in value:
            raise ctx.error(_join(path, key), "missing required key")
    return value


def _without(ctx: _Ctx, value: object) -> str:
    """`without`: mechanisms switched off (`PlannerConfig.without`), as a list of names or a
    comma-separated string; returned comma-separated."""
    names = value.split(",") if isinstance(value, str) else value
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ctx.error("without", f"expected a list of mechanism names, {_got(value)}")
    names = [n.strip() for n in names if n.strip()]
    for name in names:
        if name not in MECHANISM_NAMES:
            raise ctx.error("without", f"unknown mechanism {_got(name)}; expected one of "
                            f"{', '.join(MECHANISM_NAMES)}")
    return ",".join(names)


def _field_value(ctx: _Ctx, path: str, field_name: str, typ: object, value: object
                 ) -> bool | int | float | None:
    """One config field from the file, checked against its type and range."""
    args = typing.get_args(typ)
    if type(None) in args:  # float | None
        if value is None:
            return None
        (typ,) = (a for a in args if a is not type(None))
    lower = ("positive" if field_name in POSITIVE_FIELDS
             else "none" if field_name in SIGNED_FIELDS else "nonneg")
    if typ is bool:
        if not isinstance(value, bool):
            raise ctx.error(path, f"expected true or false, {_got(value)}")
        return value
    if typ is int:
        return _integer(ctx, path, value, minimum=1 if lower == "positive" else 0)
    if typ is float:
        return _number(ctx, path, value, lower=lower)
    raise TypeError(f"unsupported config field type {typ!r} for {field_name}")  # pragma: no cover


def _config_kwargs(ctx: _Ctx, path: str, data: Mapping[str, Any], cls: type,
                   skip: typing.Container[str] = ()) -> dict[str, Any]:
    """Keyword arguments for `cls` from the keys of `data` that name its fields."""
    out: dict[str, Any] = {}
    for key, (name, typ) in _key_map(cls).items():
        if key in data and key not in skip:
            out[name] = _field_value(ctx, _join(path, key), name, typ, data[key])
    return out


def _check_limits(ctx: _Ctx, path: str, kwargs: Mapping[str, Any]) -> None:
    """v_min <= v_max on the keyword arguments of `RobotLimits`, before it is built (built
    limits refuse it themselves, without the file and key)."""
    v_min = kwargs.get("v_min_mps", RobotLimits.v_min_mps)
    v_max = kwargs.get("v_max_mps", RobotLimits.v_max_mps)
    if v_min > v_max:
        raise ctx.error(_join(path, "v_min"), f"must be <= v_max ({v_max!r}), got {v_min!r}")


def _limits(ctx: _Ctx, path: str, base: RobotLimits | None, data: Mapping[str, Any]
            ) -> RobotLimits:
    """`base` (None: the defaults) with the RobotLimits keys of `data`, checked first."""
    kwargs = dataclasses.asdict(base) if base is not None else {}
    kwargs.update(_config_kwargs(ctx, path, data, RobotLimits))
    _check_limits(ctx, path, kwargs)
    return RobotLimits(**kwargs)


def scenario_from_dict(data: object, source: str = "<scenario>") -> Scenario:
    """Build and validate a `Scenario` from the parsed file format.

    Args:
        data: the parsed YAML document (a mapping).
        source: the file name (or any label) every error message starts with.

    Raises:
        ScenarioError: naming `source` and the offending field path.
    """
    ctx = _Ctx(source)
    top = _mapping(ctx, "", data, _TOP_KEYS, _TOP_REQUIRED)
    name = _string(ctx, "name", top["name"], nonempty=True)
    description = _string(ctx, "description", top.get("description", ""))
    time_limit_s = _number(ctx, "time_limit", top["time_limit"], lower="positive")
    goal_tolerance_m = _number(ctx, "goal_tolerance",
                               top.get("goal_tolerance", DEFAULT_GOAL_TOLERANCE_M),
                               lower="positive")

    limits_keys = tuple(_key_map(RobotLimits))
    defaults_raw = top.get("defaults", {})
    if defaults_raw is None:
        defaults_raw = {}
    defaults = _mapping(ctx, "defaults", defaults_raw,
                        ("radius", "planner", *limits_keys, *SUB_CONFIGS))
    default_radius_m = _number(ctx, "defaults.radius",
                               defaults.get("radius", DEFAULT_RADIUS_M), lower="positive")
    default_planner = _planner_name(ctx, "defaults.planner",
                                    defaults.get("planner", DEFAULT_PLANNER))
    default_limits = _limits(ctx, "defaults", None, defaults)
    profile = top.get("profile", "default")
    if profile not in PROFILES:
        raise ctx.error("profile", f"expected one of {', '.join(PROFILES)}, got {_got(profile)}")
    base = dataclasses.replace(profile_config(profile),
                               without=_without(ctx, top.get("without", [])))
    planner_kwargs: dict[str, Any] = {}
    for group in SUB_CONFIGS:
        if defaults.get(group) is None:
            continue
        path = _join("defaults", group)
        sub = getattr(base, group)
        # mypy takes a class for unhashable (python/mypy#11470)
        keys = _key_map(type(sub))  # type: ignore[arg-type]
        data = _mapping(ctx, path, defaults[group], tuple(keys))
        planner_kwargs[group] = dataclasses.replace(
            sub, **_config_kwargs(ctx, path, data, type(sub)))
    planner_config = dataclasses.replace(base, **planner_kwargs)

    robots_raw = top["robots"]
    if not isinstance(robots_raw, list):
        raise ctx.error("robots", f"expected a list of robots, {_got(robots_raw)}")
    if not robots_raw:
        raise ctx.error("robots", "expected at least one robot, got an empty list")
    robot_keys = ("id", "start", "goal", "radius", "planner", *limits_keys)
    robots = []
    for k, item in enumerate(robots_raw):
        path = _join("robots", k)
        r = _mapping(ctx, path, item, robot_keys, _ROBOT_REQUIRED)
        limits = _limits(ctx, path, default_limits, r)
        robots.append(RobotSpec(
            id=_integer(ctx, _join(path, "id"), r["id"], minimum=0, maximum=MAX_ROBOT_ID),
            start=_vector(ctx, _join(path, "start"), r["start"], ("x", "y", "theta")),
            goal=_vector(ctx, _join(path, "goal"), r["goal"], ("x", "y")),
            radius_m=_number(ctx, _join(path, "radius"), r.get("radius", default_radius_m),
                             lower="positive"),
            limits=limits,
            planner=_planner_name(ctx, _join(path, "planner"),
                                  r.get("planner", default_planner)),
        ))

    obstacles_raw = top.get("obstacles", [])
    if obstacles_raw is None:
        obstacles_raw = []
    if not isinstance(obstacles_raw, list):
        raise ctx.error("obstacles", f"expected a list of obstacles, {_got(obstacles_raw)}")
    obstacles = []
    for k, item in enumerate(obstacles_raw):
        path = _join("obstacles", k)
        o = _mapping(ctx, path, item, _OBSTACLE_KEYS, _OBSTACLE_REQUIRED)
        obstacles.append(ObstacleSpec(
            id=-(k + 1),
            center=_vector(ctx, _join(path, "center"), o["center"], ("x", "y")),
            radius_m=_number(ctx, _join(path, "radius"), o["radius"], lower="positive"),
            velocity=_vector(ctx, _join(path, "velocity"), o.get("velocity", [0.0, 0.0]),
                             ("vx", "vy")),
        ))

    scenario = Scenario(
        name=name,
        description=description,
        time_limit_s=time_limit_s,
        goal_tolerance_m=goal_tolerance_m,
        planner_config=planner_config,
        robots=tuple(robots),
        obstacles=tuple(obstacles),
    )
    validate_scenario(scenario, source)
    return scenario


def validate_scenario(scenario: Scenario, source: str = "<scenario>") -> Scenario:
    """Check a built `Scenario` (from a file or a generator) and return it unchanged.

    Checks finiteness and signs of every number, planner names, unique robot ids,
    obstacle ids, and the geometry at t = 0: robot discs at their starts must not overlap
    each other or an obstacle; goal discs (robot radius around the goal) must not overlap
    an obstacle disc or another robot's goal disc; every goal must be reachable round the
    static obstacles (`_check_reachable`).

    Raises:
        ScenarioError: naming `source` and the field path in the file format.
    """
    ctx = _Ctx(source)
    _number(ctx, "time_limit", scenario.time_limit_s, lower="positive")
    _at_most(ctx, "time_limit", scenario.time_limit_s, MAX_TIME_S, "s")
    _number(ctx, "goal_tolerance", scenario.goal_tolerance_m, lower="positive")
    _check_config(ctx, "defaults", scenario.planner_config)
    if not scenario.robots:
        raise ctx.error("robots", "expected at least one robot, got an empty list")
    # The wire's bounds (`eifp_wire.limits`): what passes here can be sent, so no run fails
    # later.
    if len(scenario.robots) > MAX_ROBOTS:
        raise ctx.error("robots", f"at most {MAX_ROBOTS} robots, got {len(scenario.robots)}")
    if len(scenario.obstacles) > MAX_OBSTACLES:
        raise ctx.error("obstacles",
                        f"at most {MAX_OBSTACLES} obstacles, got {len(scenario.obstacles)}")
    seen: dict[int, int] = {}
    for k, r in enumerate(scenario.robots):
        path = _join("robots", k)
        rid = _integer(ctx, _join(path, "id"), r.id, minimum=0, maximum=MAX_ROBOT_ID)
        if rid in seen:
            raise ctx.error(_join(path, "id"),
                            f"duplicate id {rid} (robots[{seen[rid]}] has it too)")
        seen[rid] = k
        _vector(ctx, _join(path, "start"), r.start, ("x", "y", "theta"))
        _vector(ctx, _join(path, "goal"), r.goal, ("x", "y"))
        _number(ctx, _join(path, "radius"), r.radius_m, lower="positive")
        _check_config(ctx, path, r.limits)
        for key, values in (("start", r.start[:2]), ("goal", r.goal)):
            for v in values:
                _at_most(ctx, _join(path, key), abs(v), MAX_COORD_M, "m (|x|, |y|)")
        _at_most(ctx, _join(path, "radius"), r.radius_m, MAX_RADIUS_M, "m")
        _at_most(ctx, _join(path, "v_max"), r.limits.v_max_mps, MAX_SPEED, "m/s")
        _planner_name(ctx, _join(path, "planner"), r.planner)
    for k, o in enumerate(scenario.obstacles):
        path = _join("obstacles", k)
        if o.id != -(k + 1):
            raise ctx.error(path, f"obstacle ids must be -1, -2, ... in order, got {o.id}")
        _vector(ctx, _join(path, "center"), o.center, ("x", "y"))
        _number(ctx, _join(path, "radius"), o.radius_m, lower="positive")
        _vector(ctx, _join(path, "velocity"), o.velocity, ("vx", "vy"))
        _at_most(ctx, _join(path, "radius"), o.radius_m, MAX_RADIUS_M, "m")
        for v in o.velocity:
            _at_most(ctx, _join(path, "velocity"), abs(v), MAX_SPEED, "m/s")
        # A moving obstacle must stay on the wire's map for the whole run.
        for c, v in zip(o.center, o.velocity):
            _at_most(ctx, _join(path, "center"), abs(c) + abs(v) * scenario.time_limit_s,
                     MAX_COORD_M, "m (|x|, |y| over the time limit)")

    start = np.array([r.start[:2] for r in scenario.robots], dtype=float)
    goal = np.array([r.goal for r in scenario.robots], dtype=float)
    radius = np.array([r.radius_m for r in scenario.robots], dtype=float)
    ob_c = np.array([o.center for o in scenario.obstacles], dtype=float).reshape(-1, 2)
    ob_r = np.array([o.radius_m for o in scenario.obstacles], dtype=float)

    # Pairwise gaps (centre distance minus both radii); < 0 means the discs overlap.
    start_gap = _gaps(start, radius, start, radius)
    goal_gap = _gaps(goal, radius, goal, radius)
    later = np.tril(np.ones_like(start_gap, dtype=bool), k=-1)  # j > i: report the later one
    _raise_first_overlap(ctx, start_gap, later, "start",
                         lambda i: f"disc overlaps robots[{i}] at t=0")
    _raise_first_overlap(ctx, goal_gap, later, "goal",
                         lambda i: f"goal disc overlaps the goal disc of robots[{i}]")
    if ob_r.size:
        everywhere = np.ones((len(radius), len(ob_r)), dtype=bool)
        _raise_first_overlap(ctx, _gaps(start, radius, ob_c, ob_r), everywhere, "start",
                             lambda i: f"disc overlaps obstacles[{i}] at t=0")
        _raise_first_overlap(ctx, _gaps(goal, radius, ob_c, ob_r), everywhere, "goal",
                             lambda i: f"goal disc overlaps obstacles[{i}] at t=0")
        _check_reachable(ctx, scenario)
    return scenario


def _check_reachable(ctx: _Ctx, scenario: Scenario) -> None:
    """Every goal is reachable round the static obstacles (`agent.planning.routing`):
    a goal enclosed by them, or behind gaps narrower than the robot, is refused. Other
    robots never make a goal unreachable (they move, or can be waited out)."""
    static = StaticMap.of_obstacles(scenario.obstacles)
    if not static.routable:
        return
    for k, r in enumerate(scenario.robots):
        why = unreachable_reason(np.array(r.start[:2]), np.array(r.goal), static, r.radius_m)
        if why is not None:
            raise ctx.error(_join(_join("robots", k), "goal"),
                            f"robot {r.id} cannot reach its goal: {why}")


def _at_most(ctx: _Ctx, path: str, value: float, bound: float, unit: str) -> None:
    """Refuse `value` above the wire's `bound` (`eifp_wire.limits`), naming the field."""
    if value > bound:
        raise ctx.error(path, f"must be at most {bound:g} {unit}, got {value!r}")


def _gaps(a: np.ndarray, ra: np.ndarray, b: np.ndarray, rb: np.ndarray) -> np.ndarray:
    """(len(a), len(b)) gaps between discs a_i and b_j [m]."""
    d = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
    gaps: np.ndarray = d - ra[:, None] - rb[None, :]
    return gaps


def _raise_first_overlap(ctx: _Ctx, gaps: np.ndarray, mask: np.ndarray, key: str,
                         what: typing.Callable[[int], str]) -> None:
    bad = np.argwhere(mask & (gaps < 0.0))
    if bad.size:
        j, i = (int(x) for x in bad[0])
        raise ctx.error(_join(_join("robots", j), key),
                        f"{what(i)} (gap {gaps[j, i]:.3f} m)")


def _check_config(ctx: _Ctx, path: str, config: object) -> None:
    """Re-check a config dataclass's fields (for scenarios built in code)."""
    # mypy takes a class for unhashable (python/mypy#11470)
    for key, (name, typ) in _key_map(type(config)).items():  # type: ignore[arg-type]
        value = getattr(config, name)
        if dataclasses.is_dataclass(value):
            _check_config(ctx, _join(path, key), value)
        elif name == "without":
            _without(ctx, value)
        elif name == "profile":
            if value not in PROFILES:
                raise ctx.error("profile", f"expected one of {', '.join(PROFILES)}, "
                                f"{_got(value)}")
        else:
            _field_value(ctx, _join(path, key), name, typ, value)


def scenario_to_dict(scenario: Scenario) -> dict[str, Any]:
    """The file format of `scenario` (plain Python types; `scenario_from_dict` inverts it).

    `defaults` holds the first robot's radius, planner and limits and the full planner
    configuration; each robot lists only what differs from the defaults.
    """
    first = scenario.robots[0] if scenario.robots else RobotSpec(0, (0.0, 0.0, 0.0), (0.0, 0.0))
    defaults: dict[str, Any] = {"radius": float(first.radius_m), "planner": first.planner}
    defaults.update(_config_to_dict(first.limits))
    planner = _config_to_dict(scenario.planner_config)
    profile = planner.pop("profile")
    without = planner.pop("without")
    defaults.update(planner)
    robots = []
    for r in scenario.robots:
        item: dict[str, Any] = {
            "id": int(r.id),
            "start": [float(x) for x in r.start],
            "goal": [float(x) for x in r.goal],
        }
        if r.radius_m != first.radius_m:
            item["radius"] = float(r.radius_m)
        if r.planner != first.planner:
            item["planner"] = r.planner
        limits = _config_to_dict(r.limits)
        item.update({k: v for k, v in limits.items() if v != defaults[k]})
        robots.append(item)
    out: dict[str, Any] = {
        "name": scenario.name,
        "description": scenario.description,
        "profile": profile,
        **({"without": without.split(",")} if without else {}),
        "time_limit": float(scenario.time_limit_s),
        "goal_tolerance": float(scenario.goal_tolerance_m),
        "defaults": defaults,
        "robots": robots,
    }
    if scenario.obstacles:
        out["obstacles"] = [
            {"center": [float(x) for x in o.center], "radius": float(o.radius_m),
             "velocity": [float(x) for x in o.velocity]}
            for o in scenario.obstacles
        ]
    return out


def _config_to_dict(config: object) -> dict[str, Any]:
    out: dict[str, Any] = {}
    # mypy takes a class for unhashable (python/mypy#11470)
    for key, (name, _typ) in _key_map(type(config)).items():  # type: ignore[arg-type]
        value = getattr(config, name)
        if dataclasses.is_dataclass(value):
            out[key] = _config_to_dict(value)
        elif value is None or isinstance(value, bool | str):
            out[key] = value
        elif isinstance(value, int | np.integer):
            out[key] = int(value)
        else:
            out[key] = float(value)
    return out


@functools.cache
def _yaml_loader() -> type:
    """A SafeLoader that rejects duplicate keys and reads `1e4` as a float (YAML 1.2)."""
    import re

    import yaml

    class Loader(yaml.SafeLoader):
        def compose_node(self, parent: yaml.Node | None, index: int) -> yaml.Node | None:
            # An alias re-uses a node: a few hundred bytes of nested aliases expand to
            # billions of values. No scenario needs one; refuse it where it appears.
            if self.check_event(yaml.events.AliasEvent):
                # types-PyYAML leaves Parser.peek_event unannotated
                event = self.peek_event()  # type: ignore[no-untyped-call]
                raise yaml.composer.ComposerError(
                    None, None, "YAML aliases (*name) are not allowed in a scenario file",
                    event.start_mark)
            return super().compose_node(parent, index)

        def construct_mapping(self, node: yaml.MappingNode, deep: bool = False
                              ) -> dict[Hashable, Any]:
            seen: set[Hashable] = set()
            for key_node, _value_node in node.value:
                key = self.construct_object(key_node, deep=deep)
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"duplicate key {shown(key)}", key_node.start_mark)
                seen.add(key)
            return super().construct_mapping(node, deep=deep)

    Loader.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
        list("-+0123456789"),
    )
    return Loader


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Read and validate a scenario file.

    Raises:
        ScenarioError: unreadable file, YAML syntax error (with line and column), or any
            validation failure; the message starts with the file name.
    """
    import yaml

    source = str(path)
    try:
        with open(path, "rb") as f:
            raw = f.read(MAX_SCENARIO_BYTES + 1)
        if len(raw) > MAX_SCENARIO_BYTES:
            raise ScenarioError(f"{source}: larger than {MAX_SCENARIO_BYTES >> 20} MiB; not read")
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) else "not UTF-8 text"
        raise ScenarioError(f"{source}: cannot read: {why or type(exc).__name__}") from exc
    try:
        data = yaml.load(text, Loader=_yaml_loader())
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "unknown place"
        problem = getattr(exc, "problem", None) or str(exc)
        raise ScenarioError(f"{source}: YAML syntax error at {where}: {problem}") from exc
    if data is None:
        raise ScenarioError(f"{source}: (top level): empty file, expected a mapping")
    return scenario_from_dict(data, source)


def dump_scenario(scenario: Scenario, path: str | os.PathLike[str]) -> None:
    """Write `scenario` in the file format (atomically); `load_scenario` reads it back equal."""
    import yaml

    text = yaml.safe_dump(scenario_to_dict(scenario), sort_keys=False,
                          default_flow_style=None, width=100)
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    # A fresh sibling, then rename: readers never see half a file, and a symlink planted at
    # `target` is replaced, never written through.
    replace_file(target, f"# eifp-swarm scenario (SI units: m, s, rad)\n{text}".encode())
