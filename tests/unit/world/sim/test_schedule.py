"""Tests of `world.sim.schedule`: the pose slots a world tick goes on and a robot plans on."""

from __future__ import annotations

import math

import pytest

from world.sim.schedule import plan_pose_slot, pose_slot_count, pose_slot_of_tick


@pytest.mark.parametrize(("world_hz", "control_hz", "slots"), [
    (50.0, 10.0, 5), (50.0, 5.0, 10), (50.0, 50.0, 1), (50.0, 20.0, 1), (50.0, 100.0, 1),
    (60.0, 10.0, 6), (50.0, 10.000000001, 5), (50.0, 3.0, 1)])
def test_pose_slot_count_is_whole_ticks_per_period(world_hz, control_hz, slots) -> None:
    assert pose_slot_count(world_hz, control_hz) == slots


def test_pose_slot_count_rejects_bad_rates() -> None:
    for rates in ((0.0, 10.0), (50.0, -1.0), (math.inf, 10.0), (50.0, math.nan)):
        with pytest.raises(ValueError):
            pose_slot_count(*rates)


def test_plan_pose_slot_matches_the_ticks_a_robot_plans_on() -> None:
    tick_s, slots = 0.02, 5
    for phase_ticks in range(12):
        phase_s = phase_ticks * tick_s
        slot = plan_pose_slot(0.1, phase_s, tick_s, slots)
        assert slot == phase_ticks % 5
        # Every plan time over many periods is a tick published on that slot.
        for k in range(200):
            tick = round((phase_s + k * 0.1) / tick_s)
            assert pose_slot_of_tick(tick, slots) == slot
    assert plan_pose_slot(0.2, 0.04, tick_s, slots) == 2      # 5 Hz: every other period
    assert plan_pose_slot(0.05, 0.0, tick_s, slots) is None   # 20 Hz: 2.5 ticks apart
    assert plan_pose_slot(0.04, 0.0, tick_s, slots) is None   # 25 Hz: cycles the slots
    assert plan_pose_slot(0.1, 0.03, tick_s, slots) is None   # phase between ticks
    assert plan_pose_slot(0.1, 0.0, tick_s, 1) == 0           # one slot: everything on 0
