"""Turns of a heading history, their reversals and what caused them (pure).

The definitions are `orchestrator.analysis.metrics`'s (its module docstring, "oscillations"
and "reversal causes"): a *turn* is a maximal run of samples turning one way fast and far
enough, a *reversal* a turn the other way soon after the previous one; `reversal_causes`
puts each reversal in the first class that fits, from the speed and the plans in force.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

TURN_RATE_MIN_RADPS = 0.05
TURN_ANGLE_MIN_RAD = 0.1
REVERSAL_WINDOW_S = 3.0
# Below this speed a reversal is `slow` (`metrics` module docstring, reversal causes) [m/s].
SLOW_REVERSAL_MPS = 0.5
REVERSAL_CAUSES = ("slow", "escape", "no_via_point", "side_flip", "threat_switch",
                   "same_via_point", "unknown")
_TIME_EPS_S = 1.0e-6  # tolerance on sample times [s]


@dataclass(frozen=True)
class Turn:
    """One turn of the heading: sign (+1 counter-clockwise), span and heading change."""

    sign: int
    start_s: float
    end_s: float
    angle_rad: float


def find_turns(t_s: np.ndarray, heading_rad: np.ndarray, *,
               min_rate_radps: float = TURN_RATE_MIN_RADPS,
               min_angle_rad: float = TURN_ANGLE_MIN_RAD) -> list[Turn]:
    """The turns of one heading history (see the module docstring).

    Args:
        t_s: (T,) increasing times.
        heading_rad: (T,) headings, wrapped or not.
    """
    t = np.asarray(t_s, dtype=float)
    if t.size < 2:
        return []
    dtheta = np.diff(np.unwrap(np.asarray(heading_rad, dtype=float)))
    rate = dtheta / np.diff(t)
    sign = np.where(rate >= min_rate_radps, 1, np.where(rate <= -min_rate_radps, -1, 0))
    # Run boundaries: where the sign changes (interval indices).
    edges = np.flatnonzero(np.diff(sign)) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [sign.size]])  # exclusive
    turns = []
    for i0, i1 in zip(starts.tolist(), ends.tolist()):
        s = int(sign[i0])
        if s == 0:
            continue
        angle = abs(float(dtheta[i0:i1].sum()))
        if angle >= min_angle_rad:
            turns.append(Turn(sign=s, start_s=float(t[i0]), end_s=float(t[i1]),
                              angle_rad=angle))
    return turns


def find_reversals(turns: Sequence[Turn], window_s: float = REVERSAL_WINDOW_S
                   ) -> list[tuple[Turn, Turn]]:
    """(previous turn, reversing turn) for every turn that follows a turn of the opposite
    sign and starts within window_s of its end."""
    return [
        (prev, cur) for prev, cur in zip(turns, turns[1:])
        if cur.sign == -prev.sign and cur.start_s - prev.end_s <= window_s + _TIME_EPS_S
    ]


def count_reversals(turns: Sequence[Turn], window_s: float = REVERSAL_WINDOW_S) -> int:
    """Turns that follow a turn of the opposite sign and start within window_s of its end."""
    return len(find_reversals(turns, window_s))


@dataclass(frozen=True)
class PlanInForce:
    """One robot's applied commands as a step function of time, for `reversal_causes`.

    Args:
        t_applied_s: (C,) increasing application times.
        status: (C,) `PlanStatus` values.
        side: (C,) -1 RIGHT, 0 NONE, +1 LEFT, or None when not recorded.
        resolved: (C,) resolved threat id, NaN for none, or None when not recorded.
    """

    t_applied_s: np.ndarray
    status: np.ndarray
    side: np.ndarray | None
    resolved: np.ndarray | None

    def at(self, t_s: float) -> tuple[str, int, float] | None:
        """(status, side, resolved id) of the last command applied at or before t_s."""
        i = int(np.searchsorted(self.t_applied_s, t_s + _TIME_EPS_S, side="right")) - 1
        if i < 0:
            return None
        side = int(self.side[i]) if self.side is not None else 0
        resolved = float(self.resolved[i]) if self.resolved is not None else math.nan
        return str(self.status[i]), side, resolved


def reversal_causes(t_s: np.ndarray, heading_rad: np.ndarray, speed_mps: np.ndarray,
                    plans: PlanInForce) -> dict[str, int]:
    """The reversals of one heading history by cause (module docstring).

    Args:
        t_s, heading_rad, speed_mps: (T,) the robot's run.
        plans: its applied commands.

    Returns:
        {cause: count} over `REVERSAL_CAUSES`; the counts sum to `oscillations`.
    """
    counts = dict.fromkeys(REVERSAL_CAUSES, 0)
    t = np.asarray(t_s, dtype=float)
    speed = np.asarray(speed_mps, dtype=float)
    known = plans.side is not None and plans.resolved is not None
    for prev, cur in find_reversals(find_turns(t, heading_rad)):
        i = min(int(np.searchsorted(t, cur.start_s - _TIME_EPS_S)), t.size - 1)
        a, b = plans.at(prev.start_s), plans.at(cur.start_s)
        if abs(float(speed[i])) < SLOW_REVERSAL_MPS:
            cause = "slow"
        elif a is None or b is None:
            cause = "unknown"
        elif "escape" in (a[0], b[0]):
            cause = "escape"
        elif not known:
            cause = "unknown"
        elif math.isnan(a[2]) or math.isnan(b[2]) or 0 in (a[1], b[1]):
            cause = "no_via_point"
        elif a[2] != b[2]:
            cause = "threat_switch"
        else:
            cause = "side_flip" if a[1] != b[1] else "same_via_point"
        counts[cause] += 1
    return counts


def oscillations(t_s: np.ndarray, heading_rad: np.ndarray) -> int:
    """Reversals of turning direction of one heading history."""
    return count_reversals(find_turns(t_s, heading_rad))
