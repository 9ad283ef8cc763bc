"""Tests of agent/config.py: the range rules every configuration obeys, wherever it is built."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.core.config import (
    POSITIVE_FIELDS,
    SIGNED_FIELDS,
    MpcConfig,
    PlannerConfig,
    RobotLimits,
    field_range_error,
)

CLASSES = (RobotLimits, MpcConfig, PlannerConfig)


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
    for cls, name in ((RobotLimits, "v_max_mps"), (MpcConfig, "q_heading"),
                      (PlannerConfig, "t_max_s"), (PlannerConfig, "w_length")):
        with pytest.raises(ValueError, match=f"^{name}: expected a finite number"):
            cls(**{name: bad})


def test_zero_is_allowed_where_only_a_sign_is_ruled_out() -> None:
    assert PlannerConfig(w_angle=0.0, side_hysteresis=0.0).w_angle == 0.0
    assert MpcConfig(max_constraints=0, clearance_margin_m=0.0).max_constraints == 0


def test_optional_fields_may_be_none_but_not_out_of_range() -> None:
    assert PlannerConfig(d_thresh_m=None, ghost_clearance_m=None).d_thresh_m is None
    with pytest.raises(ValueError, match="^d_thresh_m: must be > 0"):
        PlannerConfig(d_thresh_m=0.0)
    with pytest.raises(ValueError, match="^ghost_clearance_m: must be >= 0"):
        PlannerConfig(ghost_clearance_m=-0.1)


def test_v_min_may_be_negative_but_not_above_v_max() -> None:
    assert RobotLimits(v_min_mps=-0.5).v_min_mps == -0.5
    with pytest.raises(ValueError, match="^v_min_mps: must be <= v_max_mps"):
        RobotLimits(v_max_mps=1.0, v_min_mps=1.5)


def test_replace_is_checked_too() -> None:
    with pytest.raises(ValueError, match="^command_hold_periods: must be > 0"):
        dataclasses.replace(PlannerConfig(), command_hold_periods=-1.0)


@given(name=st.sampled_from(sorted(POSITIVE_FIELDS)),
       value=st.floats(allow_nan=False, allow_infinity=False))
def test_positive_rule_is_the_sign_of_the_value(name: str, value: float) -> None:
    problem = field_range_error(name, value)
    assert (problem is None) == (value > 0.0)


def test_non_numbers_are_left_to_the_type_checks_of_the_loaders() -> None:
    for value in (None, True, "x", (1.0, 2.0)):
        assert field_range_error("t_max_s", value) is None


def test_paper_config_turns_every_addition_off():
    from agent.core.config import (
        PAPER_MPC_OVERRIDES,
        PAPER_OVERRIDES,
        is_paper_config,
        paper_config,
    )

    cfg = paper_config()
    assert is_paper_config(cfg)
    assert not is_paper_config(PlannerConfig())
    for name, value in PAPER_OVERRIDES.items():
        assert getattr(cfg, name) == value, name
    for name, value in PAPER_MPC_OVERRIDES.items():
        assert getattr(cfg.mpc, name) == value, name
    assert cfg.dcpa_threshold_m(0.5) == 5 * 0.5 + cfg.d_safety_m  # D_thresh of Eq. (6)
    # overrides apply last; the profile is still frozen and hashable
    assert paper_config(t_max_s=5.0).t_max_s == 5.0
    hash(cfg)


def test_paper_file_defaults_load_as_the_paper_config():
    from agent.core.config import is_paper_config, paper_file_defaults
    from world.scenario_file import scenario_from_dict

    data = {"name": "x", "time_limit": 10.0, "goal_tolerance": 0.25,
            "defaults": paper_file_defaults(),
            "robots": [{"id": 0, "start": [0.0, 0.0, 0.0], "goal": [5.0, 0.0]}]}
    assert is_paper_config(scenario_from_dict(data).planner_config)
