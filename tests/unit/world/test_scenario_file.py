"""Scenario files: one test per validation rule (file name and field path in the message),
the key <-> field mapping, and the dump/load round trip."""

from __future__ import annotations

import dataclasses
import math
import textwrap
from pathlib import Path

import pytest
import yaml

from agent.core.config import SUB_CONFIGS, MpcConfig, PlannerConfig, RobotLimits
from agent.core.scenario import ObstacleSpec, RobotSpec, Scenario
from world.scenario_file import (
    ScenarioError,
    dump_scenario,
    file_key,
    load_scenario,
    scenario_from_dict,
    scenario_to_dict,
    validate_scenario,
)

GOOD = """\
name: good
description: two robots
time_limit: 60
goal_tolerance: 0.3
defaults:
  radius: 0.5
  v_max: 1.1
  omega_max: 1.5
  safety:
    d_safety: 0.3
  threats: {t_max: 6}
  cost: {w_angle: 1e-1}
  planner: eifp
  mpc:
    horizon_steps: 15
    dt: 0.1
    clearance_margin: 0.2
robots:
  - {id: 0, start: [-10, 0, 0], goal: [10, 0]}
  - id: 1
    start: [10, 0, 3.14159]
    goal: [-10, 0]
    radius: 0.4
    v_max: 0.8
    planner: orca
obstacles:
  - {center: [0, 5], radius: 1.0}
  - {center: [0, -5], radius: 0.5, velocity: [0.1, 0]}
"""


