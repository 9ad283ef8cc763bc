"""The route-graph benchmark (`orchestrator.experiments.route_bench`, `orchestrator bench
--routes`)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agent.planning.routing import MAX_ROUTED_OBSTACLES
from orchestrator.cli import main
from orchestrator.experiments.route_bench import halls, time_route_graphs


def test_a_hall_grows_by_its_shelf_rows_and_has_no_overlapping_start_corner() -> None:
    sizes = [len(halls(rows)) for rows in range(1, 27)]
    assert all(26 <= b - a <= 30 for a, b in zip(sizes, sizes[1:]))  # a row and its side walls
    assert sizes[-1] > MAX_ROUTED_OBSTACLES > sizes[15] > 128
    small = halls(1)
    corner = np.array([-13.0, 2.5])  # the benchmark's start
    assert (np.hypot(*(small.center_m - corner).T) > small.radius_m + 0.5).all()


def test_each_hall_gets_a_route_longer_than_the_straight_line() -> None:
    (row,) = time_route_graphs([3])
    top = 5.0 * 4
    straight = float(np.hypot(26.0, top - 5.0))
    assert row["discs"] == len(halls(3)) and row["edges"] > row["nodes"] > 0
    assert straight < row["route_m"] < 1.5 * straight
    assert min(row["build_full_s"], row["build_tight_s"], row["with_discs_s"]) > 0.0


def test_the_cli_prints_the_table_and_needs_robots_otherwise(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--routes", "1", "--json"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("rows  discs  nodes")
    assert json.loads(out[-1])["rows"][0]["rows"] == 1.0
    assert main(["bench", "--planner", "eifp-mpc"]) != 0
    assert "--robots is required" in capsys.readouterr().err
