"""The schedule of a run: pose slots, planning slots and the transport lease (pure).

The world publishes tick t's poses on ``poses/<t mod K>`` (`eifp_wire.keys.RunKeys.poses_slot`);
a robot that plans once a control period on a fixed tick needs only its slot. The lockstep
loop (`world.sim.lockstep`) and the processes (`world.node`, `agent.node`) share these.
"""

from __future__ import annotations

import math

MAX_POSE_SLOTS = 1000
"""Largest number of pose slots (a bound the wire format checks too)."""
LINK_LEASE_MS = 1000
"""Transport lease: a hung (SIGSTOPped) peer is noticed after about this long."""


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
