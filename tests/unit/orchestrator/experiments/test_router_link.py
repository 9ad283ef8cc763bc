"""The router-link benchmark's pure parts: the two-host layout, the control window, the
rows (`orchestrator.experiments.router_link`). A real run is tests/system/test_router_link.py."""

from __future__ import annotations

import math

import pytest

from orchestrator.experiments.families import CIRCLES_PITCH_M, circles
from orchestrator.experiments.router_link import (
    border_layout,
    control_window,
    format_link_rows,
    link_row,
    received_by,
    whole_fleet_bytes_per_tick,
)
from world.sim.cells import CellRule


@pytest.mark.parametrize("n", [32, 48, 64, 128])
def test_the_border_population_is_the_same_for_every_n(n: int) -> None:
    """Near: host A's nearest column of tiles (16 robots) is within host B's cells, for
    every N; farther columns are not. Far: no robot of host A is."""
    near, far = border_layout(n, "near"), border_layout(n, "far")
    assert len(near.host_b) == len(far.host_b) == 16
    assert len(near.scenario.robots) == len(far.scenario.robots) == n
    assert len(near.border) == 16 and far.border == ()
    starts = {r.id: r.start for r in near.scenario.robots}
    assert all(starts[i][0] > near.border_x_m for i in near.host_b)
    assert all(starts[i][0] < near.border_x_m for i in near.host_a)
    assert all(abs(starts[i][0]) < CIRCLES_PITCH_M / 2 for i in near.border)


def test_the_border_is_what_host_b_holds() -> None:
    """The border robots are exactly host A's robots in a cell some host-B robot holds."""
    layout = border_layout(48, "near")
    rule = CellRule.of_config(layout.scenario.planner_config)
    robots = {r.id: r for r in layout.scenario.robots}
    held = set().union(*(rule.needed(robots[i].start[0], robots[i].start[1])
                         for i in layout.host_b))
    assert set(layout.border) == {i for i in layout.host_a
                                  if rule.cell_of(*robots[i].start[:2]) in held}


def test_tiles_are_circles_tiles() -> None:
    """Every robot swaps to the antipodal point of an 8 m circle, as in `circles`, and
    starts far enough from every other."""
    layout = border_layout(64, "near")
    reference = circles(8).robots
    for r in layout.scenario.robots:
        assert math.dist(r.start[:2], r.goal) == pytest.approx(16.0, abs=1e-3)
    assert {round(math.dist(r.start[:2], r.goal), 3) for r in reference} == {16.0}
    ids = [r.id for r in layout.scenario.robots]
    assert ids == list(range(64)) and layout.host_b == tuple(range(48, 64))


def test_bad_layouts_are_refused() -> None:
    with pytest.raises(ValueError, match="case"):
        border_layout(32, "middle")
    with pytest.raises(ValueError, match="host A"):
        border_layout(17, "near")
    assert len(border_layout(4, "near", host_b_robots=2).host_b) == 2


def test_whole_fleet_message_grows_with_n() -> None:
    """About 36 bytes per disc (the figure docs/scale.md uses), one message of every disc."""
    small, large = border_layout(32), border_layout(64)
    b_small = whole_fleet_bytes_per_tick(small.scenario)
    b_large = whole_fleet_bytes_per_tick(large.scenario)
    assert 30.0 < (b_large - b_small) / 32 < 45.0
    assert 30.0 * 32 < b_small < 45.0 * 32 + 200


def test_control_window_is_start_to_first_robot_left() -> None:
    events = [{"kind": "world_ready", "wall": 1.0}, {"kind": "start", "t": 0.0, "wall": 10.0},
              {"kind": "end", "t": 12.0}, {"kind": "robot_left", "wall": 58.5, "robot": 1},
              {"kind": "robot_left", "wall": 58.2, "robot": 0}]
    assert control_window(events) == (10.0, 58.2, 12.0)
    assert control_window(events[:2]) is None


def test_rows_are_per_sim_second() -> None:
    layout = border_layout(32, "near")
    exits = {"processes": [{"robot": i, "rx_pose_bytes": 1000} for i in range(32)]}
    assert received_by(exits, layout.host_b) == 16_000
    row = link_row(layout, relay=True, down_b=120_000, up_b=60_000,
                   window=(10.0, 58.0, 12.0), exits=exits, links=1, world_status=0,
                   time_scale=0.25, wall_s=70.0, acl=["world", "router-b"])
    assert row["link_down_bytes_s"] == 10_000 and row["link_up_bytes_s"] == 5_000
    assert row["link_bytes_s"] == 15_000 and row["host_b_rx_pose_bytes_s"] == 16_000 / 12
    assert row["border_robots"] == 16 and row["case"] == "near"
    assert row["whole_fleet_bytes_s"] == 50.0 * whole_fleet_bytes_per_tick(layout.scenario)
    direct = link_row(layout, relay=False, down_b=0, up_b=0, window=None, exits={},
                      links=0, world_status=3, time_scale=0.25, wall_s=1.0, acl=[])
    assert direct["case"] == "direct" and direct["link_bytes_s"] is None
    table = format_link_rows([row, direct])
    assert "near" in table and "direct" in table and "15.0" not in table.splitlines()[0]
    assert "10.0 / 5.0" in table and "0.94" in table  # 15 kB/s over 16 robots


def test_the_cli_refuses_before_any_run(tmp_path, capsys) -> None:
    """A robot count that leaves host A fewer than 2 robots, and plain TCP (the routers'
    access control needs TLS), are refused with status 2 and nothing started."""
    from orchestrator.cli import main as cli_main

    assert cli_main(["scale", "--router-link", "--agents", "32,17",
                     "--out", str(tmp_path / "a")]) == 2
    assert "host A" in capsys.readouterr().err
    assert not list((tmp_path / "a").glob("*_32"))
    assert cli_main(["scale", "--router-link", "--agents", "32", "--insecure",
                     "--out", str(tmp_path / "b")]) == 2
    assert "TLS" in capsys.readouterr().err
    assert cli_main(["scale", "--router-link", "--world-bench", "--agents", "32",
                     "--out", str(tmp_path / "c")]) == 2
    assert "one at a time" in capsys.readouterr().err
