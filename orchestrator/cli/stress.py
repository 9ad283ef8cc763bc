"""`orchestrator stress`: fault levels x planners x seeds, the table and the safety envelope."""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path
from typing import Any

from agent.core.config import PLANNER_NAMES, PROFILES
from agent.flags import link_faults
from agent.process import ExitCode
from orchestrator.analysis.rundir import safe_name
from orchestrator.cli.common import (
    JITTER_HELP,
    MODES,
    BadInput,
    add_fault_args,
    fault_plan,
    make_dir,
    split_list,
    start_jitter_m,
)


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("stress", help="fault levels x planners x seeds: table and envelope")
    p.add_argument("--profile", choices=PROFILES, default=None,
                   help="planner configuration: default, paper (the paper\'s method as "
                        "written) or lanes (the default with lanes in corridors, "
                        "docs/method.md); default: the scenario\'s own")
    p.add_argument("setup", help="a setup, family or scenario file (as for run)")
    p.add_argument("--sweep", action="append", metavar="KEY=V1,V2,...",
                   help="latency_ms, jitter_ms, drop, dup or reorder; repeat for a grid")
    p.add_argument("--planners", default="all", help="comma-separated names, or 'all'")
    p.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 per level (default 3)")
    p.add_argument("--mode", choices=MODES, default="lockstep",
                   help="lockstep (default: deterministic, fast) or distributed")
    p.add_argument("--jobs", type=int, default=1, help="runs at a time (default 1)")
    p.add_argument("--jitter-frac", type=float, default=0.3,
                   help="jitter = this x latency unless jitter_ms is set (default 0.3)")
    p.add_argument("--agents", type=int)
    p.add_argument("--start-jitter-m", type=float, default=None, help=JITTER_HELP)
    p.add_argument("--time-scale", type=float, default=None)
    p.add_argument("--out", required=True)
    add_fault_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from orchestrator.analysis.report import format_table
    from orchestrator.analysis.rundir import write_json
    from orchestrator.experiments import stress
    from orchestrator.experiments.families import resolve

    planners = list(PLANNER_NAMES) if args.planners == "all" else split_list(args.planners)
    bad = [p for p in planners if p not in PLANNER_NAMES]
    if not planners or bad:
        raise BadInput(f"--planners: unknown {bad} (known: {', '.join(PLANNER_NAMES)})")
    if args.seeds < 1 or args.jobs < 1:
        raise BadInput("--seeds and --jobs must be >= 1")
    try:
        base = link_faults(args)
        # no --sweep: one level, the base faults as given (--latency-ms is not overridden)
        sweep = stress.parse_sweep(args.sweep or [f"latency_ms={args.latency_ms!r}"])
    except ValueError as exc:
        raise BadInput(str(exc)) from None
    for planner in planners:  # fail before starting
        scenario = resolve(args.setup, agents=args.agents, seed=0,
                           start_jitter_m=start_jitter_m(args.setup, 0, args.start_jitter_m),
                           planner=planner,
                           profile=args.profile)
    robot_faults = fault_plan(args, scenario, links=False)
    out = Path(args.out)
    make_dir(out)
    keys = list(sweep)
    jitter_m = {seed: start_jitter_m(args.setup, seed, args.start_jitter_m, agents=args.agents)
                for seed in range(args.seeds)}
    jobs = []
    for level, planner, seed in itertools.product(stress.levels(sweep), planners,
                                                  range(args.seeds)):
        links = stress.level_faults(level, base, args.jitter_frac)
        name = safe_name(f"{args.setup}-{planner}-{stress.level_name(level)}-s{seed}")
        jobs.append(stress.StressJob(
            setup=args.setup, planner=planner, seed=seed, level=tuple(level.items()),
            links=links, mode=args.mode, out_dir=str(out / name), agents=args.agents,
            start_jitter_m=jitter_m[seed],
            time_scale=args.time_scale or 1.0,
            compensate_latency=not args.no_latency_compensation, robot_faults=robot_faults,
            profile=args.profile))
    print(f"stress: {len(jobs)} runs ({args.mode}), {args.jobs} at a time, into {out}",
          file=sys.stderr)
    t0 = time.monotonic()
    done = [0]

    def on_done(row: dict[str, Any]) -> None:
        done[0] += 1
        print(f"  [{done[0]}/{len(jobs)}] {row['dir']}: contacts {row.get('contacts')} "
              f"success {row.get('success')} ({row['wall_s']:.1f} s)"
              + (f" ERROR {row['error']}" if row.get("error") else ""), file=sys.stderr)

    rows = stress.run_jobs(jobs, args.jobs, on_done)
    table = stress.aggregate(rows, keys)
    env = stress.envelope(table, keys)
    header = ["setup", "planner", *keys, "runs", "success_rate", "arrived_frac", "contacts",
              "runs_with_contact", "runs_incomplete", "min_gap_m", "time_ratio_mean"]
    print(f"\n{args.setup}, {args.mode}, jitter = {args.jitter_frac:g} x latency unless set, "
          f"seeds 0..{args.seeds - 1}")
    print(format_table(header, [[t[h] for h in header] for t in table]))
    env_header = ["setup", "planner", *[f"max_{k}" for k in keys]]
    print("\nlargest level at which every run arrived without contact (every seed, every "
          "smaller level too; '-': none):")
    print(format_table(env_header, [[e[h] for h in env_header] for e in env]))
    stress.write_csv(out / "stress.csv", rows)
    write_json(out / "stress.json", {
        "args": {k: v for k, v in vars(args).items() if k not in ("func",)},
        "wall_s": round(time.monotonic() - t0, 1), "rows": rows, "table": table,
        "envelope": env})
    print(f"\n{out / 'stress.csv'}, {out / 'stress.json'}")
    return ExitCode.worst(r.get("exit", ExitCode.ERROR) for r in rows)
