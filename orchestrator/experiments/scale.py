"""Scale benchmark: real-time distributed runs of N robot processes, what each one costs.

    orchestrator scale --agents 16,32,64,128 [--family circles] [--planner P] [--seed S]
                       [--hosts 127.0.0.1,127.0.0.2] [--launcher fork|spawn]
                       [--time-scale 1] --out DIR [--json]

Every N is one normal distributed run
(`orchestrator.experiments.distributed.run_distributed`: the world
process and one robot process per robot, over Zenoh) in ``DIR/<family>_<N>/``, with its
metrics.json and trajectory.png. While it runs, a sampler thread in this process reads every
child process once per `SAMPLE_PERIOD_S` (psutil): its CPU time and, every
`MEMORY_EVERY`-th sample (5 s), its PSS (proportional set size: shared pages split between the
processes that map them; RSS where the kernel gives no PSS). Per N it reports:

- plan_ms p50/p99, latency_ms p50/p99, deadline_miss_rate, success, contacts, min_gap_m:
  the run's usual metrics (`orchestrator.analysis.metrics`; the latency is in sim time, quantised to
  world ticks);
- cpu_share_robots / cpu_share_world: CPU seconds used by all robot processes (the world)
  between the start and the end of the control phase (the first ``robot_left``), over that
  wall time times the
  number of CPUs (1.0 = the whole machine); cpu_pct_per_robot: the same per robot, in % of
  one core;
- mem_robot_mib: a robot process's peak PSS, mean over the robots; mem_total_mib: the
  largest simultaneous sum over the world, the robots and (``--launcher fork``) the
  `agent.fleet` parent that forked them (mem_fleet_mib); threads_per_robot: the most
  threads a robot process had;
- alive_s: wall time from spawning the processes to the world seeing the last robot's
  liveliness token (`robot_joined` events carry the wall clock);
- world_overruns: world ticks that fell more than a tick behind (the world resynchronises);
- robots_lost: robots whose liveliness token the world saw disappear during the run (a
  process that missed its 1 s transport lease under overload, or crashed);
- connections: the world's TCP connections per local address (robots reaching it through
  each of ``--hosts``);
- cpu_ms_per_plan_sense / _plan / _send / _loop / _threads: where a robot process's CPU
  went, per plan it sent: the robots' own thread and process CPU clocks over their loops
  (`agent.node.CpuMeter.summary`, from their exit lines in robots.json), summed over
  the robots and divided by all their plans. sense: decoding, assembling and observing
  poses; plan: estimates and the planner; send: encoding and publishing the command; loop:
  the rest of the main thread; threads: the other threads (Zenoh's runtime, the pose
  callback's);
- rx_bytes_per_robot_s / rx_msgs_per_robot_s: the pose payload bytes and messages one robot
  received per second of sim time (per wall second at time scale 1), mean over the robots
  (their exit lines: ``rx_pose_bytes``, ``rx_pose_msgs``, every message of the cells it
  held); cells_partial_rate: the share of its views released without every expected cell
  (`eifp_wire.pose_cells`);
- world_tick_ms_mean / world_tick_us_per_robot: the world's mean tick wall time (drain,
  step, publish every cell, record; the ``end`` event's ``tick_ms``), and divided by N.

``--hosts A,B``: the world listens on ``tls/0.0.0.0:PORT`` and robot k connects to
``tls/<hosts[k % len]>:PORT``, as robots on other hosts would (on Linux every 127.x.y.z
address is loopback, no set-up needed). Runs use mutual TLS and the run's access control
like ``orchestrator run`` (the world's certificate names every host); ``--insecure`` (plain
TCP) is refused with ``--hosts``: nothing listens on every interface without TLS.

Written to DIR: ``scale.csv``, ``scale.json`` (rows and the command line) and ``scale.png``
(one subplot per figure against N). Figures only: nothing here asserts a time budget.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import os
import secrets
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import psutil

from orchestrator.analysis.panels import Panel

SAMPLE_PERIOD_S = 0.5
MEMORY_EVERY = 10
"""Read PSS on every this many samples (reading smaps_rollup costs ~1 ms per process)."""
FAMILIES = ("circles", "circle", "crossing", "random")
DEFAULT_FAMILY = "circles"
"""Tiled 8-robot circles: the same local density and run length for every N (see docs/scale.md)."""
MIB = float(1 << 20)
ROBOT_NICE = 0
"""Default niceness added to the robots (see docs/scale.md: a nicer robot's Zenoh threads
starve too, and a missed 1 s lease loses the robot)."""

CPU_PARTS = ("sense", "plan", "send", "loop", "threads")
"""Parts of a robot process's CPU time (`agent.node.CpuMeter.summary`)."""

