"""The benchmark suite (`orchestrator benchmark`): planners side by side on scenarios the
default planner was never tuned on.

The suite is a frozen list of cases (a family and a robot count, or a paper setup), run
for every chosen planner and seed. Seeds come in two disjoint named sets:
`EVALUATION_SEEDS`, which the suite reports on by default, and `TUNING_SEEDS`, which is
what anyone tuning a planner against the suite should use (`--seeds tuning`), so the
reported figures never come from the seeds a parameter was chosen on. A seed draws the
seeded families (`circle_mixed`, `random_*`, `obstacles_circle`, and of the liveness
families the doorway offsets, corridor lanes, pillar, platoon offset, speeds and the odd
grids' leaving robot) and, for every case, a start jitter of up to `START_JITTER_M` (the
deterministic families and the setups would otherwise repeat one run exactly; lockstep
runs are deterministic).

Each run is an ordinary run directory (`orchestrator report` reads it), lockstep by
default or distributed (`experiments.distributed.run_scenario_distributed`, the path of
`orchestrator run`). The table has one row per case and planner, aggregated over seeds
from the runs' `metrics.json` (`summarize`): per-robot figures (reversals, time and path
ratios) as median, 95th percentile (and maximum) over every robot of every run, and the
issue-39 targets the row misses (`target_misses`).
"""

from __future__ import annotations

import csv
import datetime as dt
import math
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, SupportsFloat, TypeGuard

import numpy as np

from agent.core.scenario import Scenario
from orchestrator.analysis.rundir import (
    end_event,
    numerics_cpu,
    numerics_versions,
    run_ending,
    safe_name,
    write_json,
)
from orchestrator.experiments.families import SETUPS, resolve
from orchestrator.experiments.scenario_blocks import ideal_time_s
from orchestrator.experiments.seeds import EVALUATION_SEEDS as EVALUATION_SEEDS
from orchestrator.experiments.seeds import QUICK_SEEDS as QUICK_SEEDS
from orchestrator.experiments.seeds import TUNING_SEEDS as TUNING_SEEDS
from orchestrator.experiments.seeds import parse_seeds as parse_seeds

if TYPE_CHECKING:
    from orchestrator.analysis.metrics import RunMetrics

START_JITTER_M = 0.2
"""Every run's starts are moved by up to this much, drawn from the seed."""
DEFAULT_PLANNERS: tuple[str, ...] = ("eifp-mpc", "orca")
MODES = ("lockstep", "distributed")


@dataclass(frozen=True)
class Case:
    """One scenario of the suite.

    Args:
        family: the family it belongs to (`--families` selects by it; "setups" for A-G).
        scenario: what `families.resolve` takes (a family or setup name).
        agents: robot count (None: the setup's own size).
    """

    family: str
    scenario: str
    agents: int | None = None

    @property
    def label(self) -> str:
        """The row name: `circle_24`, `crossing_90_16`, `setup_a`."""
        return self.scenario if self.agents is None else f"{self.scenario}_{self.agents}"


def _cases(family: str, sizes: Iterable[int]) -> tuple[Case, ...]:
    return tuple(Case(family, family, n) for n in sizes)


SUITE: tuple[Case, ...] = (
    *_cases("circle", (8, 16, 24, 32, 48)),
    *_cases("circle_mixed", (16, 32)),
    *_cases("crossing_45", (16,)),
    *_cases("crossing_90", (16,)),
    *_cases("crossing_135", (16,)),
    *_cases("swap_pairs", (6, 12)),
    *_cases("swap_grid", (4, 16)),
    *_cases("random_sparse", (20,)),
    *_cases("random_medium", (20,)),
    *_cases("random_dense", (20,)),
    *_cases("obstacles_circle", (12, 24)),
    *_cases("wall_door", (12,)),
    *_cases("wall_doors", (16,)),
    *_cases("corridor", (8,)),
    *_cases("grid_dense", (16, 25)),
    *_cases("pillar_circle", (24, 40)),
    *_cases("random_40", (40,)),
    *_cases("platoons", (18,)),
    *_cases("crossing_60_mixed", (16,)),
    *(Case("setups", name) for name in SETUPS),
)
"""The full suite, in table order."""