def write(tmp_path: Path, text: str, name: str = "setup_x.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def bad(tmp_path: Path, old: str, new: str) -> Path:
    assert old in GOOD, old
    return write(tmp_path, GOOD.replace(old, new, 1))


def expect_error(path: Path, *fragments: str) -> str:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    assert "setup_x.yaml" in message
    for fragment in fragments:
        assert fragment in message, message
    return message


# --- the good file -------------------------------------------------------------------

def test_good_file_loads_with_defaults_and_overrides(tmp_path):
    s = load_scenario(write(tmp_path, GOOD))
    assert s.name == "good" and s.time_limit_s == 60.0 and s.goal_tolerance_m == 0.3
    config = s.planner_config
    assert config.safety.d_safety_m == 0.3 and config.threats.t_max_s == 6.0
    assert config.cost.w_angle == 0.1 and config.cost.w_length == 1.0  # the rest: defaults
    assert config.mpc == MpcConfig(horizon_steps=15, dt_s=0.1, clearance_margin_m=0.2)
    r0, r1 = s.robots
    assert r0.start == (-10.0, 0.0, 0.0) and r0.goal == (10.0, 0.0)
    assert r0.radius_m == 0.5 and r0.planner == "eifp"
    assert r0.limits == RobotLimits(v_max_mps=1.1, omega_max_radps=1.5)
    assert r1.radius_m == 0.4 and r1.planner == "orca" and r1.limits.v_max_mps == 0.8
    assert r1.limits.omega_max_radps == 1.5
    assert [o.id for o in s.obstacles] == [-1, -2]
    assert s.obstacles[1].velocity == (0.1, 0.0)
    assert isinstance(r0.start[0], float) and isinstance(s.planner_config.mpc.horizon_steps, int)


def test_minimal_file_uses_documented_defaults(tmp_path):
    s = load_scenario(write(tmp_path, """\
        name: tiny
        time_limit: 10
        robots: [{id: 3, start: [0, 0, 0], goal: [1, 0]}]
    """))
    assert s.description == "" and s.goal_tolerance_m == 0.25 and s.obstacles == ()
    assert s.planner_config == PlannerConfig()
    assert s.robots[0] == RobotSpec(id=3, start=(0.0, 0.0, 0.0), goal=(1.0, 0.0))


def test_file_keys_strip_unit_suffixes():
    assert file_key("d_safety_m") == "d_safety"
    assert file_key("v_max_mps") == "v_max"
    assert file_key("accel_max_mps2") == "accel_max"
    assert file_key("omega_max_radps") == "omega_max"
    assert file_key("alpha_max_radps2") == "alpha_max"
    assert file_key("t_max_s") == "t_max"
    assert file_key("dt_s") == "dt"
    assert file_key("horizon_steps") == "horizon_steps"
    assert file_key("max_neighbors") == "max_neighbors"


def test_every_setting_is_settable(tmp_path):
    defaults = {}
    for group in SUB_CONFIGS:
        sub = getattr(PlannerConfig(), group)
        defaults[group] = {file_key(f.name): 2 if isinstance(getattr(sub, f.name), int) else 0.7
                           for f in dataclasses.fields(sub)}
    s = scenario_from_dict({"name": "all", "time_limit": 5, "defaults": defaults,
                            "robots": [{"id": 0, "start": [0, 0, 0], "goal": [2, 0]}]}, "all")
    for group in SUB_CONFIGS:
        sub = getattr(s.planner_config, group)
        for f in dataclasses.fields(sub):
            assert getattr(sub, f.name) == defaults[group][file_key(f.name)], (group, f.name)
            assert getattr(sub, f.name) != getattr(getattr(PlannerConfig(), group), f.name)


def test_a_setting_outside_its_sub_config_is_an_unknown_key(tmp_path):
    expect_error(bad(tmp_path, "  threats: {t_max: 6}\n", "  threats: {t_max: 6}\n  t_max: 6\n"),
                 "defaults.t_max: unknown key")
    expect_error(bad(tmp_path, "  cost: {w_angle: 1e-1}\n", "  cost: {t_max: 6}\n"),
                 "defaults.cost.t_max: unknown key; expected one of side_hysteresis, w_angle")


# --- round trip ----------------------------------------------------------------------

def test_round_trip_through_file(tmp_path):
    s = load_scenario(write(tmp_path, GOOD))
    dump_scenario(s, tmp_path / "out" / "scenario.yaml")
    again = load_scenario(tmp_path / "out" / "scenario.yaml")
    assert again == s
    assert scenario_from_dict(scenario_to_dict(s), "dict") == s


def test_round_trip_of_a_scenario_built_in_code(tmp_path):
    s = Scenario(
        name="code", description="x", time_limit_s=12.5, goal_tolerance_m=0.2,
        planner_config=PlannerConfig(mpc=MpcConfig(clearance_margin_m=0.1234567890123),
                                     profile="paper"),
        robots=(
            RobotSpec(0, (0.1, 0.2, 0.30000000000000004), (5.0, 5.0), 0.5,
                      RobotLimits(v_min_mps=-0.2), "ifp"),
            RobotSpec(7, (3.0, 0.0, -3.0), (-5.0, 5.0), 0.45,
                      RobotLimits(alpha_max_radps2=3.0), "eifp-mpc"),
        ),
        obstacles=(ObstacleSpec(-1, (0.0, -4.0), 1.0, (0.0, 0.25)),),
    )
    path = tmp_path / "code.yaml"
    dump_scenario(s, path)
    assert load_scenario(path) == s


# --- one test per validation rule ----------------------------------------------------

def test_yaml_syntax_error_names_file_and_line(tmp_path):
    path = bad(tmp_path, "  - {id: 0, start: [-10, 0, 0], goal: [10, 0]}",
               "  - {id: 0, start: [-10, 0, 0, goal: [10, 0]}")
    expect_error(path, "YAML syntax error at line 19")


def test_duplicate_yaml_key(tmp_path):
    expect_error(bad(tmp_path, "time_limit: 60\n", "time_limit: 60\ntime_limit: 70\n"),
                 "duplicate key 'time_limit'")


def test_empty_file(tmp_path):
    expect_error(write(tmp_path, ""), "expected a mapping")


def test_top_level_not_a_mapping(tmp_path):
    expect_error(write(tmp_path, "- 1\n- 2\n"), "(top level)", "expected a mapping")


def test_missing_file(tmp_path):
    expect_error(tmp_path / "setup_x.yaml", "cannot read")


def test_duplicate_robot_ids(tmp_path):
    expect_error(bad(tmp_path, "  - id: 1\n", "  - id: 0\n"),
                 "robots[1].id: duplicate id 0 (robots[0] has it too)")


def test_robot_id_range(tmp_path):
    expect_error(bad(tmp_path, "  - id: 1\n", "  - id: -1\n"), "robots[1].id: must be >= 0")
    expect_error(bad(tmp_path, "  - id: 1\n", "  - id: 2147483648\n"),
                 "robots[1].id: must be <= 2147483647")


def test_overlapping_starts(tmp_path):
    expect_error(bad(tmp_path, "start: [10, 0, 3.14159]", "start: [-9.2, 0, 3.14159]"),
                 "robots[1].start: disc overlaps robots[0] at t=0")


def test_start_inside_obstacle(tmp_path):
    expect_error(bad(tmp_path, "start: [-10, 0, 0]", "start: [0.5, 5.5, 0]"),
                 "robots[0].start: disc overlaps obstacles[0] at t=0")


def test_goal_inside_obstacle(tmp_path):
    expect_error(bad(tmp_path, "goal: [10, 0]", "goal: [0, 3.7]"),
                 "robots[0].goal: goal disc overlaps obstacles[0] at t=0")


def test_goals_overlapping_each_other(tmp_path):
    expect_error(bad(tmp_path, "goal: [-10, 0]", "goal: [10.5, 0]"),
                 "robots[1].goal: goal disc overlaps the goal disc of robots[0]")


@pytest.mark.parametrize("value", [".nan", ".inf", "-.inf"])
def test_non_finite_numbers(tmp_path, value):
    expect_error(bad(tmp_path, "time_limit: 60", f"time_limit: {value}"),
                 "time_limit: expected a finite number")


def test_non_finite_inside_a_vector(tmp_path):
    expect_error(bad(tmp_path, "start: [-10, 0, 0]", "start: [-10, .nan, 0]"),
                 "robots[0].start: expected [x, y, theta] of finite numbers, y")


@pytest.mark.parametrize(("old", "new", "field"), [
    ("  radius: 0.5\n", "  radius: 0\n", "defaults.radius: must be > 0"),
    ("    radius: 0.4\n", "    radius: -0.4\n", "robots[1].radius: must be > 0"),
    ("radius: 1.0}", "radius: 0.0}", "obstacles[0].radius: must be > 0"),
    ("time_limit: 60", "time_limit: 0", "time_limit: must be > 0"),
    ("goal_tolerance: 0.3", "goal_tolerance: -1", "goal_tolerance: must be > 0"),
    ("  v_max: 1.1\n", "  v_max: 0\n", "defaults.v_max: must be > 0"),
    ("    d_safety: 0.3\n", "    d_safety: -0.1\n", "defaults.safety.d_safety: must be >= 0"),
    ("    horizon_steps: 15\n", "    horizon_steps: 0\n",
     "defaults.mpc.horizon_steps: must be >= 1"),
    ("    dt: 0.1\n", "    dt: 0.0\n", "defaults.mpc.dt: must be > 0"),
    ("  cost: {w_angle: 1e-1}\n", "  reference: {max_depth: 0}\n",
     "defaults.reference.max_depth: must be >= 1"),
    ("  cost: {w_angle: 1e-1}\n", "  reference: {corner_radius: -1}\n",
     "defaults.reference.corner_radius: must be >= 0"),
])
def test_zero_or_negative_sizes(tmp_path, old, new, field):
    expect_error(bad(tmp_path, old, new), field)


def test_v_min_above_v_max(tmp_path):
    expect_error(bad(tmp_path, "    v_max: 0.8\n", "    v_max: 0.8\n    v_min: 0.9\n"),
                 "robots[1].v_min: must be <= v_max")


@pytest.mark.parametrize(("old", "new", "field"), [
    ("description: two robots", "description: two robots\nrobot: []", "robot: unknown key"),
    ("    d_safety: 0.3\n", "    d_safety_m: 0.3\n", "defaults.safety.d_safety_m: unknown key"),
    ("    dt: 0.1\n", "    dt_s: 0.1\n", "defaults.mpc.dt_s: unknown key"),
    ("    planner: orca\n", "    planner: orca\n    colour: red\n",
     "robots[1].colour: unknown key"),
    ("radius: 1.0}", "radius: 1.0, id: -1}", "obstacles[0].id: unknown key"),
])
def test_unknown_keys_at_every_level(tmp_path, old, new, field):
    expect_error(bad(tmp_path, old, new), field)


@pytest.mark.parametrize(("old", "new", "field"), [
    ("time_limit: 60", "time_limit: soon", "time_limit: expected a number, got 'soon'"),
    ("time_limit: 60", "time_limit: true", "time_limit: expected a number, got True"),
    ("name: good", "name: [good]", "name: expected a string"),
    ("  - id: 1\n", "  - id: 1.0\n", "robots[1].id: expected an integer"),
    ("start: [-10, 0, 0]", "start: [-10, 0]",
     "robots[0].start: expected [x, y, theta], got [-10, 0]"),
    ("goal: [10, 0]", "goal: 10", "robots[0].goal: expected [x, y], got 10"),
    ("    horizon_steps: 15\n", "    horizon_steps: 15.5\n",
     "defaults.mpc.horizon_steps: expected an integer"),
    ("  mpc:\n", "  mpc: 3\n  mpc_unused:\n", "defaults.mpc_unused: unknown key"),
    ("robots:\n", "robots: {}\nunused:\n", "unused: unknown key"),
    ("obstacles:\n", "obstacles: 3\nxx:\n", "xx: unknown key"),
])
def test_wrong_types(tmp_path, old, new, field):
    expect_error(bad(tmp_path, old, new), field)


def test_robots_not_a_list(tmp_path):
    text = GOOD[:GOOD.index("robots:")] + "robots: {id: 0}\n"
    expect_error(write(tmp_path, text), "robots: expected a list of robots")


def test_mpc_not_a_mapping(tmp_path):
    text = GOOD.replace("  mpc:\n    horizon_steps: 15\n    dt: 0.1\n    clearance_margin: 0.2\n",
                        "  mpc: fast\n")
    expect_error(write(tmp_path, text), "defaults.mpc: expected a mapping, got 'fast'")
    expect_error(bad(tmp_path, "  threats: {t_max: 6}\n", "  threats: [6]\n"),
                 "defaults.threats: expected a mapping")


@pytest.mark.parametrize(("old", "new", "field"), [
    ("  planner: eifp\n", "  planner: rrt\n", "defaults.planner: unknown planner 'rrt'"),
    ("    planner: orca\n", "    planner: ORCA\n", "robots[1].planner: unknown planner 'ORCA'"),
])
def test_unknown_planner_names(tmp_path, old, new, field):
    message = expect_error(bad(tmp_path, old, new), field)
    assert "eifp-mpc, eifp, ifp, orca" in message


@pytest.mark.parametrize(("old", "new", "field"), [
    ("name: good\n", "", "name: missing required key"),
    ("time_limit: 60\n", "", "time_limit: missing required key"),
    ("  - {id: 0, start: [-10, 0, 0], goal: [10, 0]}", "  - {id: 0, start: [-10, 0, 0]}",
     "robots[0].goal: missing required key"),
    ("  - id: 1\n", "  - idx: 1\n", "robots[1].idx: unknown key"),
    ("{center: [0, 5], radius: 1.0}", "{center: [0, 5]}",
     "obstacles[0].radius: missing required key"),
])
def test_missing_required_keys(tmp_path, old, new, field):
    expect_error(bad(tmp_path, old, new), field)


def test_robots_missing_entirely_and_empty(tmp_path):
    text = GOOD[:GOOD.index("robots:")]
    expect_error(write(tmp_path, text), "robots: missing required key")
    expect_error(write(tmp_path, text + "robots: []\n"), "robots: expected at least one robot")


def test_validate_catches_bad_generated_scenarios():
    s = Scenario("gen", "", 10.0, 0.25, PlannerConfig(),
                 (RobotSpec(0, (0.0, 0.0, 0.0), (5.0, 0.0)),
                  RobotSpec(1, (0.0, float("nan"), 0.0), (5.0, 3.0))))
    with pytest.raises(ScenarioError, match=r"^gen: robots\[1\]\.start: .*finite"):
        validate_scenario(s, "gen")
    s2 = dataclasses.replace(s, robots=(RobotSpec(0, (0.0, 0.0, 0.0), (5.0, 0.0),
                                                  planner="nope"),))
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.planner: unknown planner"):
        validate_scenario(s2, "gen")


# --- profiles ----------------------------------------------------------------------------

_PROFILE_DOC = """
name: profiled
time_limit: 60
{profile}
defaults:
  {extra}
robots:
  - {{id: 0, start: [0, 0, 0], goal: [10, 0]}}
"""


def _load_profile_doc(tmp_path, profile: str, extra: str = "radius: 0.5"):
    from world.scenario_file import load_scenario

    path = tmp_path / "profiled.yaml"
    path.write_text(_PROFILE_DOC.format(profile=profile, extra=extra))
    return load_scenario(path)


def test_profile_paper_loads_the_paper_config(tmp_path):
    from agent.core.config import PlannerConfig, is_paper_config

    paper = _load_profile_doc(tmp_path, "profile: paper").planner_config
    default = _load_profile_doc(tmp_path, "").planner_config
    assert is_paper_config(paper)
    assert not is_paper_config(default) and default == PlannerConfig()


def test_profile_lanes_loads_the_default_with_lanes_and_round_trips(tmp_path):
    from agent.core.config import PlannerConfig
    from agent.planning.mechanisms import mechanisms
    from world.scenario_file import scenario_from_dict, scenario_to_dict

    s = _load_profile_doc(tmp_path, "profile: lanes")
    config = s.planner_config
    assert config == dataclasses.replace(PlannerConfig(), profile="lanes")
    assert mechanisms("eifp-mpc", config).lanes
    assert scenario_from_dict(scenario_to_dict(s), "dict") == s  # as robot processes get it


def test_defaults_override_the_profile(tmp_path):
    from agent.core.config import is_paper_config

    config = _load_profile_doc(tmp_path, "profile: paper",
                               "cost: {side_hysteresis: 0.2}\n  mpc: {horizon_steps: 12}"
                               ).planner_config
    assert config.cost.side_hysteresis == 0.2 and not is_paper_config(config)
    assert config.is_paper  # the profile (the paper's mechanisms) stays under the override
    assert config.mpc.horizon_steps == 12
    assert config.threats.sensing_radius_m == 1.0e3  # the profile's other settings too


def test_unknown_profile_names_file_and_field(tmp_path):
    from world.scenario_file import ScenarioError

    with pytest.raises(ScenarioError, match=r"profiled.yaml: profile: expected one of"):
        _load_profile_doc(tmp_path, "profile: fancy")


def test_without_switches_mechanisms_off_and_round_trips(tmp_path):
    from world.scenario_file import ScenarioError, scenario_from_dict, scenario_to_dict

    config = _load_profile_doc(tmp_path, "without: [routing, liveness]").planner_config
    assert config.without_names == ("routing", "liveness")
    same = _load_profile_doc(tmp_path, "without: routing,liveness").planner_config
    assert same == config
    scenario = _load_profile_doc(tmp_path, "without: [routing]")
    data = scenario_to_dict(scenario)
    assert data["without"] == ["routing"]
    assert scenario_from_dict(data, "again.yaml").planner_config == scenario.planner_config
    assert "without" not in scenario_to_dict(_load_profile_doc(tmp_path, ""))
    with pytest.raises(ScenarioError, match=r"profiled.yaml: without: unknown mechanism"):
        _load_profile_doc(tmp_path, "without: [routes]")
    with pytest.raises(ScenarioError, match=r"profiled.yaml: without: expected a list"):
        _load_profile_doc(tmp_path, "without: 3")


# --- the wire's bounds --------------------------------------------------------------------


@pytest.mark.parametrize("snippet, message", [
    ("time_limit: 1.0e12", r"time_limit: must be at most 1e\+07 s"),
    ("goal: [2.0e6, 0]", r"robots\[0\].goal: must be at most 1e\+06 m"),
    ("start: [-1.5e6, 0, 0]", r"robots\[0\].start: must be at most 1e\+06 m"),
    ("v_max: 5000", r"robots\[0\].v_max: must be at most 1000 m/s"),
])
def test_values_beyond_the_wire_bounds_are_refused(tmp_path, snippet, message):
    from world.scenario_file import ScenarioError, load_scenario

    robot = {"start": "start: [0, 0, 0]", "goal": "goal: [10, 0]", "v_max": ""}
    top = "time_limit: 60"
    key = snippet.split(":")[0]
    if key == "time_limit":
        top = snippet
    else:
        robot[key] = snippet
    body = ", ".join(v for v in robot.values() if v)
    path = tmp_path / "bounds.yaml"
    path.write_text(f"name: bounds\n{top}\nrobots:\n  - {{id: 0, {body}}}\n")
    with pytest.raises(ScenarioError, match=rf"bounds.yaml: {message}"):
        load_scenario(path)


def test_a_moving_obstacle_must_stay_on_the_map_for_the_whole_run(tmp_path):
    from world.scenario_file import ScenarioError, load_scenario

    path = tmp_path / "drift.yaml"
    path.write_text("name: drift\ntime_limit: 1.0e6\nrobots:\n  - {id: 0, start: [0, 0, 0], "
                    "goal: [10, 0]}\nobstacles:\n  - {center: [0, 50], radius: 1, "
                    "velocity: [2, 0]}\n")
    with pytest.raises(ScenarioError, match=r"drift.yaml: obstacles\[0\].center: must be at most"):
        load_scenario(path)


def test_a_goal_no_route_reaches_is_refused_naming_the_file_and_robot(tmp_path):
    """A goal inside a closed ring of obstacles (gaps narrower than the robot) is refused
    at validation; one the robot fits to, through a gap wider than its diameter, is not."""
    import math

    def ring(radius_m: float) -> list[dict]:
        return [{"center": [10.0 * math.cos(2 * math.pi * k / 40),
                            10.0 * math.sin(2 * math.pi * k / 40)], "radius": radius_m}
                for k in range(40)]

    robots = [{"id": 0, "start": [20.0, 0.0, 0.0], "goal": [0.0, 0.0]},
              {"id": 1, "start": [0.0, 20.0, 0.0], "goal": [0.0, 30.0]}]
    path = tmp_path / "ring.yaml"
    # centres 1.57 m apart: 0.9 m discs leave 0 m gaps (closed); 0.2 m discs leave 1.17 m
    path.write_text(yaml.safe_dump({"name": "ring", "time_limit": 60, "robots": robots,
                                    "obstacles": ring(0.9)}))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    message = str(err.value)
    assert message.startswith(str(path)) and "robots[0].goal" in message
    assert "robot 0 cannot reach its goal" in message and "\n" not in message
    path.write_text(yaml.safe_dump({"name": "ring", "time_limit": 60, "robots": robots,
                                    "obstacles": ring(0.2)}))
    assert len(load_scenario(path).robots) == 2


def test_a_goal_enclosed_in_a_map_of_several_hundred_discs_is_refused(tmp_path: Path) -> None:
    # a ring of 160 touching discs (more than the 128 that were routed before), one robot
    # inside it going out; and the walled hall of docs/examples with 138 discs loads
    ring = [{"center": [30.0 * math.cos(2 * math.pi * k / 160),
                        30.0 * math.sin(2 * math.pi * k / 160)], "radius": 0.6}
            for k in range(160)]
    robots = [{"id": 0, "start": [0.0, 0.0, 0.0], "goal": [40.0, 0.0]}]
    path = tmp_path / "big_ring.yaml"
    path.write_text(yaml.safe_dump({"name": "big_ring", "time_limit": 60, "robots": robots,
                                    "obstacles": ring}))
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.goal: robot 0 cannot reach"):
        load_scenario(path)
    hall = load_scenario(Path(__file__).parents[3] / "docs" / "examples" / "warehouse.yaml")
    assert len(hall.obstacles) == 138 and len(hall.robots) == 12


@pytest.mark.parametrize("path", sorted((Path(__file__).parents[3] / "docs" / "examples"
                                         / "probes").glob("*.yaml")), ids=lambda p: p.stem)
def test_every_probe_scene_of_the_docs_loads(path: Path) -> None:
    scenario = load_scenario(path)
    assert scenario.name == path.stem and len(scenario.robots) >= 1
