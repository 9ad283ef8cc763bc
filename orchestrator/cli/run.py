"""`orchestrator run`: one scenario, distributed (a process per robot) or lockstep."""

from __future__ import annotations

import argparse
import datetime as dt
import math
import sys
import time
from pathlib import Path
from typing import Any

from agent.core.config import PLANNER_NAMES
from agent.core.scenario import Scenario
from agent.process import ExitCode
from orchestrator.analysis.console import ProgressLine, run_summary
from orchestrator.analysis.plots import write_run_plots
from orchestrator.analysis.rundir import end_event, safe_name
from orchestrator.cli.common import (
    DEFAULT_RUNS_DIR,
    MODES,
    BadInput,
    add_fault_args,
    fault_plan,
    planner_label,
)

RUN_ENDINGS = frozenset({ExitCode.OK, ExitCode.CONTACT, ExitCode.INCOMPLETE, ExitCode.ROBOT_LOST,
                         ExitCode.INTERRUPTED})
"""World exit statuses of a run that ended normally (anything else: the world was lost)."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run one scenario")
    p.add_argument("setup", help="setup_a..setup_g (or a..g), a family (circle, crossing, "
                                 "crossing4, random, ...: orchestrator list), or a scenario "
                                 ".yaml file")
    p.add_argument("--agents", type=int, help="robot count (setup_f, setup_g, families)")
    p.add_argument("--planner", choices=PLANNER_NAMES,
                   help="every robot uses this planner (default: the scenario's)")
    p.add_argument("--mode", choices=MODES, default="distributed")
    p.add_argument("--seed", type=int, default=0, help="seeds the random family and jitter")
    p.add_argument("--start-jitter-m", type=float, default=0.0,
                   help="move each start by up to this much (uniform in a disc)")
    p.add_argument("--time-scale", type=float, default=None,
                   help="sim seconds per wall second (distributed mode; default 1)")
    p.add_argument("--out", help="run directory (default runs/<setup>-<planner>-<seed>-<time>)")
    p.add_argument("--gif", action="store_true", help="also write trajectory.gif")
    p.add_argument("--quiet", action="store_true", help="no progress line and no summary")
    add_fault_args(p)
    p.set_defaults(func=run)


def default_out_dir(scenario: Scenario, planner: str, seed: int) -> Path:
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return DEFAULT_RUNS_DIR / f"{safe_name(scenario.name)}-{planner}-{seed}-{stamp}"


def run(args: argparse.Namespace) -> int:
    from orchestrator.analysis.rundir import write_json
    from orchestrator.experiments.families import resolve

    if args.time_scale is not None and not (math.isfinite(args.time_scale)
                                            and args.time_scale > 0):
        raise BadInput(f"--time-scale: must be > 0, got {args.time_scale}")
    scenario = resolve(args.setup, agents=args.agents, seed=args.seed,
                       start_jitter_m=args.start_jitter_m, planner=args.planner)
    faults = fault_plan(args, scenario)
    planner = planner_label(scenario)
    out_dir = Path(args.out) if args.out else default_out_dir(scenario, planner, args.seed)
    if (out_dir / "trajectory.csv").exists() or (out_dir / "metrics.json").exists():
        raise BadInput(f"--out: {out_dir} already holds a run; choose another directory")
    out_dir.mkdir(parents=True, exist_ok=True)
    label = f"{scenario.name} {planner} {args.mode}"
    write_json(out_dir / "run.json", {
        "setup": args.setup, "scenario": scenario.name, "planner": planner,
        "seed": args.seed, "mode": args.mode, "agents": len(scenario.robots),
        "start_jitter_m": args.start_jitter_m, "time_scale": args.time_scale,
        "faults": faults.to_json() if faults is not None else None,
        "started": dt.datetime.now().isoformat(timespec="seconds"),
        "argv": list(args.argv),
    })
    progress = ProgressLine(label, quiet=args.quiet)
    wall0 = time.monotonic()
    try:
        if args.mode == "lockstep":
            from orchestrator.experiments.lockstep import run_lockstep

            outcome = run_lockstep(scenario, out_dir, on_progress=progress, faults=faults)
            metrics = outcome.metrics
            world_status = None
        else:
            metrics, world_status = _run_distributed(scenario, out_dir, args, progress, faults)
    finally:
        progress.done()
    wall_s = time.monotonic() - wall0
    if metrics is None:
        print(f"error: the distributed run left no trajectory (world exit status "
              f"{world_status}); see {out_dir}/world.log", file=sys.stderr)
        print(out_dir)
        return ExitCode.WORLD_LOST
    content = metrics.to_json_dict()
    write_run_plots(out_dir, gif=args.gif)
    if not args.quiet:
        print(run_summary(content, label))
        print(f"\nwall time {wall_s:.1f} s")
    print(out_dir)
    if world_status is not None and world_status not in RUN_ENDINGS:
        print(f"error: the world exited with status {world_status}; see {out_dir}/world.log",
              file=sys.stderr)
        return ExitCode.WORLD_LOST
    end = end_event(out_dir)
    return ExitCode.of_run(contacts=int(content.get("contacts") or 0),
                           all_arrived=content.get("arrived") == content.get("robots"),
                           robots_lost=bool(end.get("lost")),
                           interrupted=end.get("reason") == "signal")


def _run_distributed(scenario: Scenario, out_dir: Path, args: argparse.Namespace,
                     progress: ProgressLine, faults: Any = None) -> tuple[Any, int]:
    """Run the real processes; (metrics or None, the world's exit status)."""
    from orchestrator.experiments.distributed import run_scenario_distributed

    return run_scenario_distributed(scenario, out_dir, args.seed,
                                    time_scale=args.time_scale or 1.0,
                                    on_progress=progress, faults=faults)
