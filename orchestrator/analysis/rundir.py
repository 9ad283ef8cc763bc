"""Reading run directories (the I/O edge of `orchestrator.analysis.metrics`).

A run directory holds `scenario.yaml`, `trajectory.csv`, `commands.csv`, `events.jsonl`
(written by `world.recorder.RunRecorder`), and, once the run is over, `metrics.json`;
the CLI adds `run.json` (how the run was started: setup, planner, seed, mode, ...).
"""

from __future__ import annotations

import csv
import importlib
import json
import math
import platform
import re
from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from agent.core.scenario import Scenario
from agent.files import replace_file
from eifp_wire import TIMING_COLUMNS
from orchestrator.analysis.latency import router_groups, wall_latency_ms, wall_latency_ms_by_group
from orchestrator.analysis.metrics import Commands, RunMetrics, RunSpec, Trajectory, compute_metrics
from world.scenario_file import load_scenario

REQUIRED_COMMAND_COLUMNS = ("t_applied", "robot", "seq", "pose_stamp", "v", "omega",
                            "plan_ms", "status")
TRAJECTORY_COLUMNS = ("t", "robot", "x", "y", "theta", "v", "omega")
DEFAULT_WORLD_RATE_HZ = 50.0
DEFAULT_CONTROL_RATE_HZ = 10.0


class RunDirError(RuntimeError):
    """A run directory is missing a file or holds a malformed one."""


@dataclass(frozen=True)
class RunData:
    """Everything a run directory holds."""

    path: Path
    scenario: Scenario
    trajectory: Trajectory
    commands: Commands
    events: list[dict[str, Any]]


def read_trajectory(path: Path, robot_ids: np.ndarray) -> Trajectory:
    """`trajectory.csv` as arrays; ticks at which some robot is missing are dropped.

    Args:
        path: the CSV file.
        robot_ids: (n,) the scenario's robot ids (column order of the result).
    """
    with open(path, encoding="utf-8") as f:
        header = f.readline().strip().split(",")
        if tuple(header[:len(TRAJECTORY_COLUMNS)]) != TRAJECTORY_COLUMNS:
            raise RunDirError(f"{path}: header {header} is not {list(TRAJECTORY_COLUMNS)}")
        rows = [line for line in f if line.count(",") >= len(TRAJECTORY_COLUMNS) - 1]
    n = robot_ids.size
    if not rows:
        return Trajectory(np.zeros(0), robot_ids, np.zeros((0, n, 3)), np.zeros((0, n, 2)))
    try:
        data = np.loadtxt(rows, delimiter=",", ndmin=2, usecols=range(len(TRAJECTORY_COLUMNS)))
    except ValueError:  # a half-written last line of a killed run
        data = np.loadtxt(rows[:-1], delimiter=",", ndmin=2,
                          usecols=range(len(TRAJECTORY_COLUMNS)))
    times, t_idx = np.unique(data[:, 0], return_inverse=True)
    order = np.argsort(robot_ids)
    pos = np.searchsorted(robot_ids[order], data[:, 1].astype(np.int64))
    pos = np.clip(pos, 0, n - 1)
    known = robot_ids[order][pos] == data[:, 1].astype(np.int64)
    col = order[pos]
    grid = np.full((times.size, n, 5), np.nan)
    grid[t_idx[known], col[known]] = data[known, 2:7]
    complete = ~np.isnan(grid).any(axis=(1, 2))
    grid = grid[complete]
    return Trajectory(times[complete], robot_ids, grid[:, :, :3], grid[:, :, 3:])


def read_commands(path: Path) -> Commands:
    """`commands.csv` as arrays; the optional `side` and `resolved` columns are kept."""
    with open(path, encoding="utf-8", newline="") as f:
        reader = csv.DictReader(f)
        fields = reader.fieldnames or []
        missing = [c for c in REQUIRED_COMMAND_COLUMNS if c not in fields]
        if missing:
            raise RunDirError(f"{path}: missing columns {missing}")
        rows = [r for r in reader if r.get("status")]  # skip a half-written last line
    has_side = "side" in fields and "resolved" in fields

    def col(name: str) -> list[str]:
        return [r[name] for r in rows]

    try:
        side = resolved = None
        if has_side:
            side = np.array([int(x or 0) for x in col("side")], dtype=np.int64)
            resolved = np.array([float(x) if x not in ("", None) else math.nan
                                 for x in col("resolved")])
        return Commands(
            t_applied_s=np.array(col("t_applied"), dtype=float),
            robot=np.array([int(x) for x in col("robot")], dtype=np.int64),
            seq=np.array([int(x) for x in col("seq")], dtype=np.int64),
            pose_stamp_s=np.array(col("pose_stamp"), dtype=float),
            v=np.array(col("v"), dtype=float),
            omega=np.array(col("omega"), dtype=float),
            plan_ms=np.array(col("plan_ms"), dtype=float),
            status=np.array(col("status"), dtype=str),
            side=side,
            resolved=resolved,
        )
    except (TypeError, ValueError) as exc:
        raise RunDirError(f"{path}: malformed row: {exc}") from exc


