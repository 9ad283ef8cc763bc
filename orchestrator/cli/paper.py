"""`orchestrator paper`: the paper's Table I reproduced in the paper profile, beside the
paper's figures, as a table and a plot."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

from agent.flags import positive_int
from agent.process import ExitCode
from orchestrator.analysis.plots import plot_report_bars
from orchestrator.analysis.report import (
    ALL_METRICS,
    PAPER_METRICS,
    aggregate,
    collect,
    format_table,
    paper_table,
    write_stats_csv,
)
from orchestrator.analysis.rundir import write_json
from orchestrator.cli.common import BadInput, make_dir, split_list
from orchestrator.experiments import stress
from orchestrator.experiments.paper import (
    DEFAULT_SEEDS,
    DEFAULT_START_JITTER_M,
    PAPER_PLANNERS,
    PAPER_SETUPS,
    QUICK_SEEDS,
    QUICK_SETUPS,
    paper_jobs,
    shape_checks,
)


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "paper", help="the paper's Table I: A-G x seeds for IFP, eIFP, eIFP-MPC, paper profile",
        description="Run setups A-G for IFP, eIFP and eIFP-MPC exactly as the paper writes "
                    "them (--profile paper), lockstep, and print the means beside the "
                    "paper's Table I.")
    p.add_argument("--seeds", type=positive_int, default=None,
                   help=f"seeds 0..N-1 per setup and planner (default {DEFAULT_SEEDS}; "
                        f"--quick: {QUICK_SEEDS})")
    p.add_argument("--setups", default=None,
                   help="comma-separated setups (default: all seven; --quick: "
                        f"{','.join(QUICK_SETUPS)})")
    p.add_argument("--start-jitter-m", type=float, default=DEFAULT_START_JITTER_M,
                   help="start jitter (default 0.05: breaks setup A's exact mirror symmetry)")
    p.add_argument("--jobs", type=positive_int, default=1, help="runs at a time (default 1)")
    p.add_argument("--quick", action="store_true", help="a small check (two setups, 2 seeds)")
    p.add_argument("--out", default="runs/paper", help="output directory (default runs/paper)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    setups = (split_list(args.setups) if args.setups
              else list(QUICK_SETUPS if args.quick else PAPER_SETUPS))
    bad = [s for s in setups if s not in PAPER_SETUPS]
    if bad or not setups:
        raise BadInput(f"--setups: unknown {bad} (known: {', '.join(PAPER_SETUPS)})")
    seeds = args.seeds or (QUICK_SEEDS if args.quick else DEFAULT_SEEDS)
    if not (math.isfinite(args.start_jitter_m) and args.start_jitter_m >= 0):
        raise BadInput(f"--start-jitter-m: must be >= 0, got {args.start_jitter_m}")
    out = Path(args.out)
    make_dir(out)
    jobs = paper_jobs(out / "runs", setups=setups, seeds=seeds,
                      start_jitter_m=args.start_jitter_m)
    print(f"paper: {len(jobs)} lockstep runs (paper profile), {args.jobs} at a time, "
          f"into {out}", file=sys.stderr)
    t0 = time.monotonic()
    done = [0]

    def on_done(row: dict[str, Any]) -> None:
        done[0] += 1
        print(f"  [{done[0]}/{len(jobs)}] {row['dir']}: success {row.get('success')} "
              f"({row['wall_s']:.1f} s)" + (f" ERROR {row['error']}" if row.get("error") else ""),
              file=sys.stderr)

    rows = stress.run_jobs(jobs, args.jobs, on_done)
    stats = aggregate(collect([out / "runs"]), ALL_METRICS)
    table = paper_table(stats)
    checks = shape_checks(stats)
    shape = format_table(
        ["setup", "all succeed", "osc IFP", "osc eIFP", "osc eIFP-MPC", "eIFP-MPC <= eIFP <= IFP"],
        [[c.setup, "yes" if c.all_succeeded else "no",
          *(f"{c.oscillations[p]:.2f}" for p in PAPER_PLANNERS), "yes" if c.ordered else "no"]
         for c in checks])
    print(table)
    print("\nexpected shape (100 % success; oscillations eIFP-MPC <= eIFP <= IFP):")
    print(shape)
    (out / "table.txt").write_text(table + "\n\n" + shape + "\n", encoding="utf-8")
    write_stats_csv(out / "table.csv", stats)
    bar_stats = {k: {m: (v[0], v[1]) for m, v in s.items()} for k, s in stats.items()}
    plots = plot_report_bars(bar_stats, PAPER_METRICS, out, prefix="paper")
    write_json(out / "paper.json", {
        "argv": ["orchestrator", *args.argv], "seeds": seeds, "setups": setups,
        "start_jitter_m": args.start_jitter_m, "wall_s": round(time.monotonic() - t0, 1),
        "rows": rows,
        "shape": [{"setup": c.setup, "all_succeeded": c.all_succeeded, "ordered": c.ordered,
                   "oscillations": {p: _finite(v) for p, v in c.oscillations.items()}}
                  for c in checks]})
    print(f"\n{out / 'table.txt'}, {out / 'table.csv'}, {out / 'paper.json'}, "
          f"{', '.join(str(p) for p in plots[-1:])}")
    return ExitCode.ERROR if any(r.get("error") for r in rows) else ExitCode.OK


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None
