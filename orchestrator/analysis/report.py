"""Aggregating run directories: mean +- std over seeds per setup and planner, the paper's
Table I beside ours, and text tables (the CLI's `report` and `sweep` print these).
"""

from __future__ import annotations

import csv
import hashlib
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from orchestrator.analysis.rundir import find_run_dirs, read_json
from orchestrator.analysis.turns import REVERSAL_CAUSES
from world.scenario_file import ScenarioError, load_scenario

# The paper's four metrics (Table I, Fig. "plots"): key in metrics.json, label.
PAPER_METRICS: tuple[tuple[str, str], ...] = (
    ("plan_ms_mean", "planning time per cycle [ms]"),
    ("oscillations_per_robot", "oscillations per robot"),
    ("path_length_mean_m", "path length [m]"),
    ("time_to_goal_mean_s", "time to goal [s]"),
)
EXTRA_METRICS: tuple[tuple[str, str], ...] = (
    ("success", "success rate"),
    ("contacts", "contacts"),
    ("min_gap_m", "min gap [m]"),
    ("path_ratio_mean", "path / straight"),
    ("time_ratio_mean", "time / ideal"),
    ("side_flips_per_robot", "side flips per robot"),
    ("plan_ms_p99", "planning p99 [ms]"),
    ("sim_latency_ms_p50", "command age p50 [sim ms]"),
    ("wall_latency_ms.sense_to_act.p99", "sense to act p99 [wall ms]"),
    ("deadline_miss_rate", "deadline miss rate"),
)
ALL_METRICS = PAPER_METRICS + EXTRA_METRICS

# Table I of the paper: setup -> planner -> (planning ms, oscillations, path length, time to
# goal s). Path lengths are the paper's "cm" (grid units), which this project reads as
# metres. Rows are in the table's order A..G; the two 3-robot rows are taken as B then C.
PAPER_TABLE_I: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "setup_a": {"eifp": (6.711, 0.0, 39.85, 26.567), "eifp-mpc": (54.286, 0.0, 37.609, 29.202)},
    "setup_b": {"eifp": (8.447, 12.0, 39.633, 30.845),
                "eifp-mpc": (66.587, 23.667, 39.034, 31.620)},
    "setup_c": {"eifp": (13.137, 85.333, 41.867, 27.912),
                "eifp-mpc": (66.806, 12.0, 39.241, 34.343)},
    "setup_d": {"eifp": (13.127, 5.0, 39.947, 26.634),
                "eifp-mpc": (74.733, 12.75, 36.852, 37.353)},
    "setup_e": {"eifp": (24.529, 48.0, 51.664, 40.469),
                "eifp-mpc": (79.906, 11.6, 48.15, 65.642)},
    "setup_f": {"eifp": (69.922, 86.083, 81.77, 90.656),
                "eifp-mpc": (88.619, 9.667, 80.107, 197.496)},
    "setup_g": {"eifp": (44.784, 25.0, 80.789, 336.446),
                "eifp-mpc": (67.722, 14.25, 78.698, 502.260)},
}
PAPER_ROBOTS = {"setup_a": 2, "setup_b": 3, "setup_c": 3, "setup_d": 4, "setup_e": 5,
                "setup_f": 12, "setup_g": 16}


@dataclass(frozen=True)
class RunRecord:
    """One finished run: where, what, and its metrics.json."""

    path: Path
    setup: str
    planner: str
    seed: int | None
    mode: str
    metrics: dict[str, Any]


def collect(paths: Iterable[Path], by_dir: bool = False) -> list[RunRecord]:
    """Every run directory (holding metrics.json) at or below `paths`.

    Args:
        paths: run or sweep directories.
        by_dir: label each record's planner "planner [name of the path it was found
            under]", so that runs of the same setup and planner under different paths (two
            variants of one scenario, two commits) are aggregated apart. When two paths
            share a name (runs/a/x, runs/b/x) the labels use the paths as given.
    """
    if by_dir:
        paths = [Path(p) for p in paths]
        names = [p.name for p in paths]
        unique = len(set(names)) == len(names)
        return [replace(r, planner=f"{r.planner} [{p.name if unique else p}]")
                for p in paths for r in collect([p])]
    records = []
    for run_dir in find_run_dirs(paths):
        metrics = read_json(run_dir / "metrics.json")
        if not metrics:
            continue
        info = read_json(run_dir / "run.json")
        setup = info.get("scenario")
        planner = info.get("planner")
        if setup is None or planner is None:
            try:
                scenario = load_scenario(run_dir / "scenario.yaml")
            except ScenarioError:
                continue
            setup = setup or scenario.name
            names = sorted({r.planner for r in scenario.robots})
            planner = planner or (names[0] if len(names) == 1 else "mixed")
        seed = info.get("seed")
        records.append(RunRecord(run_dir, str(setup), str(planner),
                                 seed if isinstance(seed, int) else None,
                                 str(info.get("mode", "?")), metrics))
    return records


