"""`orchestrator bench`: planning time per cycle, by stage, per planner and crowd size."""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from agent.core.config import PLANNER_NAMES
from agent.flags import non_negative_int, positive, positive_int, robot_counts, shelf_rows
from orchestrator.cli.common import BadInput, make_dir
from orchestrator.experiments.bench import (
    DEFAULT_CYCLES,
    bench_scenario,
    format_rows,
    run_bench,
    summarize,
)
from orchestrator.experiments.route_bench import format_route_rows, time_route_graphs


def _planners(text: str) -> list[str]:
    names = list(PLANNER_NAMES) if text.strip() == "all" else \
        [x.strip() for x in text.split(",") if x.strip()]
    bad = [x for x in names if x not in PLANNER_NAMES]
    if not names or bad:
        raise argparse.ArgumentTypeError(
            f"expected 'all' or names from {', '.join(PLANNER_NAMES)}, got {text!r}")
    return names


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = sub.add_parser(
        "bench", help="planning time per cycle by stage, per planner and crowd size; "
                      "--process: a robot process's own CPU per cycle",
        description="Wall and CPU time of the planning cycle (RobotController.plan) per "
                    "planner and crowd size: N robots converging on the centre of a circle. "
                    "With --process: N real robot processes that sense and command a stop "
                    "without planning, and the CPU each spends per cycle, by part. With "
                    "--floor: the same for N clients that only receive the poses and send "
                    "a command (the transport's floor).")
    parser.add_argument("--planner", type=_planners, default=None,
                        help="a planner, a comma-separated list, or 'all' (required unless "
                             "--process)")
    parser.add_argument("--robots", type=robot_counts, default=None,
                        help="robot count, or a comma-separated list (e.g. 2,8,16,32,64); "
                             "required unless --routes")
    parser.add_argument("--routes", type=shelf_rows, default=None, metavar="ROWS",
                        help="instead: the time to build the route graph of a walled hall "
                             "with this many shelf rows (a comma-separated list; 2 rows: "
                             "about 100 discs, 26: about 500)")
    parser.add_argument("--process", action="store_true",
                        help="run N robot processes and a world for real (orchestrator scale "
                             "--no-plan) and print the CPU a robot process spends per cycle")
    parser.add_argument("--floor", action="store_true",
                        help="the transport's floor: N Zenoh clients that do a robot's I/O "
                             "and nothing else, and the CPU each spends per cycle "
                             "(compare with --process)")
    parser.add_argument("--seconds", type=positive, default=None,
                        help="with --process or --floor: length of each run [s] (default 20)")
    parser.add_argument("--out", type=Path, default=None,
                        help="with --process: run directory (default: a new temporary one)")
    parser.add_argument("--insecure", action="store_true",
                        help="with --process: plain TCP (default: mutual TLS and access "
                             "control, as orchestrator run)")
    parser.add_argument("--cycles", type=positive_int, default=DEFAULT_CYCLES,
                        help=f"planning cycles to time per row (default {DEFAULT_CYCLES})")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="seeds the start jitter")
    parser.add_argument("--json", action="store_true",
                        help="also print one JSON object per row; the last line is the "
                             "row (one row) or {\"rows\": [...]}")
    parser.set_defaults(func=run)


def _json_safe(row: dict[str, Any]) -> dict[str, Any]:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in row.items()}


def run(args: argparse.Namespace) -> int:
    """Entry point of `orchestrator bench`; returns the exit status."""
    if args.routes is not None:
        rows = time_route_graphs(args.routes)
        print(format_route_rows(rows))
        if args.json:
            print(json.dumps({"rows": rows}))
        return 0
    if args.robots is None:
        raise BadInput("orchestrator bench: --robots is required (or --routes)")
    if args.floor:
        return run_floor_bench(args)
    if args.process:
        return run_process(args)
    if args.planner is None:
        raise BadInput("orchestrator bench: --planner is required (or --process)")
    if args.seconds is not None or args.out is not None or args.insecure:
        raise BadInput("orchestrator bench: --seconds, --out and --insecure go with --process")
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


def run_floor_bench(args: argparse.Namespace) -> int:
    """`orchestrator bench --floor`: the CPU per cycle of a Zenoh client that does a robot's
    I/O and nothing else (`orchestrator.experiments.transport_floor`), per robot count."""
    from dataclasses import asdict

    from orchestrator.experiments.scale import PROCESS_BENCH_SECONDS
    from orchestrator.experiments.transport_floor import format_floor_row, run_floor

    if args.process or args.planner is not None or args.out is not None or args.insecure:
        raise BadInput("orchestrator bench --floor: goes with --robots and --seconds only "
                       "(no --process, --planner, --out or --insecure)")
    seconds = args.seconds or PROCESS_BENCH_SECONDS
    rows = []
    for n in args.robots:
        print(f"bench --floor: {n} clients, {seconds:g} s ...", file=sys.stderr, flush=True)
        row = run_floor(n, seconds)
        rows.append(asdict(row))
        print(format_floor_row(row))
    if args.json:
        print(json.dumps(rows[0] if len(rows) == 1 else {"rows": rows}))
    return 0


def run_process(args: argparse.Namespace) -> int:
    """`orchestrator bench --process`: one real run per robot count (`orchestrator scale
    --no-plan`, cut at --seconds) and the CPU per cycle of a robot process, by part."""
    from orchestrator.experiments.scale import (
        PROCESS_BENCH_SECONDS,
        format_process_row,
        process_bench_args,
        run_one,
        write_outputs,
    )

    if args.planner is not None:
        raise BadInput("orchestrator bench --process: the robots do not plan; no --planner")
    seconds = args.seconds or PROCESS_BENCH_SECONDS
    out_root = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench-process-"))
    make_dir(out_root)
    argv = ["orchestrator", *getattr(args, "argv", [])]
    rows = []
    for n in args.robots:
        print(f"bench --process: {n} robots, {seconds:g} s ...", file=sys.stderr, flush=True)
        row = run_one(n, process_bench_args(n, seconds, insecure=args.insecure, argv=argv),
                      out_root)
        row["transport"] = "plain TCP" if args.insecure else "TLS"
        rows.append(row)
        print(format_process_row(row))
    for path in write_outputs(rows, out_root, argv):
        print(path)
    if args.json:
        safe = [_json_safe(r) for r in rows]
        print(json.dumps(safe[0] if len(safe) == 1 else {"rows": safe}))
    return 0
