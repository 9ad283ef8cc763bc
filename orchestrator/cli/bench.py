"""`orchestrator bench`: planning time per cycle, by stage, per planner and crowd size."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

from agent.core.config import PLANNER_NAMES
from agent.flags import positive_int, robot_counts
from orchestrator.experiments.bench import (
    DEFAULT_CYCLES,
    bench_scenario,
    format_rows,
    run_bench,
    summarize,
)


def _planners(text: str) -> list[str]:
    names = list(PLANNER_NAMES) if text.strip() == "all" else \
        [x.strip() for x in text.split(",") if x.strip()]
    bad = [x for x in names if x not in PLANNER_NAMES]
    if not names or bad:
        raise argparse.ArgumentTypeError(
            f"expected 'all' or names from {', '.join(PLANNER_NAMES)}, got {text!r}")
    return names


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "bench", help="planning time per cycle by stage, per planner and crowd size",
        description="Wall time of the planning cycle (RobotController.plan) per planner and "
                    "crowd size: N robots converging on the centre of a circle.")
    parser.add_argument("--planner", type=_planners, required=True,
                        help="a planner, a comma-separated list, or 'all'")
    parser.add_argument("--robots", type=robot_counts, required=True,
                        help="robot count, or a comma-separated list (e.g. 2,8,16,32,64)")
    parser.add_argument("--cycles", type=positive_int, default=DEFAULT_CYCLES,
                        help=f"planning cycles to time per row (default {DEFAULT_CYCLES})")
    parser.add_argument("--seed", type=int, default=0, help="seeds the start jitter")
    parser.add_argument("--json", action="store_true",
                        help="also print one JSON object per row; the last line is the "
                             "row (one row) or {\"rows\": [...]}")
    parser.set_defaults(func=run)


def _json_safe(row: dict) -> dict:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in row.items()}


def run(args: argparse.Namespace) -> int:
    """Entry point of `orchestrator bench`; returns the exit status."""
    rows = []
    for planner in args.planner:
        for n in args.robots:
            wall0 = time.perf_counter()
            samples = run_bench(planner, n, args.cycles, args.seed)
            wall_s = time.perf_counter() - wall0
            row = summarize(planner, n, samples, seed=args.seed, wall_s=wall_s,
                            scenario=bench_scenario(n, planner))
            rows.append(row)
            print(f"bench {planner} N={n}: {row['cycles']} cycles, p50 "
                  f"{row['plan_ms_p50']:.3f} ms, p99 {row['plan_ms_p99']:.3f} ms wall; CPU "
                  f"p50 {row['cpu_ms_p50']:.3f} ms, p99 {row['cpu_ms_p99']:.3f} ms "
                  f"({wall_s:.1f} s)", file=sys.stderr, flush=True)
    print(format_rows(rows))
    if args.json:
        safe = [_json_safe(r) for r in rows]
        for row in safe:
            print(json.dumps(row))
        if len(safe) > 1:
            print(json.dumps({"rows": safe}))
    return 0
