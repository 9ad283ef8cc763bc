"""Aggregation of run records: the reversal-cause table and grouping by directory (the rest
is exercised through the CLI in test_cli.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from orchestrator.analysis.report import (
    RunRecord,
    aggregate,
    collect,
    encounter_rates,
    reversal_causes,
    reversal_table,
)
from orchestrator.analysis.turns import REVERSAL_CAUSES


def record(setup: str, causes: dict[str, float] | None) -> RunRecord:
    metrics = {"oscillations_per_robot": sum((causes or {}).values())}
    if causes is not None:
        metrics["reversal_causes_per_robot"] = causes
    return RunRecord(Path(setup), setup, "eifp-mpc", 0, "lockstep", metrics)


def test_causes_are_averaged_per_setup_and_old_runs_are_left_out():
    zero = dict.fromkeys(REVERSAL_CAUSES, 0.0)
    runs = [
        record("setup_f", {**zero, "slow": 1.0, "threat_switch": 2.0}),
        record("setup_f", {**zero, "threat_switch": 1.0}),
        record("setup_f", None),  # written before the key existed
        record("setup_g", None),
    ]
    causes = reversal_causes(runs)
    assert list(causes) == [("setup_f", "eifp-mpc")]
    by = causes[("setup_f", "eifp-mpc")]
    assert by["slow"] == pytest.approx(0.5) and by["threat_switch"] == pytest.approx(1.5)
    assert by["same_via_point"] == 0.0
    table = reversal_table(causes)
    header, _rule, row = table.splitlines()
    assert header.split()[2:5] == ["osc/robot", "encounters/robot", "osc/encounter"]
    assert header.split()[5:] == list(REVERSAL_CAUSES)
    assert row.split()[:6] == ["setup_f", "eifp-mpc", "2", "-", "-", "0.5"]


def encounter_record(setup: str, robots: int, osc_total: int,
                     encounters_per_robot: float | None) -> RunRecord:
    metrics: dict[str, object] = {"robots": robots, "oscillations_total": osc_total,
                                  "reversal_causes_per_robot": dict.fromkeys(
                                      REVERSAL_CAUSES, osc_total / robots)}
    if encounters_per_robot is not None:
        metrics["encounters_per_robot"] = encounters_per_robot
        metrics["reversals_per_encounter"] = (osc_total / (encounters_per_robot * robots)
                                              if encounters_per_robot else None)
    return RunRecord(Path(setup), setup, "orca", 0, "lockstep", metrics)


def test_encounter_columns_pool_oscillations_over_encounters_across_runs():
    runs = [
        encounter_record("crowd", 4, 6, 2.0),  # 6 reversals, 8 encounters
        encounter_record("crowd", 2, 0, 1.0),  # 0 reversals, 2 encounters
        encounter_record("crowd", 4, 9, None),  # written before the fields existed
        encounter_record("open", 2, 3, 0.0),  # no encounter at all
    ]
    rates = encounter_rates(runs)
    assert list(rates) == [("crowd", "orca"), ("open", "orca")]
    crowd = rates[("crowd", "orca")]
    assert crowd.runs == 2 and crowd.encounters_per_robot == pytest.approx(1.5)
    assert crowd.reversals_per_encounter == pytest.approx(6 / 10)
    assert math.isnan(rates[("open", "orca")].reversals_per_encounter)
    header, _rule, *rows = reversal_table(reversal_causes(runs), rates).splitlines()
    cells = header.split()
    at = cells.index("encounters/robot")
    assert cells[at + 1] == "osc/encounter"
    assert [r.split()[at:at + 2] for r in rows] == [["1.5", "0.6"], ["0", "-"]]


def write_run(path: Path, osc: float) -> None:
    path.mkdir(parents=True)
    (path / "run.json").write_text(json.dumps(
        {"scenario": "setup_f", "planner": "eifp-mpc", "seed": 0, "mode": "lockstep"}))
    (path / "metrics.json").write_text(json.dumps({"oscillations_per_robot": osc}))


def test_by_dir_keeps_variants_of_one_setup_apart(tmp_path):
    write_run(tmp_path / "default" / "s0", 2.0)
    write_run(tmp_path / "default" / "s1", 4.0)
    write_run(tmp_path / "variant" / "s0", 10.0)
    paths = [tmp_path / "default", tmp_path / "variant"]
    pooled = aggregate(collect(paths))
    assert list(pooled) == [("setup_f", "eifp-mpc")]
    assert pooled[("setup_f", "eifp-mpc")]["oscillations_per_robot"][0] == pytest.approx(16 / 3)
    apart = aggregate(collect(paths, by_dir=True))
    assert list(apart) == [("setup_f", "eifp-mpc [default]"), ("setup_f", "eifp-mpc [variant]")]
    assert apart[("setup_f", "eifp-mpc [default]")]["oscillations_per_robot"][:2] == \
        pytest.approx((3.0, math.sqrt(2.0)))
    assert apart[("setup_f", "eifp-mpc [variant]")]["runs"][2] == 1


def test_by_dir_uses_the_paths_when_two_directories_share_a_name(tmp_path):
    write_run(tmp_path / "a" / "x" / "s0", 2.0)
    write_run(tmp_path / "b" / "x" / "s0", 6.0)
    apart = aggregate(collect([tmp_path / "a" / "x", tmp_path / "b" / "x"], by_dir=True))
    assert sorted(apart) == [("setup_f", f"eifp-mpc [{tmp_path / 'a' / 'x'}]"),
                             ("setup_f", f"eifp-mpc [{tmp_path / 'b' / 'x'}]")]
    assert apart[("setup_f", f"eifp-mpc [{tmp_path / 'b' / 'x'}]")][
        "oscillations_per_robot"][0] == pytest.approx(6.0)
