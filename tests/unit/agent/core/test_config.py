"""Tests of agent/core/config.py: the range rules every configuration obeys, wherever it is
built, the settings list, and the paper profile."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.core.config import (
    POSITIVE_FIELDS,
    SETTINGS,
    SIGNED_FIELDS,
    SUB_CONFIGS,
    CostConfig,
    MpcConfig,
    OrcaConfig,
    PlannerConfig,
    ReferenceConfig,
    RobotLimits,
    SafetyConfig,
    ThreatConfig,
    field_range_error,
    setting,
)

CLASSES = (RobotLimits, SafetyConfig, ThreatConfig, CostConfig, ReferenceConfig, MpcConfig,
           OrcaConfig)


def numeric_fields(cls: type) -> list[str]:
    """Names of the fields whose default is a number (not bool, not None, not nested)."""
    out = []
    for f in dataclasses.fields(cls):
        default = getattr(cls(), f.name)
        if isinstance(default, int | float) and not isinstance(default, bool):
            out.append(f.name)
    return out


def test_defaults_are_valid_and_every_positive_field_exists() -> None:
    for cls in CLASSES:
        cls()  # the defaults pass their own rules
    names = {f.name for cls in CLASSES for f in dataclasses.fields(cls)}
    # a misspelt rule would silently stop checking its field
    assert POSITIVE_FIELDS.issubset(names)
    assert SIGNED_FIELDS.issubset(names)


def test_settings_list_every_sub_config_field_once_and_at_most_15() -> None:
    config = PlannerConfig()
    fields = {f"{group}.{f.name}" for group in SUB_CONFIGS
              for f in dataclasses.fields(getattr(config, group))}
    assert set(SETTINGS) == fields
    assert len(SETTINGS) <= 15
    assert {f.name for f in dataclasses.fields(PlannerConfig)} == {*SUB_CONFIGS, "profile",
                                                                   "without"}
    for name, planners in SETTINGS.items():
        assert planners and set(planners) <= {"ifp", "eifp", "eifp-mpc", "orca"}, name
        setting(config, name)  # resolvable


@pytest.mark.parametrize("cls", CLASSES)
def test_each_numeric_field_rejects_values_below_its_range_by_name(cls: type) -> None:
    fields = numeric_fields(cls)
    assert fields
    for name in fields:
        if name in SIGNED_FIELDS:
            continue
        default = getattr(cls(), name)
        bad = 0 if name in POSITIVE_FIELDS else -1
        bad = type(default)(bad)
        with pytest.raises(ValueError, match=f"^{name}: must be"):
            cls(**{name: bad})


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_numbers_are_rejected(bad: float) -> None:
    for cls, name in ((RobotLimits, "v_max_mps"), (MpcConfig, "dt_s"),
                      (ThreatConfig, "t_max_s"), (CostConfig, "w_length")):
        with pytest.raises(ValueError, match=f"^{name}: expected a finite number"):
            cls(**{name: bad})


def test_zero_is_allowed_where_only_a_sign_is_ruled_out() -> None:
    assert CostConfig(w_angle=0.0, side_hysteresis=0.0).w_angle == 0.0
    assert MpcConfig(clearance_margin_m=0.0).clearance_margin_m == 0.0
    assert ReferenceConfig(corner_radius_m=0.0).corner_radius_m == 0.0


def test_v_min_may_be_negative_but_not_above_v_max() -> None:
    assert RobotLimits(v_min_mps=-0.5).v_min_mps == -0.5
    with pytest.raises(ValueError, match="^v_min_mps: must be <= v_max_mps"):
        RobotLimits(v_max_mps=1.0, v_min_mps=1.5)


def test_replace_is_checked_too() -> None:
    with pytest.raises(ValueError, match="^t_max_s: must be > 0"):
        dataclasses.replace(ThreatConfig(), t_max_s=-1.0)
    with pytest.raises(ValueError, match="^profile: expected one of default, paper"):
        dataclasses.replace(PlannerConfig(), profile="fast")


def test_with_settings_replaces_by_dotted_name_and_names_unknown_ones() -> None:
    config = PlannerConfig().with_settings(**{"cost.w_angle": 0.5, "mpc.dt_s": 0.2,
                                              "profile": "paper"})
    assert config.cost.w_angle == 0.5 and config.mpc.dt_s == 0.2 and config.is_paper
    assert config.cost.w_length == CostConfig().w_length  # the rest kept
    with pytest.raises(ValueError, match="^cost.w_speed: not a setting of cost"):
        PlannerConfig().with_settings(**{"cost.w_speed": 1.0})
    with pytest.raises(ValueError, match="^gains: not a sub-config"):
        PlannerConfig().with_settings(**{"gains.k": 1.0})
    with pytest.raises(ValueError, match="^w_angle: not a field"):
        PlannerConfig().with_settings(w_angle=1.0)
    with pytest.raises(ValueError, match="^w_angle: must be >= 0"):
        PlannerConfig().with_settings(**{"cost.w_angle": -1.0})


@given(name=st.sampled_from(sorted(POSITIVE_FIELDS)),
       value=st.floats(allow_nan=False, allow_infinity=False))
def test_positive_rule_is_the_sign_of_the_value(name: str, value: float) -> None:
    problem = field_range_error(name, value)
    assert (problem is None) == (value > 0.0)


def test_non_numbers_are_left_to_the_type_checks_of_the_loaders() -> None:
    for value in (None, True, "x", (1.0, 2.0)):
        assert field_range_error("t_max_s", value) is None


def test_paper_config_sets_the_paper_profile_and_its_settings():
    from agent.core.config import PAPER_OVERRIDES, is_paper_config, paper_config

    cfg = paper_config()
    assert is_paper_config(cfg) and cfg.is_paper
    assert not is_paper_config(PlannerConfig()) and not PlannerConfig().is_paper
    for name, value in PAPER_OVERRIDES.items():
        assert setting(cfg, name) == value, name
    assert cfg.cost.side_hysteresis == 0.0  # plain argmin (Eq. 18)
    assert cfg.dcpa_threshold_m(0.5) == 5 * 0.5 + cfg.safety.d_safety_m  # D_thresh of Eq. (6)
    # settings apply last; the profile is still frozen and hashable
    assert paper_config(**{"threats.t_max_s": 5.0}).threats.t_max_s == 5.0
    assert not is_paper_config(paper_config(**{"profile": "default"}))
    hash(cfg)


def test_paper_file_defaults_load_as_the_paper_config():
    from agent.core.config import is_paper_config, paper_file_defaults
    from world.scenario_file import scenario_from_dict

    data = {"name": "x", "time_limit": 10.0, "goal_tolerance": 0.25, "profile": "paper",
            "defaults": paper_file_defaults(),
            "robots": [{"id": 0, "start": [0.0, 0.0, 0.0], "goal": [5.0, 0.0]}]}
    assert is_paper_config(scenario_from_dict(data).planner_config)
    data["profile"] = "default"
    assert not is_paper_config(scenario_from_dict(data).planner_config)
