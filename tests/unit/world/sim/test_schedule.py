"""Tests of `world.sim.schedule`: the pose slots a world tick goes on, and a robot's planning
slots and the pose slot they fall on."""

from __future__ import annotations

import math

import pytest

from world.sim.schedule import (
    PlanSchedule,
    plan_phase_s,
    plan_pose_slot,
    pose_slot_count,
    pose_slot_of_tick,
)


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


def test_schedule_plans_on_first_pose_then_every_period() -> None:
    schedule = PlanSchedule(0.1)
    planned = []
    for tick in range(26):  # poses every 0.02 s of sim time, 0.00 .. 0.50
        stamp = tick * 0.02
        if schedule.due(stamp):
            planned.append(round(stamp, 6))
            assert schedule.planned(stamp) == 0
    assert planned == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]
    assert schedule.skipped == 0


def test_schedule_starts_at_first_stamp_seen() -> None:
    schedule = PlanSchedule(0.1)
    assert schedule.due(3.14)
    schedule.planned(3.14)
    assert not schedule.due(3.2)
    assert schedule.due(3.24)


def test_schedule_skips_missed_slots_instead_of_a_backlog() -> None:
    schedule = PlanSchedule(0.1)
    schedule.due(0.0)
    schedule.planned(0.0)
    # The robot was stalled: the next pose it sees is stamped 0.36 (slots 0.1..0.3 passed).
    assert schedule.due(0.36)
    assert schedule.planned(0.36) == 2  # 0.2 and 0.3 skipped (0.1 is the one planned late)
    assert not schedule.due(0.38)
    assert schedule.due(0.4)
    assert schedule.skipped == 2


def test_schedule_tolerates_float_accumulation() -> None:
    schedule = PlanSchedule(0.1)
    stamp = 0.0
    plans = 0
    for _ in range(5000):  # stamps accumulated as the world does: t += dt
        if schedule.due(stamp):
            schedule.planned(stamp)
            plans += 1
        stamp += 0.02
    assert plans == 1000 and schedule.skipped == 0


def test_schedule_on_a_phase_plans_on_its_slots_only() -> None:
    schedule = PlanSchedule(0.1, phase_s=0.04)
    planned = []
    for tick in range(26):  # poses every 0.02 s: 0.00 .. 0.50
        stamp = tick * 0.02
        if schedule.due(stamp):
            planned.append(round(stamp, 6))
            assert schedule.planned(stamp) == 0
    assert planned == [0.04, 0.14, 0.24, 0.34, 0.44]
    assert schedule.skipped == 0


def test_schedule_on_a_phase_joins_at_the_next_slot() -> None:
    schedule = PlanSchedule(0.1, phase_s=0.04)
    assert not schedule.due(3.16)  # a robot that starts late keeps its phase
    assert schedule.next_s == pytest.approx(3.24)
    assert schedule.due(3.24)


def test_plan_phases_spread_robots_evenly_over_the_ticks() -> None:
    phases = [plan_phase_s(rid, 0.1, 0.02) for rid in range(20)]
    ticks = [round(p / 0.02) for p in phases]
    assert all(abs(p - 0.02 * t) < 1e-12 for p, t in zip(phases, ticks))
    assert sorted(set(ticks)) == [0, 1, 2, 3, 4]
    assert all(ticks.count(t) == 4 for t in range(5))  # 20 robots: 4 plan on each tick
    assert plan_phase_s(7, 0.1, 0.1) == 0.0  # one tick per period: everyone on it


def test_schedule_rejects_bad_period() -> None:
    with pytest.raises(ValueError):
        PlanSchedule(0.0)


def test_schedule_with_a_phase_plans_on_absolute_slots() -> None:
    schedule = PlanSchedule(0.1, phase_s=0.04)
    planned = []
    for tick in range(20):
        stamp = tick * 0.02 + 0.3  # the first pose the robot sees is stamped 0.30
        if schedule.due(stamp):
            planned.append(round(stamp, 6))
            schedule.planned(stamp)
    assert planned == [0.34, 0.44, 0.54, 0.64]


def test_a_robot_on_one_tick_a_period_needs_one_pose_slot_only() -> None:
    slots = pose_slot_count(50.0, 10.0)
    assert slots == 5
    for rid in range(10):  # robot k plans on tick k mod 5: its slot
        phase_s = plan_phase_s(rid, 0.1, 0.02)
        assert plan_pose_slot(0.1, phase_s, 0.02, slots) == rid % 5
    assert plan_pose_slot(0.1, 0.01, 0.02, slots) is None  # between ticks: every slot
    assert plan_pose_slot(0.04, 0.0, 0.02, slots) is None  # cycles through the slots
