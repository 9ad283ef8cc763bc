"""A lockstep run into a run directory: `world.sim.lockstep` recorded by `world.recorder`.

The run directory holds the same files as a distributed run's (trajectory.csv,
commands.csv, events.jsonl, scenario.yaml) plus metrics.json.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from agent.core.scenario import Scenario
from orchestrator.analysis.metrics import RunMetrics
from orchestrator.analysis.rundir import metrics_from_run_dir, write_metrics
from world.recorder import RunRecorder
from world.sim.faults import FaultPlan
from world.sim.lockstep import SimProgress
from world.sim.lockstep import run_lockstep as run_loop


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
        reason: "all_arrived" or "time_limit".
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


def run_lockstep(scenario: Scenario, out_dir: Path, *, world_rate_hz: float = 50.0,
                 control_rate_hz: float = 10.0,
                 on_progress: Callable[[LockstepProgress], None] | None = None,
                 faults: FaultPlan | None = None) -> LockstepOutcome:
    """Run `scenario` in lockstep; write the run directory and `metrics.json`.

    Args:
        scenario: the resolved scenario.
        out_dir: run directory (created).
        world_rate_hz: world ticks per sim second.
        control_rate_hz: planning cycles per sim second; must divide world_rate_hz.
        on_progress: called about every sim second with a `LockstepProgress`.
        faults: injected faults (`world.sim.faults.FaultPlan`); None: none.
    """
    out_dir = Path(out_dir)
    wall0 = time.perf_counter()

    def progress(p: SimProgress) -> None:
        if on_progress is not None:
            on_progress(LockstepProgress(wall_s=time.perf_counter() - wall0,
                                         sim_t_s=p.sim_t_s, n_robots=p.n_robots,
                                         arrived=p.arrived, contacts=p.contacts, lost=p.lost))

    with RunRecorder(out_dir, scenario) as rec:
        result = run_loop(scenario, rec, world_rate_hz=world_rate_hz,
                          control_rate_hz=control_rate_hz, faults=faults, on_progress=progress)
    wall_s = time.perf_counter() - wall0
    metrics = metrics_from_run_dir(out_dir, control_period_s=1.0 / control_rate_hz,
                                   world_dt_s=1.0 / world_rate_hz)
    write_metrics(out_dir, metrics)
    return LockstepOutcome(out_dir=out_dir, reason=result.reason, success=metrics.success,
                           sim_time_s=result.sim_time_s, ticks=result.ticks, wall_s=wall_s,
                           metrics=metrics)