COLUMNS = (
    "agents", "family", "planner", "success", "arrived", "contacts", "min_gap_m",
    "plan_ms_p50", "plan_ms_p99", "sim_latency_ms_p50", "sim_latency_ms_p99",
    "sense_to_act_ms_p50", "sense_to_act_ms_p99", "deadline_miss_rate",
    "cpu_share_robots", "cpu_share_world", "cpu_pct_per_robot", "mem_robot_mib",
    "mem_world_mib", "mem_fleet_mib", "mem_total_mib", "mem_kind", "threads_per_robot",
    "alive_s", "sim_time_s", "wall_s", "world_overruns", "robots_lost", "world_status",
    "connections",
    "launcher",
    *(f"cpu_ms_per_plan_{part}" for part in CPU_PARTS), "cpu_ms_per_plan_total",
    "rx_bytes_per_robot_s", "rx_msgs_per_robot_s", "cells_partial_rate",
    "world_tick_ms_mean", "world_tick_us_per_robot",
)
PLOTTED = (
    Panel("planning time [ms]", ("plan_ms_p50", "plan_ms_p99")),
    Panel("sense -> act [wall ms]", ("sense_to_act_ms_p50", "sense_to_act_ms_p99")),
    Panel("deadline-miss rate", ("deadline_miss_rate",)),
    Panel("CPU share of the machine", ("cpu_share_robots", "cpu_share_world")),
    Panel("PSS per robot process [MiB]", ("mem_robot_mib",)),
    Panel("total PSS [MiB]", ("mem_total_mib",)),
    Panel("every robot alive after [s]", ("alive_s",)),
    Panel("contacts", ("contacts",)),
    Panel("pose kB received per robot per s", ("rx_bytes_per_robot_s",), factor=1e-3),
    Panel("pose messages received per robot per s", ("rx_msgs_per_robot_s",)),
    Panel("world tick per robot [us]", ("world_tick_us_per_robot",)),
)
"""The panels of scale.png."""


@dataclass
class _Proc:
    role: str  # "world" or "robot"
    cpu_s: list[tuple[float, float]] = field(default_factory=list)  # (wall, user + system)
    mem_peak_b: float = 0.0
    threads_peak: int = 0


