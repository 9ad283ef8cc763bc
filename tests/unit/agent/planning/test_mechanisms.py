"""The mechanisms each planner runs, and ablations built from the configuration."""

from __future__ import annotations

import dataclasses

import pytest

from agent.core.config import MECHANISM_NAMES, PlannerConfig, paper_config
from agent.planning.mechanisms import (
    EIFP_MPC_MECHANISMS,
    PAPER_MECHANISMS,
    Mechanisms,
    mechanisms,
)


def test_mechanism_names_are_the_switchable_fields():
    fields = tuple(f.name for f in dataclasses.fields(Mechanisms))
    assert fields == (*MECHANISM_NAMES, "primary_hold_s")


def test_without_switches_each_named_mechanism_to_the_papers_value():
    config = PlannerConfig().with_settings(without="routing, liveness,via_margin_m")
    assert config.without_names == ("routing", "liveness", "via_margin_m")
    mech = mechanisms("eifp-mpc", config)
    assert not mech.routing and mech.liveness is None
    assert mech.via_margin_m == PAPER_MECHANISMS.via_margin_m != EIFP_MPC_MECHANISMS.via_margin_m
    # everything else as the default
    rest = {f.name for f in dataclasses.fields(Mechanisms)} - {"routing", "liveness",
                                                               "via_margin_m"}
    for name in rest:
        assert getattr(mech, name) == getattr(EIFP_MPC_MECHANISMS, name), name
    assert mechanisms("eifp-mpc", PlannerConfig()) == EIFP_MPC_MECHANISMS


def test_each_mechanism_can_be_switched_off_alone():
    for name in MECHANISM_NAMES:
        mech = mechanisms("eifp-mpc", PlannerConfig(without=name))
        assert getattr(mech, name) == getattr(PAPER_MECHANISMS, name)


def test_without_refuses_unknown_names_and_leaves_the_paper_profile_alone():
    with pytest.raises(ValueError, match="unknown mechanism 'routes'"):
        PlannerConfig(without="routing,routes")
    assert mechanisms("eifp-mpc", paper_config().with_settings(without="routing")) == (
        PAPER_MECHANISMS)
