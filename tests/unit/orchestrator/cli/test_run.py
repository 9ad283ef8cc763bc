"""`orchestrator run`'s choice of robot launcher."""

from __future__ import annotations

import pytest

from orchestrator.cli.common import BadInput
from orchestrator.cli.run import FORK_ABOVE_ROBOTS, choose_launcher


def test_auto_forks_only_large_runs_without_faults() -> None:
    fault = object()
    assert choose_launcher("auto", FORK_ABOVE_ROBOTS, None) == "spawn"
    assert choose_launcher("auto", FORK_ABOVE_ROBOTS + 1, None) == "fork"
    assert choose_launcher("auto", FORK_ABOVE_ROBOTS + 1, fault) == "spawn"
    assert choose_launcher("spawn", 256, None) == "spawn"
    assert choose_launcher("fork", 2, None) == "fork"


def test_forking_with_faults_is_refused_with_the_flag_named() -> None:
    with pytest.raises(BadInput, match="--launcher fork"):
        choose_launcher("fork", 4, object())