class ResourceSampler(threading.Thread):
    """Samples this process's children (world and robots) until `stop()`.

    Args:
        period_s: wall time between samples.
        memory_every: read the memory on every this many samples.
    """

    def __init__(self, period_s: float = SAMPLE_PERIOD_S, memory_every: int = MEMORY_EVERY
                 ) -> None:
        super().__init__(name="scale-sampler", daemon=True)
        self.period_s = period_s
        self.memory_every = memory_every
        self.procs: dict[int, _Proc] = {}
        self.mem_total_peak_b = 0.0
        self.mem_kind = "pss"
        self.connections: dict[str, int] = {}
        self._handles: dict[int, psutil.Process] = {}
        self._done = threading.Event()

    def stop(self) -> None:
        self._done.set()
        self.join()

    def _role(self, proc: psutil.Process) -> str | None:
        try:
            cmd = proc.cmdline()
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
            return None
        if "-m" in cmd:
            module = cmd[cmd.index("-m") + 1] if cmd.index("-m") + 1 < len(cmd) else ""
            if module in ("world", "agent"):
                return "world" if module == "world" else "robot"
            if module == "agent.fleet":  # the launcher is our child, its robots are its
                return "fleet" if proc.ppid() == os.getpid() else "robot"
        return None

    def sample(self, k: int) -> None:
        """One pass over the children."""
        wall = time.monotonic()
        mem_sum = 0.0
        with_memory = k % self.memory_every == 0
        for child in psutil.Process().children(recursive=True):
            pid = child.pid
            if pid not in self._handles:
                role = self._role(child)
                if role is None:
                    continue
                self._handles[pid] = child
                self.procs[pid] = _Proc(role)
            proc, rec = self._handles[pid], self.procs[pid]
            try:
                with proc.oneshot():
                    t = proc.cpu_times()
                    rec.cpu_s.append((wall, t.user + t.system))
                    rec.threads_peak = max(rec.threads_peak, proc.num_threads())
                    if with_memory:
                        mem = self._memory_b(proc)
                        rec.mem_peak_b = max(rec.mem_peak_b, mem)
                        mem_sum += mem
                    if rec.role == "world" and with_memory:
                        self._count_connections(proc)
            except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
                continue
        self.mem_total_peak_b = max(self.mem_total_peak_b, mem_sum)

    def _memory_b(self, proc: psutil.Process) -> float:
        try:
            info = proc.memory_full_info()
            pss = getattr(info, "pss", None)
            if pss is not None:
                return float(pss)
        except psutil.AccessDenied:
            pass
        self.mem_kind = "rss"
        return float(proc.memory_info().rss)

    def _count_connections(self, proc: psutil.Process) -> None:
        counts: dict[str, int] = {}
        for conn in proc.net_connections(kind="tcp"):
            if conn.status == psutil.CONN_ESTABLISHED and conn.laddr:
                counts[conn.laddr.ip] = counts.get(conn.laddr.ip, 0) + 1
        for ip, count in counts.items():
            self.connections[ip] = max(self.connections.get(ip, 0), count)

    def run(self) -> None:
        k = 0
        while not self._done.is_set():
            self.sample(k)
            k += 1
            self._done.wait(self.period_s)

    def cpu_between(self, role: str, t0: float, t1: float) -> tuple[float, int]:
        """(CPU seconds of all `role` processes between monotonic t0 and t1, processes)."""
        total = 0.0
        count = 0
        for rec in self.procs.values():
            if rec.role != role or not rec.cpu_s:
                continue
            count += 1
            total += _cpu_at(rec.cpu_s, t1) - _cpu_at(rec.cpu_s, t0)
        return total, count


def _cpu_at(series: Sequence[tuple[float, float]], t: float) -> float:
    """Cumulative CPU time at monotonic t, linear between samples, clamped at the ends."""
    if t <= series[0][0]:
        return series[0][1] if t >= series[0][0] - SAMPLE_PERIOD_S else 0.0
    for (w0, c0), (w1, c1) in zip(series, series[1:]):
        if w0 <= t <= w1:
            return c0 + (c1 - c0) * (t - w0) / max(w1 - w0, 1e-9)
    return series[-1][1]


# --------------------------------------------------------------------------------------
# One run per N
# --------------------------------------------------------------------------------------

def _events(out_dir: Path) -> list[dict[str, Any]]:
    from orchestrator.analysis.rundir import read_events

    path = out_dir / "events.jsonl"
    return read_events(path) if path.exists() else []


def cpu_per_plan_ms(exits: dict[str, Any]) -> dict[str, float | None]:
    """The robots' CPU per plan by part (ms), from robots.json's parsed exit lines.

    Sums every process that reported its CPU split and divides by the plans those sent;
    None for every part if none did (or none planned).
    """
    reported = [p for p in exits.get("processes", ())
                if all(f"cpu_{part}_us" in p for part in CPU_PARTS)]
    plans = sum(int(p.get("plans", 0)) for p in reported)
    out: dict[str, float | None] = {
        f"cpu_ms_per_plan_{part}":
        (sum(int(p[f"cpu_{part}_us"]) for p in reported) / plans / 1e3 if plans else None)
        for part in CPU_PARTS}
    parts = [v for v in out.values() if v is not None]
    out["cpu_ms_per_plan_total"] = sum(parts) if parts else None
    return out


