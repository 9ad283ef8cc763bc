"""The Hypothesis profile a session runs under (tests/conftest.py, tests/examples.py)."""

from __future__ import annotations

import pytest
from hypothesis import settings

from tests.conftest import REPO_ROOT, hypothesis_profile
from tests.examples import CI_EXAMPLES, FAST_EXAMPLES, examples


@pytest.mark.parametrize(("args", "profile"), [
    (["tests/unit", "tests/integration"], "fast"),  # plain pytest: testpaths
    (["tests/unit/agent/planning/test_mpc.py::test_result_is_frozen"], "fast"),
    (["tests"], "ci"),
    (["tests/"], "ci"),
    (["tests/unit", "tests/scenarios"], "ci"),
    (["tests/system/test_relay.py"], "ci"),
    ([str(REPO_ROOT)], "ci"),
])
def test_the_profile_follows_the_layers_the_session_runs(args, profile, monkeypatch):
    monkeypatch.chdir(REPO_ROOT)
    monkeypatch.delenv("HYPOTHESIS_PROFILE", raising=False)
    assert hypothesis_profile(args) == profile
    monkeypatch.setenv("HYPOTHESIS_PROFILE", "ci")
    assert hypothesis_profile(["tests/unit"]) == "ci"


def test_counts_are_full_under_ci_and_half_under_fast():
    assert settings.get_profile("ci").max_examples == CI_EXAMPLES
    assert settings.get_profile("fast").max_examples == FAST_EXAMPLES == CI_EXAMPLES // 2
    loaded = settings.default.max_examples
    assert loaded in (CI_EXAMPLES, FAST_EXAMPLES)
    assert examples(300) == (300 if loaded == CI_EXAMPLES else 150)
    assert examples(1) == 1