QUICK_SUITE: tuple[Case, ...] = (
    Case("setups", "setup_a"),
    *_cases("circle", (8,)),
    *_cases("circle_mixed", (8,)),
    *_cases("crossing_90", (8,)),
    *_cases("swap_pairs", (4,)),
    *_cases("swap_grid", (4,)),
    *_cases("random_dense", (8,)),
    *_cases("obstacles_circle", (8,)),
    *_cases("wall_door", (6,)),
    *_cases("corridor", (4,)),
)
"""`--quick`: small cases, for CI and a first look."""

STRUCTURED_SUITE: tuple[Case, ...] = (
    *_cases("rooms", (10,)),
    *_cases("evacuate", (18,)),
    *_cases("cross_corridors", (12,)),
    *_cases("dead_end", (6,)),
    *_cases("parking", (12,)),
    *_cases("pocket", (6,)),
    *_cases("random_walls", (14,)),
)
"""Structured scenes (`structured_families`): not part of `SUITE` (``--families all``), run
by name or as ``--families structured``; a held-out check of the liveness rules."""

LIVENESS_FAMILIES: tuple[str, ...] = ("wall_door", "wall_doors", "corridor", "grid_dense",
                                      "pillar_circle", "random_40", "platoons",
                                      "crossing_60_mixed")
"""The families of issue 39 (`liveness_families`)."""

FAMILY_ALIASES: dict[str, tuple[str, ...]] = {
    "crossing": ("crossing_45", "crossing_90", "crossing_135", "crossing_60_mixed"),
    "random": ("random_sparse", "random_medium", "random_dense", "random_40"),
    "swap": ("swap_pairs", "swap_grid"),
    "walls": ("wall_door", "wall_doors", "corridor"),
    "liveness": LIVENESS_FAMILIES,
    "structured": tuple(c.family for c in STRUCTURED_SUITE),
}
"""`--families` names that stand for several families."""


def family_names(cases: Sequence[Case] = SUITE) -> tuple[str, ...]:
    """The families of `cases`, in order."""
    return tuple(dict.fromkeys(c.family for c in cases))


def select_cases(cases: Sequence[Case], families: str | Sequence[str]) -> tuple[Case, ...]:
    """The cases whose family (or setup name, or label) is named; "all" keeps every case.

    Raises:
        ValueError: a name that selects no case of `cases`.
    """
    names = [families] if isinstance(families, str) else list(families)
    if names == ["all"]:
        return tuple(cases)
    wanted: set[str] = set()
    for name in names:
        expanded = FAMILY_ALIASES.get(name, (name,))
        if not any(c.family in expanded or c.scenario in expanded or c.label in expanded
                   for c in cases):
            known = ", ".join((*family_names(cases), *FAMILY_ALIASES))
            raise ValueError(f"--families: {name!r} selects no case; expected 'all' or "
                             f"some of {known}")
        wanted.update(expanded)
    return tuple(c for c in cases if wanted & {c.family, c.scenario, c.label})


# --------------------------------------------------------------------------------------
# Runs
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Job:
    """One run of the suite: a case, a planner and a seed, into `out_dir`."""

    case: Case
    planner: str
    seed: int
    mode: str
    out_dir: Path
    time_scale: float = 1.0
    without: str | None = None

    @property
    def name(self) -> str:
        return f"{safe_name(self.case.label)}-{self.planner}-s{self.seed}"

    def scenario(self) -> Scenario:
        return resolve(self.case.scenario, agents=self.case.agents, seed=self.seed,
                       start_jitter_m=START_JITTER_M, planner=self.planner,
                       without=self.without)


def plan_jobs(cases: Sequence[Case], planners: Sequence[str], seeds: Sequence[int], *,
              mode: str, out: Path, time_scale: float = 1.0,
              without: str | None = None) -> list[Job]:
    """Every (case, planner, seed), run directories `out/runs/<case>-<planner>-s<seed>`;
    `without`: mechanisms switched off in every run (`PlannerConfig.without`)."""
    return [Job(case, planner, seed, mode, Path(out) / "runs" /
                f"{safe_name(case.label)}-{planner}-s{seed}", time_scale, without)
            for case in cases for planner in planners for seed in seeds]


def job_cost(job: Job) -> float:
    """A rough cost for ordering (robots x time limit): the largest runs start first."""
    s = job.scenario()
    return len(s.robots) * s.time_limit_s


RECORD_METRICS = ("robots", "arrived", "success", "contacts", "min_gap_m",
                  "min_gap_robots_m", "min_gap_obstacles_m",
                  "oscillations_per_robot", "oscillations_max", "path_ratio_mean",
                  "time_ratio_mean", "plan_ms_p50", "plan_ms_p99", "sim_time_s",
                  "time_limit_s")