def scale_row(metrics: dict[str, Any], events: Sequence[dict[str, Any]],
              sampler: ResourceSampler, *, n: int, family: str, planner: str,
              spawn_wall: float, spawn_mono: float, wall_s: float, time_scale: float,
              world_status: int, launcher: str = "spawn", exits: dict[str, Any] | None = None
              ) -> dict[str, Any]:
    """One table row from a finished run (see the module docstring for each column).

    `exits`: the run's robots.json (`orchestrator.experiments.distributed.collect_robot_exits`).
    """
    lost = {int(e["robot"]) for e in events if e.get("kind") == "robot_lost" and "robot" in e}
    end: dict[str, Any] = next((e for e in reversed(events) if e.get("kind") == "end"), {})
    sim_time_s = float(metrics.get("sim_time_s") or 0.0)
    tick_ms = (end.get("tick_ms") or {}).get("mean")
    return {
        "agents": n,
        "family": family,
        "planner": planner,
        **_metric_columns(metrics),
        **_cpu_shares(events, sampler, spawn_wall=spawn_wall, spawn_mono=spawn_mono,
                      sim_time_s=sim_time_s, time_scale=time_scale),
        **_memory_columns(sampler, launcher),
        "alive_s": _alive_s(events, n, spawn_wall),
        "sim_time_s": sim_time_s,
        "wall_s": wall_s,
        "world_overruns": end.get("overruns"),
        "robots_lost": len(lost),
        "world_status": world_status,
        "connections": dict(sorted(sampler.connections.items())),
        **cpu_per_plan_ms(exits or {}),
        **received_per_robot(exits or {}, sim_time_s),
        "world_tick_ms_mean": tick_ms,
        "world_tick_us_per_robot": None if tick_ms is None else float(tick_ms) * 1e3 / n,
    }


def received_per_robot(exits: dict[str, Any], sim_time_s: float) -> dict[str, float | None]:
    """Pose bytes and messages one robot received per sim second, and the share of views
    released without every expected cell, from robots.json's parsed exit lines (None where
    no robot reported them)."""
    reported = [p for p in exits.get("processes", ())
                if "rx_pose_bytes" in p and "rx_pose_msgs" in p]
    views = sum(int(p.get("cells_views", 0)) for p in reported)
    per = len(reported) * sim_time_s
    return {
        "rx_bytes_per_robot_s": (sum(int(p["rx_pose_bytes"]) for p in reported) / per
                                 if per > 0 else None),
        "rx_msgs_per_robot_s": (sum(int(p["rx_pose_msgs"]) for p in reported) / per
                                if per > 0 else None),
        "cells_partial_rate": (sum(int(p.get("cells_partial", 0)) for p in reported) / views
                               if views else None),
    }


def _metric_columns(metrics: dict[str, Any]) -> dict[str, Any]:
    """The columns taken from metrics.json."""
    sense_to_act = (metrics.get("wall_latency_ms") or {}).get("sense_to_act") or {}
    return {
        "success": bool(metrics.get("success")),
        **{k: metrics.get(k) for k in ("arrived", "contacts", "min_gap_m", "plan_ms_p50",
                                       "plan_ms_p99", "sim_latency_ms_p50",
                                       "sim_latency_ms_p99")},
        "sense_to_act_ms_p50": sense_to_act.get("p50"),
        "sense_to_act_ms_p99": sense_to_act.get("p99"),
        "deadline_miss_rate": metrics.get("deadline_miss_rate"),
    }


def _alive_s(events: Sequence[dict[str, Any]], n: int, spawn_wall: float) -> float | None:
    """Wall time from the spawn until every robot's first token (None if some never came)."""
    first_join: dict[int, float] = {}  # a robot's first token (re-joins come later)
    for e in events:
        if e.get("kind") == "robot_joined" and "wall" in e and "robot" in e:
            first_join.setdefault(int(e["robot"]), float(e["wall"]))
    joined = list(first_join.values())
    return (max(joined) - spawn_wall) if len(joined) >= n else None


def _cpu_shares(events: Sequence[dict[str, Any]], sampler: ResourceSampler, *, spawn_wall: float,
                spawn_mono: float, sim_time_s: float, time_scale: float
                ) -> dict[str, float | None]:
    """The robots' and the world's share of the machine's CPUs from the start to the end,
    and the robots' CPU percent per robot (None before a start)."""
    start = next((e for e in events if e.get("kind") == "start"), None)
    if start is None or "wall" not in start:
        return dict.fromkeys(("cpu_share_robots", "cpu_share_world", "cpu_pct_per_robot"))
    t0 = spawn_mono + (float(start["wall"]) - spawn_wall)
    # The end: robots leave within milliseconds of the world's end message. A world
    # that fell behind real time took longer than sim time / time scale.
    left = [float(e["wall"]) for e in events if e.get("kind") == "robot_left" and "wall" in e]
    t1 = spawn_mono + (min(left) - spawn_wall) if left else t0 + sim_time_s / time_scale
    span = max(t1 - t0, 1e-9)
    cpus = psutil.cpu_count() or 1
    robots_s, n_robots = sampler.cpu_between("robot", t0, t1)
    world_s, _ = sampler.cpu_between("world", t0, t1)
    return {"cpu_share_robots": robots_s / (span * cpus),
            "cpu_share_world": world_s / (span * cpus),
            "cpu_pct_per_robot": 100.0 * robots_s / span / max(n_robots, 1)}


