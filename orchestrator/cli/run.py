"""`orchestrator run`: one scenario, distributed (a process per robot) or lockstep."""

from __future__ import annotations

import argparse
import datetime as dt
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from agent.core.config import PLANNER_NAMES, PROFILES
from agent.core.scenario import Scenario
from agent.flags import non_negative_int
from agent.process import ExitCode
from orchestrator.analysis.console import ProgressLine, run_summary
from orchestrator.analysis.plots import profile_note, write_run_plots
from orchestrator.analysis.rundir import (
    end_event,
    numerics_cpu,
    numerics_versions,
    run_ending,
    safe_name,
)
from orchestrator.cli.common import (
    DEFAULT_RUNS_DIR,
    JITTER_HELP,
    MODES,
    BadInput,
    add_fault_args,
    add_tls_args,
    fault_plan,
    planner_label,
    start_jitter_m,
    tls_ca,
)

if TYPE_CHECKING:
    from orchestrator.analysis.metrics import RunMetrics
    from world.mcap_log import LiveView
    from world.sim.faults import FaultPlan

RUN_ENDINGS = frozenset({ExitCode.OK, ExitCode.CONTACT, ExitCode.INCOMPLETE, ExitCode.ROBOT_LOST,
                         ExitCode.INTERRUPTED})
"""World exit statuses of a run that ended normally (anything else: the world was lost)."""


LAUNCHERS = ("auto", "spawn", "fork")
FORK_ABOVE_ROBOTS = 64
"""With more robots than this on one machine, 'auto' forks them from one warmed-up parent: N
interpreters importing numpy, scipy, osqp and zenoh and opening TLS sessions all at once
outlast any start-up deadline on a small host, while the fork launcher starts them a few at
a time from a parent that imported once."""


def choose_launcher(requested: str, robots: int, faults: FaultPlan | None) -> str:
    """The robot launcher of a distributed run (see `FORK_ABOVE_ROBOTS`).

    Raises:
        BadInput: 'fork' with injected faults (only spawned robots can be faulted).
    """
    if requested == "fork" and faults is not None:
        raise BadInput("--launcher fork: faults are injected per robot process; use spawn")
    if requested != "auto":
        return requested
    return "fork" if robots > FORK_ABOVE_ROBOTS and faults is None else "spawn"


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("run", help="run one scenario")
    p.add_argument("--profile", choices=PROFILES, default=None,
                   help="planner configuration: default, paper (the paper\'s method as "
                        "written) or lanes (the default with lanes in corridors, "
                        "docs/method.md); default: the scenario\'s own")
    p.add_argument("--without", default=None, metavar="LIST",
                   help="mechanisms of the default profile to switch off, comma-separated "
                        "(ablations; docs/method.md): e.g. routing,liveness")
    p.add_argument("setup", help="setup_a..setup_g (or a..g), a family (circle, crossing, "
                                 "crossing4, random, ...: orchestrator list), or a scenario "
                                 ".yaml file")
    p.add_argument("--agents", type=int, help="robot count (setup_f, setup_g, families)")
    p.add_argument("--planner", choices=PLANNER_NAMES,
                   help="every robot uses this planner (default: the scenario's)")
    p.add_argument("--mode", choices=MODES, default="distributed")
    p.add_argument("--seed", type=non_negative_int, default=0,
                   help="seeds the random family and jitter")
    p.add_argument("--start-jitter-m", type=float, default=None, help=JITTER_HELP)
    p.add_argument("--time-scale", type=float, default=None,
                   help="sim seconds per wall second (distributed mode, and lockstep with "
                        "--live; default 1)")
    p.add_argument("--launcher", choices=LAUNCHERS, default="auto",
                   help="distributed mode: 'spawn' starts one python -m agent per robot, "
                        "'fork' one python -m agent.fleet that imports once and forks every "
                        "robot, a few at a time; 'auto' (default): fork above "
                        f"{FORK_ABOVE_ROBOTS} robots when no fault is injected, else spawn")
    p.add_argument("--out", help="run directory (default runs/<setup>-<planner>-<seed>-<time>)")
    p.add_argument("--gif", action="store_true", help="also write trajectory.gif")
    p.add_argument("--mp4", action="store_true",
                   help="also write trajectory.mp4 (needs the 'video' extra: imageio-ffmpeg)")
    p.add_argument("--live", action="store_true",
                   help="serve the run live to Foxglove (WebSocket) while it runs")
    p.add_argument("--live-port", type=int, default=8765,
                   help="port of the live view (default 8765; 0: any free port)")
    p.add_argument("--live-host", default="127.0.0.1",
                   help="address the live view binds (default 127.0.0.1: this machine only)")
    p.add_argument("--quiet", action="store_true", help="no progress line and no summary")
    add_tls_args(p)
    add_fault_args(p)
    p.set_defaults(func=run)


