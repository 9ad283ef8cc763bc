"""Wall-clock latency by stage from the commands' stamps (`orchestrator.analysis.latency`)."""

from __future__ import annotations

import numpy as np
import pytest

from orchestrator.analysis.latency import (
    DIRECT_ROUTER,
    TRANSPORT_STAGE,
    router_groups,
    wall_latency_ms,
    wall_latency_ms_by_group,
)


def stamps_row(robot_clock: int, world_clock: int, base: int) -> list[int]:
    """One row of `TIMING_COLUMNS` stamps (ns) of a command on the given clocks."""
    # pose published at base, received +1 ms, plan +2..+5 ms, sent +5.1, at the world +6,
    # applied +20 ms.
    ms = 1_000_000
    return [robot_clock, world_clock, base, base + 1 * ms, base + 2 * ms, base + 5 * ms,
            base + 5 * ms + 100_000, base + 6 * ms, base + 20 * ms]


def test_wall_stages_from_stamps_on_one_host():
    stamps = np.array([stamps_row(7, 7, 10**9 + k * 10**8) for k in range(10)])
    w = wall_latency_ms(stamps)
    assert w["pose_to_robot"]["p50"] == pytest.approx(1.0)
    assert w["plan"]["p99"] == pytest.approx(3.0)
    assert w["send"]["max"] == pytest.approx(0.1)
    assert w["cmd_to_world"]["p50"] == pytest.approx(0.9)
    assert w["sense_to_act"]["p50"] == pytest.approx(6.0)
    assert w["end_to_end"]["max"] == pytest.approx(20.0) and w["end_to_end"]["n"] == 10


def test_stages_across_two_clocks_are_left_out_but_world_stages_stay():
    w = wall_latency_ms(np.array([stamps_row(3, 9, 10**9)]))
    assert "pose_to_robot" not in w and "cmd_to_world" not in w
    assert w["sense_to_act"]["p50"] == pytest.approx(6.0)  # both ends on the world's clock
    assert w["plan"]["p50"] == pytest.approx(3.0)          # both ends on the robot's clock


def test_unstamped_commands_measure_nothing():
    assert wall_latency_ms(np.zeros((4, 9), dtype=np.int64)) == {}
    assert wall_latency_ms(np.zeros((0, 9), dtype=np.int64)) == {}


def test_transport_is_sense_to_act_less_the_robots_own_time_on_any_clocks():
    # 6 ms pose -> command at the world, 4.1 ms of it between pose received and command
    # sent at the robot: 1.9 ms on the wire, whether or not the robot shares the clock.
    for robot_clock in (7, 3):
        w = wall_latency_ms(np.array([stamps_row(robot_clock, 7, 10**9)]))
        assert w[TRANSPORT_STAGE]["p50"] == pytest.approx(1.9)
    # A robot on another host: its stamps are on a clock shifted by an unknown offset.
    row = stamps_row(3, 9, 10**9)
    shifted = row[:3] + [v + 5 * 10**12 for v in row[3:7]] + row[7:]
    w = wall_latency_ms(np.array([shifted]))
    assert w[TRANSPORT_STAGE]["p50"] == pytest.approx(1.9)
    assert w["sense_to_act"]["p50"] == pytest.approx(6.0)
    unstamped = row[:]
    unstamped[3] = 0  # pose_rx missing
    assert TRANSPORT_STAGE not in wall_latency_ms(np.array([unstamped]))


def test_router_groups_put_every_robot_not_behind_a_relay_on_the_worlds_router():
    assert router_groups([0, 1, 2, 3], {}) == {}
    assert router_groups([0, 1, 2, 3], {"router-b": [3, 2]}) == {
        DIRECT_ROUTER: [0, 1], "router-b": [2, 3]}
    assert router_groups([2, 3], {"router-b": [2, 3]}) == {"router-b": [2, 3]}


def test_latency_by_group_splits_the_commands_by_robot():
    ms = 1_000_000
    rows, robots = [], []
    for k in range(20):
        robot = k % 4
        row = stamps_row(7, 7, 10**9 + k * 10**8)
        if robot >= 2:  # behind a relay: 0.5 ms more each way
            row[3:] = [v + ms // 2 for v in row[3:7]] + [v + ms for v in row[7:]]
        rows.append(row)
        robots.append(robot)
    by = wall_latency_ms_by_group(np.array(robots), np.array(rows),
                                  {"world": [0, 1], "router-b": [2, 3]})
    assert by["world"]["sense_to_act"]["p50"] == pytest.approx(6.0)
    assert by["router-b"]["sense_to_act"]["p50"] == pytest.approx(7.0)
    assert by["world"]["transport"]["p50"] == pytest.approx(1.9)
    assert by["router-b"]["transport"]["p50"] == pytest.approx(2.9)
    assert by["router-b"]["pose_to_robot"]["p50"] == pytest.approx(1.5)
    assert by["world"]["sense_to_act"]["n"] == by["router-b"]["sense_to_act"]["n"] == 10
    with pytest.raises(ValueError):
        wall_latency_ms_by_group(np.array([0]), np.array(rows), {"world": [0]})
