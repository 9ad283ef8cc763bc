"""A committed turn on the spot for a stuck robot that stands facing away from its path.

Not in the paper (arXiv 2508.08264). eIFP-MPC's tracker linearises the unicycle about its
prediction: a robot that stands, hemmed in so that no forward speed is allowed (its nose
a few centimetres from another robot's, say), finds no gain in turning on the spot, and
stands for good while its reference leaves sideways or behind it (`pillar_circle` 40,
tuning seed 101: two robots 0.1 m apart beside the pillar stood for the last 40 s of the
run). A turn on the spot decided every cycle does not work either: the reference swings
as the robot turns, and robots spun back and forth (docs/method.md, "Tried and not kept").

So the turn is a decision taken once and kept: when the progress monitor finds the robot
stuck (`agent.planning.liveness`), the tracker's command stands (below `STANDING_MPS`) and
the reference leaves more than `TURN_FROM_RAD` off the heading, the robot fixes that
direction (a world angle, `start_turn`) and turns on the spot towards it, one way round
(the shorter, or the way it already turns when the direction is more than
`EITHER_WAY_RAD` off), until it faces it within `TURN_DONE_RAD` or `TURN_MAX_S` is over
(`turn_command`). The turn
is bounded, so it ends; turning in place moves no part of a disc robot, so it cannot bring
the robot closer to anyone. Pure: no clock, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.core.config import RobotLimits
from agent.planning.unicycle import HEADING_GAIN, clamp_command, wrap_angle

STANDING_MPS = 0.05
"""A robot, and a command, slower than this stand [m/s]."""

TURN_FROM_RAD = math.radians(60.0)
"""A turn starts when the reference leaves more than this off the heading."""

TURN_DONE_RAD = math.radians(10.0)
"""The turn ends when the robot faces its direction within this."""

TURN_MAX_S = 3.0
"""A turn ends after this long at the latest (half a turn takes about 2.1 s at 1.5 rad/s
with the default rate limits) [s]."""

EITHER_WAY_RAD = math.radians(120.0)
"""A direction more than this off the heading is turned to the way the robot already turns."""

TURNING_RADPS = 0.1
"""A robot turning at least this fast already turns one way [rad/s]."""

REFERENCE_AIM_M = 0.1
"""The direction is that of the first reference point at least this far from the robot [m]."""


@dataclass(frozen=True)
class Turn:
    """A committed turn: towards `heading_rad` (world frame), `sign` +1 counter-clockwise,
    until `until_s` (sim time) at the latest."""

    heading_rad: float
    sign: int
    until_s: float


def start_turn(x_m: float, y_m: float, heading_rad: float, v_mps: float, omega_radps: float,
               v_cmd_mps: float, ref_x_m: np.ndarray, ref_y_m: np.ndarray, now_s: float
               ) -> Turn | None:
    """The turn a stuck robot commits to, or None (it moves, its command moves, it already
    faces its reference within `TURN_FROM_RAD`, or the reference goes nowhere). The turn
    goes the shorter way round, or the way the robot already turns (at least
    `TURNING_RADPS`) when the direction is more than `EITHER_WAY_RAD` off: then both ways
    are about as long, and turning back would add a reversal.

    Args:
        x_m, y_m, heading_rad, v_mps, omega_radps: the robot's pose, speed and turn rate.
        v_cmd_mps: the tracker's commanded speed.
        ref_x_m, ref_y_m: (M,) the reference path from the robot.
        now_s: sim time [s].
    """
    if v_mps >= STANDING_MPS or v_cmd_mps >= STANDING_MPS:
        return None
    far = np.hypot(np.asarray(ref_x_m) - x_m, np.asarray(ref_y_m) - y_m) >= REFERENCE_AIM_M
    if not far.any():
        return None
    k = int(np.argmax(far))
    direction = math.atan2(float(ref_y_m[k]) - y_m, float(ref_x_m[k]) - x_m)
    err = float(wrap_angle(direction - heading_rad))
    if abs(err) <= TURN_FROM_RAD:
        return None
    sign = 1 if err > 0.0 else -1
    if abs(err) > EITHER_WAY_RAD and abs(omega_radps) >= TURNING_RADPS:
        sign = 1 if omega_radps > 0.0 else -1
    return Turn(heading_rad=direction, sign=sign, until_s=now_s + TURN_MAX_S)


def turn_command(turn: Turn, heading_rad: float, omega_radps: float, limits: RobotLimits,
                 dt_s: float, now_s: float) -> tuple[float, float] | None:
    """(v = 0, omega) turning the committed way towards the turn's direction, rate-limited
    from the last turn rate; None when the turn is over (faced within `TURN_DONE_RAD`, or
    past its time).

    Args:
        turn: the committed turn.
        heading_rad: the robot's heading now.
        omega_radps: the turn rate commanded last period.
        limits: actuation limits.
        dt_s: the control period [s].
        now_s: sim time [s].
    """
    err = float(wrap_angle(turn.heading_rad - heading_rad))
    if now_s >= turn.until_s or abs(err) <= TURN_DONE_RAD:
        return None
    # the committed way round, even past half a turn (the heading law's shorter way
    # would flip the turn there)
    left = err if turn.sign * err > 0.0 else err + turn.sign * 2.0 * math.pi
    omega = turn.sign * min(HEADING_GAIN * abs(left), limits.omega_max_radps)
    return clamp_command(0.0, omega, limits, last_omega_radps=omega_radps, dt_s=dt_s)