"""The `metrics.json` keys a run record keeps (plus `PER_ROBOT_METRICS`)."""
PER_ROBOT_METRICS = (("robot_oscillations", "oscillations"),
                     ("robot_time_ratios", "time_ratio"),
                     ("robot_path_ratios", "path_ratio"))
"""(record key, `metrics.json` per-robot key): lists with one value per robot (None for a
ratio of a robot that did not arrive)."""


def run_record(job: Job, metrics: dict[str, Any] | None, *, wall_s: float,
               ideal_s: float | None = None, world_status: int | None = None,
               error: str | None = None) -> dict[str, Any]:
    """One run's row of `benchmark.json` (`runs`): what `summarize` aggregates."""
    m = metrics or {}
    record: dict[str, Any] = {
        "family": job.case.family, "case": job.case.label, "planner": job.planner,
        "seed": job.seed, "mode": job.mode, "dir": str(job.out_dir),
        **{k: m.get(k) for k in RECORD_METRICS},
        **{key: [r.get(field) for r in m.get("per_robot") or []]
           for key, field in PER_ROBOT_METRICS},
        "ideal_time_s": ideal_s, "wall_s": round(wall_s, 3),
        "world_status": world_status, "error": error,
    }
    if metrics is None and error is None:
        record["error"] = f"no metrics (world exit status {world_status})"
    return record


