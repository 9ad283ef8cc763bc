"""`orchestrator benchmark`: the planners side by side on the benchmark suite.

    orchestrator benchmark [--planners eifp-mpc,orca|all] [--families all|a,b,...]
                           [--seeds evaluation|tuning|N] [--mode lockstep|distributed]
                           [--jobs N] [--quick] [--out DIR]

Prints the table (one row per case and planner) and writes OUT/benchmark.csv, .json, .md
and .png; every run is a run directory under OUT/runs. Exit status 0 when every run
produced metrics (whatever the planners achieved), ERROR when a run broke.
"""

from __future__ import annotations

import argparse
import datetime as dt
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from agent.core.config import PLANNER_NAMES
from agent.process import ExitCode
from orchestrator.cli.common import DEFAULT_RUNS_DIR, BadInput, split_list

if TYPE_CHECKING:
    from orchestrator.experiments.benchmark import Case


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from orchestrator.experiments.benchmark import (
        DEFAULT_PLANNERS,
        EVALUATION_SEEDS,
        FAMILY_ALIASES,
        MODES,
        STRUCTURED_SUITE,
        TUNING_SEEDS,
        family_names,
    )

    p = sub.add_parser(
        "benchmark", help="planners side by side on the benchmark suite",
        description="Run the benchmark suite (families the planners were not tuned on, and "
                    "setups A-G) for each planner and seed; print one table and write "
                    "OUT/benchmark.{csv,json,md,png}.")
    p.add_argument("--planners", default=",".join(DEFAULT_PLANNERS),
                   help=f"comma-separated planners or 'all' (default "
                        f"{','.join(DEFAULT_PLANNERS)})")
    p.add_argument("--families", default="all",
                   help=f"comma-separated families or 'all': {', '.join(family_names())}; "
                        f"also {', '.join(FAMILY_ALIASES)} (several at once), a setup or a "
                        "case (circle_24); structured scenes, not in 'all': "
                        f"{', '.join(family_names(STRUCTURED_SUITE))}")
    p.add_argument("--seeds", default=None,
                   help=f"'evaluation' ({','.join(map(str, EVALUATION_SEEDS))}, the default), "
                        f"'tuning' ({','.join(map(str, TUNING_SEEDS))}: tune on these, "
                        "report on the others), N (seeds 0..N-1) or a list S1,S2,... of "
                        "either set; --quick: seed 0")
    p.add_argument("--mode", choices=MODES, default="lockstep",
                   help="lockstep (default) or distributed (one process per robot)")
    p.add_argument("--time-scale", type=float, default=1.0,
                   help="sim seconds per wall second (distributed mode; default 1)")
    p.add_argument("--jobs", type=int, default=1,
                   help="runs at a time (a process pool; default 1)")
    p.add_argument("--quick", action="store_true",
                   help="a handful of small cases (CI; about a minute for two planners)")
    p.add_argument("--without", default=None, metavar="LIST",
                   help="mechanisms of the default profile to switch off in every run, "
                        "comma-separated (an ablation; docs/method.md)")
    p.add_argument("--out", help="output directory (default runs/benchmark-<time>)")
    p.add_argument("--readme", type=Path, default=None, metavar="FILE",
                   help="also write the table into FILE between <!-- results:begin --> and "
                        "<!-- results:end --> (the README's Results section)")
    p.add_argument("--max-cases", type=int, default=None, help=argparse.SUPPRESS)
    p.set_defaults(func=run)


def _planners(text: str) -> list[str]:
    names = list(PLANNER_NAMES) if text.strip() == "all" else split_list(text)
    bad = [x for x in names if x not in PLANNER_NAMES]
    if not names or bad:
        raise BadInput(f"--planners: expected 'all' or names from {', '.join(PLANNER_NAMES)}, "
                       f"got {text!r}")
    return list(dict.fromkeys(names))


