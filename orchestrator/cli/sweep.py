"""`orchestrator sweep`: setups x planners x seeds, one `orchestrator run` each."""

from __future__ import annotations

import argparse
import concurrent.futures
import csv
import itertools
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agent.core.config import PLANNER_NAMES, PROFILES
from agent.process import ExitCode
from orchestrator.analysis.rundir import safe_name
from orchestrator.cli.common import (
    JITTER_HELP,
    MODES,
    BadInput,
    make_dir,
    split_list,
    start_jitter_m,
)

SWEEP_RUN_TIMEOUT_S = 4 * 3600.0
"""Wall time after which one run of a sweep is abandoned."""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("sweep", help="many runs: setups x planners x seeds")
    p.add_argument("--profile", choices=PROFILES, default=None,
                   help="planner configuration: default, paper (the paper\'s method as "
                        "written) or lanes (the default with lanes in corridors, "
                        "docs/method.md); default: the scenario\'s own")
    p.add_argument("--setups", required=True, help="comma-separated names, or 'all' (A-G)")
    p.add_argument("--planners", required=True, help="comma-separated names, or 'all'")
    p.add_argument("--seeds", type=int, default=1, help="seeds 0..N-1 (default 1)")
    p.add_argument("--mode", choices=MODES, default="distributed")
    p.add_argument("--jobs", type=int, default=1, help="runs at a time (default 1)")
    p.add_argument("--agents", type=int)
    p.add_argument("--start-jitter-m", type=float, default=None, help=JITTER_HELP)
    p.add_argument("--time-scale", type=float, default=None)
    p.add_argument("--out", required=True)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from orchestrator.analysis.report import format_table
    from orchestrator.analysis.rundir import read_json, write_json

    out = Path(args.out)
    jobs = _jobs(args, out)
    make_dir(out / "logs")
    print(f"sweep: {len(jobs)} runs, {args.jobs} at a time, into {out}", file=sys.stderr)

    def launch(job: _Job) -> tuple[_Job, int, float]:
        t0 = time.monotonic()
        with open(out / "logs" / f"{job.name}.log", "w") as f:
            try:
                rc = subprocess.run(job.cmd, stdout=f, stderr=subprocess.STDOUT,
                                    timeout=SWEEP_RUN_TIMEOUT_S, check=False).returncode
            except subprocess.TimeoutExpired:
                # Killed by the sweep, not broken: an interruption, said so in its log.
                f.write(f"\nsweep: stopped this run after {SWEEP_RUN_TIMEOUT_S:.0f} s wall\n")
                rc = ExitCode.INTERRUPTED
        return job, rc, time.monotonic() - t0

    results = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        for job, rc, wall in pool.map(launch, jobs):
            results.append(_row(job, rc, wall, read_json(out / job.name / "metrics.json")))
            print(f"  {job.name}: exit {rc} ({wall:.1f} s)", file=sys.stderr)
    header = list(results[0])
    print(format_table(header[:-1], [[r[h] for h in header[:-1]] for r in results]))
    with open(out / "sweep.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=header)
        writer.writeheader()
        writer.writerows(results)
    write_json(out / "sweep.json", {"args": {k: v for k, v in vars(args).items()
                                             if k not in ("func", "argv")},
                                    "runs": results})
    print(f"\n{out}  (orchestrator report {out} [--paper])")
    worst = ExitCode.worst(r["exit"] for r in results)
    if worst != ExitCode.OK:
        runs = [r["dir"] for r in results if ExitCode.worst([r["exit"]]) == worst]
        print(f"sweep: exit {int(worst)} ({worst.name}), the worst ending of its runs: "
              f"{', '.join(runs[:5])}{' ...' if len(runs) > 5 else ''} (logs in "
              f"{out / 'logs'})", file=sys.stderr)
    return worst


@dataclass(frozen=True)
class _Job:
    """One run of the sweep: its setup, planner and seed, its directory name, its command."""

    setup: str
    planner: str
    seed: int
    name: str
    cmd: list[str]


def _jobs(args: argparse.Namespace, out: Path) -> list[_Job]:
    """Every run of the sweep; raises `BadInput` before any starts (every scenario resolves)."""
    from orchestrator.experiments.families import SETUPS, resolve

    setups = list(SETUPS) if args.setups == "all" else split_list(args.setups)
    planners = list(PLANNER_NAMES) if args.planners == "all" else split_list(args.planners)
    if not setups or not planners:
        raise BadInput("--setups and --planners must name at least one each")
    if args.seeds < 1:
        raise BadInput(f"--seeds: must be >= 1, got {args.seeds}")
    if args.jobs < 1:
        raise BadInput(f"--jobs: must be >= 1, got {args.jobs}")
    for setup, planner in itertools.product(setups, planners):  # fail before starting
        resolve(setup, agents=args.agents, seed=1, planner=planner, profile=args.profile,
                start_jitter_m=start_jitter_m(setup, 1, args.start_jitter_m, agents=args.agents))
    options = []
    if args.start_jitter_m is not None:  # else each run's default for its seed
        options += ["--start-jitter-m", repr(args.start_jitter_m)]
    if args.agents is not None:
        options += ["--agents", str(args.agents)]
    if args.time_scale is not None:
        options += ["--time-scale", repr(args.time_scale)]
    if args.profile is not None:
        options += ["--profile", args.profile]
    jobs = []
    for setup, planner, seed in itertools.product(setups, planners, range(args.seeds)):
        name = f"{safe_name(setup)}-{planner}-{seed}"
        cmd = [sys.executable, "-m", "orchestrator", "run", setup, "--planner", planner,
               "--seed", str(seed), "--mode", args.mode, "--out", str(out / name), "--quiet",
               *options]
        jobs.append(_Job(setup, planner, seed, name, cmd))
    return jobs


def _row(job: _Job, rc: int, wall_s: float, m: dict[str, Any]) -> dict[str, Any]:
    """sweep.csv's row of one finished run (`m`: its metrics.json, empty if none)."""
    return {
        "setup": job.setup, "planner": job.planner, "seed": job.seed, "exit": rc,
        "success": m.get("success"), "arrived": m.get("arrived"),
        "robots": m.get("robots"), "contacts": m.get("contacts"),
        "min_gap_m": m.get("min_gap_m"),
        "oscillations_per_robot": m.get("oscillations_per_robot"),
        "path_length_mean_m": m.get("path_length_mean_m"),
        "time_to_goal_mean_s": m.get("time_to_goal_mean_s"),
        "plan_ms_mean": m.get("plan_ms_mean"), "plan_ms_p99": m.get("plan_ms_p99"),
        "wall_s": round(wall_s, 2), "dir": job.name,
    }
