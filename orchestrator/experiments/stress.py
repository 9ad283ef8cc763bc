"""`orchestrator stress`: fault level x planner x seed runs, a table and the safety envelope.

A *level* is one point of the swept grid (the Cartesian product of the ``--sweep KEY=V,...``
options), applied on top of the base link faults. The keys are `world.sim.link.LinkFaults`
fields: ``latency_ms``, ``jitter_ms``, ``drop``, ``dup``, ``reorder``. Unless ``jitter_ms``
is swept or given, a level's jitter is ``jitter_frac x latency_ms`` (30 % by default, so
``latency_ms=100`` means 100 ms ± 30 ms on every pose and command link). Run ``s`` of a
level uses seed ``s`` for the start jitter and for every link's generator.

Each run is one `run_lockstep` (default: deterministic, fast) or `run_distributed` call in a
worker process (``--jobs`` at a time). Written in ``--out``: one run directory per run,
``stress.csv`` (one row per run), ``stress.json`` (the rows, the per-level table and the
envelope) and the printed table: per planner and level, the success rate, the contacts
(total, and runs with any), the smallest gap over the seeds and the mean time ratio.

The *envelope* of a planner, per swept key: the largest value v such that every level with
that key <= v (the other keys at their smallest swept value) had zero contacts in every
seed and every robot arrived (robots lost to a ``--kill-robot`` aside): a planner that
deadlocks is never in contact, and is not in the envelope for it. None: contacts or robots
short of their goals already at the smallest value.

Robot faults (``--kill-robot``, ``--stop-robot``, ``--restart-robot``, ``--slow-robot``,
``--robot-rate``, as for ``orchestrator run``) apply unchanged to every run of the sweep:
``orchestrator stress setup_g --kill-robot 0@28 --sweep latency_ms=0,100 --drop 0.1``
measures whether a crashed robot is avoided at each link level. A killed robot never
arrives, so such runs end once every other robot has arrived, and do not succeed; read
their contacts and the arrived fraction (``arrived_frac``: robots arrived over robots,
summed over the seeds).
"""

from __future__ import annotations

import concurrent.futures
import csv
import itertools
import math
import multiprocessing
import sys
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from world.sim.faults import FaultPlan
from world.sim.link import LinkFaults

SWEEP_KEYS = ("latency_ms", "jitter_ms", "drop", "dup", "reorder")


class StressSpecError(ValueError):
    """A bad ``--sweep`` value."""


def parse_sweep(specs: Sequence[str]) -> dict[str, list[float]]:
    """``["latency_ms=0,50", "drop=0,0.1"]`` -> ordered {key: sorted values}."""
    out: dict[str, list[float]] = {}
    for spec in specs:
        key, sep, values = spec.partition("=")
        key = key.strip()
        if not sep or key not in SWEEP_KEYS:
            raise StressSpecError(f"--sweep {spec!r}: expected KEY=V1,V2,... with KEY one of "
                                  f"{', '.join(SWEEP_KEYS)}")
        if key in out:
            raise StressSpecError(f"--sweep: {key} given twice")
        try:
            vals = sorted({float(v) for v in values.split(",") if v.strip()})
        except ValueError:
            raise StressSpecError(f"--sweep {spec!r}: values must be numbers") from None
        if not vals:
            raise StressSpecError(f"--sweep {spec!r}: no values")
        for v in vals:
            try:
                LinkFaults(**{key: v})
            except ValueError as exc:
                raise StressSpecError(f"--sweep {spec!r}: {exc}") from None
        out[key] = vals
    return out


def levels(sweep: dict[str, list[float]]) -> list[dict[str, float]]:
    """Every grid point as {key: value}, in sweep order."""
    keys = list(sweep)
    return [dict(zip(keys, combo)) for combo in itertools.product(*(sweep[k] for k in keys))]


def level_faults(level: dict[str, float], base: LinkFaults, jitter_frac: float) -> LinkFaults:
    """The link faults of one level (jitter from `jitter_frac` unless set)."""
    faults = replace(base, **level)
    if "jitter_ms" not in level and not base.jitter_ms:
        faults = replace(faults, jitter_ms=jitter_frac * faults.latency_ms)
    return faults


def level_name(level: dict[str, float]) -> str:
    return ",".join(f"{k}={v:g}" for k, v in level.items())


@dataclass(frozen=True)
class StressJob:
    """One run of a stress sweep (picklable, for the worker processes)."""

    setup: str
    planner: str
    seed: int
    level: tuple[tuple[str, float], ...]
    links: LinkFaults
    mode: str
    out_dir: str
    agents: int | None = None
    start_jitter_m: float = 0.0
    time_scale: float = 1.0
    compensate_latency: bool = True
    robot_faults: FaultPlan | None = None  # its timing and process faults (links: `links`)
    profile: str | None = None  # planner profile (`agent.core.config.PROFILES`)