def _memory_columns(sampler: ResourceSampler, launcher: str) -> dict[str, Any]:
    """Peak memory per robot, of the world, of the fleet launcher and in all; the launcher;
    the most threads of one robot."""
    robots = [p for p in sampler.procs.values() if p.role == "robot" and p.mem_peak_b > 0]
    world = [p for p in sampler.procs.values() if p.role == "world"]
    fleet = [p for p in sampler.procs.values() if p.role == "fleet"]
    return {
        "mem_robot_mib": (sum(p.mem_peak_b for p in robots) / len(robots) / MIB
                          if robots else None),
        "mem_world_mib": world[0].mem_peak_b / MIB if world else None,
        "mem_fleet_mib": fleet[0].mem_peak_b / MIB if fleet else None,
        "launcher": launcher,
        "mem_total_mib": sampler.mem_total_peak_b / MIB if sampler.mem_total_peak_b else None,
        "mem_kind": sampler.mem_kind,
        "threads_per_robot": max((p.threads_peak for p in robots), default=None),
    }


def robot_endpoints(hosts: Sequence[str], port: int, robot_ids: Sequence[int]
                    ) -> dict[int, str]:
    """Robot k (in scenario order) connects through hosts[k % len(hosts)]."""
    return {rid: f"tcp/{hosts[k % len(hosts)]}:{port}" for k, rid in enumerate(robot_ids)}


def run_one(n: int, args: argparse.Namespace, out_root: Path) -> dict[str, Any]:
    """One distributed run of n robots; returns its row."""
    from orchestrator.analysis.rundir import (
        RunDirError,
        metrics_from_run_dir,
        write_json,
        write_metrics,
    )
    from orchestrator.experiments.distributed import free_tcp_endpoint, run_distributed
    from orchestrator.experiments.families import resolve
    from world.scenario_file import dump_scenario

    scenario = resolve(args.family, agents=n, seed=args.seed, planner=args.planner)
    if getattr(args, "seconds", None):
        scenario = dataclasses.replace(scenario, time_limit_s=float(args.seconds))
    out_dir = out_root / f"{args.family}_{n}"
    if (out_dir / "trajectory.csv").exists():
        raise SystemExit(f"error: {out_dir} already holds a run; choose another --out")
    out_dir.mkdir(parents=True, exist_ok=True)
    scenario_path = out_dir / "scenario.input.yaml"
    dump_scenario(scenario, scenario_path)
    planner = args.planner or scenario.robots[0].planner
    write_json(out_dir / "run.json", {
        "setup": args.family, "scenario": scenario.name, "planner": planner, "seed": args.seed,
        "mode": "distributed", "agents": n, "time_scale": args.time_scale,
        "hosts": list(args.hosts), "launcher": args.launcher, "robot_nice": args.robot_nice,
        "cpu_tokens": args.cpu_tokens, "no_plan": bool(getattr(args, "no_plan", False)),
        "argv": list(args.argv),
    })
    port = int(free_tcp_endpoint().rsplit(":", 1)[1])
    ids = [r.id for r in scenario.robots]
    if len(args.hosts) > 1 or args.hosts[0] != "127.0.0.1":
        endpoint = f"tcp/0.0.0.0:{port}"
        connect = robot_endpoints(args.hosts, port, ids)
    else:
        endpoint, connect = f"tcp/127.0.0.1:{port}", None
    run_id = f"scale-{n}-{secrets.token_hex(4)}"
    sampler = ResourceSampler()
    sampler.start()
    spawn_wall, spawn_mono = time.time(), time.monotonic()
    try:
        status = run_distributed(scenario_path, out_dir, run_id, time_scale=args.time_scale,
                                 endpoint=endpoint, robot_endpoints=connect,
                                 startup_timeout_s=args.startup_timeout_s,
                                 robot_launcher=args.launcher,
                                 robot_nice=args.robot_nice, cpu_tokens=args.cpu_tokens,
                                 tls=not getattr(args, "insecure", False),
                                 tls_ca=getattr(args, "tls_ca_dir", None),
                                 robot_args=["--no-plan"] if getattr(args, "no_plan", False)
                                 else [])
    finally:
        sampler.stop()
    wall_s = time.monotonic() - spawn_mono
    try:
        metrics = metrics_from_run_dir(out_dir)
        write_metrics(out_dir, metrics)
        content = metrics.to_json_dict()
    except RunDirError as exc:
        print(f"warning: {out_dir}: no metrics: {exc}", file=sys.stderr)
        content = {}
    _plot_run(out_dir)
    try:
        exits = json.loads((out_dir / "robots.json").read_text())
    except (OSError, ValueError) as exc:
        print(f"warning: {out_dir}: no robots.json: {exc}", file=sys.stderr)
        exits = {}
    return scale_row(content, _events(out_dir), sampler, n=n, family=args.family,
                     planner=planner, spawn_wall=spawn_wall, spawn_mono=spawn_mono,
                     wall_s=wall_s, time_scale=args.time_scale, world_status=status,
                     launcher=args.launcher, exits=exits)


