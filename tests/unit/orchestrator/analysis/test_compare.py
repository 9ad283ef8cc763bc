"""Paired comparison of two sets of runs: pairing, the bootstrap interval, the verdicts and
the `report --compare` command."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from orchestrator.analysis.compare import (
    compare,
    difference,
    format_difference,
    metric_value,
    pair_runs,
)
from orchestrator.cli import main


def runs(case: str, values: list[float], seeds: list[int | None] | None = None,
         planner: str = "eifp-mpc") -> list[tuple[tuple[str, str, int | None], dict]]:
    seeds = list(range(len(values))) if seeds is None else seeds
    return [((case, planner, s), {"oscillations_per_robot": v, "robots": 4, "arrived": 4})
            for s, v in zip(seeds, values)]


def test_runs_pair_by_case_planner_and_seed_and_the_rest_is_counted():
    base = runs("a", [1, 2, 3]) + runs("b", [5.0], [7]) + runs("a", [9.0], [None])
    variant = runs("a", [2, 3], [2, 1]) + runs("b", [6.0], [8]) + runs("a", [1, 1], [0, 0])
    pairs, unmatched = pair_runs(base, variant)
    # a: seeds 1 and 2 pair (in seed order); seed 0 is twice in the variant: both unpaired.
    assert list(pairs) == [("a", "eifp-mpc")]
    assert [(p[0]["oscillations_per_robot"], p[1]["oscillations_per_robot"])
            for p in pairs[("a", "eifp-mpc")]] == [(2, 3), (3, 2)]
    # unpaired: base a/0, b/7 and the seedless run; variant b/8 and the two a/0
    assert unmatched == 6


def test_metric_values_and_the_arrived_share():
    assert metric_value({"robots": 8, "arrived": 6}, "arrived_share") == 0.75
    assert math.isnan(metric_value({"robots": 0, "arrived": 0}, "arrived_share"))
    assert math.isnan(metric_value({"time_ratio_mean": None}, "time_ratio_mean"))
    assert metric_value({"contacts": 2}, "contacts") == 2.0


def test_a_consistent_shift_is_found_and_its_interval_holds_it():
    rng = np.random.default_rng(1)
    base = rng.normal(10.0, 2.0, 20)
    variant = base - 2.0 + rng.normal(0.0, 0.3, 20)
    d = difference(base, variant, np.random.default_rng(0))
    assert d.verdict == "lower"
    assert abs(d.delta + 2.0) < 0.2
    assert d.low < d.delta < d.high < 0.0
    assert difference(variant, base, np.random.default_rng(0)).verdict == "higher"


def test_noise_alone_is_within_noise_and_equal_runs_differ_by_nothing():
    rng = np.random.default_rng(2)
    base = rng.normal(10.0, 3.0, 10)
    variant = base + rng.normal(0.0, 3.0, 10) - rng.normal(0.0, 3.0, 10).mean()
    d = difference(base, variant, np.random.default_rng(0))
    assert d.low < 0.0 < d.high
    assert d.verdict == "within noise"
    same = difference(base, base.copy(), np.random.default_rng(0))
    assert (same.delta, same.low, same.high) == (0.0, 0.0, 0.0)
    assert same.verdict == "within noise"


def test_fewer_than_three_pairs_give_no_interval():
    d = difference(np.array([1.0, 2.0]), np.array([5.0, 6.0]), np.random.default_rng(0))
    assert d.delta == 4.0 and d.pairs == 2
    assert math.isnan(d.low) and d.verdict == "too few"
    assert format_difference(d) == "1.50 -> 5.50 (+4.00)"


def test_overall_weights_cases_equally_and_is_reproducible():
    base = runs("many", [10.0] * 10) + runs("few", [10.0] * 2)
    variant = runs("many", [11.0] * 10) + runs("few", [9.0] * 2)
    pairs, unmatched = pair_runs(base, variant)
    result = compare(pairs, unmatched, metrics=("oscillations_per_robot",))
    overall = result.overall["oscillations_per_robot"]
    assert overall.delta == 0.0  # +1 and -1, one case each, not (10 - 2) / 12
    assert overall.pairs == 12 and unmatched == 0
    assert result.cases[("few", "eifp-mpc")]["oscillations_per_robot"].verdict == "too few"
    assert result.cases[("many", "eifp-mpc")]["oscillations_per_robot"].verdict == "higher"
    again = compare(pairs, unmatched, metrics=("oscillations_per_robot",))
    assert again.overall == result.overall


def test_a_metric_missing_on_one_side_is_left_out_of_that_pair():
    base = runs("a", [1.0, 2.0, 3.0])
    variant = runs("a", [2.0, 3.0, 4.0])
    del variant[1][1]["oscillations_per_robot"]
    pairs, _ = pair_runs(base, variant)
    d = compare(pairs, metrics=("oscillations_per_robot",)).cases[("a", "eifp-mpc")]
    only = d["oscillations_per_robot"]
    assert (only.pairs, only.base, only.variant, only.delta) == (2, 2.0, 3.0, 1.0)


def write_run(path: Path, case: str, seed: int, osc: float) -> None:
    path.mkdir(parents=True)
    (path / "run.json").write_text(json.dumps(
        {"scenario": case, "planner": "eifp-mpc", "seed": seed, "mode": "lockstep"}))
    (path / "metrics.json").write_text(json.dumps(
        {"oscillations_per_robot": osc, "robots": 2, "arrived": 2, "contacts": 0}))


def test_report_compare_prints_the_paired_table(tmp_path, capsys):
    for seed in range(4):
        write_run(tmp_path / "base" / f"s{seed}", "circle_8", seed, 5.0 + seed)
        write_run(tmp_path / "variant" / f"s{seed}", "circle_8", seed, 3.0 + seed)
    write_run(tmp_path / "variant" / "s9", "circle_8", 9, 1.0)
    assert main(["report", "--compare", str(tmp_path / "base"), str(tmp_path / "variant")]) == 0
    out = capsys.readouterr().out
    assert "4 paired runs, 1 without a partner" in out
    assert "6.50 -> 4.50 (-2.00 [-2.00, -2.00]) lower" in out


def test_report_compare_refuses_other_than_two_directories(tmp_path, capsys):
    write_run(tmp_path / "base" / "s0", "circle_8", 0, 5.0)
    assert main(["report", "--compare", str(tmp_path / "base")]) != 0
    assert "exactly two directories" in capsys.readouterr().err
    write_run(tmp_path / "other" / "s0", "circle_16", 0, 5.0)
    assert main(["report", "--compare", str(tmp_path / "base"), str(tmp_path / "other")]) != 0
    assert "no run of" in capsys.readouterr().err


@pytest.mark.parametrize("bad", [[], ["--paper"], ["--by-dir"]])
def test_report_compare_options(tmp_path, bad):
    write_run(tmp_path / "a" / "s0", "circle_8", 0, 5.0)
    write_run(tmp_path / "b" / "s0", "circle_8", 0, 4.0)
    rc = main(["report", "--compare", *bad, str(tmp_path / "a"), str(tmp_path / "b")])
    assert (rc == 0) == (not bad)
