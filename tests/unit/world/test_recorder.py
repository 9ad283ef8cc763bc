"""`world.recorder.RunRecorder`: the trajectory rows, written a tick at a time."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from orchestrator.experiments.families import resolve
from world.recorder import TRAJECTORY_HEADER, RunRecorder


def _row_by_row(t_s: float, ids: np.ndarray, pose: np.ndarray, applied: np.ndarray) -> str:
    """The documented format, one row at a time (`t,robot,x,y,theta,v,omega`)."""
    return "".join(f"{t_s:.4f},{rid},{p[0]:.5f},{p[1]:.5f},{p[2]:.5f},{u[0]:.4f},{u[1]:.4f}\n"
                   for rid, p, u in zip(ids.tolist(), pose.tolist(), applied.tolist()))


def test_trajectory_rows_are_the_documented_format(tmp_path: Path) -> None:
    scenario = resolve("setup_a")
    rng = np.random.default_rng(3)
    ids = np.array([0, 7, 12])
    ticks = []
    for k in range(5):
        pose = rng.normal(0.0, 20.0, (3, 3))
        applied = rng.normal(0.0, 1.0, (3, 2))
        if k == 0:  # signed zero, a value that rounds to zero, a large one
            pose[0] = (-0.0, -4e-6, math.pi)
            applied[1] = (1234.56789, -0.0)
        ticks.append((0.02 * k, pose, applied))
    with RunRecorder(tmp_path / "run", scenario, mcap=False) as rec:
        rec.record_tick(0.0, np.zeros(0, dtype=int), np.zeros((0, 3)), np.zeros((0, 2)))
        for t, pose, applied in ticks:
            rec.record_tick(t, ids, pose, applied)
    want = TRAJECTORY_HEADER + "".join(_row_by_row(t, ids, p, u) for t, p, u in ticks)
    assert (tmp_path / "run" / "trajectory.csv").read_text() == want