def _plot_run(out_dir: Path) -> None:
    try:
        from orchestrator.analysis.plots import plot_trajectories
        from orchestrator.analysis.rundir import read_run_dir

        plot_trajectories(read_run_dir(out_dir), out_dir / "trajectory.png")
    except Exception as exc:  # noqa: BLE001 - the run is done; keep its figures
        print(f"warning: plotting {out_dir} failed: {type(exc).__name__}: {exc}",
              file=sys.stderr)


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------

def _fmt(value: object, digits: int = 2) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return "-" if not math.isfinite(value) else f"{value:.{digits}f}"
    return str(value)


def _kilo(value: object) -> float | None:
    return float(value) / 1e3 if isinstance(value, int | float) else None


def format_rows(rows: Sequence[dict[str, Any]]) -> str:
    """The printed table, one row per N."""
    head = ["N", "ok", "arrived", "contacts", "plan p50/p99 ms", "latency p50/p99 ms",
            "miss %", "CPU robots/world %", "CPU/robot %",
            "CPU ms/plan sense/plan/send/loop/threads = total", "sense->act p50/p99 ms",
            "PSS/robot MiB", "PSS total MiB", "rx kB/s / msgs/s per robot",
            "world tick us/robot", "alive s", "lost", "sim s", "wall s"]
    body = []
    for r in rows:
        miss = r["deadline_miss_rate"]
        cpu_r, cpu_w = r["cpu_share_robots"], r["cpu_share_world"]
        body.append([
            str(r["agents"]), _fmt(r["success"]), f"{_fmt(r['arrived'])}/{r['agents']}",
            _fmt(r["contacts"]),
            f"{_fmt(r['plan_ms_p50'])}/{_fmt(r['plan_ms_p99'])}",
            f"{_fmt(r['sim_latency_ms_p50'], 1)}/{_fmt(r['sim_latency_ms_p99'], 1)}",
            _fmt(100.0 * miss if miss is not None else None),
            f"{_fmt(100 * cpu_r if cpu_r is not None else None, 1)}/"
            f"{_fmt(100 * cpu_w if cpu_w is not None else None, 1)}",
            _fmt(r["cpu_pct_per_robot"], 1),
            "/".join(_fmt(r.get(f"cpu_ms_per_plan_{part}")) for part in CPU_PARTS)
            + f" = {_fmt(r.get('cpu_ms_per_plan_total'))}",
            f"{_fmt(r.get('sense_to_act_ms_p50'), 1)}/{_fmt(r.get('sense_to_act_ms_p99'), 1)}",
            _fmt(r["mem_robot_mib"], 1),
            _fmt(r["mem_total_mib"], 0),
            f"{_fmt(_kilo(r.get('rx_bytes_per_robot_s')), 1)} / "
            f"{_fmt(r.get('rx_msgs_per_robot_s'), 0)}",
            _fmt(r.get("world_tick_us_per_robot"), 1),
            _fmt(r["alive_s"], 1), _fmt(r["robots_lost"]),
            _fmt(r["sim_time_s"], 1),
            _fmt(r["wall_s"], 1),
        ])
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h)
              for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths)),
             "  ".join("-" * w for w in widths)]
    lines += ["  ".join(c.ljust(w) for c, w in zip(b, widths)) for b in body]
    return "\n".join(lines)


