"""The committed turn on the spot of a stuck robot (`agent.planning.turning`) and its use in
eIFP-MPC (`agent.planning.planners`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from agent.core.config import PlannerConfig, RobotLimits
from agent.core.types import EgoState, Observation, Others
from agent.planning.mechanisms import EIFP_MPC_MECHANISMS
from agent.planning.planners import ViaPointPlanner, make_planner
from agent.planning.turning import (
    TURN_DONE_RAD,
    TURN_MAX_S,
    Turn,
    start_turn,
    turn_command,
)

LIMITS = RobotLimits()
EAST = (np.array([0.0, 0.05, 0.5]), np.array([0.0, 0.0, 0.0]))  # a reference leaving east


def test_a_turn_starts_only_for_a_standing_robot_facing_away_from_its_reference() -> None:
    away = math.radians(120.0)
    turn = start_turn(0.0, 0.0, away, 0.0, 0.0, 0.0, *EAST, now_s=10.0)
    assert turn is not None
    assert turn.heading_rad == pytest.approx(0.0)  # the first point 0.1 m away or more
    assert turn.sign == -1  # clockwise: the shorter way from 120 deg to 0
    assert turn.until_s == pytest.approx(10.0 + TURN_MAX_S)
    assert start_turn(0.0, 0.0, -away, 0.0, 0.0, 0.0, *EAST, now_s=0.0).sign == 1  # type: ignore[union-attr]
    assert start_turn(0.0, 0.0, math.radians(50.0), 0.0, 0.0, 0.0, *EAST, now_s=0.0) is None
    assert start_turn(0.0, 0.0, away, 0.3, 0.0, 0.0, *EAST, now_s=0.0) is None  # it moves
    assert start_turn(0.0, 0.0, away, 0.0, 0.0, 0.2, *EAST, now_s=0.0) is None  # the MPC drives it
    short = (np.array([0.0, 0.05]), np.array([0.0, 0.0]))
    assert start_turn(0.0, 0.0, away, 0.0, 0.0, 0.0, *short, now_s=0.0) is None  # nowhere to aim
    # nearly behind it, and already turning counter-clockwise: it keeps that way round
    behind = start_turn(0.0, 0.0, math.radians(170.0), 0.0, 0.5, 0.0, *EAST, now_s=0.0)
    assert behind is not None and behind.sign == 1
    # ... but not for a direction the other way round is much shorter to
    assert start_turn(0.0, 0.0, away, 0.0, 0.5, 0.0, *EAST, now_s=0.0).sign == -1  # type: ignore[union-attr]


def test_the_turn_keeps_its_way_round_and_ends_when_faced_or_timed_out() -> None:
    turn = Turn(heading_rad=0.0, sign=1, until_s=5.0)
    dw = LIMITS.alpha_max_radps2 * 0.1
    # from standing: counter-clockwise, rate-limited
    assert turn_command(turn, math.radians(-90.0), 0.0, LIMITS, 0.1, 1.0) == (0.0, dw)
    # at full rate, and still counter-clockwise from 170 deg clockwise of the target,
    # where the shorter way would now be clockwise
    v, w = turn_command(turn, math.radians(170.0), LIMITS.omega_max_radps, LIMITS, 0.1,
                        1.0) or (1.0, 0.0)
    assert v == 0.0 and w == LIMITS.omega_max_radps
    # slowing as it comes round
    v, w = turn_command(turn, math.radians(-15.0), LIMITS.omega_max_radps, LIMITS, 0.1,
                        1.0) or (1.0, 0.0)
    assert v == 0.0 and 0.0 < w < LIMITS.omega_max_radps
    assert turn_command(turn, 0.5 * TURN_DONE_RAD, 0.0, LIMITS, 0.1, 1.0) is None  # faced
    assert turn_command(turn, math.radians(-90.0), 0.0, LIMITS, 0.1, 5.0) is None  # timed out


def test_a_stuck_eifp_mpc_robot_nose_to_nose_with_a_parked_one_commits_to_one_turn() -> None:
    """The wiring: held in place facing a parked robot 5 cm in front, its goal behind it,
    once the progress monitor finds it stuck (4 s) it commits to one turn and turns on
    the spot one way, without speed, for the rest of the bounded turn; without the
    mechanism no turn is started. Held in place, the MPC turns this robot by itself too,
    so this test does not show the failure the mechanism mends: that one (the MPC leaving
    a hemmed-in robot standing) was seen only closed-loop in a crowd (`pillar_circle` 40,
    tuning seed 101, 38 of 40 arrived without the turn, 40 with it; docs/method.md)."""
    parked = Others(ids=np.array([4]), position_m=np.array([[1.05, 0.0]]),
                    velocity_mps=np.zeros((1, 2)), radius_m=np.array([0.5]),
                    linearity=np.zeros(1), track_start_m=np.array([[1.05, 0.0]]),
                    is_robot=np.array([True]), heading_rad=np.zeros(1),
                    recent_speed_mps=np.zeros(1), recent_interval_s=np.full(1, 0.1),
                    recent_turn_rate_radps=np.zeros(1))

    def run(on: bool) -> tuple[list[tuple[float, float]], int]:
        mech = dataclasses.replace(EIFP_MPC_MECHANISMS, turn_when_stuck=on)
        planner = make_planner("eifp-mpc", PlannerConfig(), mechanisms=mech)
        assert isinstance(planner, ViaPointPlanner)
        commands = []
        omega = 0.0
        for k in range(60):
            obs = Observation(robot_id=9, ego=EgoState(x_m=0.0, y_m=0.0, heading_rad=0.0,
                                                       v_mps=0.0, omega_radps=omega),
                              goal_m=np.array([-6.0, 0.3]), radius_m=0.5, limits=LIMITS,
                              goal_tolerance_m=0.25, others=parked)
            res = planner.plan(obs, 0.1 * k)
            commands.append((res.v_mps, res.omega_radps))
            omega = res.omega_radps
        return commands, planner.turns

    commands, turns = run(True)
    turned = commands[41:60]  # after the first stuck spell (4 s), within TURN_MAX_S
    assert turns == 1
    assert all(v == 0.0 for v, _ in turned)
    signs = {np.sign(w) for _, w in turned}
    assert len(signs) == 1 and 0.0 not in signs  # one way round, never back
    assert max(abs(w) for _, w in turned) == pytest.approx(LIMITS.omega_max_radps)
    assert run(False)[1] == 0
