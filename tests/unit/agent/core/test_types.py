"""Tests of agent/types.py: what the typed inputs of the planners accept and refuse."""

import math

import numpy as np
import pytest

from agent.core.types import EgoState, Observation, Others


@pytest.mark.parametrize(("field", "value", "message"), [
    ("recent_speed_mps", [0.5, 0.5], "shape"),
    ("recent_speed_mps", [math.inf], "NaN .unknown. or finite"),
    ("recent_interval_s", [-0.1], "NaN .unknown. or finite"),
    ("recent_turn_rate_radps", [0.1, 0.2], "shape"),
    ("recent_turn_rate_radps", [-math.inf], "NaN .unknown. or finite"),
])
def test_others_reject_bad_recent_motion(field, value, message):
    base = dict(ids=[1], position_m=[[1.0, 0.0]], velocity_mps=[[0.0, 0.0]], radius_m=[0.5],
                linearity=[1.0], track_start_m=[[1.0, 0.0]], is_robot=[True])
    ok = Others(**base, recent_speed_mps=[math.nan], recent_interval_s=[0.1])
    assert math.isnan(ok.recent_speed_mps[0]) and ok.recent_interval_s[0] == 0.1
    assert np.isnan(Others(**base).recent_speed_mps).all()  # None: unknown
    assert np.isnan(Others(**base).recent_turn_rate_radps).all()
    assert Others(**base, recent_turn_rate_radps=[-1.2]).recent_turn_rate_radps[0] == -1.2
    with pytest.raises(ValueError, match=f"{field}: .*{message}"):
        Others(**base, **{field: value})


def test_with_others_swaps_only_the_others_and_leaves_the_original_alone():
    base = dict(ids=[1, 2], position_m=[[1.0, 0.0], [3.0, 0.0]], velocity_mps=[[0.0, 0.0]] * 2,
                radius_m=[0.5, 0.5], linearity=[1.0, 1.0], track_start_m=[[1.0, 0.0]] * 2,
                is_robot=[True, True])
    obs = Observation(robot_id=0, ego=EgoState(0.0, 0.0, 0.0, 0.4, 0.1), goal_m=[5.0, 1.0],
                      radius_m=0.5, others=Others(**base), pose_age_s=0.05)
    near = obs.others.subset(np.array([0]))
    narrowed = obs.with_others(near)
    assert narrowed is not obs and narrowed.others is near
    assert obs.others.ids.tolist() == [1, 2]  # the original is unchanged
    for name in ("robot_id", "ego", "goal_m", "radius_m", "limits", "goal_tolerance_m",
                 "pose_age_s"):
        assert getattr(narrowed, name) is getattr(obs, name)


def test_plan_debug_trusted_holds_what_the_checked_constructor_holds() -> None:
    from agent.core.types import PlanDebug

    fields = dict(ego=np.array([1.0, 2.0, 0.5]), threat_ids=(np.int64(3), -1),
                  via_points_m=np.zeros((1, 2)), reference_m=np.ones((21, 2)),
                  predicted_m=np.full((21, 2), 2.0))
    checked, trusted = PlanDebug(**fields), PlanDebug.trusted(**fields)
    assert trusted.threat_ids == checked.threat_ids == (3, -1)
    assert all(type(i) is int for i in trusted.threat_ids)
    for name in ("ego", "via_points_m", "reference_m", "predicted_m"):
        np.testing.assert_array_equal(getattr(trusted, name), getattr(checked, name))