def write_outputs(rows: Sequence[dict[str, Any]], out_root: Path, argv: Sequence[str]
                  ) -> list[Path]:
    """scale.csv, scale.json and scale.png in out_root."""
    from orchestrator.analysis.rundir import write_json

    csv_path = out_root / "scale.csv"
    with open(csv_path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        for r in rows:
            writer.writerow({k: (json.dumps(r[k]) if isinstance(r[k], dict) else r[k])
                             for k in COLUMNS})
    json_path = write_json(out_root / "scale.json", {
        "argv": list(argv), "cpus": psutil.cpu_count(),
        "memory_total_mib": psutil.virtual_memory().total / MIB, "rows": list(rows)})
    png_path = plot_scale(rows, out_root / "scale.png")
    return [csv_path, json_path, png_path]


def plot_scale(rows: Sequence[dict[str, Any]], path: Path) -> Path:
    """One panel per figure of `PLOTTED` against N (log2 axis)."""
    from orchestrator.analysis.plots import plot_against_n

    return plot_against_n(rows, PLOTTED, path, ncols=4, x_label="robot processes N",
                          title="orchestrator scale")


# --------------------------------------------------------------------------------------
# `orchestrator bench --process`: a non-planning robot's own cost per cycle
# --------------------------------------------------------------------------------------

PROCESS_BENCH_SECONDS = 20.0
"""Sim (= wall) seconds of an `orchestrator bench --process` run."""


def process_bench_args(robots: int, seconds: float, *, insecure: bool = False,
                       argv: Sequence[str] = ()) -> argparse.Namespace:
    """The `run_one` options of `orchestrator bench --process`: the default family at real
    time, robots forked by `agent.fleet`, ``--no-plan`` and the run cut at `seconds`."""
    return argparse.Namespace(
        family=DEFAULT_FAMILY, seed=0, planner=None, agents=[robots], seconds=seconds,
        time_scale=1.0, hosts=["127.0.0.1"], launcher="fork", robot_nice=ROBOT_NICE,
        cpu_tokens=None, startup_timeout_s=60.0, no_plan=True, insecure=insecure,
        tls_ca_dir=None, argv=list(argv))


def format_process_row(row: dict[str, Any]) -> str:
    """The figures of one `orchestrator bench --process` run, one per line.

    Per cycle is per command sent: a non-planning robot senses once and commands a stop
    once per control period.
    """
    parts = [row.get(f"cpu_ms_per_plan_{part}") for part in CPU_PARTS]
    labels = ("sense", "brake", "send", "loop", "Zenoh threads")
    split = "  ".join(f"{label} {_fmt(v, 3)}" for label, v in zip(labels, parts))
    sampled = row.get("cpu_pct_per_robot")
    lines = [
        f"robot process without planning, {row['agents']} robots, "
        f"{_fmt(row.get('sim_time_s'), 0)} s ({row.get('transport', '')}):",
        f"  CPU ms per cycle: {split} = {_fmt(row.get('cpu_ms_per_plan_total'), 3)}",
        "    (each robot's own thread and process CPU clocks over its loop: sense = decode "
        "and observe the pose, brake = the stop command, send = encode and publish, loop = "
        "the rest of the main thread: waiting, control and liveliness; Zenoh threads = "
        "every other thread. Compare with orchestrator bench --floor)",
        f"  robot process CPU sampled from outside (psutil): {_fmt(sampled, 2)} % of a core "
        f"= {_fmt(sampled, 3)} ms per 100 ms cycle",
        f"  sense -> act wall ms p50 / p99: {_fmt(row.get('sense_to_act_ms_p50'), 1)} / "
        f"{_fmt(row.get('sense_to_act_ms_p99'), 1)}; threads per robot "
        f"{row.get('threads_per_robot')}; robots lost {row.get('robots_lost')}",
    ]
    return "\n".join(lines)