def read_events(path: Path) -> list[dict[str, Any]]:
    """`events.jsonl`; lines that are not JSON objects (a killed run's last) are skipped."""
    events: list[dict[str, Any]] = []
    if not path.exists():
        return events
    with open(path, encoding="utf-8") as f:
        for line in f:
            try:
                record = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(record, dict):
                events.append(record)
    return events


def read_run_dir(run_dir: Path) -> RunData:
    """Scenario, trajectory, commands and events of a run directory."""
    run_dir = Path(run_dir)
    for name in ("scenario.yaml", "trajectory.csv", "commands.csv"):
        if not (run_dir / name).is_file():
            raise RunDirError(f"{run_dir}: no {name}")
    scenario = load_scenario(run_dir / "scenario.yaml")
    robot_ids = np.array([r.id for r in scenario.robots], dtype=np.int64)
    return RunData(
        path=run_dir,
        scenario=scenario,
        trajectory=read_trajectory(run_dir / "trajectory.csv", robot_ids),
        commands=read_commands(run_dir / "commands.csv"),
        events=read_events(run_dir / "events.jsonl"),
    )


def contact_events(events: Iterable[dict[str, Any]]) -> list[tuple[float, int, int]]:
    """(t, id_a, id_b) of the `contact` events (fields `a`/`b`, `id_a`/`id_b` or `pair`)."""
    out = []
    for e in events:
        if e.get("kind") != "contact":
            continue
        pair = None
        for ka, kb in (("a", "b"), ("id_a", "id_b"), ("robot_a", "robot_b")):
            if ka in e and kb in e:
                pair = (e[ka], e[kb])
        for key in ("pair", "ids", "robots"):
            if pair is None and isinstance(e.get(key), list) and len(e[key]) == 2:
                pair = tuple(e[key])
        try:
            if pair is not None:
                out.append((float(e["t"]), int(pair[0]), int(pair[1])))
        except (KeyError, TypeError, ValueError):
            continue
    return out


def run_rates(data: RunData) -> tuple[float, float]:
    """(control period [s], world tick [s]) of a run.

    From an event carrying `control_rate_hz` / `world_rate_hz` (the runners log one at
    start) if any, else inferred: the median spacing of trajectory samples and of one
    robot's consecutive pose stamps; else the defaults (10 Hz, 50 Hz).
    """
    control_hz = world_hz = None
    for e in data.events:
        control_hz = control_hz or _positive(e.get("control_rate_hz"))
        world_hz = world_hz or _positive(e.get("world_rate_hz"))
    world_dt = 1.0 / world_hz if world_hz else None
    if world_dt is None and data.trajectory.t_s.size > 1:
        world_dt = float(np.median(np.diff(data.trajectory.t_s)))
    period = 1.0 / control_hz if control_hz else None
    cmds = data.commands
    if period is None and cmds.robot.size > 1:
        diffs = []
        for rid in np.unique(cmds.robot):
            mine = cmds.robot == rid
            stamps = cmds.pose_stamp_s[mine][np.argsort(cmds.seq[mine])]
            diffs.extend(np.diff(stamps).tolist())
        if diffs:
            period = float(np.median(diffs))
    return (period or 1.0 / DEFAULT_CONTROL_RATE_HZ, world_dt or 1.0 / DEFAULT_WORLD_RATE_HZ)


def _positive(value: object) -> float | None:
    if isinstance(value, int | float) and not isinstance(value, bool) and value > 0:
        return float(value)
    return None