def run(args: argparse.Namespace) -> int:
    from orchestrator.experiments import benchmark as bm

    planners = _planners(args.planners)
    cases, seeds = _cases_and_seeds(args)
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else DEFAULT_RUNS_DIR / f"benchmark-{stamp}"
    jobs = bm.plan_jobs(cases, planners, seeds, mode=args.mode, out=out,
                        time_scale=args.time_scale, without=args.without)
    for job in jobs:  # fail before starting: every scenario resolves, no run is overwritten
        try:
            job.scenario()
        except ValueError as exc:
            raise BadInput(str(exc)) from None
        if (job.out_dir / "metrics.json").exists() or (job.out_dir / "trajectory.csv").exists():
            raise BadInput(f"--out: {job.out_dir} already holds a run; choose another "
                           "directory")
    seed_set = ("evaluation" if seeds == bm.EVALUATION_SEEDS else
                "tuning" if seeds == bm.TUNING_SEEDS else
                "quick" if seeds == bm.QUICK_SEEDS and args.seeds is None else "custom")
    print(f"benchmark: {len(cases)} cases x {len(planners)} planners x {len(seeds)} seeds "
          f"({seed_set}) = {len(jobs)} {args.mode} runs, {args.jobs} at a time, into {out}",
          file=sys.stderr, flush=True)
    wall0 = time.monotonic()

    def done(count: int, record: dict[str, Any]) -> None:
        print(f"  [{count}/{len(jobs)}] {_outcome(record)}", file=sys.stderr, flush=True)

    records = bm.run_jobs(jobs, workers=args.jobs, on_done=done)
    wall_s = time.monotonic() - wall0
    rows = bm.summarize(records, case_order=[c.label for c in cases], planner_order=planners)
    suite = {"cases": [c.label for c in cases], "planners": planners, "seeds": list(seeds),
             "seed_set": seed_set, "mode": args.mode, "without": args.without or "",
             "quick": args.quick,
             "jobs": args.jobs, "start_jitter_m": bm.START_JITTER_M,
             "wall_s": round(wall_s, 1), "argv": list(getattr(args, "argv", []))}
    paths = bm.write_outputs(out, rows, records, suite)
    if args.readme is not None:
        _update_readme(args.readme, rows, getattr(args, "argv", []))
        paths.append(args.readme)
    print(bm.format_text(rows))
    print()
    print(bm.TABLE_NOTES)
    print(f"\n{len(jobs)} runs in {wall_s:.1f} s wall; wrote " +
          ", ".join(str(p) for p in paths))
    return _worst_ending(records)


def _cases_and_seeds(args: argparse.Namespace) -> tuple[tuple[Case, ...], tuple[int, ...]]:
    """The suite's cases (``--families``, ``--quick``, ``--max-cases``) and the seeds; raises
    `BadInput` for any argument out of range."""
    from orchestrator.experiments import benchmark as bm

    try:
        seeds = bm.parse_seeds(args.seeds, quick=args.quick)
        families = ["all"] if args.families.strip() == "all" else split_list(args.families)
        # 'all' is the suite; a name may also pick the structured scenes, outside it
        cases = bm.select_cases(bm.QUICK_SUITE if args.quick else bm.SUITE, families) \
            if args.quick or families == ["all"] else \
            bm.select_cases((*bm.SUITE, *bm.STRUCTURED_SUITE), families)
    except ValueError as exc:
        raise BadInput(str(exc)) from None
    if args.max_cases is not None:
        if args.max_cases < 1:
            raise BadInput(f"--max-cases: must be >= 1, got {args.max_cases}")
        cases = cases[:args.max_cases]
    if args.jobs < 1:
        raise BadInput(f"--jobs: must be >= 1, got {args.jobs}")
    if not args.time_scale > 0:
        raise BadInput(f"--time-scale: must be > 0, got {args.time_scale}")
    return cases, seeds


def _outcome(record: dict[str, Any]) -> str:
    """One finished run, as the progress line names it."""
    what = (f"error: {record['error']}" if record.get("error") else
            f"success {'yes' if record.get('success') else 'no'}, arrived "
            f"{record.get('arrived')}/{record.get('robots')}, contacts "
            f"{record.get('contacts')}")
    return (f"{record['case']} {record['planner']} s{record['seed']}: {what} "
            f"({record['wall_s']:.1f} s)")


def _update_readme(readme: Path, rows: list[dict[str, Any]], argv: list[str]) -> None:
    """Replace the README's results table with this benchmark's (``--readme``)."""
    from orchestrator.experiments import benchmark as bm

    try:
        text = readme.read_text(encoding="utf-8")
        table = (bm.format_readme_summary(rows) + "\nEvery case, seed and column: "
                 "[docs/results.md](docs/results.md) (`benchmark.md` of the run).\n")
        readme.write_text(bm.replace_results(text, table, bm.portable_command(argv)),
                          encoding="utf-8")
    except (OSError, ValueError) as exc:
        raise BadInput(f"--readme: {readme}: {exc}") from None


def _worst_ending(records: list[dict[str, Any]]) -> ExitCode:
    """Report the runs that broke; the worst ending of the runs (`ExitCode.worst`)."""
    for r in records:
        if r.get("error"):
            print(f"error: {r['case']} {r['planner']} s{r['seed']}: {r['error']} ({r['dir']})",
                  file=sys.stderr)
    worst = ExitCode.worst(r.get("exit", ExitCode.ERROR) for r in records)
    if worst != ExitCode.OK:
        print(f"benchmark: exit {int(worst)} ({worst.name}), the worst ending of its runs",
              file=sys.stderr)
    return worst
