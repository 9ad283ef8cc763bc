"""The schedule of a run: pose slots, planning slots and the transport lease (pure).

The world publishes tick t's poses on ``poses/<t mod K>`` (`eifp_wire.keys.RunKeys.poses_slot`);
a robot that plans once a control period on a fixed tick needs only its slot. The lockstep
loop (`world.sim.lockstep`) and the processes (`world.node`, `agent.node`) share these; a
robot process plans on the slots of a `PlanSchedule`.
"""

from __future__ import annotations

import math

MAX_POSE_SLOTS = 1000
"""Largest number of pose slots (a bound the wire format checks too)."""
LINK_LEASE_MS = 1000
"""Transport lease: a hung (SIGSTOPped) peer is noticed after about this long."""
STAMP_EPS_S = 1e-6
"""Tolerance on sim-time comparisons (stamps are sums of float ticks)."""


def pose_slot_count(world_rate_hz: float, control_rate_hz: float) -> int:
    """K, the number of pose slots: world ticks per control period if that is a whole number.

    The world publishes tick t's poses on ``poses/<t mod K>``. With K world ticks per control
    period, a robot planning once a period on a fixed tick phase needs only the poses of one
    slot, a K-th of the stream (K = 5 at 50 Hz world, 10 Hz control). If the ratio is not a
    whole number (within 1e-6) there is one slot, every tick on ``poses/0``.
    """
    if not (math.isfinite(world_rate_hz) and math.isfinite(control_rate_hz)
            and world_rate_hz > 0.0 and control_rate_hz > 0.0):
        raise ValueError("rates must be positive and finite")
    ratio = world_rate_hz / control_rate_hz
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-6 * max(1.0, ratio):
        return 1
    return min(k, MAX_POSE_SLOTS)


def pose_slot_of_tick(tick: int, slots: int) -> int:
    """The slot a world tick's poses are published on."""
    return int(tick) % int(slots)


def plan_pose_slot(period_s: float, phase_s: float, tick_s: float, slots: int) -> int | None:
    """The one pose slot that holds every plan slot ``phase_s + k * period_s`` (k integer).

    Returns None when the plan slots do not all fall on world ticks of one slot (a phase
    between ticks, a period that is not a multiple of the tick, or one that cycles through
    several slots): such a robot needs every tick's poses (``poses/*``).

    Args:
        period_s: planning period [sim s].
        phase_s: offset of the planning slots [sim s].
        tick_s: world tick [sim s].
        slots: K, from `pose_slot_count`.
    """
    if not (period_s > 0.0 and tick_s > 0.0 and slots >= 1):
        raise ValueError("period_s and tick_s must be positive, slots >= 1")
    ticks_per_period = period_s / tick_s
    phase_ticks = phase_s / tick_s
    if (abs(ticks_per_period - round(ticks_per_period)) > 1e-6
            or abs(phase_ticks - round(phase_ticks)) > 1e-6):
        return None
    step = round(ticks_per_period) % slots
    if step != 0:  # successive plans land on different slots
        return None
    return round(phase_ticks) % slots


class PlanSchedule:
    """When to plan, in sim time: every `period_s`, from the first pose's stamp or on a phase.

    A plan is due when the newest pose's stamp reaches the next scheduled time. After a
    plan the schedule advances by one period; slots that have already passed (the robot was
    slow, or poses were lost) are skipped and counted, never planned as a backlog.

    Args:
        period_s: planning period in sim time (> 0).
        phase_s: None: the first slot is the first stamp seen. Else the slots are
            ``phase_s + k * period_s`` (k integer): the first one at or after the first
            stamp seen. Robots on different phases spread their planning over the world's
            ticks instead of all planning on the same pose.
    """

    def __init__(self, period_s: float, phase_s: float | None = None) -> None:
        if not period_s > 0.0:
            raise ValueError("period_s must be positive")
        if phase_s is not None and not math.isfinite(phase_s):
            raise ValueError("phase_s must be finite")
        self.period_s = float(period_s)
        self.phase_s = None if phase_s is None else float(phase_s)
        self.next_s: float | None = None
        self.skipped = 0

    def _first(self, stamp_s: float) -> float:
        if self.phase_s is None:
            return stamp_s
        k = math.ceil((stamp_s - self.phase_s) / self.period_s - STAMP_EPS_S)
        return self.phase_s + k * self.period_s

    def due(self, stamp_s: float) -> bool:
        """True if a pose stamped `stamp_s` should be planned on now."""
        if self.next_s is None:
            self.next_s = self._first(stamp_s)
        return stamp_s + STAMP_EPS_S >= self.next_s

    def planned(self, stamp_s: float) -> int:
        """Record a plan made on the pose stamped `stamp_s`; returns the slots skipped."""
        if self.next_s is None:
            self.next_s = self._first(stamp_s)
        self.next_s += self.period_s
        missed = 0
        if self.next_s + STAMP_EPS_S <= stamp_s:
            missed = math.floor((stamp_s - self.next_s) / self.period_s + STAMP_EPS_S) + 1
            self.next_s += missed * self.period_s
        self.skipped += missed
        return missed


def plan_phase_s(robot_id: int, period_s: float, tick_s: float) -> float:
    """This robot's planning phase: robots spread evenly over the world ticks of a period.

    With a 0.1 s period and 0.02 s ticks, robot k plans on the ticks ``k mod 5`` of every
    period, so at any tick only a fifth of the robots plan (and compete for the CPU).
    """
    slots = max(1, round(period_s / tick_s))
    return (robot_id % slots) * period_s / slots
