"""Turn commitment (`agent.planning.decisive`)."""

from __future__ import annotations

import pytest

from agent.planning.decisive import TurnCommitment, TurnCommitmentConfig

CFG = TurnCommitmentConfig(release_radps=0.35, turning_radps=0.05)


def test_small_corrections_against_the_turn_are_held_and_large_ones_taken() -> None:
    turns = TurnCommitment(CFG)
    assert turns.filter(0.3) == 0.3  # first turn: left, committed
    assert turns.filter(0.1) == 0.1  # the same way: unchanged
    assert turns.filter(-0.2) == 0.0  # a small correction to the right: held
    assert turns.held == 1
    assert turns.filter(-0.5) == -0.5  # a real turn to the right: taken, now committed
    assert turns.filter(0.2) == 0.0  # and a small one back to the left is held
    assert turns.filter(0.02) == 0.02  # no turn at all passes (and changes nothing)
    assert turns.sign == -1


def test_release_forgets_the_direction() -> None:
    turns = TurnCommitment(CFG)
    turns.filter(0.3)
    turns.release()
    assert turns.filter(-0.1) == -0.1


def test_a_wiggle_becomes_one_turn() -> None:
    """The MPC's answer to a reference that jitters: +-0.2 rad/s every cycle. Committed,
    the robot turns one way only."""
    turns = TurnCommitment(CFG)
    sent = [turns.filter(0.2 if k % 2 == 0 else -0.2) for k in range(20)]
    assert min(sent) >= 0.0 and max(sent) == 0.2


def test_config_refuses_non_positive_thresholds() -> None:
    with pytest.raises(ValueError, match="release_radps"):
        TurnCommitmentConfig(release_radps=0.0)
