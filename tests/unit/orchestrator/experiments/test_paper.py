"""The Table I experiment (`orchestrator.experiments.paper`): its jobs and the shape check."""

from __future__ import annotations

import math
from pathlib import Path

from orchestrator.experiments.paper import PAPER_PLANNERS, paper_jobs, shape_checks


def test_jobs_run_every_setup_planner_and_seed_in_the_paper_profile(tmp_path: Path) -> None:
    jobs = paper_jobs(tmp_path, setups=("setup_a", "setup_d"), seeds=3)
    assert len(jobs) == 2 * len(PAPER_PLANNERS) * 3
    assert {j.profile for j in jobs} == {"paper"} and {j.mode for j in jobs} == {"lockstep"}
    assert {(j.setup, j.planner, j.seed) for j in jobs} == {
        (s, p, k) for s in ("setup_a", "setup_d") for p in PAPER_PLANNERS for k in range(3)}
    assert len({j.out_dir for j in jobs}) == len(jobs)
    assert all(not j.links.active for j in jobs)


def _stats(osc: dict[str, float], success: float = 1.0) -> dict:
    return {("setup_a", p): {"oscillations_per_robot": (v, 0.0, 3), "success": (success, 0.0, 3)}
            for p, v in osc.items()}


def test_shape_holds_when_oscillations_fall_from_ifp_to_eifp_mpc() -> None:
    (check,) = shape_checks(_stats({"ifp": 9.0, "eifp": 4.0, "eifp-mpc": 4.0}))
    assert check.ordered and check.all_succeeded


def test_shape_fails_on_a_wrong_order_a_failure_or_a_missing_planner() -> None:
    (wrong,) = shape_checks(_stats({"ifp": 3.0, "eifp": 4.0, "eifp-mpc": 1.0}))
    assert not wrong.ordered
    (failed,) = shape_checks(_stats({"ifp": 9.0, "eifp": 4.0, "eifp-mpc": 1.0}, success=2 / 3))
    assert failed.ordered and not failed.all_succeeded
    (missing,) = shape_checks(_stats({"ifp": 9.0, "eifp-mpc": 1.0}))
    assert not missing.ordered and math.isnan(missing.oscillations["eifp"])
