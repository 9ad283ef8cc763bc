"""`orchestrator report`: mean +- std over seeds per setup and planner, tables and plots."""

from __future__ import annotations

import argparse
import datetime as dt
import math
from pathlib import Path
from typing import TYPE_CHECKING

from agent.process import ExitCode
from orchestrator.cli.common import (
    DEFAULT_RUNS_DIR,
    BadInput,
    make_dir,
)

if TYPE_CHECKING:
    from orchestrator.analysis.compare import Difference
    from orchestrator.analysis.report import EncounterRates, RunRecord


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("report", help="mean ± std over seeds per setup and planner, plots")
    p.add_argument("dirs", nargs="+", help="run or sweep directories")
    p.add_argument("--paper", action="store_true", help="print the paper's Table I beside ours")
    p.add_argument("--out", help="where plots and tables go (default: the one DIR; with "
                                 "several, runs/report-<time>, under the git-ignored runs/)")
    p.add_argument("--by-dir", action="store_true",
                   help="one row per setup, planner and DIR (compare variants of one setup "
                        "kept in different directories); default: runs are pooled by setup "
                        "and planner")
    p.add_argument("--compare", action="store_true",
                   help="exactly two DIRs, BASE VARIANT: pair their runs by case, planner and "
                        "seed and print each metric's mean difference (VARIANT - BASE) with "
                        "a 95 %% bootstrap interval, per case and overall "
                        "(orchestrator.analysis.compare)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.compare:
        return run_compare(args)
    from orchestrator.analysis.plots import plot_report_bars
    from orchestrator.analysis.report import (
        ALL_METRICS,
        PAPER_METRICS,
        aggregate,
        encounter_rates,
        identical_runs,
        paper_table,
        reversal_causes,
        reversal_table,
        summary_table,
        write_stats_csv,
    )

    paths = [Path(p) for p in args.dirs]
    records, partial = _complete_runs(paths, by_dir=args.by_dir)
    stats = aggregate(records, ALL_METRICS)
    print(f"{len(records)} runs")
    print(summary_table(stats))
    same = identical_runs(records)
    for (setup, planner), (distinct, n) in same.items():
        print(f"warning: {setup} {planner}: {n} runs but only {distinct} distinct "
              f"trajectories (byte-identical trajectory.csv): their seeds changed nothing, so "
              f"± is not a spread over seeds (give --start-jitter-m or link faults)")
    causes = reversal_causes(records)
    encounters = encounter_rates(records)
    if causes:
        print("\noscillations per robot by cause (README, \"Metrics\"):")
        print(reversal_table(causes, encounters))
    if args.paper:
        print()
        print(paper_table(stats))
    out = Path(args.out) if args.out else (paths[0] if len(paths) == 1 and paths[0].is_dir()
                                           else default_report_dir())
    make_dir(out)
    bar_stats = {k: {m: (v[0], v[1]) for m, v in s.items()} for k, s in stats.items()}
    written = plot_report_bars(bar_stats, PAPER_METRICS, out)
    _write_report_json(out / "report.json", records, partial, same, stats, causes, encounters)
    write_stats_csv(out / "report.csv", stats)
    print(f"\nplots: {', '.join(str(p) for p in written)}")
    print(f"tables: {out / 'report.csv'}, {out / 'report.json'}")
    return ExitCode.OK


def run_compare(args: argparse.Namespace) -> int:
    """`report --compare BASE VARIANT`: paired differences per case and overall."""
    from orchestrator.analysis.compare import (
        COMPARE_METRICS,
        compare,
        pair_runs,
    )
    from orchestrator.analysis.report import format_table

    if len(args.dirs) != 2 or args.paper or args.by_dir:
        raise BadInput("report --compare: give exactly two directories, BASE VARIANT "
                       "(without --paper or --by-dir)")
    sides = []
    for path in map(Path, args.dirs):
        records, _ = _complete_runs([path], by_dir=False)
        sides.append([((r.setup, r.planner, r.seed), r.metrics) for r in records])
    pairs, unmatched = pair_runs(sides[0], sides[1])
    if not pairs:
        raise BadInput(f"report --compare: no run of {args.dirs[1]} has a partner in "
                       f"{args.dirs[0]} (same case, planner and seed)")
    result = compare(pairs, unmatched)
    header = ["case", "planner", "pairs", *COMPARE_METRICS]
    rows = [[case, planner, diffs[COMPARE_METRICS[0]].pairs,
             *(_cell(diffs[m]) for m in COMPARE_METRICS)]
            for (case, planner), diffs in sorted(result.cases.items())]
    rows.append(["overall (cases weighted equally)", "", result.overall[COMPARE_METRICS[0]].pairs,
                 *(_cell(result.overall[m]) for m in COMPARE_METRICS)])
    print(f"{args.dirs[0]} -> {args.dirs[1]}: {sum(len(v) for v in pairs.values())} paired "
          f"runs, {unmatched} without a partner")
    print(format_table(header, rows))
    print("\nEach cell: BASE mean -> VARIANT mean (mean paired difference [95 % bootstrap "
          "interval]) and the verdict: lower / higher when the interval excludes 0, else "
          "within noise; too few below 3 pairs.")
    return ExitCode.OK


def _cell(d: Difference) -> str:
    """A difference and its verdict, for the table."""
    from orchestrator.analysis.compare import format_difference

    return f"{format_difference(d)} {d.verdict}" if d.pairs else "-"


def _complete_runs(paths: list[Path], *, by_dir: bool
                   ) -> tuple[list[RunRecord], list[RunRecord]]:
    """The run directories under `paths` with metrics.json, and the partial (interrupted)
    ones, which are named and left out; raises `BadInput` if no complete run is left."""
    from orchestrator.analysis.report import collect

    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise BadInput(f"report: no such directory: {', '.join(missing)}")
    records = collect(paths, by_dir=by_dir)
    if not records:
        raise BadInput(f"report: no run directories with metrics.json under "
                       f"{', '.join(map(str, paths))}")
    partial = [r for r in records if r.metrics.get("partial")]
    records = [r for r in records if not r.metrics.get("partial")]
    if partial:
        print(f"{len(partial)} partial runs (interrupted before their end; left out of the "
              f"means): {', '.join(str(r.path) for r in partial)}")
    if not records:
        raise BadInput("report: every run found is partial (interrupted)")
    return records, partial


def _write_report_json(path: Path, records: list[RunRecord], partial: list[RunRecord],
                       same: dict[tuple[str, str], tuple[int, int]],
                       stats: dict[tuple[str, str], dict[str, tuple[float, float, int]]],
                       causes: dict[tuple[str, str], dict[str, float]],
                       encounters: dict[tuple[str, str], EncounterRates]) -> None:
    """report.json: the runs, the partial ones, the identical ones and every group's stats,
    reversal causes and crossing encounters."""
    from orchestrator.analysis.rundir import write_json

    write_json(path, {
        "runs": [str(r.path) for r in records],
        "partial_runs": [str(r.path) for r in partial],
        "identical_runs": [{"setup": k[0], "planner": k[1], "distinct": d, "runs": n}
                           for k, (d, n) in same.items()],
        "groups": [{"setup": k[0], "planner": k[1],
                    **{m: {"mean": _finite(v[0]), "std": _finite(v[1]), "n": v[2]}
                       for m, v in s.items()},
                    "reversal_causes_per_robot": causes.get(k),
                    **_encounter_json(encounters.get(k))} for k, s in stats.items()],
    })


def _encounter_json(rates: EncounterRates | None) -> dict[str, float | None]:
    """A group's `encounters_per_robot` and `reversals_per_encounter` (None if unknown)."""
    if rates is None:
        return {"encounters_per_robot": None, "reversals_per_encounter": None}
    return {"encounters_per_robot": _finite(rates.encounters_per_robot),
            "reversals_per_encounter": _finite(rates.reversals_per_encounter)}


def default_report_dir() -> Path:
    """Where `report DIR DIR...` writes without ``--out``: a new directory under the
    git-ignored ``runs/``, never the current directory."""
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return DEFAULT_RUNS_DIR / f"report-{stamp}"


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None