def default_run_name(scenario: Scenario, planner: str, seed: int) -> str:
    """``<scenario>-<planner>[-paper]-<seed>-<time>``: the paper profile is in the name."""
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    profile = "-paper" if scenario.planner_config.is_paper else ""
    return f"{safe_name(scenario.name)}-{planner}{profile}-{seed}-{stamp}"


def new_run_dir(out: str | None, scenario: Scenario, planner: str, seed: int) -> Path:
    """The run's directory, made 0700 for this run alone (`agent.files`): ``--out`` if it
    is new or an empty directory of this user, else a fresh ``runs/<default_run_name>``
    (``-2``, ``-3``, ... when two runs start in the same second)."""
    from agent.files import UnsafePathError, create_run_dir, unique_dir

    try:
        if out:
            return create_run_dir(Path(out))
        return unique_dir(DEFAULT_RUNS_DIR, default_run_name(scenario, planner, seed))
    except UnsafePathError as exc:
        raise BadInput(str(exc)) from None


def run(args: argparse.Namespace) -> int:
    from orchestrator.analysis.rundir import read_json, write_json
    from orchestrator.experiments.families import resolve

    if args.time_scale is not None and not (math.isfinite(args.time_scale)
                                            and args.time_scale > 0):
        raise BadInput(f"--time-scale: must be > 0, got {args.time_scale}")
    jitter_m = start_jitter_m(args.setup, args.seed, args.start_jitter_m, agents=args.agents)
    if args.start_jitter_m is None and jitter_m > 0.0:
        print(f"run: seed {args.seed} moves each start by up to {jitter_m:g} m ({args.setup} "
              "does not draw from the seed; --start-jitter-m 0 runs it as written)",
              file=sys.stderr)
    scenario = resolve(args.setup, agents=args.agents, seed=args.seed,
                       start_jitter_m=jitter_m, planner=args.planner,
                       profile=args.profile, without=args.without)
    if args.mp4:
        from orchestrator.analysis.plots import mp4_available

        if (why := mp4_available()) is not None:
            raise BadInput(f"--mp4: {why}")
    faults = fault_plan(args, scenario)
    ca_dir = tls_ca(args) if args.mode == "distributed" else None  # checked before any file
    launcher = choose_launcher(args.launcher, len(scenario.robots), faults)
    planner = planner_label(scenario)
    out_dir = new_run_dir(args.out, scenario, planner, args.seed)
    label = run_label(scenario, planner, args.mode)
    claim_run_dir(out_dir, {
        "setup": args.setup, "scenario": scenario.name, "planner": planner,
        "seed": args.seed, "mode": args.mode, "profile": args.profile,
        "without": scenario.planner_config.without_names, "agents": len(scenario.robots),
        "start_jitter_m": jitter_m, "time_scale": args.time_scale,
        "launcher": launcher if args.mode == "distributed" else None,
        "faults": faults.to_json() if faults is not None else None,
        "started": dt.datetime.now().isoformat(timespec="seconds"),
        "argv": list(args.argv),
        "versions": numerics_versions(), "cpu": numerics_cpu(),
    })
    live = _start_live(args, scenario)
    progress = ProgressLine(label, quiet=args.quiet)
    wall0 = time.monotonic()
    interrupted = False
    world_status: int | None = None
    metrics: RunMetrics | None
    try:
        if args.mode == "lockstep":
            from orchestrator.experiments.lockstep import run_lockstep

            metrics = run_lockstep(scenario, out_dir, on_progress=progress, faults=faults,
                                   live=live,
                                   time_scale=(args.time_scale or 1.0) if live else None
                                   ).metrics
        else:
            metrics, world_status = _run_distributed(scenario, out_dir, args, progress, faults,
                                                     live, launcher, ca_dir)
    except KeyboardInterrupt:
        interrupted = True
        metrics = _partial_metrics(out_dir)
    finally:
        progress.done()
        if live is not None:
            live.stop()
    wall_s = time.monotonic() - wall0
    end = end_event(out_dir)
    crashed = metrics is None or (world_status is not None and world_status not in RUN_ENDINGS)
    content = metrics.to_json_dict() if metrics is not None else None
    ending = run_ending(content, end, interrupted=interrupted, crashed=crashed)
    code, status = ExitCode(ending.exit_code), ending.status
    write_json(out_dir / "run.json", {
        **read_json(out_dir / "run.json"), **ending.as_json(),
        "world_exit_status": world_status, "wall_s": round(wall_s, 2),
        "finished": dt.datetime.now().isoformat(timespec="seconds")})
    if metrics is None:
        print(f"error: the run left no trajectory (world exit status {world_status}); "
              f"see {out_dir}/world.log", file=sys.stderr)
        print(out_dir)
        return code
    write_run_plots(out_dir, gif=args.gif, mp4=args.mp4)
    if not args.quiet:
        print(run_summary(read_json(out_dir / "metrics.json") or content or {}, label))
        print(f"\nstatus {status}, wall time {wall_s:.1f} s")
    print(out_dir)
    if crashed:
        print(f"error: the world exited with status {world_status}; see {out_dir}/world.log",
              file=sys.stderr)
    return code