def metrics_from_run_dir(run_dir: Path, *, control_period_s: float | None = None,
                         world_dt_s: float | None = None) -> RunMetrics:
    """Compute the metrics of a finished (or killed) run directory."""
    data = read_run_dir(Path(run_dir))
    period, tick = run_rates(data)
    metrics = compute_metrics(
        data.trajectory, data.commands, RunSpec.from_scenario(data.scenario),
        control_period_s=control_period_s or period,
        world_dt_s=world_dt_s or tick,
        contact_events=contact_events(data.events),
    )
    robot, stamps = read_timing_by_robot(Path(run_dir))
    groups = router_groups([r.id for r in data.scenario.robots], run_relays(data.events))
    return replace(metrics, wall_latency_ms=wall_latency_ms(stamps),
                   wall_latency_ms_by_router=wall_latency_ms_by_group(robot, stamps, groups))


def run_relays(events: Iterable[dict[str, Any]]) -> dict[str, list[int]]:
    """The relay routers of a run and their robots (the world's ``world_ready`` event:
    certificate name -> robot ids); empty if it had none."""
    for e in events:
        if e.get("kind") == "world_ready" and isinstance(e.get("relays"), dict):
            return {str(name): [int(i) for i in ids] for name, ids in e["relays"].items()}
    return {}


