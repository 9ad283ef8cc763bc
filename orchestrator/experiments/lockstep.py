"""A lockstep run into a run directory: `world.sim.lockstep` recorded by `world.recorder`.

The run directory holds the same files as a distributed run's (trajectory.csv,
commands.csv, events.jsonl, scenario.yaml, run.mcap) plus metrics.json.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from agent.core.scenario import Scenario
from orchestrator.analysis.metrics import RunMetrics
from orchestrator.analysis.rundir import metrics_from_run_dir, write_metrics
from world.recorder import RunRecorder
from world.sim.faults import FaultPlan
from world.sim.lockstep import SimProgress
from world.sim.lockstep import run_lockstep as run_loop

if TYPE_CHECKING:
    from world.mcap_log import LiveView


@dataclass(frozen=True)
class LockstepProgress:
    """What `run_lockstep` reports to `on_progress` (field names as `DistributedProgress`)."""

    wall_s: float
    sim_t_s: float
    n_robots: int
    arrived: frozenset[int]
    contacts: int
    started: bool = True
    lost: frozenset[int] = field(default_factory=frozenset)


@dataclass(frozen=True)
class LockstepOutcome:
    """How a lockstep run ended.

    Args:
        out_dir: the run directory.
        reason: "all_arrived", "arrived_or_lost" or "time_limit" (`world.sim.lockstep`).
        success: every robot arrived and no contact (as `metrics.success`).
        sim_time_s: sim time at the end.
        ticks: world ticks run.
        wall_s: wall time of the run (without the metrics).
        metrics: the run's metrics (also in `metrics.json`).
    """

    out_dir: Path
    reason: str
    success: bool
    sim_time_s: float
    ticks: int
    wall_s: float
    metrics: RunMetrics


class PacedSink:
    """A run sink that holds each tick back until its sim time is due in wall time at
    `time_scale` sim seconds per wall second (for watching a lockstep run live)."""

    def __init__(self, sink: RunRecorder, time_scale: float) -> None:
        if not time_scale > 0.0:
            raise ValueError(f"time_scale must be > 0, got {time_scale!r}")
        self.sink = sink
        self.time_scale = float(time_scale)
        self._wall0: float | None = None

    def record_tick(self, t_s: float, robot_ids: np.ndarray, pose: np.ndarray,
                    applied: np.ndarray) -> None:
        now = time.monotonic()
        if self._wall0 is None:
            self._wall0 = now - t_s / self.time_scale
        delay = self._wall0 + t_s / self.time_scale - now
        if delay > 0.0:
            time.sleep(delay)
        self.sink.record_tick(t_s, robot_ids, pose, applied)

    def record_command(self, *args: Any, **kwargs: Any) -> None:
        self.sink.record_command(*args, **kwargs)

    def record_plan(self, *args: Any, **kwargs: Any) -> None:
        self.sink.record_plan(*args, **kwargs)

    def event(self, kind: str, t_s: float, **fields: Any) -> None:
        self.sink.event(kind, t_s, **fields)


def run_lockstep(scenario: Scenario, out_dir: Path, *, world_rate_hz: float = 50.0,
                 control_rate_hz: float = 10.0,
                 on_progress: Callable[[LockstepProgress], None] | None = None,
                 faults: FaultPlan | None = None,
                 live: LiveView | None = None,
                 time_scale: float | None = None) -> LockstepOutcome:
    """Run `scenario` in lockstep; write the run directory and `metrics.json`.

    Args:
        scenario: the resolved scenario.
        out_dir: run directory (created).
        world_rate_hz: world ticks per sim second.
        control_rate_hz: planning cycles per sim second; must divide world_rate_hz.
        on_progress: called about every sim second with a `LockstepProgress`.
        faults: injected faults (`world.sim.faults.FaultPlan`); None: none.
        live: a live Foxglove server that gets every message run.mcap gets.
        time_scale: pace the run at this many sim seconds per wall second (`PacedSink`);
            None: as fast as it computes.
    """
    out_dir = Path(out_dir)
    wall0 = time.perf_counter()

    def progress(p: SimProgress) -> None:
        if on_progress is not None:
            on_progress(LockstepProgress(wall_s=time.perf_counter() - wall0,
                                         sim_t_s=p.sim_t_s, n_robots=p.n_robots,
                                         arrived=p.arrived, contacts=p.contacts, lost=p.lost))

    with RunRecorder(out_dir, scenario, live=live) as rec:
        sink = rec if time_scale is None else PacedSink(rec, time_scale)
        result = run_loop(scenario, sink, world_rate_hz=world_rate_hz,
                          control_rate_hz=control_rate_hz, faults=faults, on_progress=progress)
    wall_s = time.perf_counter() - wall0
    metrics = metrics_from_run_dir(out_dir, control_period_s=1.0 / control_rate_hz,
                                   world_dt_s=1.0 / world_rate_hz)
    write_metrics(out_dir, metrics)
    return LockstepOutcome(out_dir=out_dir, reason=result.reason, success=metrics.success,
                           sim_time_s=result.sim_time_s, ticks=result.ticks, wall_s=wall_s,
                           metrics=metrics)