def run_label(scenario: Scenario, planner: str, mode: str) -> str:
    """What the summary header and the plot title call a run: scenario, planner (with
    ``(paper profile)`` when the paper's method as written is run) and mode."""
    return f"{scenario.name} {planner}{profile_note(scenario)} {mode}"


def claim_run_dir(out_dir: Path, started: dict[str, Any]) -> None:
    """Write the first ``run.json`` as a new file: a second run given the same empty
    ``--out`` at the same moment finds it there and stops (`BadInput`)."""
    import json

    from agent.files import write_new

    try:
        write_new(out_dir / "run.json", (json.dumps(started, indent=2) + "\n").encode())
    except FileExistsError:
        raise BadInput(f"--out: {out_dir} is taken by another run") from None


def _partial_metrics(out_dir: Path) -> RunMetrics | None:
    """The metrics of what an interrupted run recorded (written, marked partial), or None."""
    from orchestrator.analysis.rundir import RunDirError, metrics_from_run_dir, write_metrics

    try:
        metrics = metrics_from_run_dir(out_dir)
    except (RunDirError, OSError, ValueError):
        return None
    write_metrics(out_dir, metrics, partial=True)
    return metrics


def _start_live(args: argparse.Namespace, scenario: Scenario) -> LiveView | None:
    """The live Foxglove server of ``--live`` (printing its address), or None."""
    if not args.live:
        return None
    if not 0 <= args.live_port <= 65535:
        raise BadInput(f"--live-port: {args.live_port} is not a TCP port")
    from orchestrator.experiments.live import start_live_view

    try:
        return start_live_view(args.live_host, args.live_port, scenario)
    except Exception as exc:  # foxglove raises its own error types (port in use, bad host)
        raise BadInput(f"--live: cannot serve on {args.live_host}:{args.live_port}: "
                       f"{exc}") from exc


def _run_distributed(scenario: Scenario, out_dir: Path, args: argparse.Namespace,
                     progress: ProgressLine, faults: FaultPlan | None = None,
                     live: LiveView | None = None, launcher: str = "spawn",
                     ca_dir: Path | None = None) -> tuple[RunMetrics | None, int]:
    """Run the real processes; (metrics or None, the world's exit status)."""
    from orchestrator.experiments.distributed import run_scenario_distributed

    return run_scenario_distributed(scenario, out_dir, args.seed,
                                    time_scale=args.time_scale or 1.0,
                                    on_progress=progress, faults=faults, live=live,
                                    tls=not args.insecure, tls_ca=ca_dir,
                                    robot_launcher=launcher)
