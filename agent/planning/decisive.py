"""Turn commitment: a small correction against the current turn is not a reversal.

Not in the paper (arXiv 2508.08264). The MPC re-solves every cycle on a reference that
moves a little with every new estimate of the others, and at the slow speeds of a crowd a
turn costs it almost nothing in position, so it answers each small change of the
reference with a small turn the other way: the robot wiggles (the reversals the
benchmark counts). `TurnCommitment` keeps the direction the robot is turning in: a
command that turns the other way by less than `TurnCommitment.release_radps` is sent
without its turn (the robot goes straight on, at the MPC's speed, until the correction
has grown past the release rate), and a turn the other way at least that fast is taken
and becomes the new direction. A turn in the same direction, and any command while the
robot is not turning, pass unchanged. The braking guard runs after it, on the command
actually sent, so safety does not depend on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class TurnCommitmentConfig:
    """Thresholds of `TurnCommitment`.

    Args:
        release_radps: a turn against the committed direction at least this fast is
            taken [rad/s].
        turning_radps: slower turns than this are no turn (they neither commit nor count
            as a reversal) [rad/s].
    """

    release_radps: float = 0.35
    turning_radps: float = 0.05

    def __post_init__(self) -> None:
        for name in ("release_radps", "turning_radps"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"TurnCommitmentConfig.{name} must be positive, got {value!r}")


class TurnCommitment:
    """The committed turn direction of one robot (module docstring).

    Args:
        config: thresholds.
    """

    def __init__(self, config: TurnCommitmentConfig) -> None:
        self.config = config
        self.sign = 0  # +1 turning left, -1 right, 0 not committed
        self.held = 0  # commands whose turn was held back

    def reset(self) -> None:
        """Forget the direction."""
        self.sign = 0
        self.held = 0

    def release(self) -> None:
        """Forget the direction (the robot stopped, escaped or yielded)."""
        self.sign = 0

    def filter(self, omega_radps: float) -> float:
        """The turn rate to send for the MPC's `omega_radps`."""
        cfg = self.config
        if abs(omega_radps) < cfg.turning_radps:
            return omega_radps
        sign = 1 if omega_radps > 0.0 else -1
        if self.sign == 0 or sign == self.sign or abs(omega_radps) >= cfg.release_radps:
            self.sign = sign
            return omega_radps
        self.held += 1
        return 0.0
