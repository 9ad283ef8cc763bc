"""The live view's gathering of a tick's cell messages (`orchestrator.experiments.live`)."""

from __future__ import annotations

import numpy as np

from eifp_wire import PosesMsg
from orchestrator.experiments.live import TickGather


def _cell(tick: int, robots: dict[int, float]) -> PosesMsg:
    ids = sorted(robots)
    return PosesMsg(t_s=tick * 0.02, tick=tick, robot_ids=ids,
                    robot_pose=[[robots[i], 0.0, 0.0] for i in ids],
                    robot_radius_m=[0.5] * len(ids), obstacle_ids=[],
                    obstacle_xy_m=np.zeros((0, 2)), obstacle_radius_m=[])


def test_a_tick_is_handed_out_whole_when_the_next_begins() -> None:
    gather = TickGather()
    assert gather.add(_cell(3, {4: 40.0})) is None
    assert gather.add(_cell(3, {0: 0.0, 2: 20.0})) is None
    assert gather.add(_cell(3, {4: 40.0})) is None  # the same cell heard twice
    assert gather.add(_cell(2, {9: 9.0})) is None  # an older tick: dropped
    out = gather.add(_cell(4, {0: 0.1}))
    assert out is not None
    t_s, tick, ids, pose = out
    assert (t_s, tick, ids.tolist()) == (0.06, 3, [0, 2, 4])
    assert pose[:, 0].tolist() == [0.0, 20.0, 40.0]
    assert gather.add(_cell(4, {5: 50.0})) is None and gather.tick == 4