def read_timing_by_robot(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """timing.csv as ``(robot ids (K,), stamps (K, 9))`` int64
    (`eifp_wire.messages.TIMING_COLUMNS`); K = 0 if there is none."""
    path = Path(run_dir) / "timing.csv"
    robots: list[int] = []
    rows: list[list[int]] = []
    if path.is_file():
        with open(path, encoding="utf-8", newline="") as f:
            reader = csv.reader(f)
            next(reader, None)
            for row in reader:
                try:
                    robot = int(row[0])
                    values = [int(v) for v in row[2:]]
                except (ValueError, IndexError):
                    continue  # a killed run's half-written last line
                if len(values) == len(TIMING_COLUMNS):
                    robots.append(robot)
                    rows.append(values)
    return (np.array(robots, dtype=np.int64),
            np.array(rows, dtype=np.int64).reshape(-1, len(TIMING_COLUMNS)))


def read_timing(run_dir: Path) -> np.ndarray:
    """timing.csv's stamps as (K, 9) int64 (`eifp_wire.messages.TIMING_COLUMNS`); (0, 9) if none."""
    return read_timing_by_robot(run_dir)[1]


NUMERICS_PACKAGES = ("numpy", "scipy", "osqp", "pyrvo")
"""The libraries a lockstep run's numbers depend on: the same code and seed give the same
trajectory only with the same versions of these (and of Python)."""


def numerics_versions() -> dict[str, str | None]:
    """The installed versions of Python and of `NUMERICS_PACKAGES` (None if not installed),
    for run.json: a crowd run is chaotic, so another numpy or OSQP release can move its
    later decisions (docs/results.md)."""
    from importlib import metadata

    versions: dict[str, str | None] = {"python": platform.python_version()}
    for name in NUMERICS_PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def numerics_cpu() -> dict[str, Any]:
    """The processor a run's numbers came from, for run.json: its model name (Linux) and
    the SIMD targets numpy dispatches to on it. numpy picks its kernels at run time, so
    the same package versions can round differently on another CPU, and a chaotic crowd
    run can then end differently (docs/results.md: a run that left one robot short on one
    machine brought every robot on another, with the same versions)."""
    model = platform.processor() or None
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    dispatch: list[str] | None = None  # another numpy layout: say so, do not fail
    for module in ("numpy._core._multiarray_umath", "numpy.core._multiarray_umath"):
        try:  # numpy 2 names it _core; 1.26 (the oldest the project takes) core
            umath = importlib.import_module(module)
            features: dict[str, bool] = umath.__cpu_features__
            dispatch = [name for name in umath.__cpu_dispatch__ if features.get(name)]
            break
        except (ImportError, AttributeError):
            continue
    return {"model": model, "machine": platform.machine(), "numpy_simd": dispatch}


def write_json(path: Path, content: Any) -> Path:
    """Write JSON atomically (readers never see half a file), never through a symlink
    (`agent.files.replace_file`)."""
    return replace_file(path, (json.dumps(content, indent=2) + "\n").encode("utf-8"))


END_FIELDS = ("reason", "lost", "rejected", "stale", "stale_poses", "cmd_timeouts",
              "cmd_hold_expiries", "overruns", "rejected_by_reason", "seq_jumps", "future_cmds")
"""What `metrics.json` keeps of the run's ``end`` event (under ``end``)."""
ROBOT_FIELDS = ("rejected_poses", "refused_poses", "refused_control", "refused_config")
"""What `metrics.json` keeps (under ``end``) of the robots' totals in ``robots.json`` (a
distributed run): malformed poses, and well-formed poses, control messages and configuration
replies refused as not the world's."""


def write_metrics(run_dir: Path, metrics: RunMetrics, *, partial: bool = False) -> Path:
    """`metrics.json` of a run directory: the metrics, how the run ended (``end``: reason,
    lost robots, rejected, refused and stale message counts) and ``partial`` (true when the
    run was interrupted before its end: the figures cover only what was recorded)."""
    end = end_event(run_dir)
    content = metrics.to_json_dict()
    content["end"] = {k: end[k] for k in END_FIELDS if k in end}
    robots = read_json(Path(run_dir) / "robots.json")
    content["end"].update({k: robots[k] for k in ROBOT_FIELDS if k in robots})
    content["partial"] = bool(partial or not end)
    return write_json(Path(run_dir) / "metrics.json", content)


def find_run_dirs(paths: Iterable[Path]) -> list[Path]:
    """Run directories (holding `metrics.json`) at or below the given paths, sorted."""
    found: set[Path] = set()
    for p in map(Path, paths):
        if (p / "metrics.json").is_file():
            found.add(p)
        elif p.is_dir():
            found.update(m.parent for m in p.rglob("metrics.json"))
    return sorted(found)


def read_json(path: Path) -> dict[str, Any]:
    """A JSON object file, or {} when absent or malformed."""
    try:
        with open(path, encoding="utf-8") as f:
            content = json.load(f)
    except (OSError, json.JSONDecodeError):
        return {}
    return content if isinstance(content, dict) else {}


def safe_name(text: str) -> str:
    """`text` with every run of unsafe characters replaced by `_` (for file names)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_.-") or "run"


def end_event(run_dir: Path) -> dict[str, Any]:
    """The run's ``end`` event from events.jsonl ({} if there is none)."""
    events = read_events(Path(run_dir) / "events.jsonl")
    return next((e for e in reversed(events) if e.get("kind") == "end"), {})


@dataclass(frozen=True)
class RunEnding:
    """How a run ended, as `run.json` records it (the same for every way of running).

    Args:
        status: ``complete``, ``timed-out``, ``interrupted`` or ``crashed``.
        exit_code: the run's `agent.process.ExitCode`.
        end_reason: the ``end`` event's reason (``all_arrived``, ``arrived_or_lost``,
            ``time_limit``, ``signal``, ``startup_timeout``), None without an end event.
        lost: robots lost at the end.
    """

    status: str
    exit_code: int
    end_reason: str | None
    lost: tuple[int, ...]

    def as_json(self) -> dict[str, Any]:
        """The `run.json` fields: ``status``, ``exit_code``, ``end_reason``, ``lost``."""
        return {"status": self.status, "exit_code": int(self.exit_code),
                "end_reason": self.end_reason, "lost": list(self.lost)}


def run_ending(metrics: dict[str, Any] | None, end: dict[str, Any], *,
               interrupted: bool = False, crashed: bool = False) -> RunEnding:
    """The ending of a run from its metrics (`RunMetrics.to_json_dict`) and ``end`` event.

    Args:
        metrics: the run's metrics; None when it left none (crashed).
        end: its ``end`` event ({} if none).
        interrupted: the launcher was interrupted before the run ended.
        crashed: the world was lost (or left no trajectory).
    """
    from agent.process import ExitCode

    reason = end.get("reason")
    lost = tuple(int(r) for r in end.get("lost") or ())
    if interrupted:
        return RunEnding("interrupted", ExitCode.INTERRUPTED, reason, lost)
    if crashed or metrics is None:
        return RunEnding("crashed", ExitCode.WORLD_LOST, reason, lost)
    code = ExitCode.of_run(contacts=int(metrics.get("contacts") or 0),
                           all_arrived=metrics.get("arrived") == metrics.get("robots"),
                           robots_lost=bool(lost), interrupted=reason == "signal")
    status = ("interrupted" if reason == "signal" else
              "timed-out" if reason == "time_limit" else "complete")
    return RunEnding(status, code, reason, lost)