def identical_runs(records: Sequence[RunRecord]) -> dict[tuple[str, str], tuple[int, int]]:
    """Groups (setup, planner) of two or more runs whose ground truth repeats: runs that
    recorded byte-identical ``trajectory.csv`` files (seeds that changed nothing, e.g. a
    lockstep sweep of a fixed setup without start jitter or link faults).

    Returns:
        (setup, planner) -> (distinct trajectories, runs), for the groups with fewer
        distinct trajectories than runs; its std over such runs says nothing.
    """
    groups: dict[tuple[str, str], list[Path]] = {}
    for r in records:
        groups.setdefault((r.setup, r.planner), []).append(r.path / "trajectory.csv")
    out = {}
    for key in sorted(groups):
        files = [p for p in groups[key] if p.is_file()]
        if len(files) < 2:
            continue
        by_size: dict[int, list[Path]] = {}
        for p in files:
            by_size.setdefault(p.stat().st_size, []).append(p)
        # Only files of one size can be equal: hash those, not every file.
        distinct = sum(len({_digest(p) for p in same}) if len(same) > 1 else 1
                       for same in by_size.values())
        if distinct < len(files):
            out[key] = (distinct, len(files))
    return out


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _value(metrics: Mapping[str, Any], key: str) -> float:
    """`metrics[key]`, or a nested value named with dots (``wall_latency_ms.plan.p99``)."""
    v: Any = metrics
    for part in key.split("."):
        v = v.get(part) if isinstance(v, Mapping) else None
    if isinstance(v, bool):
        return float(v)
    return float(v) if isinstance(v, int | float) and math.isfinite(v) else math.nan


def aggregate(records: Sequence[RunRecord],
              metrics: Sequence[tuple[str, str]] = ALL_METRICS
              ) -> dict[tuple[str, str], dict[str, tuple[float, float, int]]]:
    """(setup, planner) -> metric -> (mean, std, runs with a value).

    std is the sample standard deviation (ddof = 1; 0 for a single run). Runs where a
    metric is undefined (e.g. time to goal when no robot arrived) are left out of it.
    """
    groups: dict[tuple[str, str], list[RunRecord]] = {}
    for r in records:
        groups.setdefault((r.setup, r.planner), []).append(r)
    out: dict[tuple[str, str], dict[str, tuple[float, float, int]]] = {}
    for key in sorted(groups):
        stats: dict[str, tuple[float, float, int]] = {}
        for name, _label in metrics:
            vals = np.array([_value(r.metrics, name) for r in groups[key]])
            vals = vals[np.isfinite(vals)]
            if vals.size:
                std = float(np.std(vals, ddof=1)) if vals.size > 1 else 0.0
                stats[name] = (float(vals.mean()), std, int(vals.size))
            else:
                stats[name] = (math.nan, math.nan, 0)
        stats["runs"] = (float(len(groups[key])), 0.0, len(groups[key]))
        out[key] = stats
    return out


def format_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A plain-text table, columns padded to their widest cell."""
    cells = [[str(h) for h in header]] + [[_cell(c) for c in row] for row in rows]
    widths = [max(len(r[k]) for r in cells) for k in range(len(header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return "-" if not math.isfinite(value) else f"{value:.3g}" if abs(value) < 1e-3 \
            else f"{value:.3f}".rstrip("0").rstrip(".") if abs(value) < 100 else f"{value:.1f}"
    return str(value)


def _pm(stat: tuple[float, float, int] | None) -> str:
    if stat is None or not math.isfinite(stat[0]):
        return "-"
    mean, std, n = stat
    return f"{_cell(mean)} ± {_cell(std)}" if n > 1 else _cell(mean)


def summary_table(stats: Mapping[tuple[str, str], Mapping[str, tuple[float, float, int]]]
                  ) -> str:
    """Mean ± std per setup and planner of the paper's metrics and the safety metrics."""
    keys = [k for k, _ in PAPER_METRICS] + ["success", "contacts", "min_gap_m",
                                            "wall_latency_ms.sense_to_act.p99"]
    header = ["setup", "planner", "runs", "plan ms", "osc/robot", "path m", "t_goal s",
              "success", "contacts", "min gap m", "sense->act p99 wall ms"]
    rows = [[setup, planner, int(s["runs"][2]), *(_pm(s.get(k)) for k in keys)]
            for (setup, planner), s in stats.items()]
    return format_table(header, rows)


