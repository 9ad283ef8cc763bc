"""The `orchestrator` command line: list, run, sweep, report, bench.

Exit status of `run`: 0 every robot arrived with no contact; 1 contact or time-out;
2 bad input (an invalid scenario or option: the message names the file and field);
3 any other error. `sweep` exits with the worst of its runs (3 > 2 > 1 > 0).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import csv
import datetime as dt
import io
import itertools
import math
import re
import secrets
import subprocess
import sys
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from agent.config import PLANNER_NAMES
from world.scenario import Scenario, ScenarioError, dump_scenario

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_ERROR = 3
EXIT_INTERRUPTED = 130

MODES = ("distributed", "lockstep")
DEFAULT_RUNS_DIR = Path("runs")
SWEEP_RUN_TIMEOUT_S = 4 * 3600.0


class BadInput(Exception):
    """A bad option value (exit status 2)."""


# --------------------------------------------------------------------------------------
# Progress and tables
# --------------------------------------------------------------------------------------

class ProgressLine:
    """One live status line on stderr: rewritten in place on a terminal, else every 5 s."""

    def __init__(self, label: str, stream: TextIO | None = None, *, quiet: bool = False) -> None:
        self.label = label
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.tty = self.stream.isatty()
        self._last_wall = -math.inf
        self._width = 0

    def __call__(self, progress: Any) -> None:
        """Accepts `LockstepProgress` or `DistributedProgress` (same field names)."""
        if self.quiet:
            return
        now = time.monotonic()
        if not self.tty and now - self._last_wall < 5.0:
            return
        self._last_wall = now
        arrived = getattr(progress, "arrived", ())
        n_arrived = arrived if isinstance(arrived, int) else len(arrived)
        sim_t = float(getattr(progress, "sim_t_s", 0.0))
        wall = float(getattr(progress, "wall_s", 0.0))
        text = (f"[{self.label}] t = {sim_t:7.1f} s   arrived {n_arrived}/"
                f"{getattr(progress, 'n_robots', '?')}   contacts "
                f"{getattr(progress, 'contacts', 0)}   wall {wall:6.1f} s")
        if not getattr(progress, "started", True):
            text += "   (waiting for robots)"
        lost = getattr(progress, "lost", ())
        if lost:
            text += f"   lost {sorted(lost)}"
        if self.tty:
            self.stream.write("\r" + text.ljust(self._width))
            self._width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def done(self) -> None:
        if self.tty and self._width and not self.quiet:
            self.stream.write("\n")
            self.stream.flush()


def run_summary(metrics: dict[str, Any], label: str) -> str:
    """The end-of-run table: run-level metrics, then one row per robot."""
    from orchestrator.report import format_table

    keys = [
        ("success", "success"), ("arrived", "robots arrived"), ("contacts", "contacts"),
        ("min_gap_m", "min gap [m]"), ("makespan_s", "all arrived at [s]"),
        ("time_to_goal_mean_s", "time to goal, mean [s]"),
        ("time_ratio_mean", "time / ideal, mean"),
        ("path_length_mean_m", "path length, mean [m]"),
        ("path_ratio_mean", "path / straight, mean"),
        ("oscillations_per_robot", "oscillations per robot"),
        ("side_flips_per_robot", "side flips per robot"),
        ("plan_ms_p50", "planning p50 [ms]"), ("plan_ms_p99", "planning p99 [ms]"),
        ("plan_ms_max", "planning max [ms]"),
        ("latency_ms_p50", "latency p50 [ms]"), ("latency_ms_p99", "latency p99 [ms]"),
        ("deadline_miss_rate", "deadline miss rate"), ("sim_time_s", "sim time [s]"),
    ]
    rows = [[label_, metrics.get(k)] for k, label_ in keys]
    rows[1][1] = f"{metrics.get('arrived')}/{metrics.get('robots')}"
    top = format_table([label, ""], rows)
    per = [[r.get("id"), r.get("arrived"), r.get("time_to_goal_s"), r.get("time_ratio"),
            r.get("path_length_m"), r.get("path_ratio"), r.get("oscillations"),
            r.get("side_flips"), r.get("contacts"), r.get("min_gap_m"), r.get("plan_ms_p50")]
           for r in metrics.get("per_robot", [])]
    robots = format_table(["robot", "arrived", "t_goal s", "t/ideal", "path m", "path/line",
                           "osc", "flips", "contacts", "min gap m", "plan p50 ms"], per)
    return top + "\n\n" + robots


# --------------------------------------------------------------------------------------
# list
# --------------------------------------------------------------------------------------

def cmd_list(args: argparse.Namespace) -> int:
    from orchestrator.families import FAMILIES, SCALABLE_SETUPS, SETUPS, setup_path
    from orchestrator.report import format_table
    from world.scenario import load_scenario

    rows = []
    for name in SETUPS:
        s = load_scenario(setup_path(name))
        scal = "--agents" if name in SCALABLE_SETUPS else "fixed"
        rows.append([name, len(s.robots), scal, s.description])
    print("Setups (the paper's A-G, orchestrator/setups/*.yaml):")
    print(format_table(["name", "robots", "size", "description"], rows))
    print("\nFamilies (sized with --agents N, seeded with --seed):")
    print(format_table(["name", "default N", "what"],
                       [[k, n, what] for k, (n, what) in FAMILIES.items()]))
    print("\nPlanners (--planner):")
    for p in PLANNER_NAMES:
        print(f"  {p}")
    print("\nModes (--mode): distributed (default: one process per robot over Zenoh), "
          "lockstep (one deterministic process)")
    return EXIT_OK


# --------------------------------------------------------------------------------------
# run
# --------------------------------------------------------------------------------------

def _planner_label(scenario: Scenario) -> str:
    names = sorted({r.planner for r in scenario.robots})
    return names[0] if len(names) == 1 else "mixed"


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_.-") or "run"


def default_out_dir(scenario: Scenario, planner: str, seed: int) -> Path:
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return DEFAULT_RUNS_DIR / f"{_safe(scenario.name)}-{planner}-{seed}-{stamp}"


def cmd_run(args: argparse.Namespace) -> int:
    from orchestrator.families import resolve
    from orchestrator.rundir import write_json

    if args.time_scale is not None and not (math.isfinite(args.time_scale)
                                            and args.time_scale > 0):
        raise BadInput(f"--time-scale: must be > 0, got {args.time_scale}")
    scenario = resolve(args.setup, agents=args.agents, seed=args.seed,
                       start_jitter_m=args.start_jitter_m, planner=args.planner)
    faults = _fault_plan(args, scenario)
    planner = _planner_label(scenario)
    out_dir = Path(args.out) if args.out else default_out_dir(scenario, planner, args.seed)
    if (out_dir / "trajectory.csv").exists() or (out_dir / "metrics.json").exists():
        raise BadInput(f"--out: {out_dir} already holds a run; choose another directory")
    out_dir.mkdir(parents=True, exist_ok=True)
    label = f"{scenario.name} {planner} {args.mode}"
    write_json(out_dir / "run.json", {
        "setup": args.setup, "scenario": scenario.name, "planner": planner,
        "seed": args.seed, "mode": args.mode, "agents": len(scenario.robots),
        "start_jitter_m": args.start_jitter_m, "time_scale": args.time_scale,
        "faults": faults.to_json() if faults is not None else None,
        "started": dt.datetime.now().isoformat(timespec="seconds"),
        "argv": list(args.argv),
    })
    progress = ProgressLine(label, quiet=args.quiet)
    wall0 = time.monotonic()
    try:
        if args.mode == "lockstep":
            from orchestrator.lockstep import run_lockstep

            outcome = run_lockstep(scenario, out_dir, on_progress=progress, faults=faults)
            metrics = outcome.metrics
            world_status = None
        else:
            metrics, world_status = _run_distributed(scenario, out_dir, args, progress, faults)
    finally:
        progress.done()
    wall_s = time.monotonic() - wall0
    if metrics is None:
        print(f"error: the distributed run left no trajectory (world exit status "
              f"{world_status}); see {out_dir}/world.log", file=sys.stderr)
        print(out_dir)
        return EXIT_ERROR
    content = metrics.to_json_dict()
    _plots(out_dir, gif=args.gif)
    if not args.quiet:
        print(run_summary(content, label))
        print(f"\nwall time {wall_s:.1f} s")
    print(out_dir)
    if world_status is not None and world_status not in (0, 1):
        print(f"error: the world exited with status {world_status}; see {out_dir}/world.log",
              file=sys.stderr)
        return EXIT_ERROR
    return EXIT_OK if metrics.success else EXIT_FAILED


def _run_distributed(scenario: Scenario, out_dir: Path, args: argparse.Namespace,
                     progress: ProgressLine, faults: Any = None) -> tuple[Any, int]:
    """Run the real processes; (metrics or None, the world's exit status)."""
    from orchestrator.distributed import run_distributed
    from orchestrator.rundir import RunDirError, metrics_from_run_dir, write_metrics

    scenario_path = out_dir / "scenario.input.yaml"
    dump_scenario(scenario, scenario_path)
    run_id = f"{_safe(scenario.name)[:24]}-{args.seed}-{secrets.token_hex(4)}"
    status = run_distributed(scenario_path, out_dir, run_id, rate_hz=50.0,
                             time_scale=args.time_scale or 1.0, on_progress=progress,
                             faults=faults)
    if not (out_dir / "trajectory.csv").exists():
        return None, status
    try:
        metrics = metrics_from_run_dir(out_dir)
    except RunDirError:
        return None, status
    write_metrics(out_dir, metrics)
    return metrics, status


def _plots(out_dir: Path, *, gif: bool) -> None:
    """trajectory.png (and trajectory.gif); a plotting failure is reported, not fatal."""
    try:
        from orchestrator.plots import animate, plot_trajectories
        from orchestrator.rundir import read_run_dir

        data = read_run_dir(out_dir)
        plot_trajectories(data, out_dir / "trajectory.png")
        if gif:
            animate(data, out_dir / "trajectory.gif")
    except Exception as exc:  # noqa: BLE001 - the run itself is done; keep its result
        print(f"warning: plotting failed: {type(exc).__name__}: {exc}", file=sys.stderr)


# --------------------------------------------------------------------------------------
# sweep
# --------------------------------------------------------------------------------------

def _split(text: str) -> list[str]:
    return [x.strip() for x in text.split(",") if x.strip()]


def cmd_sweep(args: argparse.Namespace) -> int:
    from orchestrator.families import SETUPS, resolve
    from orchestrator.report import format_table
    from orchestrator.rundir import read_json, write_json

    setups = list(SETUPS) if args.setups == "all" else _split(args.setups)
    planners = list(PLANNER_NAMES) if args.planners == "all" else _split(args.planners)
    if not setups or not planners:
        raise BadInput("--setups and --planners must name at least one each")
    if args.seeds < 1:
        raise BadInput(f"--seeds: must be >= 1, got {args.seeds}")
    if args.jobs < 1:
        raise BadInput(f"--jobs: must be >= 1, got {args.jobs}")
    for setup, planner in itertools.product(setups, planners):  # fail before starting
        resolve(setup, agents=args.agents, seed=0, start_jitter_m=args.start_jitter_m,
                planner=planner)
    out = Path(args.out)
    (out / "logs").mkdir(parents=True, exist_ok=True)
    jobs = []
    for setup, planner, seed in itertools.product(setups, planners, range(args.seeds)):
        name = f"{_safe(setup)}-{planner}-{seed}"
        cmd = [sys.executable, "-m", "orchestrator", "run", setup, "--planner", planner,
               "--seed", str(seed), "--mode", args.mode, "--out", str(out / name), "--quiet",
               "--start-jitter-m", repr(args.start_jitter_m)]
        if args.agents is not None:
            cmd += ["--agents", str(args.agents)]
        if args.time_scale is not None:
            cmd += ["--time-scale", repr(args.time_scale)]
        jobs.append((setup, planner, seed, name, cmd))
    print(f"sweep: {len(jobs)} runs, {args.jobs} at a time, into {out}", file=sys.stderr)

    def launch(job: tuple) -> tuple[tuple, int, float]:
        t0 = time.monotonic()
        log = out / "logs" / f"{job[3]}.log"
        with open(log, "w") as f:
            try:
                rc = subprocess.run(job[4], stdout=f, stderr=subprocess.STDOUT,
                                    timeout=SWEEP_RUN_TIMEOUT_S, check=False).returncode
            except subprocess.TimeoutExpired:
                rc = EXIT_ERROR
        return job, rc, time.monotonic() - t0

    results = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        for job, rc, wall in pool.map(launch, jobs):
            m = read_json(out / job[3] / "metrics.json")
            row = {
                "setup": job[0], "planner": job[1], "seed": job[2], "exit": rc,
                "success": m.get("success"), "arrived": m.get("arrived"),
                "robots": m.get("robots"), "contacts": m.get("contacts"),
                "min_gap_m": m.get("min_gap_m"),
                "oscillations_per_robot": m.get("oscillations_per_robot"),
                "path_length_mean_m": m.get("path_length_mean_m"),
                "time_to_goal_mean_s": m.get("time_to_goal_mean_s"),
                "plan_ms_mean": m.get("plan_ms_mean"), "plan_ms_p99": m.get("plan_ms_p99"),
                "wall_s": round(wall, 2), "dir": job[3],
            }
            results.append(row)
            print(f"  {job[3]}: exit {rc} ({wall:.1f} s)", file=sys.stderr)
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
    worst = max(r["exit"] for r in results)
    return worst if worst in (EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT) else EXIT_ERROR


# --------------------------------------------------------------------------------------
# fault injection (run flags) and stress
# --------------------------------------------------------------------------------------

def _add_link_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("link faults (every pose and command link; sim time)")
    g.add_argument("--latency-ms", type=float, default=0.0, help="fixed delay per link [ms]")
    g.add_argument("--jitter-ms", type=float, default=0.0,
                   help="uniform jitter half-width [ms] (100 ± 30: --jitter-ms 30)")
    g.add_argument("--drop", type=float, default=0.0, help="loss probability")
    g.add_argument("--dup", type=float, default=0.0, help="duplication probability")
    g.add_argument("--reorder", type=float, default=0.0,
                   help="probability a message is held back 50 ms (overtaken)")
    g.add_argument("--no-latency-compensation", action="store_true",
                   help="robots plan on poses as stamped (no forward prediction by age)")


def _add_fault_args(p: argparse.ArgumentParser) -> None:
    _add_link_args(p)
    g = p.add_argument_group("robot faults (T, DUR in sim seconds)")
    g.add_argument("--slow-robot", action="append", default=[], metavar="I:MS",
                   help="robot I's commands leave MS ms late (a CPU-starved robot)")
    g.add_argument("--robot-rate", action="append", default=[], metavar="I:HZ[:PHASE_S]",
                   help="robot I plans at HZ, its slots offset by PHASE_S")
    g.add_argument("--kill-robot", action="append", default=[], metavar="I@T",
                   help="SIGKILL robot I at T")
    g.add_argument("--stop-robot", action="append", default=[], metavar="I@T:DUR",
                   help="SIGSTOP robot I at T, SIGCONT at T + DUR")
    g.add_argument("--restart-robot", action="append", default=[], metavar="I@T",
                   help="SIGKILL robot I at T and start it again with the same id")


def _fault_plan(args: argparse.Namespace, scenario: Scenario, *, links: bool = True) -> Any:
    """The `FaultPlan` of the fault flags, checked against `scenario` (robot ids, lockstep
    rates), or None when no fault flag is given. `links=False` leaves the link flags and
    the seed out: `stress` sets those per level and run, the robot faults apply to all."""
    from orchestrator.faults import FaultSpecError, build_plan

    link_flags = dict(
        latency_ms=args.latency_ms, jitter_ms=args.jitter_ms, drop=args.drop, dup=args.dup,
        reorder=args.reorder, seed=args.seed,
        compensate_latency=not args.no_latency_compensation) if links else {}
    try:
        plan = build_plan(slow=args.slow_robot, rates=args.robot_rate, kill=args.kill_robot,
                          stop=args.stop_robot, restart=args.restart_robot, **link_flags)
        plan.check([r.id for r in scenario.robots])
    except FaultSpecError as exc:
        raise BadInput(str(exc)) from None
    for rid, timing in plan.timing.items():
        hz = timing.control_rate_hz
        if args.mode == "lockstep" and hz is not None and abs(50.0 / hz - round(50.0 / hz)) > 1e-9:
            raise BadInput(f"--robot-rate {rid}:{hz:g}: in lockstep the rate must divide 50 Hz")
    return plan if plan.active else None


def cmd_stress(args: argparse.Namespace) -> int:
    from agent.link import LinkFaults
    from orchestrator import stress
    from orchestrator.families import resolve
    from orchestrator.report import format_table
    from orchestrator.rundir import write_json

    planners = list(PLANNER_NAMES) if args.planners == "all" else _split(args.planners)
    bad = [p for p in planners if p not in PLANNER_NAMES]
    if not planners or bad:
        raise BadInput(f"--planners: unknown {bad} (known: {', '.join(PLANNER_NAMES)})")
    if args.seeds < 1 or args.jobs < 1:
        raise BadInput("--seeds and --jobs must be >= 1")
    try:
        base = LinkFaults(latency_ms=args.latency_ms, jitter_ms=args.jitter_ms, drop=args.drop,
                          dup=args.dup, reorder=args.reorder)
        # no --sweep: one level, the base faults as given (--latency-ms is not overridden)
        sweep = stress.parse_sweep(args.sweep or [f"latency_ms={args.latency_ms!r}"])
    except ValueError as exc:
        raise BadInput(str(exc)) from None
    for planner in planners:  # fail before starting
        scenario = resolve(args.setup, agents=args.agents, seed=0,
                           start_jitter_m=args.start_jitter_m, planner=planner)
    robot_faults = _fault_plan(args, scenario, links=False)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    keys = list(sweep)
    jobs = []
    for level, planner, seed in itertools.product(stress.levels(sweep), planners,
                                                  range(args.seeds)):
        links = stress.level_faults(level, base, args.jitter_frac)
        name = _safe(f"{args.setup}-{planner}-{stress.level_name(level)}-s{seed}")
        jobs.append(stress.StressJob(
            setup=args.setup, planner=planner, seed=seed, level=tuple(level.items()),
            links=links, mode=args.mode, out_dir=str(out / name), agents=args.agents,
            start_jitter_m=args.start_jitter_m, time_scale=args.time_scale or 1.0,
            compensate_latency=not args.no_latency_compensation, robot_faults=robot_faults))
    print(f"stress: {len(jobs)} runs ({args.mode}), {args.jobs} at a time, into {out}",
          file=sys.stderr)
    t0 = time.monotonic()
    done = [0]

    def on_done(row: dict) -> None:
        done[0] += 1
        print(f"  [{done[0]}/{len(jobs)}] {row['dir']}: contacts {row.get('contacts')} "
              f"success {row.get('success')} ({row['wall_s']:.1f} s)"
              + (f" ERROR {row['error']}" if row.get("error") else ""), file=sys.stderr)

    rows = stress.run_jobs(jobs, args.jobs, on_done)
    table = stress.aggregate(rows, keys)
    env = stress.envelope(table, keys)
    header = ["setup", "planner", *keys, "runs", "success_rate", "arrived_frac", "contacts",
              "runs_with_contact", "min_gap_m", "time_ratio_mean"]
    print(f"\n{args.setup}, {args.mode}, jitter = {args.jitter_frac:g} x latency unless set, "
          f"seeds 0..{args.seeds - 1}")
    print(format_table(header, [[t[h] for h in header] for t in table]))
    env_header = ["setup", "planner", *[f"max_{k}" for k in keys]]
    print("\nlargest contact-free level (every seed, every smaller level too):")
    print(format_table(env_header, [[e[h] for h in env_header] for e in env]))
    stress.write_csv(out / "stress.csv", rows)
    write_json(out / "stress.json", {
        "args": {k: v for k, v in vars(args).items() if k not in ("func",)},
        "wall_s": round(time.monotonic() - t0, 1), "rows": rows, "table": table,
        "envelope": env})
    print(f"\n{out / 'stress.csv'}, {out / 'stress.json'}")
    return EXIT_ERROR if any(r.get("error") for r in rows) else EXIT_OK


# --------------------------------------------------------------------------------------
# report
# --------------------------------------------------------------------------------------

def cmd_report(args: argparse.Namespace) -> int:
    from orchestrator.plots import plot_report_bars
    from orchestrator.report import (
        ALL_METRICS,
        PAPER_METRICS,
        aggregate,
        collect,
        paper_table,
        reversal_causes,
        reversal_table,
        summary_table,
    )
    from orchestrator.rundir import write_json

    paths = [Path(p) for p in args.dirs]
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise BadInput(f"report: no such directory: {', '.join(missing)}")
    records = collect(paths, by_dir=args.by_dir)
    if not records:
        raise BadInput(f"report: no run directories with metrics.json under "
                       f"{', '.join(map(str, paths))}")
    stats = aggregate(records, ALL_METRICS)
    print(f"{len(records)} runs")
    print(summary_table(stats))
    causes = reversal_causes(records)
    if causes:
        print("\noscillations per robot by cause (README, \"Metrics\"):")
        print(reversal_table(causes))
    if args.paper:
        print()
        print(paper_table(stats))
    out = Path(args.out) if args.out else (paths[0] if len(paths) == 1 and paths[0].is_dir()
                                           else Path("report"))
    out.mkdir(parents=True, exist_ok=True)
    bar_stats = {k: {m: (v[0], v[1]) for m, v in s.items()} for k, s in stats.items()}
    written = plot_report_bars(bar_stats, PAPER_METRICS, out)
    write_json(out / "report.json", {
        "runs": [str(r.path) for r in records],
        "groups": [{"setup": k[0], "planner": k[1],
                    **{m: {"mean": _finite(v[0]), "std": _finite(v[1]), "n": v[2]}
                       for m, v in s.items()},
                    "reversal_causes_per_robot": causes.get(k)} for k, s in stats.items()],
    })
    with open(out / "report.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["setup", "planner", "runs"]
                   + [f"{m}_{x}" for m, _ in ALL_METRICS for x in ("mean", "std")])
        for (setup, planner), s in stats.items():
            w.writerow([setup, planner, s["runs"][2]]
                       + [_finite(s[m][i]) for m, _ in ALL_METRICS for i in (0, 1)])
    print(f"\nplots: {', '.join(str(p) for p in written)}")
    print(f"tables: {out / 'report.csv'}, {out / 'report.json'}")
    return EXIT_OK


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


# --------------------------------------------------------------------------------------
# bench and the parser
# --------------------------------------------------------------------------------------

def cmd_bench(args: argparse.Namespace) -> int:
    from orchestrator import bench

    return int(bench.main(list(args.bench_args)) or 0)


def cmd_scale(args: argparse.Namespace) -> int:
    from orchestrator import scale

    return scale.main(list(args.scale_args))


def cmd_compose(args: argparse.Namespace) -> int:
    from orchestrator import compose

    return compose.main(list(args.compose_args))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="orchestrator",
        description="Run, sweep and report decentralised multi-robot collision avoidance "
                    "(IFP, eIFP, eIFP-MPC, ORCA).")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="setups, families and planners")
    p.set_defaults(func=cmd_list)

    p = sub.add_parser("run", help="run one scenario")
    p.add_argument("setup", help="setup_a..setup_g (or a..g), circle, crossing, crossing4, "
                                 "random, or a scenario .yaml file")
    p.add_argument("--agents", type=int, help="robot count (setup_f, setup_g, families)")
    p.add_argument("--planner", choices=PLANNER_NAMES,
                   help="every robot uses this planner (default: the scenario's)")
    p.add_argument("--mode", choices=MODES, default="distributed")
    p.add_argument("--seed", type=int, default=0, help="seeds the random family and jitter")
    p.add_argument("--start-jitter-m", type=float, default=0.0,
                   help="move each start by up to this much (uniform in a disc)")
    p.add_argument("--time-scale", type=float, default=None,
                   help="sim seconds per wall second (distributed mode; default 1)")
    p.add_argument("--out", help="run directory (default runs/<setup>-<planner>-<seed>-<time>)")
    p.add_argument("--gif", action="store_true", help="also write trajectory.gif")
    p.add_argument("--quiet", action="store_true", help="no progress line and no summary")
    _add_fault_args(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("stress", help="fault levels x planners x seeds: table and envelope")
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
    p.add_argument("--start-jitter-m", type=float, default=0.0)
    p.add_argument("--time-scale", type=float, default=None)
    p.add_argument("--out", required=True)
    _add_fault_args(p)
    p.set_defaults(func=cmd_stress)

    p = sub.add_parser("sweep", help="many runs: setups x planners x seeds")
    p.add_argument("--setups", required=True, help="comma-separated names, or 'all' (A-G)")
    p.add_argument("--planners", required=True, help="comma-separated names, or 'all'")
    p.add_argument("--seeds", type=int, default=1, help="seeds 0..N-1 (default 1)")
    p.add_argument("--mode", choices=MODES, default="distributed")
    p.add_argument("--jobs", type=int, default=1, help="runs at a time (default 1)")
    p.add_argument("--agents", type=int)
    p.add_argument("--start-jitter-m", type=float, default=0.0)
    p.add_argument("--time-scale", type=float, default=None)
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("report", help="mean ± std over seeds per setup and planner, plots")
    p.add_argument("dirs", nargs="+", help="run or sweep directories")
    p.add_argument("--paper", action="store_true", help="print the paper's Table I beside ours")
    p.add_argument("--out", help="where plots and tables go (default: the one DIR, or ./report)")
    p.add_argument("--by-dir", action="store_true",
                   help="one row per setup, planner and DIR (compare variants of one setup "
                        "kept in different directories); default: runs are pooled by setup "
                        "and planner")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("bench", help="planner benchmarks (orchestrator.bench)")
    p.add_argument("bench_args", nargs=argparse.REMAINDER)
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("scale", help="real-time runs of N robot processes: timing, CPU, "
                                     "memory, start-up (orchestrator.scale)")
    p.add_argument("scale_args", nargs=argparse.REMAINDER)
    p.set_defaults(func=cmd_scale)

    p = sub.add_parser("compose", help="steps of the docker-compose demo (orchestrator.compose)")
    p.add_argument("compose_args", nargs=argparse.REMAINDER)
    p.set_defaults(func=cmd_compose)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `orchestrator` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["bench"]:
        # Everything after `bench` belongs to the benchmark, --help included (argparse's
        # REMAINDER would reject leading options such as `bench --planner`).
        return _guarded(cmd_bench, argparse.Namespace(bench_args=argv[1:], argv=argv))
    if argv[:1] == ["scale"]:  # its own parser, help included (orchestrator.scale)
        return _guarded(cmd_scale, argparse.Namespace(scale_args=argv[1:], argv=argv))
    if argv[:1] == ["compose"]:  # its own parser, help included (orchestrator.compose)
        return _guarded(cmd_compose, argparse.Namespace(compose_args=argv[1:], argv=argv))
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return int(exc.code or 0)
    args.argv = argv
    return _guarded(args.func, args)


def _guarded(func: Any, args: argparse.Namespace) -> int:
    """Run a subcommand and map its failure to an exit status."""
    try:
        return int(func(args))
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BadInput as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:  # noqa: BLE001 - the CLI's last line: report, exit 3
        buf = io.StringIO()
        traceback.print_exc(file=buf)
        print(buf.getvalue().rstrip(), file=sys.stderr)
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

