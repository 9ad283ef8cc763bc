"""`orchestrator scale`: real-time distributed runs of N robot processes: cost per robot."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from agent.core.config import PLANNER_NAMES
from agent.flags import non_negative_int, positive, robot_counts
from orchestrator.cli.common import BadInput, add_tls_args, make_dir, tls_ca
from orchestrator.experiments.scale import (
    DEFAULT_FAMILY,
    FAMILIES,
    ROBOT_NICE,
    _fmt,
    format_rows,
    run_one,
    write_outputs,
)
from orchestrator.experiments.world_bench import (
    format_world_rows,
    world_tick_costs,
    write_world_outputs,
)


def _hosts(text: str) -> list[str]:
    hosts = [x.strip() for x in text.split(",") if x.strip()]
    if not hosts:
        raise argparse.ArgumentTypeError(f"expected addresses, got {text!r}")
    return hosts


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = sub.add_parser(
        "scale", help="real-time runs of N robot processes: timing, CPU, memory per robot",
        description="Real-time distributed runs of N robot processes: timing, CPU, memory, "
                    "start-up, safety per N.")
    parser.add_argument("--agents", type=robot_counts, required=True,
                        help="robot counts, comma-separated (e.g. 16,32,64,128)")
    parser.add_argument("--family", choices=FAMILIES, default=DEFAULT_FAMILY,
                        help=f"scenario family (default {DEFAULT_FAMILY})")
    parser.add_argument("--planner", choices=PLANNER_NAMES, default=None,
                        help="every robot uses this planner (default: the family's, eifp-mpc)")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="seeds the random family")
    parser.add_argument("--time-scale", type=positive, default=1.0,
                        help="sim seconds per wall second (default 1: real time)")
    parser.add_argument("--hosts", type=_hosts, default=["127.0.0.1"],
                        help="addresses of the world robots connect through, round robin "
                             "(e.g. 127.0.0.1,127.0.0.2; default 127.0.0.1)")
    parser.add_argument("--launcher", choices=("fork", "spawn"), default="fork",
                        help="fork: one agent.fleet process imports once and forks every "
                             "robot process (default); spawn: one python -m agent each")
    parser.add_argument("--robot-nice", type=int, choices=range(0, 20), default=ROBOT_NICE,
                        metavar="N", help="with --launcher fork: robots run N steps nicer "
                        f"than the world (default {ROBOT_NICE})")
    parser.add_argument("--cpu-tokens", type=int, default=None, metavar="N",
                        help="with --launcher fork: robots computing at once (default: no "
                             "tokens; see agent.fleet)")
    parser.add_argument("--startup-timeout-s", type=positive, default=60.0,
                        help="deadline for every robot to be alive (default 60)")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--json", action="store_true",
                        help="also print {\"rows\": [...]} as the last line")
    parser.add_argument("--no-plan", action="store_true",
                        help="robots sense and command a stop every cycle without planning: "
                             "the CPU columns are then the process's own cost per cycle")
    parser.add_argument("--seconds", type=positive, default=None,
                        help="end every run after this much sim time (default: the "
                             "scenario's time limit)")
    parser.add_argument("--world-bench", action="store_true",
                        help="instead of runs: time the world's per-tick work in-process for "
                             "each N (no processes, no transport); writes world_bench.json "
                             "and world_bench.png, the per-robot cost against N")
    parser.add_argument("--router-link", action="store_true",
                        help="instead of runs of the family: robots split between two hosts' "
                             "routers; bytes crossing the link between them per N, with host "
                             "B's robots near the border, far from it, and without a relay "
                             "(docs/scale.md; --seconds defaults to 12)")
    parser.add_argument("--ticks", type=int, default=500,
                        help="ticks timed per N with --world-bench (default 500)")
    add_tls_args(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Entry point of `orchestrator scale`; returns 0 (figures), 2 for bad arguments."""
    argv = ["orchestrator", *args.argv]
    if args.insecure and list(args.hosts) != ["127.0.0.1"]:
        raise BadInput("--hosts listens on every interface (0.0.0.0): not with --insecure, "
                       "only with TLS and the run's access control")
    if args.world_bench and args.router_link:
        raise BadInput("--world-bench and --router-link are separate benchmarks: one at a time")
    args.tls_ca_dir = tls_ca(args)
    out_root = Path(args.out)
    make_dir(out_root)
    if args.world_bench:
        rows = [world_tick_costs(n, max(1, args.ticks), out_root / f"world_{n}")
                for n in args.agents]
        print(format_world_rows(rows))
        for path in write_world_outputs(rows, out_root, argv):
            print(path)
        if args.json:
            print(json.dumps({"rows": rows}))
        return 0
    if args.router_link:
        from orchestrator.analysis.rundir import write_json
        from orchestrator.experiments.router_link import format_link_rows, run_router_link

        if args.insecure:
            raise BadInput("--router-link: the routers' access control needs TLS; "
                           "not with --insecure")
        try:
            rows = run_router_link(args, out_root)
        except ValueError as exc:
            raise BadInput(str(exc)) from exc
        print(f"time scale {args.time_scale:g} (sim s per wall s); kB per sim second")
        print(format_link_rows(rows))
        print(write_json(out_root / "router_link.json", {"argv": argv, "rows": rows}))
        if args.json:
            print(json.dumps({"rows": rows}))
        return 0
    env_note = os.environ.get("ZENOH_RUNTIME")
    if env_note:
        print(f"ZENOH_RUNTIME={env_note}", file=sys.stderr)
    rows = []
    for n in args.agents:
        print(f"scale: {args.family} N={n} ...", file=sys.stderr, flush=True)
        row = run_one(n, args, out_root)
        rows.append(row)
        print(f"scale: N={n}: success {row['success']}, miss rate "
              f"{_fmt(row['deadline_miss_rate'], 4)}, latency p99 "
              f"{_fmt(row['sim_latency_ms_p99'], 1)} ms, alive {_fmt(row['alive_s'], 1)} s, "
              f"PSS total {_fmt(row['mem_total_mib'], 0)} MiB, wall {row['wall_s']:.0f} s",
              file=sys.stderr, flush=True)
        write_outputs(rows, out_root, argv)  # after every N: a long sweep keeps its rows
    print(format_rows(rows))
    for path in write_outputs(rows, out_root, argv):
        print(path)
    if args.json:
        print(json.dumps({"rows": rows}))
    return 0
