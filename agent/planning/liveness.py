"""Progress monitoring and a deliberate change of strategy when a robot is stuck.

Not in the paper (arXiv 2508.08264): eIFP and its MPC are local and reactive, so two
robots (or a knot of them) can each keep choosing a plan that the other's plan undoes,
and circle or stand for ever. Each robot therefore watches its own progress along its
route (`ProgressMonitor`) and, when it has made none for `LivenessConfig.stuck_after_s`,
changes strategy (`Liveness.decide`), in this order (thresholds: `LivenessConfig`):

1. **Route round the knot.** The sensed robots that are slow (below
   `LivenessConfig.slow_mps`) within the sensing radius are added to the static map as
   discs, and the robot re-routes (`agent.planning.routing`). A route that is at most
   `LivenessConfig.detour_ratio` times the straight remainder is followed from now on
   (until the next re-route); the knot is then left to the side instead of pushed
   through. If no such route is found, rule 2 follows at once.
2. **Squeeze between still discs.** For `LivenessConfig.squeeze_s` the robot plans with
   the smaller margin `LivenessConfig.squeeze_margin_m` instead of d_safety (Eq. 8)
   against every sensed disc slower than `slow_mps` (`squeezed`): robots parked on
   their goals in a lattice as dense as 2L (a 5x5 grid of mirror swaps 2.6 m apart, two
   platoons 2.5 m apart) leave gaps that are wide enough for a robot's body but closed to
   its inflated discs, and the last robots of such a crowd stood in a closed cell of
   parked neighbours until the time limit. Moving robots keep the full margin, and the
   braking guard keeps its own gap (`SafetyConfig.braking_margin_m`) to every disc, its
   true radius, whatever the planner's margin.
3. **Yield by id.** The robot yields for up to `LivenessConfig.yield_s` while a sensed
   robot with a lower id, moving (at least `slow_mps`), is within
   `LivenessConfig.yield_radius_m`: it stands (status YIELD) and the others plan round a
   still disc, which they do well. A robot with no such lower id near it squeezes instead
   (rule 2): standing helps only a robot that moves.

Each time the robot is found stuck it applies the next rule, 1, 2, 3, 1, 2, ...; real
progress starts the rotation again at rule 1.

Why this terminates (no two robots mirror each other for ever): robots sense each other's
ids, and ids are unique, so in every knot of stuck robots the one with the lowest id never
yields to any of them, while every other stuck one stands for `yield_s` every third stuck
spell. The lowest one then plans against still discs only, which the via-point planner
resolves, routes round (rule 1) or squeezes between (rule 2); when it has left the yield
radius the next-lowest is the lowest, and so on. Yielding and squeezing are bounded in
time, and each restarts the progress clock, so a robot that waits in vain (say, behind a
robot parked on its own goal) tries the rules again after another `stuck_after_s`, never
stands for good. Nothing here is random, so lockstep runs stay deterministic.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import final

import numpy as np

from agent.core.types import Others


@dataclass(frozen=True)
class LivenessConfig:
    """Thresholds of progress monitoring and of the strategies (`Mechanisms.liveness`).

    Args:
        stuck_after_s: a robot whose remaining route has not shrunk by `progress_m` for
            this long is stuck [s].
        progress_m: what counts as progress [m].
        slow_mps: sensed robots slower than this count as part of a knot (rule 1), and
            yielding is only to robots at least this fast (rule 2) [m/s].
        detour_ratio: a re-route round a knot is taken when at most this many times the
            straight distance left to the goal.
        yield_s: how long a yielding robot stands at most [s].
        yield_radius_m: a stuck robot yields to lower ids within this distance (centres) [m].
        squeeze_margin_m: the margin of Eq. (8) against still discs while squeezing
            (rule 2); at least the tracker's and the braking guard's gaps (0.1 and 0.05 m
            by default) [m].
        squeeze_s: how long a squeeze lasts [s].
    """

    stuck_after_s: float = 4.0
    progress_m: float = 0.5
    slow_mps: float = 0.3
    detour_ratio: float = 3.0
    yield_s: float = 3.0
    yield_radius_m: float = 5.0
    squeeze_margin_m: float = 0.1
    squeeze_s: float = 8.0

    def __post_init__(self) -> None:
        for name in ("stuck_after_s", "progress_m", "slow_mps", "detour_ratio", "yield_s",
                     "yield_radius_m", "squeeze_margin_m", "squeeze_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
                raise ValueError(f"LivenessConfig.{name} must be positive, got {value!r}")


class ProgressMonitor:
    """Whether a robot is making progress: the best remaining distance and when it last
    shrank by `progress_m`.

    Args:
        config: thresholds.
    """

    def __init__(self, config: LivenessConfig) -> None:
        self.config = config
        self._best_m = math.inf
        self._since_s = 0.0
        self.progressed = False

    def restart(self, now_s: float, left_m: float) -> None:
        """Start the clock again from `left_m` at `now_s` (after a change of strategy)."""
        self._best_m = left_m
        self._since_s = now_s

    def stuck(self, now_s: float, left_m: float) -> bool:
        """Record `left_m` (distance still to go [m]) at `now_s`; True when stuck.
        `progressed` tells whether this call found progress."""
        self.progressed = (left_m <= self._best_m - self.config.progress_m
                           or not math.isfinite(self._best_m))
        if self.progressed:
            self.restart(now_s, left_m)
            return False
        return now_s - self._since_s >= self.config.stuck_after_s


class Strategy(enum.Enum):
    """What `Liveness.decide` tells the planner to do this cycle."""

    GO = "go"  # plan as usual
    REROUTE = "reroute"  # re-route round the slow robots near, then go
    YIELD = "yield"  # stand


_ROTATION = (Strategy.REROUTE, None, Strategy.YIELD)
"""The rules a stuck robot applies in turn (module docstring); None is the squeeze."""


def knot(position_m: np.ndarray, others: Others, radius_m: float, slow_mps: float
         ) -> np.ndarray:
    """Indices of the sensed robots within `radius_m` moving slower than `slow_mps`."""
    if len(others) == 0:
        return np.zeros(0, dtype=int)
    d = np.hypot(*(others.position_m - position_m).T)
    speed = np.hypot(*others.velocity_mps.T)
    return np.flatnonzero(others.is_robot & (d <= radius_m) & (speed < slow_mps))


def lower_id_moving_near(robot_id: int, position_m: np.ndarray, others: Others,
                         radius_m: float, moving_mps: float) -> bool:
    """Whether a sensed robot with a lower id than `robot_id`, moving at least
    `moving_mps`, is within `radius_m`. Standing ones are left out: yielding lets a robot
    pass, and one that stands (parked on its goal, or stuck itself) passes nobody; the
    re-route of rule 1 goes round those instead."""
    if len(others) == 0:
        return False
    d = np.hypot(*(others.position_m - position_m).T)
    speed = np.hypot(*others.velocity_mps.T)
    return bool((others.is_robot & (others.ids < robot_id) & (d <= radius_m)
                 & (speed >= moving_mps)).any())


def squeezed(others: Others, d_safety_m: float, squeeze_margin_m: float, slow_mps: float
             ) -> Others:
    """`others` with every disc slower than `slow_mps` shrunk by d_safety - squeeze_margin
    (not below 0): a planner that inflates them by d_safety (Eq. 8) then keeps
    `squeeze_margin_m` from them (rule 2). Unchanged when the squeeze margin is no smaller."""
    shrink = d_safety_m - squeeze_margin_m
    if len(others) == 0 or shrink <= 0.0:
        return others
    still = np.hypot(*others.velocity_mps.T) < slow_mps
    if not still.any():
        return others
    radius = np.where(still, np.maximum(others.radius_m - shrink, 0.0), others.radius_m)
    return others.with_radius(radius)


@final  # `reset` re-runs __init__
class Liveness:
    """The strategy state of one robot: monitor, yield timer, and which rule comes next.

    Args:
        config: thresholds.
    """

    def __init__(self, config: LivenessConfig) -> None:
        self.config = config
        self.monitor = ProgressMonitor(config)
        self._yield_until_s = -math.inf
        self._squeeze_until_s = -math.inf
        self._next = 0  # index into _ROTATION
        self.stuck_now = False  # stuck this cycle, or yielding after a stuck spell
        self.reroutes = 0
        self.yields = 0
        self.squeezes = 0

    def reset(self) -> None:
        """Forget everything (a new run)."""
        self.__init__(self.config)

    def squeezing(self, now_s: float) -> bool:
        """Whether the robot plans with the squeeze margin this cycle (rule 2)."""
        return now_s < self._squeeze_until_s

    def decide(self, now_s: float, robot_id: int, position_m: np.ndarray, left_m: float,
               others: Others) -> Strategy:
        """This cycle's strategy (module docstring); a squeeze shows in `squeezing`.

        Args:
            now_s: sim time [s].
            robot_id: this robot's id.
            position_m: (2,) its position [m].
            left_m: distance still to go along its route [m].
            others: the sensed others.
        """
        cfg = self.config
        self.stuck_now = False
        if now_s < self._yield_until_s:
            if lower_id_moving_near(robot_id, position_m, others, cfg.yield_radius_m,
                                    cfg.slow_mps):
                # a yield is a stuck spell that lasts: a robot that must escape instead of
                # standing may commit to a turn on any cycle of it (`turning`)
                self.stuck_now = True
                return Strategy.YIELD
            self._yield_until_s = -math.inf  # nobody left to give way to
            self.monitor.restart(now_s, left_m)
        self.stuck_now = self.monitor.stuck(now_s, left_m)
        if not self.stuck_now:
            if self.monitor.progressed:
                self._next = 0  # real progress: start the rules afresh
            return Strategy.GO
        self.monitor.restart(now_s, left_m)
        rule = _ROTATION[self._next]
        self._next = (self._next + 1) % len(_ROTATION)
        if rule is Strategy.REROUTE:
            return Strategy.REROUTE
        if rule is Strategy.YIELD:
            return self.fallback(now_s, robot_id, position_m, others)
        return self._squeeze(now_s)

    def _squeeze(self, now_s: float) -> Strategy:
        self._squeeze_until_s = now_s + self.config.squeeze_s
        self.squeezes += 1
        return Strategy.GO

    def fallback(self, now_s: float, robot_id: int, position_m: np.ndarray, others: Others
                 ) -> Strategy:
        """Rule 3 (yield by id), or rule 2 (squeeze) where no lower id moves near."""
        if lower_id_moving_near(robot_id, position_m, others, self.config.yield_radius_m,
                                self.config.slow_mps):
            self._yield_until_s = now_s + self.config.yield_s
            self.yields += 1
            return Strategy.YIELD
        return self._squeeze(now_s)

    def rerouted(self, now_s: float, taken: bool) -> Strategy:
        """After `Strategy.REROUTE`: count a re-route the planner took (`taken`), or go on
        to rule 2 (squeeze) at once when there was none to take."""
        if taken:
            self.reroutes += 1
            return Strategy.GO
        self._next = 2  # rule 2 now; rule 3 the next time
        return self._squeeze(now_s)
