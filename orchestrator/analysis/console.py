"""Console output of a run for humans: the live progress line and the end-of-run summary."""

from __future__ import annotations

import math
import sys
import time
from typing import Any, TextIO

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)

from orchestrator.analysis.report import format_table


class ProgressLine:
    """The live progress of a run on stderr.

    On a terminal: a `rich` progress bar of the robots that arrived, with sim time, contacts,
    lost robots and wall time, redrawn in place. Elsewhere (a log file, CI): one plain line
    every 5 s, so logs stay readable.
    """

    def __init__(self, label: str, stream: TextIO | None = None, *, quiet: bool = False) -> None:
        self.label = label
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.tty = self.stream.isatty()
        self._last_wall = -math.inf
        self._bar: Progress | None = None
        self._task: TaskID | None = None

    def __call__(self, progress: object) -> None:
        """Accepts `LockstepProgress` or `DistributedProgress` (same field names, read with
        `getattr`)."""
        if self.quiet:
            return
        arrived = getattr(progress, "arrived", ())
        n_arrived = arrived if isinstance(arrived, int) else len(arrived)
        n_robots = getattr(progress, "n_robots", None)
        sim_t = float(getattr(progress, "sim_t_s", 0.0))
        wall = float(getattr(progress, "wall_s", 0.0))
        status = f"t = {sim_t:7.1f} s   contacts {getattr(progress, 'contacts', 0)}"
        if not getattr(progress, "started", True):
            status += "   (waiting for robots)"
        lost = getattr(progress, "lost", ())
        if lost:
            status += f"   lost {sorted(lost)}"
        if self.tty:
            self._draw(n_arrived, n_robots, status)
            return
        now = time.monotonic()
        if now - self._last_wall < 5.0:
            return
        self._last_wall = now
        self.stream.write(f"[{self.label}] {status}   arrived {n_arrived}/{n_robots or '?'}"
                          f"   wall {wall:6.1f} s\n")
        self.stream.flush()

    def _draw(self, n_arrived: int, n_robots: int | None, status: str) -> None:
        if self._bar is None:
            self._bar = Progress(
                TextColumn(f"[bold]{self.label}[/bold]"), BarColumn(),
                MofNCompleteColumn(), TextColumn("arrived   {task.fields[status]}"),
                TimeElapsedColumn(), console=Console(file=self.stream), transient=False)
            self._task = self._bar.add_task(self.label, total=n_robots, status=status)
            self._bar.start()
        assert self._task is not None
        self._bar.update(self._task, completed=n_arrived, total=n_robots, status=status)

    def done(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None


def run_summary(metrics: dict[str, Any], label: str) -> str:
    """The end-of-run table: run-level metrics, then one row per robot."""
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
        ("sim_latency_ms_p50", "command age p50 [sim ms]"),
        ("sim_latency_ms_p99", "command age p99 [sim ms]"),
        ("deadline_miss_rate", "deadline miss rate"), ("sim_time_s", "sim time [s]"),
    ]
    rows = [[label_, metrics.get(k)] for k, label_ in keys]
    rows[1][1] = f"{metrics.get('arrived')}/{metrics.get('robots')}"
    wall = metrics.get("wall_latency_ms") or {}
    stages = (("sense_to_act", "sense to act"), ("end_to_end", "pose to applied"),
              ("plan", "plan (wall)"), ("transport", "on the wire, both ways"))
    for stage, label_ in stages:
        if stage in wall:
            w = wall[stage]
            rows.append([f"{label_} p50/p99/max [wall ms]",
                         f"{w['p50']:.1f} / {w['p99']:.1f} / {w['max']:.1f}"])
    for router, by_stage in (metrics.get("wall_latency_ms_by_router") or {}).items():
        for stage, label_ in (stages[0], stages[3]):
            if stage in by_stage:
                w = by_stage[stage]
                rows.append([f"{label_}, robots on {router} p50/p99/max [wall ms]",
                             f"{w['p50']:.2f} / {w['p99']:.2f} / {w['max']:.2f}"])
    end = metrics.get("end") or {}
    rows += [["end reason", end.get("reason")],
             ["robots lost", ", ".join(map(str, end.get("lost") or [])) or "none"],
             ["rejected messages", end.get("rejected")], ["stale messages", end.get("stale")]]
    if metrics.get("partial"):
        rows.append(["partial", "yes: interrupted, figures cover what was recorded"])
    top = format_table([label, ""], rows)
    per = [[r.get("id"), r.get("arrived"), r.get("time_to_goal_s"), r.get("time_ratio"),
            r.get("path_length_m"), r.get("path_ratio"), r.get("oscillations"),
            r.get("side_flips"), r.get("contacts"), r.get("min_gap_m"), r.get("plan_ms_p50")]
           for r in metrics.get("per_robot", [])]
    robots = format_table(["robot", "arrived", "t_goal s", "t/ideal", "path m", "path/line",
                           "osc", "flips", "contacts", "min gap m", "plan p50 ms"], per)
    return top + "\n\n" + robots
