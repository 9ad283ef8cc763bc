"""Planner benchmark: the wall time of one robot's planning cycle on crowded observations.

    orchestrator bench --planner P --robots N [--cycles C] [--seed S] [--json]

P is a planner name, a comma-separated list or `all`; N a robot count or a comma-separated
list (e.g. `--robots 2,8,16,32,64`). Each (planner, N) pair is one row of the table.

The scene: N robots on a circle converging on the centre (the `circle` family, every robot
with planner P), shrunk so neighbouring starts are `SPACING_M` apart, but no smaller than
half the sensing radius (small crowds then see each other from the first cycle). World
(`world.sim.dynamics.WorldSim`, 50 Hz) and one `agent.planning.controller.RobotController` per robot
(10 Hz) are stepped in-process exactly as in a lockstep run. An episode ends once every
robot has passed the centre (or after `EPISODE_TIME_FACTOR` times the ideal time); episodes
repeat, starts jittered by `JITTER_M` from `--seed`, until C planning cycles were timed.

Timed, for every call of `RobotController.plan(now_s)` (the full cycle: building the
observation, i.e. the neighbours' velocity and linearity estimates from their pose history
and the latency forward prediction, which is zero here as in-process poses are never old;
then the planner): its wall time with `time.perf_counter`, and the CPU time this thread
spent in it with `time.thread_time_ns` (``cpu_ms``: on a machine shared with other jobs the
wall time also counts the time the thread waited for a core, its CPU time does not). Also
the planner's own stage split (`PlanResult.times`, wall time: threats, via-points, spline,
control; eIFP-MPC's constant-velocity neighbour predictions fall in control). "obs" is the
full cycle minus the planner's total (observation building and call overhead). `observe()`
(adding the snapshot to the history) is not timed. Not counted: the first `WARMUP_ROUNDS` rounds of
every episode (a fresh controller sets up its solver on its first plan, and needs two
snapshots for velocity estimates) and cycles whose status is ARRIVED or STALE (no
planning happened); both are reported.

Neighbours per cycle: the others within the sensing radius of the planning robot ("in
range") and how many of them the planner considers (at most `max_neighbors`, the cap).

With `--json`, one JSON object per row is printed after the table, each on its own line;
for a single row that object is the last line, otherwise the last line is
``{"rows": [...]}`` holding every row. Figures only: nothing here asserts a time budget.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agent.core.scenario import Scenario
from agent.core.types import PlanStatus, PoseSnapshot, StageTimes
from agent.planning.mpc_qp import DEFAULT_TUNING
from orchestrator.experiments.families import circle, jitter_starts, with_planner
from orchestrator.experiments.scenario_blocks import MIN_START_SPACING_M

WORLD_RATE_HZ = 50.0
CONTROL_RATE_HZ = 10.0
SPACING_M = MIN_START_SPACING_M
"""Centre distance of neighbouring starts on the circle (the densest the family allows)."""
JITTER_M = 0.25
"""Starts are moved by up to this much per episode (breaks the circle's exact symmetry)."""
WARMUP_ROUNDS = 2
"""Planning rounds at the start of every episode that are run but not timed."""
EPISODE_TIME_FACTOR = 4.0
"""An episode gives up after this many times the ideal time to cross the circle."""
DEFAULT_CYCLES = 5000
"""Cycles timed per row: p99 rests on 50 samples."""
CMD_TIMEOUT_S = 0.5
EXCLUDED_STATUSES = (PlanStatus.ARRIVED, PlanStatus.STALE)
STAGES = ("threats", "viapoints", "spline", "control", "obs")
"""Stage columns besides the full cycle ("plan"); "obs" = full cycle - planner total."""


@dataclass
class BenchSamples:
    """Per-cycle records of one (planner, N) row; every list has one entry per counted cycle."""

    plan_ms: list[float] = field(default_factory=list)
    cpu_ms: list[float] = field(default_factory=list)
    """Thread CPU time of every counted `RobotController.plan` call [ms]."""
    stage_ms: dict[str, list[float]] = field(
        default_factory=lambda: {s: [] for s in STAGES})
    in_range: list[int] = field(default_factory=list)
    considered: list[int] = field(default_factory=list)
    statuses: Counter[str] = field(default_factory=Counter)
    solver_iterations: list[int] = field(default_factory=list)
    """OSQP iterations per counted cycle (eIFP-MPC; 0 where OSQP was not called)."""
    excluded: Counter[str] = field(default_factory=Counter)
    warmup: int = 0
    episodes: int = 0
    passed_centre: int = 0
    contacts: int = 0
    sim_time_s: float = 0.0

    def __len__(self) -> int:
        return len(self.plan_ms)

    def add(self, plan_ms: float, times: StageTimes, in_range: int, cap: int,
            status: str, solver_iterations: int = 0, cpu_ms: float = math.nan) -> None:
        """Record one counted cycle: its full wall and CPU time and the planner's stage
        split (wall)."""
        self.plan_ms.append(plan_ms)
        self.cpu_ms.append(cpu_ms)
        self.stage_ms["threats"].append(times.threats_ms)
        self.stage_ms["viapoints"].append(times.viapoints_ms)
        self.stage_ms["spline"].append(times.spline_ms)
        self.stage_ms["control"].append(times.control_ms)
        self.stage_ms["obs"].append(plan_ms - times.total_ms)
        self.in_range.append(in_range)
        self.considered.append(min(in_range, cap))
        self.statuses[status] += 1
        self.solver_iterations.append(solver_iterations)


def bench_scenario(n: int, planner: str) -> Scenario:
    """The circle family with `n` robots running `planner`, shrunk to a dense crowd.

    Neighbouring starts are `SPACING_M` apart; the radius is at least half the family's
    sensing radius, so a small crowd is in sight from the start. Starts, goals and
    headings keep the family's exact symmetry.
    """
    base = with_planner(circle(n), planner)
    old_radius_m = math.hypot(*base.robots[0].start[:2])
    radius_m = max(SPACING_M / (2.0 * math.sin(math.pi / n)),
                   base.planner_config.threats.sensing_radius_m / 2.0)
    scale = radius_m / old_radius_m
    robots = tuple(
        dataclasses.replace(r, start=(r.start[0] * scale, r.start[1] * scale, r.start[2]),
                            goal=(r.goal[0] * scale, r.goal[1] * scale))
        for r in base.robots
    )
    return dataclasses.replace(
        base, name=f"bench_circle_{n}", robots=robots,
        description=f"{n} robots on a circle of radius {radius_m:.2f} m, antipodal swap")


def circle_radius_m(scenario: Scenario) -> float:
    """Radius of the (unjittered) bench circle."""
    return math.hypot(*scenario.robots[0].start[:2])


def _in_range(snapshot: PoseSnapshot, sensing_radius_m: float) -> np.ndarray:
    """(n,) for every robot of the snapshot, the other discs within the sensing radius."""
    rows = np.flatnonzero(snapshot.ids >= 0)
    xy = snapshot.pose[:, :2]
    gap = xy[None, :, :] - xy[rows, None, :]  # (n, n_all, 2), centre to centre
    dist = np.hypot(gap[..., 0], gap[..., 1])
    dist[np.arange(rows.size), rows] = np.inf  # not oneself
    counts: np.ndarray = np.count_nonzero(dist <= sensing_radius_m, axis=1)
    return counts


def _percentiles(values: Sequence[float]) -> tuple[float, float, float]:
    """(p50, p99, max); NaN for no values."""
    if len(values) == 0:
        return math.nan, math.nan, math.nan
    a = np.asarray(values, dtype=float)
    p50, p99 = np.percentile(a, [50.0, 99.0])
    return float(p50), float(p99), float(a.max())


def run_bench(planner: str, n: int, cycles: int, seed: int = 0) -> BenchSamples:
    """Time `cycles` planning cycles of `planner` in a crowd of `n` robots
    (`bench_scenario`, starts jittered by up to `JITTER_M`).

    Args:
        planner: one of `PLANNER_NAMES`.
        n: robots on the circle (>= 2).
        cycles: planning calls to time (>= 1), over as many episodes as it takes.
        seed: seeds the per-episode start jitter.
    """
    return time_cycles(bench_scenario(n, planner), cycles, seed, jitter_m=JITTER_M)


def time_cycles(base: Scenario, cycles: int, seed: int = 0, *,
                jitter_m: float = JITTER_M) -> BenchSamples:
    """Time `cycles` planning cycles of the robots of `base`, episode after episode (see the
    module docstring); `run_bench` on any scene.

    Args:
        base: the scene; each episode starts from it, jittered.
        cycles: planning calls to time (>= 1), over as many episodes as it takes.
        seed: seeds the per-episode start jitter.
        jitter_m: each episode moves every start by up to this much [m].
    """
    from agent.planning.controller import RobotController
    from world.sim.dynamics import WorldSim

    n = len(base.robots)
    cfg = base.planner_config
    ticks_per_round = round(WORLD_RATE_HZ / CONTROL_RATE_HZ)
    dt_s = 1.0 / WORLD_RATE_HZ
    period_s = 1.0 / CONTROL_RATE_HZ
    longest_m = max(math.dist(r.start[:2], r.goal) for r in base.robots)
    v_max_mps = min(r.limits.v_max_mps for r in base.robots)
    max_rounds = WARMUP_ROUNDS + max(1, math.ceil(EPISODE_TIME_FACTOR * longest_m / v_max_mps
                                                  / period_s))
    out = BenchSamples()
    rng = np.random.default_rng(seed)
    while len(out) < cycles:
        scenario = jitter_starts(base, jitter_m, rng)
        world = WorldSim(scenario, cmd_timeout_s=CMD_TIMEOUT_S)
        controllers = [RobotController(spec, cfg, scenario.goal_tolerance_m,
                                       control_period_s=period_s)
                       for spec in scenario.robots]
        start = np.array([r.start[:2] for r in scenario.robots])
        course = np.array([r.goal for r in scenario.robots]) - start  # (n, 2)
        half_sq = 0.5 * np.einsum("ij,ij->i", course, course)  # passed: progress . course >= it
        counted_before = len(out)
        passed = np.zeros(len(controllers), dtype=bool)
        out.episodes += 1
        for round_ in range(max_rounds):
            snapshot = world.snapshot()
            in_range = _in_range(snapshot, cfg.threats.sensing_radius_m)
            timed = round_ >= WARMUP_ROUNDS
            for k, ctrl in enumerate(controllers):
                ctrl.observe(snapshot)
                c0 = time.thread_time_ns()
                t0 = time.perf_counter()
                result = ctrl.plan(world.t_s)
                elapsed_ms = (time.perf_counter() - t0) * 1e3
                cpu_ms = (time.thread_time_ns() - c0) * 1e-6
                world.set_command(ctrl.spec.id, result.v_mps, result.omega_radps)
                if not timed:
                    out.warmup += 1
                elif result.status in EXCLUDED_STATUSES:
                    out.excluded[str(result.status.value)] += 1
                elif len(out) < cycles:
                    out.add(elapsed_ms, result.times, int(in_range[k]), cfg.threats.max_neighbors,
                            str(result.status.value), result.solver_iterations, cpu_ms)
            for _ in range(ticks_per_round):
                world.step(dt_s)
            out.sim_time_s += period_s
            progress = np.einsum("ij,ij->i", world.pose[:, :2] - start, course)
            passed = progress >= half_sq
            if len(out) >= cycles or np.all(passed):
                break
        out.passed_centre += int(np.count_nonzero(passed))
        out.contacts += world.contact_count
        if len(out) == counted_before:
            raise RuntimeError(f"bench {base.name} N={n}: an episode had no cycle to time "
                               f"(excluded: {dict(out.excluded)})")
    return out


def summarize(planner: str, n: int, samples: BenchSamples, *, seed: int, wall_s: float,
              scenario: Scenario) -> dict[str, Any]:
    """One row of figures (the JSON object of the row)."""
    cfg = scenario.planner_config
    row: dict[str, Any] = {"planner": planner, "robots": n, "cycles": len(samples)}
    for name, values in (("plan", samples.plan_ms), ("cpu", samples.cpu_ms),
                         *((s, samples.stage_ms[s]) for s in STAGES)):
        p50, p99, top = _percentiles(values)
        row[f"{name}_ms_p50"] = p50
        row[f"{name}_ms_p99"] = p99
        row[f"{name}_ms_max"] = top
    row["plan_ms_mean"] = float(np.mean(samples.plan_ms)) if len(samples) else math.nan
    row["cpu_ms_mean"] = float(np.mean(samples.cpu_ms)) if len(samples) else math.nan
    row.update({
        "neighbors_mean": float(np.mean(samples.considered)) if len(samples) else math.nan,
        "neighbors_max": int(max(samples.considered, default=0)),
        "neighbors_in_range_mean": float(np.mean(samples.in_range)) if len(samples)
        else math.nan,
        "neighbors_in_range_max": int(max(samples.in_range, default=0)),
        "max_neighbors": cfg.threats.max_neighbors,
        "sensing_radius_m": cfg.threats.sensing_radius_m,
        "excluded": int(sum(samples.excluded.values())),
        "excluded_statuses": dict(sorted(samples.excluded.items())),
        "warmup_cycles": samples.warmup,
        "statuses": dict(sorted(samples.statuses.items())),
        **_iteration_figures(samples.solver_iterations, DEFAULT_TUNING.max_iter),
        "episodes": samples.episodes,
        "passed_centre": samples.passed_centre,
        "contacts": samples.contacts,
        "circle_radius_m": round(circle_radius_m(scenario), 3),
        "sim_time_s": round(samples.sim_time_s, 3),
        "wall_s": round(wall_s, 3),
        "seed": seed,
    })
    return row


def _iteration_figures(iterations: Sequence[int], cap: int) -> dict[str, Any]:
    """OSQP iterations of the cycles that called it: p50, p99, max and the share at the cap.

    The MPC stage's time tail is its iteration tail (about 6 us an iteration here), so
    these figures say why a p99 moved without depending on the machine's speed.
    """
    called = np.asarray([i for i in iterations if i > 0], dtype=float)
    if called.size == 0:
        return {}
    p50, p99 = np.percentile(called, [50.0, 99.0])
    return {"solver_iterations_p50": float(p50), "solver_iterations_p99": float(p99),
            "solver_iterations_max": int(called.max()),
            "solver_at_cap_frac": float(np.mean(called >= cap)), "solver_max_iter": cap}


def _ms(row: dict[str, Any], name: str) -> str:
    return "/".join(f"{row[f'{name}_ms_{q}']:.3f}" for q in ("p50", "p99", "max"))


def format_rows(rows: Sequence[dict[str, Any]]) -> str:
    """The table: one line per (planner, N); times in ms as p50/p99/max."""
    from orchestrator.analysis.report import format_table

    header = ["planner", "N", "cycles", "excl", "cycle ms p50/p99/max",
              "cycle CPU ms p50/p99/max", "threats ms",
              "via-points ms", "spline ms", "control ms", "obs ms", "nbrs mean/max"]
    body = [[r["planner"], r["robots"], r["cycles"], r["excluded"], _ms(r, "plan"),
             _ms(r, "cpu"), _ms(r, "threats"), _ms(r, "viapoints"), _ms(r, "spline"),
             _ms(r, "control"), _ms(r, "obs"), f"{r['neighbors_mean']:.1f}/{r['neighbors_max']}"]
            for r in rows]
    caps = sorted({(r["max_neighbors"], r["sensing_radius_m"]) for r in rows})
    cap_text = ", ".join(f"at most {m} within {s:g} m" for m, s in caps)
    notes = [f"nbrs: others the planner considers per cycle ({cap_text}); "
             "obs: full cycle minus the planner's stages (observation building). "
             "cycle ms is wall time (perf_counter), cycle CPU ms this thread's CPU time "
             "(thread_time): on a busy machine only the CPU time is the planner's own; "
             "the stage split is wall time."]
    silent = sorted({r["planner"] for r in rows
                     if r["planner"] != "orca" and r["threats_ms_max"] == 0.0})
    if silent:
        notes.append(f"threats 0 ({', '.join(silent)}): the planner reported no separate "
                     "threat-assessment time (PlanResult.times.threats_ms = 0); it is inside "
                     "via-points.")
    for r in rows:
        statuses = ", ".join(f"{k} {v}" for k, v in r["statuses"].items())
        excluded = ", ".join(f"{k} {v}" for k, v in r["excluded_statuses"].items()) or "none"
        notes.append(
            f"{r['planner']} N={r['robots']}: statuses {statuses}; excluded {excluded}; "
            f"warm-up {r['warmup_cycles']}; in range mean/max "
            f"{r['neighbors_in_range_mean']:.1f}/{r['neighbors_in_range_max']}; "
            f"{r['episodes']} episode(s), circle {r['circle_radius_m']:g} m, "
            f"{r['passed_centre']} passed the centre, contacts {r['contacts']}; "
            f"sim {r['sim_time_s']:g} s, wall {r['wall_s']:.1f} s")
        if "solver_iterations_p50" in r:
            notes.append(
                f"{r['planner']} N={r['robots']}: OSQP iterations p50/p99/max "
                f"{r['solver_iterations_p50']:.0f}/{r['solver_iterations_p99']:.0f}/"
                f"{r['solver_iterations_max']}, {100 * r['solver_at_cap_frac']:.2f} % of the "
                f"solves at the cap of {r['solver_max_iter']}")
    return format_table(header, body) + "\n\n" + "\n".join(notes)
