"""Aggregation of run records: the reversal-cause table (the rest is exercised through the
CLI in test_cli.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from orchestrator.metrics import REVERSAL_CAUSES
from orchestrator.report import RunRecord, reversal_causes, reversal_table


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
    assert header.split()[3:] == list(REVERSAL_CAUSES)
    assert row.split()[:4] == ["setup_f", "eifp-mpc", "2", "0.5"]