def run_job(job: Job) -> dict[str, Any]:
    """Run one job into its run directory and return its record (errors are recorded)."""
    t0 = time.perf_counter()
    try:
        scenario = job.scenario()
        out_dir = Path(job.out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        write_json(out_dir / "run.json", {
            "setup": job.case.label, "scenario": scenario.name, "planner": job.planner,
            "seed": job.seed, "mode": job.mode, "agents": len(scenario.robots),
            "start_jitter_m": START_JITTER_M, "benchmark_family": job.case.family,
            "time_scale": job.time_scale if job.mode == "distributed" else None,
            "started": dt.datetime.now().isoformat(timespec="seconds"),
            "versions": numerics_versions(), "cpu": numerics_cpu(),
        })
        status = None
        metrics: RunMetrics | None
        if job.mode == "lockstep":
            from orchestrator.experiments.lockstep import run_lockstep

            metrics = run_lockstep(scenario, out_dir).metrics
        else:
            from orchestrator.experiments.distributed import run_scenario_distributed

            metrics, status = run_scenario_distributed(scenario, out_dir, job.seed,
                                                       time_scale=job.time_scale)
        content = metrics.to_json_dict() if metrics is not None else None
        record = run_record(job, content, wall_s=time.perf_counter() - t0,
                            ideal_s=ideal_time_s(scenario.robots), world_status=status)
        record["exit"] = int(run_ending(content, end_event(out_dir)).exit_code)
        return record
    except Exception as exc:  # noqa: BLE001 - one broken run must not end the suite
        traceback.print_exc()  # the ERROR exit of the suite points here
        record = run_record(job, None, wall_s=time.perf_counter() - t0,
                            error=f"{type(exc).__name__}: {exc}")
        record["exit"] = 7  # agent.process.ExitCode.ERROR
        return record


def run_jobs(jobs: Sequence[Job], *, workers: int = 1,
             on_done: Callable[[int, dict[str, Any]], None] | None = None
             ) -> list[dict[str, Any]]:
    """Run the jobs, `workers` at a time (a process pool for > 1); records in job order.

    The largest jobs (`job_cost`) start first so the pool does not end on one long run.
    `on_done(count so far, record)` is called as each run finishes.
    """
    order = sorted(range(len(jobs)), key=lambda k: -job_cost(jobs[k]))
    records: list[dict[str, Any] | None] = [None] * len(jobs)
    if workers <= 1:
        for done, k in enumerate(order, 1):
            record = run_job(jobs[k])
            records[k] = record
            if on_done is not None:
                on_done(done, record)
    else:
        import concurrent.futures
        import multiprocessing

        # spawn: the workers start clean (no inherited threads or Zenoh state).
        ctx = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(max_workers=workers,
                                                    mp_context=ctx) as pool:
            futures = {pool.submit(run_job, jobs[k]): k for k in order}
            for done, fut in enumerate(concurrent.futures.as_completed(futures), 1):
                k = futures[fut]
                record = fut.result()
                records[k] = record
                if on_done is not None:
                    on_done(done, record)
    return [r for r in records if r is not None]


# --------------------------------------------------------------------------------------
# The table
# --------------------------------------------------------------------------------------

COLUMNS: tuple[tuple[str, str], ...] = (
    ("case", "family"), ("planner", "planner"), ("runs", "runs"),
    ("success_rate", "success"), ("arrived_rate", "arrived"), ("contacts", "contacts"),
    ("min_gap_robots_m", "gap r-r m"), ("min_gap_obstacles_m", "gap r-o m"),
    ("osc_per_robot_median", "osc/robot p50"), ("osc_per_robot_p95", "osc/robot p95"),
    ("osc_per_robot_max", "osc/robot max"), ("time_ratio_median", "time ratio p50"),
    ("time_ratio_p95", "time ratio p95"), ("path_ratio_median", "path ratio p50"),
    ("path_ratio_p95", "path ratio p95"), ("plan_ms_p50", "plan ms p50"),
    ("plan_ms_p99", "plan ms p99"), ("targets", "targets"),
)
"""(row key, column header) of the table, in order. Rows also keep `min_gap_m`,
`path_ratio_mean` and `time_ratio_mean` (benchmark.json, the plot and the README summary)."""

TABLE_NOTES = (
    "success: share of runs in which every robot arrived with no contact; arrived: share "
    "of robots that arrived; contacts: contact episodes summed over the runs; gap r-r and "
    "r-o: the smallest robot-robot and robot-obstacle gap over the runs (negative: "
    "overlap; '-': no such pair); osc/robot p50, p95 and max: median, 95th percentile and "
    "largest reversal count of one robot, over every robot of every run; time ratio and "
    "path ratio p50 and p95: the same over every robot that arrived (time ratio: time to "
    "goal over straight distance / own v_max; path ratio: path length over straight "
    "distance); plan ms p50: median of the runs' p50, p99: largest of the runs' p99; "
    "targets: the issue-39 targets the row misses (`Targets`), or ok.")


@dataclass(frozen=True)
class Targets:
    """The targets of issue 39 for the default planner, checked per table row.

    Args:
        arrived_rate: share of robots that arrive.
        contacts: contact episodes at most.
        min_gap_m: robot-robot and robot-obstacle clearance at least [m].
        osc_median, osc_median_open: median reversals per robot at most (open: the
            `OPEN_FAMILIES`).
        osc_p95: 95th percentile of reversals per robot at most.
        time_ratio_median, time_ratio_median_confined: median time ratio per robot at most
            (confined: the `CONFINED_FAMILIES`).
        path_ratio_median: median path ratio per robot at most.
        reference_time_factor: where the planner and `REFERENCE_PLANNER` both succeed in
            every run, its median time ratio at most this times the reference's.
    """

    arrived_rate: float = 1.0
    contacts: int = 0
    min_gap_m: float = 0.05
    osc_median: float = 3.0
    osc_median_open: float = 2.0
    osc_p95: float = 6.0
    time_ratio_median: float = 1.3
    time_ratio_median_confined: float = 1.5
    path_ratio_median: float = 1.15
    reference_time_factor: float = 1.2


TARGETS = Targets()
OPEN_FAMILIES: tuple[str, ...] = ("circle", "circle_mixed", "circles", "crossing",
                                  "crossing4", "crossing_45", "crossing_90", "crossing_135",
                                  "crossing_60_mixed", "setups")
"""Open circles and crossings (no obstacles, not a grid): the stricter reversal target."""
CONFINED_FAMILIES: tuple[str, ...] = ("grid_dense", "swap_grid", "wall_door", "wall_doors",
                                      "corridor")
"""Grids, doorways and the corridor: the looser time-ratio target."""
REFERENCE_PLANNER = "orca"
"""The planner every other one must succeed wherever it succeeds (and be nearly as fast)."""


def target_misses(row: dict[str, Any], reference: dict[str, Any] | None = None,
                  targets: Targets = TARGETS) -> list[str]:
    """The targets a `summarize` row misses, each as a short phrase ("osc p50 5 > 3").

    Args:
        row: a table row (its family picks the reversal and time-ratio targets).
        reference: the `REFERENCE_PLANNER`'s row of the same case, if any.
        targets: the limits.

    A figure that does not exist (no robot arrived, no obstacle) is not checked against
    its target; not arriving is a miss of its own.
    """
    misses: list[str] = []

    def above(label: str, value: float | None, limit: float, fmt: str = ".2f") -> None:
        if value is not None and value > limit + 1e-9:
            misses.append(f"{label} {value:{fmt}} > {limit:g}")

    if row.get("errors"):
        misses.append(f"errors {row['errors']}")
    arrived = row.get("arrived_rate")
    if arrived is None or arrived < targets.arrived_rate:
        misses.append("arrived " + ("-" if arrived is None else f"{100.0 * arrived:.0f} %"))
    if (row.get("contacts") or 0) > targets.contacts:
        misses.append(f"contacts {row['contacts']}")
    gaps = [("gap r-r", row.get("min_gap_robots_m")), ("gap r-o", row.get("min_gap_obstacles_m"))]
    if all(v is None for _, v in gaps):  # records without the split: the overall gap
        gaps = [("gap", row.get("min_gap_m"))]
    for label, gap in gaps:
        if gap is not None and gap < targets.min_gap_m:
            misses.append(f"{label} {gap:.3f} < {targets.min_gap_m:g}")
    family = row.get("family")
    above("osc p50", row.get("osc_per_robot_median"),
          targets.osc_median_open if family in OPEN_FAMILIES else targets.osc_median, "g")
    above("osc p95", row.get("osc_per_robot_p95"), targets.osc_p95, "g")
    above("time p50", row.get("time_ratio_median"),
          targets.time_ratio_median_confined if family in CONFINED_FAMILIES
          else targets.time_ratio_median)
    above("path p50", row.get("path_ratio_median"), targets.path_ratio_median)
    if reference is not None:
        ours, theirs = row.get("success_rate") or 0.0, reference.get("success_rate") or 0.0
        if ours < theirs:
            misses.append(f"success {100.0 * ours:.0f} % < {reference['planner']} "
                          f"{100.0 * theirs:.0f} %")
        t_ours, t_theirs = row.get("time_ratio_median"), reference.get("time_ratio_median")
        if ours == theirs == 1.0 and t_ours is not None and t_theirs:
            above(f"time vs {reference['planner']}", t_ours / t_theirs,
                  targets.reference_time_factor)
    return misses


def _is_number(value: object) -> TypeGuard[int | float]:
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value))