def paper_table(stats: Mapping[tuple[str, str], Mapping[str, tuple[float, float, int]]]
                ) -> str:
    """The paper's Table I beside our means (paper path lengths in cm read as m)."""
    header = ["setup", "robots", "planner", "plan ms paper", "ours", "osc paper", "ours",
              "path paper", "ours m", "t_goal paper", "ours s"]
    rows = []
    for setup, by_planner in PAPER_TABLE_I.items():
        # The paper's planners first, then any other planner we ran on this setup (the
        # paper omits IFP, and has no ORCA).
        ours_only = sorted(p for s, p in stats if s == setup and p not in by_planner)
        for planner in (*by_planner, *ours_only):
            paper = by_planner.get(planner)
            ours = stats.get((setup, planner), {})
            row: list[Any] = [setup, PAPER_ROBOTS[setup], planner]
            for k, (key, _label) in enumerate(PAPER_METRICS):
                # The paper's digits, verbatim.
                row += [f"{paper[k]:g}" if paper else "-", _pm(ours.get(key))]
            rows.append(row)
    note = ("Paper: Table I (path length in the paper's cm, read as m here; the two "
            "3-robot rows taken as B then C). Ours: mean ± std over seeds.")
    return format_table(header, rows) + "\n" + note


def reversal_causes(records: Sequence[RunRecord]) -> dict[tuple[str, str], dict[str, float]]:
    """(setup, planner) -> cause -> oscillations per robot, mean over the runs whose
    metrics.json has `reversal_causes_per_robot` (runs written before it existed have
    not; `orchestrator.analysis.metrics`, "reversal causes")."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in records:
        causes = r.metrics.get("reversal_causes_per_robot")
        if isinstance(causes, Mapping):
            groups.setdefault((r.setup, r.planner), []).append(causes)
    return {key: {c: float(np.mean([_value(g, c) for g in groups[key]]))
                  for c in REVERSAL_CAUSES}
            for key in sorted(groups)}


@dataclass(frozen=True)
class EncounterRates:
    """Crossing encounters of one setup and planner, pooled over its runs.

    Args:
        encounters_per_robot: mean over the runs of `encounters_per_robot`.
        reversals_per_encounter: the runs' oscillations over their encounters, both summed
            over the runs (NaN without encounters).
        runs: the runs that have the fields.
    """

    encounters_per_robot: float
    reversals_per_encounter: float
    runs: int


def encounter_rates(records: Sequence[RunRecord]) -> dict[tuple[str, str], EncounterRates]:
    """(setup, planner) -> its crossing encounters, over the runs whose metrics.json has
    `encounters_per_robot` (`orchestrator.analysis.encounters`; older runs have not)."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in records:
        if math.isfinite(_value(r.metrics, "encounters_per_robot")):
            groups.setdefault((r.setup, r.planner), []).append(r.metrics)
    out = {}
    for key in sorted(groups):
        runs = groups[key]
        per_robot = np.array([_value(m, "encounters_per_robot") for m in runs])
        robots = np.array([_value(m, "robots") for m in runs])
        reversals = np.array([_value(m, "oscillations_total") for m in runs])
        encounters = float(np.nansum(per_robot * robots))
        out[key] = EncounterRates(
            encounters_per_robot=float(per_robot.mean()),
            reversals_per_encounter=(float(np.nansum(reversals)) / encounters
                                     if encounters > 0 else math.nan),
            runs=len(runs))
    return out


def reversal_table(causes: Mapping[tuple[str, str], Mapping[str, float]],
                   encounters: Mapping[tuple[str, str], EncounterRates] | None = None) -> str:
    """Oscillations per robot by cause, one row per setup and planner, with the crossing
    encounters per robot and the oscillations per encounter ("-" where not recorded)."""
    header = ["setup", "planner", "osc/robot", "encounters/robot", "osc/encounter",
              *REVERSAL_CAUSES]
    rows = []
    for (setup, planner), by in causes.items():
        enc = (encounters or {}).get((setup, planner))
        rates = ([enc.encounters_per_robot, enc.reversals_per_encounter] if enc
                 else [None, None])
        rows.append([setup, planner, _cell(sum(by.values())), *(_cell(x) for x in rates),
                     *(_cell(by[c]) for c in REVERSAL_CAUSES)])
    return format_table(header, rows)


def write_stats_csv(path: Path, stats: Mapping[tuple[str, str],
                                                Mapping[str, tuple[float, float, int]]],
                    metrics: Sequence[tuple[str, str]] = ALL_METRICS) -> Path:
    """`aggregate`'s statistics as CSV: setup, planner, runs, then mean and std per metric
    (empty where undefined)."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["setup", "planner", "runs"]
                   + [f"{m}_{x}" for m, _ in metrics for x in ("mean", "std")])
        for (setup, planner), s in stats.items():
            w.writerow([setup, planner, s["runs"][2]]
                       + [_finite_or_none(s[m][i]) for m, _ in metrics for i in (0, 1)])
    return Path(path)


def _finite_or_none(x: float) -> float | None:
    return x if math.isfinite(x) else None