def run_job(job: StressJob) -> dict[str, Any]:
    """Run one job (in a worker process); its result row."""
    import json

    from orchestrator.analysis.rundir import metrics_from_run_dir, run_ending, write_metrics
    from orchestrator.experiments.families import resolve

    t0 = time.monotonic()
    row: dict[str, Any] = {"setup": job.setup, "planner": job.planner, "seed": job.seed,
                           **dict(job.level), "error": None}
    try:
        scenario = resolve(job.setup, agents=job.agents, seed=job.seed,
                           start_jitter_m=job.start_jitter_m, planner=job.planner,
                           profile=job.profile)
        plan = replace(job.robot_faults or FaultPlan(), links=job.links, seed=job.seed,
                       compensate_latency=job.compensate_latency)
        out = Path(job.out_dir)
        if job.mode == "lockstep":
            from orchestrator.experiments.lockstep import run_lockstep

            metrics = run_lockstep(scenario, out, faults=plan).metrics
        else:
            from orchestrator.analysis.rundir import safe_name
            from orchestrator.experiments.distributed import run_distributed
            from world.scenario_file import dump_scenario

            out.mkdir(parents=True, exist_ok=True)
            path = out / "scenario.input.yaml"
            dump_scenario(scenario, path)
            run_id = f"stress-{safe_name(job.setup)[:12]}-{job.planner}-{job.seed}-{out.name[-24:]}"
            run_distributed(path, out, safe_name(run_id)[:64], time_scale=job.time_scale,
                            faults=plan)
            metrics = metrics_from_run_dir(out)
            write_metrics(out, metrics)
        m = metrics.to_json_dict()
        end = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()
               if '"end"' in line]
        end_event = end[-1] if end else {}
        row["exit"] = int(run_ending(m, end_event).exit_code)
        row.update({
            "success": m.get("success"), "arrived": m.get("arrived"), "robots": m.get("robots"),
            "contacts": m.get("contacts"), "min_gap_m": m.get("min_gap_m"),
            "lost": len(end_event.get("lost") or ()),
            "time_ratio_mean": m.get("time_ratio_mean"),
            "sim_latency_ms_p50": m.get("sim_latency_ms_p50"),
            "ego_error_m_mean": end_event.get("ego_error_m_mean"),
        })
    except Exception as exc:  # noqa: BLE001 - one failed run must not end the sweep
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["exit"] = 7  # agent.process.ExitCode.ERROR; the traceback follows on stderr
        traceback.print_exc(file=sys.stderr)
    row["wall_s"] = round(time.monotonic() - t0, 2)
    row["dir"] = Path(job.out_dir).name
    return row


def run_jobs(jobs: Sequence[StressJob], n_workers: int,
             on_done: Any = None) -> list[dict[str, Any]]:
    """Run every job, `n_workers` at a time, in spawned worker processes; rows in job order."""
    rows: list[dict[str, Any] | None] = [None] * len(jobs)
    ctx = multiprocessing.get_context("spawn")  # no fork: nothing inherited but arguments
    with concurrent.futures.ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx) as pool:
        futures = {pool.submit(run_job, job): k for k, job in enumerate(jobs)}
        for fut in concurrent.futures.as_completed(futures):
            k = futures[fut]
            rows[k] = fut.result()
            if on_done is not None:
                on_done(rows[k])
    return [r for r in rows if r is not None]


def _min(values: Sequence[object]) -> float | None:
    vals = [v for v in values if isinstance(v, int | float) and math.isfinite(v)]
    return min(vals) if vals else None


def _mean(values: Sequence[object]) -> float | None:
    vals = [v for v in values if isinstance(v, int | float) and math.isfinite(v)]
    return sum(vals) / len(vals) if vals else None


def aggregate(rows: Sequence[dict[str, Any]], keys: Sequence[str]) -> list[dict[str, Any]]:
    """One row per (setup, planner, level): success rate, contacts, min gap, time ratio."""
    groups: dict[tuple[object, ...], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["setup"], r["planner"], *(r[k] for k in keys)), []).append(r)
    return [{"setup": key[0], "planner": key[1], **dict(zip(keys, key[2:])),
             **_group_summary(rs)} for key, rs in groups.items()]


def _group_summary(rs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The `aggregate` columns of one group's runs (those that ended in an error count only
    as errors)."""
    ok = [r for r in rs if r.get("error") is None]

    def total(key: str) -> int:
        return sum(int(r.get(key) or 0) for r in ok)

    return {
        "runs": len(rs), "errors": len(rs) - len(ok),
        "success_rate": (sum(bool(r.get("success")) for r in ok) / len(ok)) if ok else None,
        "contacts": total("contacts"),
        "runs_with_contact": sum(1 for r in ok if (r.get("contacts") or 0) > 0),
        "runs_incomplete": sum(1 for r in ok if int(r.get("arrived") or 0)
                               + int(r.get("lost") or 0) < int(r.get("robots") or 0)),
        "arrived_frac": total("arrived") / max(1, total("robots")) if ok else None,
        "min_gap_m": _min([r.get("min_gap_m") for r in ok]),
        "time_ratio_mean": _mean([r.get("time_ratio_mean") for r in ok]),
        "ego_error_m_mean": _mean([r.get("ego_error_m_mean") for r in ok]),
    }


def envelope(table: Sequence[dict[str, Any]], keys: Sequence[str]
             ) -> list[dict[str, Any]]:
    """Per (setup, planner) and swept key: the largest contact-free value (module docstring)."""
    out = []
    pairs = sorted({(t["setup"], t["planner"]) for t in table})
    for setup, planner in pairs:
        mine = [t for t in table if t["setup"] == setup and t["planner"] == planner]
        row: dict[str, Any] = {"setup": setup, "planner": planner}
        for key in keys:
            others = {k: min(t[k] for t in mine) for k in keys if k != key}
            line = sorted((t for t in mine if all(t[k] == v for k, v in others.items())),
                          key=lambda t: t[key])
            best = None
            for t in line:
                # Contact-free only where every robot also arrived (or was lost to a
                # robot fault): a planner that stands still is never in contact, and is
                # not safe for it.
                if t["errors"] or t["runs_with_contact"] or t["runs_incomplete"]:
                    break
                best = t[key]
            row[f"max_{key}"] = best
            row[f"seeds_{key}"] = min((t["runs"] for t in line), default=0)
        out.append(row)
    return out


def write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    header: list[str] = []
    for r in rows:
        header += [k for k in r if k not in header]
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=header)
        writer.writeheader()
        writer.writerows(rows)
