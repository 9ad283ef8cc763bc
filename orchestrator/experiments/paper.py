"""The paper's Table I, reproduced: setups A-G x seeds for IFP, eIFP and eIFP-MPC in the
``paper`` profile (`agent.core.config.paper_config`), beside the paper's own figures.

Every run is a lockstep run (deterministic) with a small start jitter: setup A is exactly
mirror-symmetric without it, and every equation of the paper is mirror-equivariant, so an
unjittered A is a tie no planner of the paper can break (docs/method.md). The expected shape
of the table is 100 % success and oscillations eIFP-MPC <= eIFP <= IFP per setup;
`shape_checks` says where ours has it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from orchestrator.analysis.rundir import safe_name
from orchestrator.experiments.stress import StressJob
from world.sim.link import LinkFaults

PAPER_PLANNERS: tuple[str, ...] = ("ifp", "eifp", "eifp-mpc")
"""The paper's three planners, least to most elaborate (the expected oscillation order)."""
PAPER_SETUPS: tuple[str, ...] = tuple(f"setup_{c}" for c in "abcdefg")
DEFAULT_SEEDS = 10
DEFAULT_START_JITTER_M = 0.05
QUICK_SETUPS: tuple[str, ...] = ("setup_a", "setup_d")
QUICK_SEEDS = 2


@dataclass(frozen=True)
class ShapeCheck:
    """Whether one setup has the paper's expected shape.

    Args:
        setup: the setup.
        all_succeeded: every run of every planner arrived with no contact.
        ordered: mean oscillations per robot eIFP-MPC <= eIFP <= IFP.
        oscillations: planner -> mean oscillations per robot (NaN if none ran).
    """

    setup: str
    all_succeeded: bool
    ordered: bool
    oscillations: Mapping[str, float]


def paper_jobs(out_dir: Path, *, setups: Sequence[str] = PAPER_SETUPS,
               planners: Sequence[str] = PAPER_PLANNERS, seeds: int = DEFAULT_SEEDS,
               start_jitter_m: float = DEFAULT_START_JITTER_M) -> list[StressJob]:
    """One lockstep job per setup, planner and seed, in the paper profile, no link faults."""
    return [StressJob(setup=setup, planner=planner, seed=seed, level=(), links=LinkFaults(),
                      mode="lockstep",
                      out_dir=str(Path(out_dir) / safe_name(f"{setup}-{planner}-{seed}")),
                      start_jitter_m=start_jitter_m, profile="paper")
            for setup in setups for planner in planners for seed in range(seeds)]


def shape_checks(stats: Mapping[tuple[str, str], Mapping[str, tuple[float, float, int]]],
                 planners: Sequence[str] = PAPER_PLANNERS) -> list[ShapeCheck]:
    """The expected shape per setup: all succeed, oscillations non-increasing along
    `planners` read from the last to the first (eIFP-MPC <= eIFP <= IFP)."""
    checks = []
    for setup in sorted({s for s, _ in stats}):
        osc = {p: stats.get((setup, p), {}).get("oscillations_per_robot",
                                                  (math.nan, 0.0, 0))[0] for p in planners}
        success = [stats.get((setup, p), {}).get("success", (math.nan, 0.0, 0))[0]
                   for p in planners]
        values = [osc[p] for p in planners]
        ordered = all(math.isfinite(v) for v in values) and all(
            later <= earlier + 1e-9 for earlier, later in zip(values, values[1:]))
        checks.append(ShapeCheck(setup=setup, all_succeeded=all(s == 1.0 for s in success),
                                 ordered=ordered, oscillations=osc))
    return checks