def _values(records: Iterable[dict[str, Any]], key: str) -> np.ndarray:
    return np.array([float(r[key]) for r in records if _is_number(r.get(key))], dtype=float)


def _per_robot(records: Iterable[dict[str, Any]], key: str,
               fallback: Sequence[str]) -> np.ndarray:
    """Every robot's value of the per-robot list `key` (`PER_ROBOT_METRICS`) over the
    runs, leaving out values that do not exist (a ratio of a robot that did not arrive).
    A record without the list (an older one) contributes its run figures `fallback`."""
    out: list[float] = []
    for r in records:
        values = r.get(key) or [r.get(k) for k in fallback]
        out += [float(v) for v in values if _is_number(v)]
    return np.array(out, dtype=float)


def _stat(values: np.ndarray, fn: Callable[[np.ndarray], SupportsFloat]) -> float | None:
    return float(fn(values)) if values.size else None


def _p95(values: np.ndarray) -> float:
    return float(np.percentile(values, 95))


def summarize(records: Sequence[dict[str, Any]],
              case_order: Sequence[str] | None = None,
              planner_order: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """One row per (case, planner) over its seeds (`COLUMNS`, `TABLE_NOTES`).

    A run that failed to produce metrics counts as a run without success (and adds to
    `errors`). Rows follow `case_order` then `planner_order` (else first appearance).
    Each row's `target_misses` (and `targets`, the cell) come from `target_misses`, with
    the `REFERENCE_PLANNER`'s row of the same case as the reference.
    """
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in records:
        groups.setdefault((r["case"], r["planner"]), []).append(r)
    cases = list(case_order or dict.fromkeys(r["case"] for r in records))
    planners = list(planner_order or dict.fromkeys(r["planner"] for r in records))
    rows = []
    for case in cases:
        for planner in planners:
            runs = groups.get((case, planner))
            if not runs:
                continue
            ok = [r for r in runs if r.get("error") is None]
            osc = _per_robot(ok, "robot_oscillations",
                             ("oscillations_per_robot", "oscillations_max"))
            time_ratio = _per_robot(ok, "robot_time_ratios", ("time_ratio_mean",))
            path_ratio = _per_robot(ok, "robot_path_ratios", ("path_ratio_mean",))
            robots = _values(ok, "robots").sum()
            rows.append({
                "family": runs[0]["family"], "case": case, "planner": planner,
                "runs": len(runs),
                "success_rate": sum(1 for r in ok if r.get("success") is True) / len(runs),
                "arrived_rate": (float(_values(ok, "arrived").sum() / robots)
                                 if robots else None),
                "contacts": int(_values(ok, "contacts").sum()),
                "min_gap_m": _stat(_values(ok, "min_gap_m"), np.min),
                "min_gap_robots_m": _stat(_values(ok, "min_gap_robots_m"), np.min),
                "min_gap_obstacles_m": _stat(_values(ok, "min_gap_obstacles_m"), np.min),
                "osc_per_robot_median": _stat(osc, np.median),
                "osc_per_robot_p95": _stat(osc, _p95),
                "osc_per_robot_max": _stat(osc, np.max),
                "time_ratio_median": _stat(time_ratio, np.median),
                "time_ratio_p95": _stat(time_ratio, _p95),
                "path_ratio_median": _stat(path_ratio, np.median),
                "path_ratio_p95": _stat(path_ratio, _p95),
                "path_ratio_mean": _stat(_values(ok, "path_ratio_mean"), np.mean),
                "time_ratio_mean": _stat(_values(ok, "time_ratio_mean"), np.mean),
                "plan_ms_p50": _stat(_values(ok, "plan_ms_p50"), np.median),
                "plan_ms_p99": _stat(_values(ok, "plan_ms_p99"), np.max),
                "errors": len(runs) - len(ok),
                "seeds": [r["seed"] for r in runs],
            })
    by = {(r["case"], r["planner"]): r for r in rows}
    for row in rows:
        reference = (by.get((row["case"], REFERENCE_PLANNER))
                     if row["planner"] != REFERENCE_PLANNER else None)
        row["target_misses"] = target_misses(row, reference)
        row["targets"] = "; ".join(row["target_misses"]) or "ok"
    return rows


def _cell(key: str, value: Any) -> str:
    if value is None:
        return "-"
    if key in ("success_rate", "arrived_rate"):
        return f"{100.0 * value:.0f} %"
    if isinstance(value, float):
        if key.startswith("osc_per_robot"):
            return f"{value:g}"
        if key.startswith("min_gap"):
            return f"{value:.3f}"
        return f"{value:.2f}"
    return str(value)


def table_cells(rows: Sequence[dict[str, Any]]) -> tuple[list[str], list[list[str]]]:
    """(headers, cells) of the table, formatted."""
    return ([h for _, h in COLUMNS],
            [[_cell(k, r.get(k)) for k, _ in COLUMNS] for r in rows])


def format_text(rows: Sequence[dict[str, Any]]) -> str:
    """The table as padded plain text (stdout)."""
    from orchestrator.analysis.report import format_table

    header, cells = table_cells(rows)
    return format_table(header, cells)


def format_markdown(rows: Sequence[dict[str, Any]], *, caption: str = "") -> str:
    """The table as GitHub markdown (with the notes below it), for a README verbatim."""
    header, cells = table_cells(rows)
    right = [k not in ("case", "planner") for k, _ in COLUMNS]
    lines = ["| " + " | ".join(header) + " |",
             "|" + "|".join("---:" if r else "---" for r in right) + "|"]
    lines += ["| " + " | ".join(c) + " |" for c in cells]
    text = "\n".join(lines) + "\n\n" + TABLE_NOTES + "\n"
    return (caption + "\n\n" + text) if caption else text


def write_outputs(out: Path, rows: Sequence[dict[str, Any]],
                  records: Sequence[dict[str, Any]], suite: dict[str, Any]) -> list[Path]:
    """benchmark.csv, benchmark.json, benchmark.md and benchmark.png under `out`."""
    from orchestrator.analysis.plots import plot_benchmark

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "benchmark.csv"
    keys = [k for k, _ in COLUMNS] + ["family", "errors"]
    with open(csv_path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    json_path = write_json(out / "benchmark.json",
                           {"suite": suite, "notes": TABLE_NOTES, "rows": list(rows),
                            "runs": list(records)})
    seeds = ", ".join(str(s) for s in suite.get("seeds", ()))
    caption = (f"`orchestrator benchmark` ({suite.get('mode')}, seeds {seeds} "
               f"[{suite.get('seed_set')}], start jitter {START_JITTER_M:g} m)")
    md_path = out / "benchmark.md"
    md_path.write_text(format_markdown(rows, caption=caption))
    png_path = plot_benchmark(rows, out / "benchmark.png", title=caption.replace("`", ""))
    return [csv_path, json_path, md_path, png_path]


RESULTS_BEGIN = "<!-- results:begin -->"
RESULTS_END = "<!-- results:end -->"


def replace_results(text: str, table_md: str, command: str) -> str:
    """`text` (a README) with the part between `RESULTS_BEGIN` and `RESULTS_END` replaced by
    `table_md` and the command that made it.

    Raises:
        ValueError: the markers are missing or out of order.
    """
    start, end = text.find(RESULTS_BEGIN), text.find(RESULTS_END)
    if start < 0 or end < start:
        raise ValueError(f"expected {RESULTS_BEGIN} ... {RESULTS_END} in the file")
    body = f"{RESULTS_BEGIN}\nGenerated by `{command}`:\n\n{table_md.strip()}\n"
    return text[:start] + body + text[end:]


LOCAL_OPTIONS = ("--out", "--readme")
"""Options whose values name places on the machine that ran the benchmark, not the suite."""


def portable_command(argv: Sequence[str]) -> str:
    """The ``orchestrator`` command line of `argv` without `LOCAL_OPTIONS` (given as
    ``--out DIR`` or ``--out=DIR``), so the README names what was run, not where it was
    written."""
    kept: list[str] = []
    skip = False
    for arg in argv:
        if skip:
            skip = False
        elif arg in LOCAL_OPTIONS:
            skip = True
        elif not arg.startswith(tuple(f"{o}=" for o in LOCAL_OPTIONS)):
            kept.append(arg)
    return " ".join(["orchestrator", *kept])


README_GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("antipodal circles (8-48)", ("circle",)),
    ("circles, mixed radii and speeds", ("circle_mixed",)),
    ("cohort crossings (45/90/135 deg)", ("crossing_45", "crossing_90", "crossing_135")),
    ("pair and grid swaps", ("swap_pairs", "swap_grid")),
    ("random starts and goals", ("random_sparse", "random_medium", "random_dense")),
    ("circles around obstacles", ("obstacles_circle",)),
    ("walls with doorways, a corridor", ("wall_door", "wall_doors", "corridor")),
    ("dense grids (2.6-3 m)", ("grid_dense",)),
    ("circles round a pillar", ("pillar_circle",)),
    ("random, 40 robots in 36 m", ("random_40",)),
    ("platoons head-on", ("platoons",)),
    ("crossing at 60 deg, mixed speeds", ("crossing_60_mixed",)),
    ("setups A-G", ("setups",)),
)
"""How the README's summary groups the benchmark's families."""


def format_readme_summary(rows: Sequence[dict[str, Any]]) -> str:
    """A short markdown table for the README: one row per `README_GROUPS` group, every
    planner side by side: success (runs), contacts, the median and worst oscillations per
    robot over the group's cases, and the mean time ratio. The full table is benchmark.md.
    """
    planners = list(dict.fromkeys(r["planner"] for r in rows))
    header = ["scenarios"] + [f"{p}: success, contacts, osc/robot median (worst), time ratio"
                              for p in planners]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label, families in README_GROUPS:
        cells = [label]
        for planner in planners:
            sel = [r for r in rows if r["planner"] == planner and r["family"] in families]
            if not sel:
                cells.append("-")
                continue
            runs = sum(int(r["runs"]) for r in sel)
            ok = sum(round(float(r["success_rate"]) * int(r["runs"])) for r in sel)
            contacts = sum(int(r["contacts"] or 0) for r in sel)
            med = [float(r["osc_per_robot_median"]) for r in sel
                   if r.get("osc_per_robot_median") is not None]
            worst = [float(r["osc_per_robot_max"]) for r in sel
                     if r.get("osc_per_robot_max") is not None]
            times = [float(r["time_ratio_mean"]) for r in sel
                     if r.get("time_ratio_mean") is not None]
            osc = (f"{float(np.median(med)):g} ({max(worst):g})" if med and worst else "-")
            time_ratio = f"{float(np.mean(times)):.2f}" if times else "-"
            cells.append(f"{ok}/{runs}, {contacts}, {osc}, {time_ratio}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
