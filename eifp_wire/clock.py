"""Sequence numbers and stamps on the sim clock: how far ahead of its receiver a message may be.

A command's ``seq`` follows the sim time of the poses it was planned on, and the world
refuses a seq beyond its own time; a robot refuses a pose stamped far ahead of its clock or
whose time is not its tick's. Forged messages therefore cannot push a clock or a sequence
out of the genuine sender's reach (docs/security.md).
"""

from __future__ import annotations

import math

SEQ_PER_S = 1000
"""A command's ``seq`` is on a clock: the sim time [ms] of the poses it was planned on, or one
more than the robot's previous seq if that is larger (`next_seq`). The world refuses a seq
beyond what its own time allows (`max_seq`), so no burst of forged commands can push a
robot's seq out of the genuine robot's reach: once a forger stops, the robot's seq, taken
from time, passes the forged ones within `MAX_CMD_AHEAD_S`."""
MAX_POSE_AHEAD_S = 1.0
"""A pose stamped more than this [sim s] (times the time scale, if > 1) ahead of the
receiving robot's clock is rejected: a forged far-future pose would otherwise move the clock
and make every genuine pose look out of date."""
MAX_CMD_AHEAD_S = 1.0
"""A command whose ``pose_stamp`` is more than this [sim s] ahead of the world's time is
rejected (no genuine plan is made from a pose of the future)."""
TICK_TIME_TOLERANCE_S = 1e-3
"""A pose's ``t`` must equal ``tick / world_rate`` within this [s] (the world ticks at a fixed
rate from 0)."""


def next_seq(previous: int, pose_stamp_s: float) -> int:
    """The ``seq`` of a robot's next command: the sim time [ms] of the poses it was planned
    on (`SEQ_PER_S`), or `previous` + 1 if that is larger (several plans on one pose).

    A robot whose commands were refused as stale because a forger pushed its seq up
    re-synchronises this way: its seq follows time, which the forger's could not outrun."""
    return max(int(previous) + 1, math.floor(pose_stamp_s * SEQ_PER_S))


def max_seq(world_t_s: float) -> int:
    """The largest ``seq`` the world accepts at its sim time `world_t_s`: the time of a pose
    `MAX_CMD_AHEAD_S` ahead of it (`SEQ_PER_S`). A genuine robot plans on poses the world
    already published, and at `SEQ_PER_S` plans per second it would still be below."""
    return math.floor((world_t_s + MAX_CMD_AHEAD_S) * SEQ_PER_S)


def check_seq(seq: int, last_seq: int | None, *, world_t_s: float) -> str | None:
    """Why a command's `seq` is refused (None: it is not), given the last one the world
    applied for that robot and the world's sim time.

    ``seq_jump``: beyond what the time allows (`max_seq`): how far a seq may advance is
    bounded by elapsed time, not by step, so a walk of small steps cannot carry it off;
    ``stale``: not above `last_seq`.
    """
    if seq > max_seq(world_t_s):
        return "seq_jump"
    if last_seq is not None and seq <= last_seq:
        return "stale"
    return None


def check_pose_time(tick: int, t_s: float, *, world_rate_hz: float, time_limit_s: float,
                    clock_s: float | None, time_scale: float = 1.0) -> str | None:
    """Why a (validated) pose's `tick` / `t_s` is refused by a robot (None: it is not).

    ``tick_time``: `t_s` is not ``tick / world_rate_hz``; ``beyond_limit``: later than the
    run's time limit (plus `MAX_POSE_AHEAD_S`); ``ahead``: more than `MAX_POSE_AHEAD_S`
    (times `time_scale` when > 1) ahead of the robot's clock `clock_s` (None: no clock yet).
    """
    if abs(tick / world_rate_hz - t_s) > TICK_TIME_TOLERANCE_S + 1e-9 * t_s:
        return "tick_time"
    if t_s > time_limit_s + MAX_POSE_AHEAD_S:
        return "beyond_limit"
    if clock_s is not None and t_s > clock_s + MAX_POSE_AHEAD_S * max(1.0, time_scale):
        return "ahead"
    return None
