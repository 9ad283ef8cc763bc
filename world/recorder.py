"""The run directory writer (an I/O edge, used by the world process and the lockstep runner).

Files (SI units):
- `scenario.yaml`: the resolved scenario.
- `trajectory.csv`: `t,robot,x,y,theta,v,omega`, one row per robot per world tick.
- `commands.csv`: `t_applied,robot,seq,pose_stamp,v,omega,plan_ms,status,side,resolved`
  (the first eight columns are the documented format; `side` and `resolved` let metrics
  count avoidance-side flips).
- `timing.csv`: `robot,seq,` then the wall-clock stamps of each applied command's way
  (`TIMING_COLUMNS`, integer ns of `time.monotonic_ns`; distributed runs only: a lockstep
  run has no wall clock to speak of).
- `events.jsonl`: one JSON object per line with at least `kind` and `t`.
- `run.mcap`: the same run for Foxglove (`world.mcap_log`): the scene every other tick,
  every applied command and every plan's internals (`record_plan`). A view of the run: the
  CSV and JSONL files stay the source of every metric.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from agent.core.scenario import Scenario
from agent.core.types import PlanDebug
from agent.files import check_own_dir, open_new
from eifp_wire import TIMING_COLUMNS

if TYPE_CHECKING:
    from world.mcap_log import LiveView

TRAJECTORY_HEADER = "t,robot,x,y,theta,v,omega\n"
COMMANDS_HEADER = "t_applied,robot,seq,pose_stamp,v,omega,plan_ms,status,side,resolved\n"
TIMING_HEADER = "robot,seq," + ",".join(TIMING_COLUMNS) + "\n"
_ROW = ",%d,%.5f,%.5f,%.5f,%.4f,%.4f\n"
"""One trajectory row after its time: robot, x, y, theta, v, omega."""


class RunRecorder:
    """Writes one run directory; line-buffered enough that a killed run leaves usable files.

    Args:
        out_dir: the run directory: created 0700 if it does not exist, else it must be this
            user's and writable by no one else (`agent.files.check_own_dir`); every file is
            new (`agent.files.open_new`: a file or symlink already there is an error).
        scenario: the resolved scenario (written as scenario.yaml).
        mcap: also write ``run.mcap``.
        live: a live Foxglove server that gets every message ``run.mcap`` gets (needs
            `mcap`).
    """

    def __init__(self, out_dir: Path, scenario: Scenario, *, mcap: bool = True,
                 live: LiveView | None = None) -> None:
        from world.scenario_file import dump_scenario

        self.out_dir = check_own_dir(Path(out_dir))
        dump_scenario(scenario, self.out_dir / "scenario.yaml")
        self.mcap = None
        if mcap:
            from world.mcap_log import McapLog

            self.mcap = McapLog(
                self.out_dir / "run.mcap", scenario, live=live,
                attachments={"scenario.yaml": (self.out_dir / "scenario.yaml").read_bytes()})
        self._traj: IO[str] = open_new(self.out_dir / "trajectory.csv", "w", buffering=1 << 16)
        self._traj.write(TRAJECTORY_HEADER)
        self._cmds: IO[str] = open_new(self.out_dir / "commands.csv", "w", buffering=1 << 16)
        self._cmds.write(COMMANDS_HEADER)
        self._timing: IO[str] = open_new(self.out_dir / "timing.csv", "w", buffering=1 << 16)
        self._timing.write(TIMING_HEADER)
        self._events: IO[str] = open_new(self.out_dir / "events.jsonl", "w", buffering=1)
        self.event_counts: dict[str, int] = {}
        self._closed = False

    def record_tick(self, t_s: float, robot_ids: np.ndarray, pose: np.ndarray,
                    applied: np.ndarray) -> None:
        """One row per robot: ground-truth pose and the (v, omega) applied during the tick."""
        n = len(robot_ids)
        if n:
            # One %-format for the tick's n rows: about twice as fast as a row at a time
            # (64 robots: 74 against 158 µs, measured under load), and the same text.
            rows = np.column_stack((pose[:, :3], applied[:, :2])).tolist()
            values = [v for rid, row in zip(np.asarray(robot_ids).tolist(), rows)
                      for v in (rid, *row)]
            self._traj.write((f"{t_s:.4f}" + _ROW) * n % tuple(values))
        if self.mcap is not None:
            self.mcap.tick(t_s, robot_ids, pose)

    def record_command(self, t_applied_s: float, robot_id: int, seq: int, pose_stamp_s: float,
                       v: float, omega: float, plan_ms: float, status: str, side: int = 0,
                       resolved: int | None = None) -> None:
        """One applied command."""
        res = "" if resolved is None else str(int(resolved))
        self._cmds.write(
            f"{t_applied_s:.4f},{int(robot_id)},{int(seq)},{pose_stamp_s:.4f},{v:.5f},"
            f"{omega:.5f},{plan_ms:.4f},{status},{int(side)},{res}\n"
        )
        if self.mcap is not None:
            self.mcap.command(t_applied_s, robot_id, seq, v, omega, status, side, resolved)

    def record_plan(self, t_s: float, robot_id: int, debug: PlanDebug, *, v_mps: float = 0.0,
                    omega_radps: float = 0.0, status: str = "ok") -> None:
        """One plan's internals (threats, via-points, reference, MPC prediction) at the sim
        time it was made; only ``run.mcap`` holds them."""
        if self.mcap is not None:
            self.mcap.plan(t_s, robot_id, debug, v_mps, omega_radps, status)

    def record_timing(self, robot_id: int, seq: int, stamps: Sequence[int]) -> None:
        """The wall stamps of one applied command, in `TIMING_COLUMNS` order."""
        if len(stamps) != len(TIMING_COLUMNS):
            raise ValueError(f"expected {len(TIMING_COLUMNS)} stamps, got {len(stamps)}")
        self._timing.write(f"{int(robot_id)},{int(seq)}," + ",".join(str(int(s)) for s in stamps)
                           + "\n")

    def event(self, kind: str, t_s: float, **fields: Any) -> None:
        """Append one event line; flushed at once so watchers see it."""
        record = {"kind": kind, "t": round(float(t_s), 4), **fields}
        self._events.write(json.dumps(record, default=_json_default) + "\n")
        self.event_counts[kind] = self.event_counts.get(kind, 0) + 1

    def flush(self) -> None:
        """Push buffered rows to disk."""
        for f in (self._traj, self._cmds, self._timing, self._events):
            f.flush()

    def close(self) -> None:
        """Flush and close every file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for f in (self._traj, self._cmds, self._timing, self._events):
            f.close()
        if self.mcap is not None:
            self.mcap.close()

    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _json_default(obj: object) -> object:
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
