"""`world.mcap_log`'s pure conversions: the plan's raw JSON and the cached scene parts."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agent.core.types import PlanDebug
from world.mcap_log import _colour, _xy_json, plan_json, robot_rgb, scene_update


@pytest.mark.parametrize("k", [0, 1, 2, 7, 40])
def test_xy_json_is_each_point_to_a_tenth_of_a_millimetre(k: int) -> None:
    points = np.random.default_rng(k).uniform(-50.0, 50.0, (k, 2))
    if k:
        points[0] = (-0.0, -0.00004)
    text = _xy_json(points)
    assert text == "[" + ",".join(f"[{x:.4f},{y:.4f}]" for x, y in points.tolist()) + "]"
    np.testing.assert_allclose(np.array(json.loads(text), dtype=float).reshape(-1, 2),
                               np.round(points, 4), atol=1e-12)


def test_plan_json_round_trips() -> None:
    debug = PlanDebug(ego=np.array([1.0, -2.0, 0.5]), threat_ids=(3, -1),
                      via_points_m=np.array([[1.0, 1.0]]),
                      reference_m=np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 1.5]]),
                      predicted_m=np.zeros((0, 2)))
    got = json.loads(plan_json(1.5, 4, debug, 0.8, -0.1, "ok"))
    assert got["threats"] == [3, -1] and got["via_points"] == [[1.0, 1.0]]
    assert got["reference_path"] == [[0.0, 0.0], [1.0, 1.0], [2.0, 1.5]]
    assert got["mpc_prediction"] == [] and got["ego"] == [1.0, -2.0, 0.5]


def test_colours_and_scenes_built_from_the_cache_are_the_same_as_fresh_ones() -> None:
    assert _colour((0.1, 0.2, 0.3), 0.5) is _colour(np.array([0.1, 0.2, 0.3]), 0.5)
    assert _colour((0.1, 0.2, 0.3), 0.5) is not _colour((0.1, 0.2, 0.3), 0.9)
    args = ([0, 1], np.array([[0.0, 0.0], [3.0, 1.0]]), np.zeros(2), np.full(2, 0.5))
    goals, colours = np.array([[5.0, 5.0], [-6.0, 7.0]]), robot_rgb(2)
    first = scene_update(1.0, *args, goals, colours, np.zeros((0, 3))).encode()
    assert scene_update(1.0, *args, goals, colours, np.zeros((0, 3))).encode() == first
    moved = scene_update(1.0, *args, goals + 1.0, colours, np.zeros((0, 3))).encode()
    assert moved != first  # another goal: another disc, not a stale one
