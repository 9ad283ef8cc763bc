"""The benchmark's seed sets and `--seeds` (`orchestrator.experiments.seeds`)."""

from __future__ import annotations

import pytest

from orchestrator.experiments import seeds as bm


def test_parse_seeds():
    assert bm.parse_seeds(None) == bm.EVALUATION_SEEDS
    assert bm.parse_seeds(None, quick=True) == bm.QUICK_SEEDS
    assert bm.parse_seeds("evaluation", quick=True) == bm.EVALUATION_SEEDS
    assert bm.parse_seeds("Tuning") == bm.TUNING_SEEDS
    assert bm.parse_seeds("3") == (0, 1, 2)
    assert bm.parse_seeds("evaluation") == tuple(range(10))
    assert bm.parse_seeds("tuning") == tuple(range(100, 106))
    assert bm.parse_seeds("100,101") == (100, 101)
    assert bm.parse_seeds("3,0") == (3, 0)
    for bad in ("0", "-1", "101", "some", "", "100,3", "1,1", "1,x", "-1,2"):
        with pytest.raises(ValueError, match="--seeds"):
            bm.parse_seeds(bad)
