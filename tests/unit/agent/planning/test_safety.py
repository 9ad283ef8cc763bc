"""Braking guard (`agent.planning.safety`): closed form, geometry, the eIFP-MPC command it caps."""

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.config import PlannerConfig, RobotLimits, SafetyConfig
from agent.core.types import EgoState, Observation, Others
from agent.planning.mechanisms import EIFP_MPC_MECHANISMS
from agent.planning.planners import RECENT_SPEED_MAX_AGE_S, make_planner
from agent.planning.safety import (
    braking_speed_limit,
    heading_sweep_rad,
    unseen_speed_up_mps,
    unseen_turn_closing_mps,
)
from tests.examples import examples

R = 0.5


def limit(others_xy, others_v=None, *, heading=0.0, sweep=0.0, tau=0.1, decel=1.5,
          margin=0.05):
    pos = np.atleast_2d(np.asarray(others_xy, dtype=float))
    vel = np.zeros_like(pos) if others_v is None else np.atleast_2d(np.asarray(others_v, float))
    return braking_speed_limit((0.0, 0.0), heading, R, pos, vel, np.full(len(pos), R),
                               reaction_s=tau, decel_mps2=decel, margin_m=margin,
                               sweep_rad=sweep)


def test_disc_straight_ahead_matches_the_hand_computed_stopping_speed():
    # gap 0.3 - margin 0.05 = 0.25 m of room; v tau + v^2 / (2 a) = 0.25 with a = 1.5,
    # tau = 0.1: v = 1.5 (-0.1 + sqrt(0.01 + 0.5 / 1.5)) = 0.72892 m/s
    v = limit([1.3, 0.0])
    assert v == pytest.approx(1.5 * (-0.1 + math.sqrt(0.01 + 0.5 / 1.5)), rel=1e-12)
    assert v == pytest.approx(0.72892, abs=1e-5)
    # and from that speed the robot stops exactly at the margin
    assert v * 0.1 + v * v / (2 * 1.5) == pytest.approx(0.25, rel=1e-12)


def test_a_disc_at_an_angle_limits_less_than_one_straight_ahead():
    ahead = limit([1.3, 0.0])
    at_60 = limit([1.3 * math.cos(math.pi / 3), 1.3 * math.sin(math.pi / 3)])
    # closing at v cos 60 deg: v/2 tau + v^2 / (4 a) = 0.25
    expected = 1.5 * (-0.1 + math.sqrt(0.01 + 2 * 0.25 / (1.5 * 0.5)))
    assert at_60 == pytest.approx(expected, rel=1e-12)
    assert at_60 > ahead


@pytest.mark.parametrize("xy", [[-1.3, 0.0], [0.0, 1.3], [0.0, -1.3], [-1.0, 0.9]])
def test_discs_behind_or_beside_put_no_limit(xy):
    assert limit(xy) == math.inf


def test_no_others_no_limit():
    assert limit(np.zeros((0, 2))) == math.inf


def test_a_receding_disc_gives_room_and_an_approaching_one_takes_its_stop_out_of_it():
    still = limit([2.0, 0.0])
    receding = limit([2.0, 0.0], [1.0, 0.0])
    approaching = limit([2.0, 0.0], [-0.8, 0.0])
    assert receding > still > approaching
    # room 0.95 + w^2 / (2 a) = 0.95 + 1 / 3
    assert receding == pytest.approx(1.5 * (-0.1 + math.sqrt(0.01 + 2 * (0.95 + 1 / 3) / 1.5)))
    # room 0.95 - (0.8 x 0.1 + 0.64 / 3): the other's own stop
    room = 0.95 - (0.08 + 0.64 / 3.0)
    assert approaching == pytest.approx(1.5 * (-0.1 + math.sqrt(0.01 + 2 * room / 1.5)))
    # two that must stop within the same gap: nothing is left when its stop fills it
    assert limit([2.0, 0.0], [-2.0, 0.0]) == 0.0


def test_within_the_margin_and_facing_it_means_stop():
    assert limit([1.02, 0.0]) == 0.0
    assert limit([0.0, 0.0]) == 0.0  # on its centre


def test_turning_towards_a_disc_counts_every_heading_swept_while_stopping():
    beside = [0.0, 1.3]  # at +90 degrees
    assert limit(beside) == math.inf
    # a sweep of 0.75 rad towards it: the worst heading is 0.75 rad, cos(pi/2 - 0.75)
    turning = limit(beside, sweep=0.75)
    cos_a = math.cos(math.pi / 2 - 0.75)
    assert turning == pytest.approx(1.5 * (-0.1 + math.sqrt(0.01 + 2 * 0.25 / (1.5 * cos_a))))
    # turning away from it does not count
    assert limit(beside, sweep=-0.75) == math.inf
    # a sweep across its direction means facing it squarely
    assert limit(beside, sweep=2.0) == pytest.approx(limit([1.3, 0.0]))
    # straight behind, at exactly -pi or +pi: a sweep past it either way faces it
    for sweep in (-3.2, 3.2):
        assert limit([0.0, -1.3], heading=math.pi / 2, sweep=sweep) == pytest.approx(
            limit([1.3, 0.0]))
    # a sweep that stops short of it does not face it squarely
    assert limit([0.0, -1.3], heading=math.pi / 2, sweep=-3.0) > limit([1.3, 0.0])


def test_the_sweep_covers_the_reaction_time_and_at_most_half_a_turn():
    assert heading_sweep_rad(1.5, 0.2) == pytest.approx(0.3)
    assert heading_sweep_rad(-1.0, 0.3) == pytest.approx(-0.3)
    assert heading_sweep_rad(12.0, 0.5) == pytest.approx(math.pi)
    assert heading_sweep_rad(-12.0, 0.5) == pytest.approx(-math.pi)


def test_the_nearest_constraint_wins():
    both = limit([[1.3, 0.0], [3.0, 0.0]])
    assert both == pytest.approx(limit([1.3, 0.0]))


@given(x=st.floats(-4.0, 4.0), y=st.floats(-4.0, 4.0), w=st.floats(-1.5, 1.5),
       up_to=st.floats(0.0, 2.0), sweep=st.floats(-1.0, 1.0))
def test_asking_up_to_a_speed_gives_the_same_answer_below_it(x, y, w, up_to, sweep):
    pos = np.array([[x, y], [x + 1.5, y - 0.7]])
    vel = np.array([[w, 0.0], [0.0, -w]])
    exact = braking_speed_limit((0.0, 0.0), 0.3, R, pos, vel, np.full(2, R), reaction_s=0.2,
                                decel_mps2=1.5, margin_m=0.05, sweep_rad=sweep)
    quick = braking_speed_limit((0.0, 0.0), 0.3, R, pos, vel, np.full(2, R), reaction_s=0.2,
                                decel_mps2=1.5, margin_m=0.05, sweep_rad=sweep, up_to_mps=up_to)
    assert min(quick, up_to) == pytest.approx(min(exact, up_to), rel=1e-12, abs=1e-12)
    assert quick >= exact


def test_longer_reaction_means_slower():
    assert limit([2.0, 0.0], tau=0.3) < limit([2.0, 0.0], tau=0.1) < limit([2.0, 0.0], tau=0.0)


@pytest.mark.parametrize("kwargs", [{"decel": 0.0}, {"tau": -0.1}, {"margin": -0.01}])
def test_bad_parameters_are_rejected(kwargs):
    with pytest.raises(ValueError):
        limit([1.3, 0.0], **kwargs)


@given(
    gap=st.floats(0.0, 5.0),
    angle=st.floats(-1.5, 1.5),
    tau=st.floats(0.0, 0.5),
    decel=st.floats(0.2, 5.0),
    w=st.floats(-2.0, 2.0),
)
def test_the_limit_is_the_speed_that_stops_the_approach_exactly(gap, angle, tau, decel, w):
    d = 2 * R + 0.05 + gap
    u = np.array([math.cos(angle), math.sin(angle)])
    v = limit(d * u, w * u, tau=tau, decel=decel)
    other_stop = -w * tau + w * w / (2 * decel) if w < 0 else -w * w / (2 * decel)
    room = gap - other_stop
    cos_a = math.cos(angle)
    assert math.isfinite(v) and v >= 0.0
    if room <= 1e-9:  # none left (up to the rounding of d - r - r_j - margin)
        # at most the speed that a rounding-sized room (2e-9 m) allows: with tau = 0 that
        # is sqrt(2 decel room / cos a), 1.1e-4 m/s for decel 3 at 1 rad (found by
        # hypothesis in stop 15 against the former fixed 1e-4)
        tiny = decel * (-tau + math.sqrt(tau * tau + 2.0 * 2e-9 / (decel * cos_a)))
        assert v <= max(tiny, 1e-12)
        return
    travelled = v * cos_a * tau + v * v * cos_a / (2 * decel)
    assert travelled == pytest.approx(room, rel=1e-6, abs=1e-9)


def test_an_unseen_speed_up_counts_as_that_much_more_approach():
    # a still disc that may already close at 0.5 m/s is limited as one seen closing at 0.5
    assert braking_speed_limit((0.0, 0.0), 0.0, R, np.array([[2.0, 0.0]]), np.zeros((1, 2)),
                               np.array([R]), reaction_s=0.1, decel_mps2=1.5, margin_m=0.05,
                               unseen_dv_mps=0.5) == pytest.approx(limit([2.0, 0.0], [-0.5, 0.0]))
    # a receding one keeps the part of its speed the lag cannot have undone
    assert braking_speed_limit((0.0, 0.0), 0.0, R, np.array([[2.0, 0.0]]), np.array([[1.0, 0.0]]),
                               np.array([R]), reaction_s=0.1, decel_mps2=1.5, margin_m=0.05,
                               unseen_dv_mps=0.4) == pytest.approx(limit([2.0, 0.0], [0.6, 0.0]))
    # per disc: only the first of two may have sped up
    pos = np.array([[2.0, 0.0], [0.0, 2.0]])
    per_disc = braking_speed_limit((0.0, 0.0), 0.0, R, pos, np.zeros((2, 2)), np.full(2, R),
                                   reaction_s=0.1, decel_mps2=1.5, margin_m=0.05,
                                   unseen_dv_mps=np.array([0.5, 0.0]))
    assert per_disc == pytest.approx(limit([2.0, 0.0], [-0.5, 0.0]))


@pytest.mark.parametrize("bad", [-0.1, math.nan, math.inf])
@pytest.mark.parametrize("as_array", [False, True])
def test_a_bad_unseen_speed_up_is_rejected(bad, as_array):
    with pytest.raises(ValueError, match="unseen_dv_mps"):
        braking_speed_limit((0.0, 0.0), 0.0, R, np.array([[2.0, 0.0]]), np.zeros((1, 2)),
                            np.array([R]), reaction_s=0.1, decel_mps2=1.5, margin_m=0.05,
                            unseen_dv_mps=np.array([bad]) if as_array else bad)


def speed_up(others_xy, heading, is_robot=True, turn=0.0, lag=0.2):
    return unseen_speed_up_mps((0.0, 0.0), np.atleast_2d(np.asarray(others_xy, float)),
                               np.atleast_1d(np.asarray(heading, float)),
                               np.atleast_1d(is_robot), accel_mps2=1.5,
                               turn_rate_radps=turn, lag_s=lag)


def test_a_robot_can_have_sped_up_only_along_its_heading():
    # 2 m ahead; facing the robot: the whole a lag = 0.3 m/s towards it
    assert speed_up([2.0, 0.0], math.pi) == pytest.approx([0.3])
    assert speed_up([2.0, 0.0], -math.pi) == pytest.approx([0.3])
    # facing away or across: none
    assert speed_up([2.0, 0.0], 0.0) == pytest.approx([0.0])
    assert speed_up([2.0, 0.0], math.pi / 2) == pytest.approx([0.0], abs=1e-12)
    # at 60 degrees off: the component towards the robot
    assert speed_up([2.0, 0.0], math.pi - math.pi / 3) == pytest.approx([0.15])
    # it may have turned by omega lag: 0.5 rad of a 1.0 rad offset
    assert speed_up([2.0, 0.0], math.pi - 1.0, turn=2.5) == pytest.approx([0.3 * math.cos(0.5)])
    assert speed_up([2.0, 0.0], math.pi + 0.4, turn=2.5) == pytest.approx([0.3])
    # unknown heading: any; scenario obstacles: none (constant velocity)
    assert speed_up([2.0, 0.0], math.nan) == pytest.approx([0.3])
    assert speed_up([2.0, 0.0], math.pi, is_robot=False) == pytest.approx([0.0])
    assert speed_up(np.zeros((0, 2)), np.zeros(0), np.zeros(0, bool)).shape == (0,)


def test_no_robot_speeds_up_past_v_max():
    ahead = np.array([[2.0, 0.0], [2.0, 1.0], [2.0, -1.0]])
    up = unseen_speed_up_mps((0.0, 0.0), ahead, np.full(3, math.pi), np.ones(3, bool),
                             accel_mps2=1.5, turn_rate_radps=0.0, lag_s=0.2,
                             others_speed_mps=np.array([1.1, 0.95, 0.0]), v_max_mps=1.1)
    facing = [1.0, math.cos(math.atan2(1.0, 2.0)), math.cos(math.atan2(1.0, 2.0))]
    assert up == pytest.approx([0.0, 0.15 * facing[1], 0.3 * facing[2]])
    # faster than v_max as estimated (noise): none, not negative
    assert unseen_speed_up_mps((0.0, 0.0), ahead[:1], np.full(1, math.pi), np.ones(1, bool),
                               accel_mps2=1.5, turn_rate_radps=0.0, lag_s=0.2,
                               others_speed_mps=np.array([1.3]), v_max_mps=1.1) == [0.0]


def test_a_leader_heading_away_may_have_braked_down_to_rest():
    # Others 2 m ahead, seen at 1.0, 1.0, 0.2 and 1.0 m/s; a lag of 0.2 s at 1.5 m/s^2.
    ahead = np.array([[2.0, 0.0], [2.0, 0.0], [2.0, 0.0], [2.0, 0.0]])
    heading = np.array([0.0, math.pi / 3, 0.0, math.pi / 2])  # away, 60 deg off, away, across
    up = unseen_speed_up_mps((0.0, 0.0), ahead, heading, np.ones(4, bool), accel_mps2=1.5,
                             turn_rate_radps=1.5, lag_s=0.2,
                             others_speed_mps=np.array([1.0, 1.0, 0.2, 1.0]), v_max_mps=1.1)
    # straight away: the whole a lag = 0.3 m/s closer; at 60 degrees its component; a slow
    # one at most its speed; one crossing at a right angle does not brake towards the
    # robot, it may only have sped up by the 0.1 m/s left to v_max, turned 0.3 rad its way
    crossing = 0.1 * math.cos(math.pi / 2 - 1.5 * 0.2)
    assert up == pytest.approx([0.3, 0.15, 0.2, crossing])
    # without the speeds the braking term is not known: the speed-up along the heading only
    assert speed_up([2.0, 0.0], 0.0) == pytest.approx([0.0])


def test_a_speed_change_seen_in_the_newest_interval_replaces_the_blind_bound():
    # Four others 2 m ahead, estimated at 1.0, 1.0, 0.3 and 1.0 m/s; lag 0.3 s at 1.5 m/s^2
    # (bound 0.45 m/s). Their newest intervals show 1.0 (no change), 0.8 (braking),
    # 0.6 (speeding up) and NaN (seen once), each 0.05 s old.
    ahead = np.tile([2.0, 0.0], (4, 1))
    heading = np.array([0.0, 0.0, math.pi, 0.0])  # away, away, facing, away
    common = {"accel_mps2": 1.5, "turn_rate_radps": 0.0, "lag_s": 0.3, "v_max_mps": 1.1,
              "others_speed_mps": np.array([1.0, 1.0, 0.3, 1.0])}
    recent = np.array([1.0, 0.8, 0.6, math.nan])
    up = unseen_speed_up_mps((0.0, 0.0), ahead, heading, np.ones(4, bool), **common,
                             recent_speed_mps=recent, recent_lag_s=np.full(4, 0.05))
    # no change seen: only what 0.05 s can hide (0.075); braking seen: 0.2 + 0.075; the
    # speed-up seen: 0.3 + 0.075; nothing known: the bound, as without recent speeds
    assert up == pytest.approx([0.075, 0.275, 0.375, 0.45])
    blind = unseen_speed_up_mps((0.0, 0.0), ahead, heading, np.ones(4, bool), **common)
    assert blind == pytest.approx([0.45, 0.45, 0.45, 0.45])
    # a change larger than the lag allows is still capped by the bound (and by v_max)
    capped = unseen_speed_up_mps((0.0, 0.0), ahead[:2], heading[:2], np.ones(2, bool),
                                 **(common | {"others_speed_mps": np.array([1.0, 1.0])}),
                                 recent_speed_mps=np.array([0.0, 1.0]),
                                 recent_lag_s=np.array([0.05, 1.0]))
    assert capped == pytest.approx([0.45, 0.45])


@settings(max_examples=examples(200), deadline=None)
@given(speed=st.floats(0.0, 1.1), recent=st.floats(0.0, 1.5), off=st.floats(-4.0, 4.0),
       lag=st.floats(0.0, 0.6), recent_lag=st.floats(0.0, 0.6))
def test_recent_speeds_never_make_the_unseen_term_larger(speed, recent, off, lag, recent_lag):
    common = {"accel_mps2": 1.5, "turn_rate_radps": 1.5, "lag_s": lag, "v_max_mps": 1.1,
              "others_speed_mps": np.array([speed])}
    args = ((0.0, 0.0), np.array([[2.0, 0.0]]), np.array([math.pi + off]), np.ones(1, bool))
    with_recent = unseen_speed_up_mps(*args, **common, recent_speed_mps=np.array([recent]),
                                      recent_lag_s=np.array([recent_lag]))
    assert 0.0 <= with_recent[0] <= unseen_speed_up_mps(*args, **common)[0] + 1e-12


@pytest.mark.parametrize("kwargs", [{"accel_mps2": 0.0}, {"turn_rate_radps": -1.0},
                                    {"lag_s": -0.1}])
def test_bad_speed_up_parameters_are_rejected(kwargs):
    args = {"accel_mps2": 1.5, "turn_rate_radps": 1.5, "lag_s": 0.2} | kwargs
    with pytest.raises(ValueError):
        unseen_speed_up_mps((0.0, 0.0), np.ones((1, 2)), np.zeros(1), np.ones(1, bool), **args)


def _observation(ahead_m: float, pose_age_s: float, is_robot: bool = False,
                 heading_rad: float | None = None) -> Observation:
    """A robot at full speed towards its goal, a still disc `ahead_m` ahead on the way: a
    scenario obstacle (moves as seen) or a robot at rest (may have set off unseen)."""
    ego = EgoState(x_m=0.0, y_m=0.0, heading_rad=0.0, v_mps=1.1, omega_radps=0.0)
    xy = np.array([[ahead_m, 0.0]])
    others = Others(ids=np.array([7 if is_robot else -1]), position_m=xy,
                    velocity_mps=np.zeros((1, 2)), radius_m=np.array([R]), linearity=np.ones(1),
                    track_start_m=xy, is_robot=np.array([is_robot]),
                    heading_rad=None if heading_rad is None else np.array([heading_rad]))
    return Observation(robot_id=1, ego=ego, goal_m=np.array([20.0, 0.0]), radius_m=R,
                       limits=RobotLimits(), others=others, pose_age_s=pose_age_s)


WINDOW_S = 0.5
"""The guard tests' arithmetic takes a 0.5 s estimation window: estimates lag 0.25 s."""


def _planner(margin_m: float, guard: bool = True):
    # On the spline reference the MPC keeps 1.1 m/s in these scenes (on the lines-and-arcs
    # reference it slows to 1.04 m/s for the turn at the start of its path), so the speeds
    # below are the guard's alone.
    config = PlannerConfig(safety=SafetyConfig(braking_margin_m=margin_m))
    mechanisms = replace(EIFP_MPC_MECHANISMS, lines_arcs=False, clamp_heading=True,
                         braking_guard=guard)
    return make_planner("eifp-mpc", config, mechanisms=mechanisms, estimation_window_s=WINDOW_S)


def test_eifp_mpc_speed_is_capped_by_the_guard_and_braking_stays_within_the_rate_limit():
    # The other is 3.5 m ahead: far outside the MPC's half-planes, which let it keep 1.1 m/s.
    # A guard margin of 2.0 m leaves 0.5 m of room: v_safe = 1.5 (-0.2 + sqrt(0.04 + 1 / 1.5))
    obs = _observation(3.5, pose_age_s=0.1)
    free = _planner(2.0, guard=False).plan(obs, 0.0)
    assert free.v_mps > 1.09
    capped = _planner(2.0).plan(obs, 0.0)
    assert capped.v_mps == pytest.approx(1.5 * (-0.2 + math.sqrt(0.04 + 1.0 / 1.5)), rel=1e-9)
    # 0.2 m of room asks for v_safe = 0.53 m/s, below one period of braking: the hardest
    # braking the rate limit allows (1.1 - 1.5 x 0.1), not a jump
    hard = _planner(2.3).plan(obs, 0.0)
    assert hard.v_mps == pytest.approx(1.1 - 0.15, abs=1e-9)


def test_a_robot_at_rest_may_have_set_off_since_its_estimate():
    # The same still disc, but a robot: its estimate (a 0.5 s least-squares slope) lags by
    # 0.25 s and the pose is 0.1 s old, so it may close at 1.5 x 0.35 = 0.525 m/s by now.
    # Margin 1.8 m: room 0.7 - (0.525 x 0.2 + 0.525^2 / 3) = 0.503125 m, v_safe 0.965 m/s
    # (above one period of braking, 0.95); the obstacle's 0.7 m allow 1.18 m/s.
    obs = _observation(3.5, pose_age_s=0.1, is_robot=True)
    capped = _planner(1.8).plan(obs, 0.0)
    room = 0.7 - (0.525 * 0.2 + 0.525**2 / 3.0)
    assert capped.v_mps == pytest.approx(1.5 * (-0.2 + math.sqrt(0.04 + 2 * room / 1.5)),
                                         rel=1e-9)
    obstacle = _planner(1.8).plan(_observation(3.5, 0.1), 0.0)
    assert capped.v_mps < obstacle.v_mps - 0.1
    # seen facing the robot, the same; seen facing away (it cannot have turned round in
    # 0.35 s at 1.5 rad/s), as an obstacle
    facing = _planner(1.8).plan(
        _observation(3.5, 0.1, is_robot=True, heading_rad=math.pi), 0.0)
    assert facing.v_mps == pytest.approx(capped.v_mps, rel=1e-12)
    away = _planner(1.8).plan(
        _observation(3.5, 0.1, is_robot=True, heading_rad=0.0), 0.0)
    assert away.v_mps == pytest.approx(obstacle.v_mps, rel=1e-12)


def test_the_guard_leaves_a_robot_alone_that_faces_away():
    obs = _observation(-2.2, pose_age_s=0.1)  # the other is behind
    a = _planner(2.0).plan(obs, 0.0)
    b = _planner(2.0, guard=False).plan(obs, 0.0)
    assert a.v_mps == b.v_mps


def _one_pass_guard(planner, obs: Observation, v_mps: float,
                    omega_radps: float) -> tuple[float, float]:
    """The guard as `ViaPointPlanner._braking_guard` defines it, written out once: the exact
    unseen speed-ups in one pass, the robot's own turn swept on through its stop, and where
    even the hardest braking misses the cap, the reachable turn (the last one, or either
    end of one period's reach) that allows the highest speed."""
    ego, limits, others = obs.ego, obs.limits, obs.others
    reaction_s = obs.pose_age_s + planner.control_period_s
    lag_s = 0.5 * WINDOW_S + obs.pose_age_s
    unseen = unseen_speed_up_mps(
        (ego.x_m, ego.y_m), others.position_m, others.heading_rad, others.is_robot,
        accel_mps2=limits.accel_max_mps2, turn_rate_radps=limits.omega_max_radps, lag_s=lag_s,
        others_speed_mps=np.hypot(*others.velocity_mps.T), v_max_mps=limits.v_max_mps,
        recent_speed_mps=(others.recent_speed_mps
                          if obs.pose_age_s <= RECENT_SPEED_MAX_AGE_S else None),
        recent_lag_s=0.5 * others.recent_interval_s + obs.pose_age_s)
    turning_s = reaction_s + max(v_mps, 0.0) / limits.accel_max_mps2  # on through the stop
    if obs.pose_age_s > RECENT_SPEED_MAX_AGE_S:
        unseen = np.maximum(unseen, unseen_turn_closing_mps(
            (ego.x_m, ego.y_m), others.position_m, others.velocity_mps, others.heading_rad,
            others.recent_turn_rate_radps, others.is_robot,
            turn_rate_max_radps=limits.omega_max_radps, age_s=obs.pose_age_s,
            reaction_s=reaction_s))

    def cap(omega: float) -> float:
        return braking_speed_limit(
            (ego.x_m, ego.y_m), ego.heading_rad, obs.radius_m, others.position_m,
            others.velocity_mps, others.radius_m, reaction_s=reaction_s,
            decel_mps2=limits.accel_max_mps2, margin_m=planner.config.safety.braking_margin_m,
            sweep_rad=heading_sweep_rad(omega, turning_s), unseen_dv_mps=unseen)

    v_safe = cap(omega_radps)
    if v_mps <= v_safe:
        return v_mps, omega_radps
    hardest = max(ego.v_mps - limits.accel_max_mps2 * planner.control_period_s,
                  limits.v_min_mps)
    if v_safe < hardest:
        step = limits.alpha_max_radps2 * planner.control_period_s
        lo = max(-limits.omega_max_radps, ego.omega_radps - step)
        hi = min(limits.omega_max_radps, ego.omega_radps + step)
        for omega in (ego.omega_radps, lo, hi):
            if cap(omega) > v_safe:
                v_safe, omega_radps = cap(omega), omega
    return min(v_mps, max(v_safe, hardest)), omega_radps


@settings(max_examples=examples(300), deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 10),
       pose_age_s=st.sampled_from([0.0, 0.03, 0.05, 0.13, 0.4]),
       v_mps=st.floats(0.0, 1.1), omega_radps=st.floats(-1.5, 1.5))
def test_the_guards_cheap_first_pass_never_changes_its_result(seed, k, pose_age_s, v_mps,
                                                              omega_radps):
    # The guard first tries every unseen speed-up at its bound and pays for the exact ones
    # only when that limits the command: the result must be the one-pass result, exactly.
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-4.0, 4.0, (k, 2))
    # headings unknown (None: any heading) in a fifth of the crowds
    heading = rng.uniform(-math.pi, math.pi, k) if rng.random() > 0.2 else None
    # recent speeds known for most (NaN: seen once), unknown altogether in a fifth
    recent = np.where(rng.random(k) < 0.8, rng.uniform(0.0, 1.1, k), np.nan)
    interval = np.where(np.isnan(recent), np.nan, rng.uniform(0.02, 0.17, k))
    known = rng.random() > 0.2
    turn = np.where(rng.random(k) < 0.8, rng.uniform(-2.0, 2.0, k), np.nan)
    others = Others(ids=np.arange(k) + 10, position_m=xy,
                    velocity_mps=rng.uniform(-0.8, 0.8, (k, 2)),
                    radius_m=np.full(k, R), linearity=np.ones(k), track_start_m=xy,
                    is_robot=rng.random(k) < 0.8, heading_rad=heading,
                    recent_speed_mps=recent if known else None,
                    recent_interval_s=interval if known else None,
                    recent_turn_rate_radps=turn if known else None)
    ego = EgoState(x_m=0.0, y_m=0.0, heading_rad=float(rng.uniform(-math.pi, math.pi)),
                   v_mps=float(rng.uniform(0.0, 1.1)), omega_radps=0.0)
    obs = Observation(robot_id=1, ego=ego, goal_m=np.array([20.0, 0.0]), radius_m=R,
                      limits=RobotLimits(), others=others, pose_age_s=pose_age_s)
    planner = _planner(0.1)
    assert planner._braking_guard(obs, v_mps, omega_radps) == \
        _one_pass_guard(planner, obs, v_mps, omega_radps)


def _follower(pose_age_s: float, recent: float | None) -> Observation:
    """A robot at 1.0 m/s, 1.3 m behind a leader heading the same way at 1.0 m/s; the
    leader's speed over its newest 0.1 s interval is `recent` (None: unknown)."""
    leader = Others(ids=np.array([2]), position_m=np.array([[1.3, 0.0]]),
                    velocity_mps=np.array([[1.0, 0.0]]), radius_m=np.array([R]),
                    linearity=np.ones(1), track_start_m=np.array([[0.8, 0.0]]),
                    is_robot=np.ones(1, bool), heading_rad=np.zeros(1),
                    recent_speed_mps=None if recent is None else np.array([recent]),
                    recent_interval_s=None if recent is None else np.array([0.1]))
    ego = EgoState(x_m=0.0, y_m=0.0, heading_rad=0.0, v_mps=1.0, omega_radps=0.0)
    return Observation(robot_id=1, ego=ego, goal_m=np.array([20.0, 0.0]), radius_m=R,
                       limits=RobotLimits(), others=leader, pose_age_s=pose_age_s)


def test_the_guard_reads_recent_speeds_from_fresh_poses_only():
    planner = _planner(0.05)
    # fresh poses: a leader seen keeping its speed is allowed a braking of a_max over half
    # the interval only, so the follower may go faster than under the blind bound
    fresh_blind = planner._braking_guard(_follower(0.0, None), 1.1, 0.0)[0]
    fresh_seen = planner._braking_guard(_follower(0.0, 1.0), 1.1, 0.0)[0]
    # blind: the leader may recede at 1.0 - 1.5 x 0.25 = 0.625 m/s, room 0.25 + 0.625^2 / 3
    assert fresh_blind == pytest.approx(1.5 * (-0.1 + math.sqrt(0.01 + 2 * 0.3802 / 1.5)),
                                        abs=1e-3)
    # seen at 1.0: at least 1.0 - 1.5 x 0.05 = 0.925 m/s, room enough for the full 1.1 m/s
    assert fresh_seen == 1.1 > fresh_blind
    # a leader seen braking (0.6 m/s over the newest interval) takes that back
    assert planner._braking_guard(_follower(0.0, 0.6), 1.1, 0.0)[0] < fresh_seen
    # poses older than RECENT_SPEED_MAX_AGE_S: the blind bound, recent speeds or not
    old = RECENT_SPEED_MAX_AGE_S + 0.05
    assert planner._braking_guard(_follower(old, 1.0), 1.1, 0.0)[0] == \
        planner._braking_guard(_follower(old, None), 1.1, 0.0)[0]


def _turn_term(heading, turn, *, velocity=(0.0, 1.0), is_robot=True, age=0.1, reaction=0.2):
    """The turn term for one other at (5, 0) seen from a robot at the origin."""
    return unseen_turn_closing_mps(
        (0.0, 0.0), np.array([[5.0, 0.0]]), np.array([velocity]), np.array([heading]),
        np.array([turn]), np.array([is_robot]), turn_rate_max_radps=1.5, age_s=age,
        reaction_s=reaction)[0]


def test_turn_term_hand_computed():
    # heading and estimate straight at the robot, not turning: nothing unseen
    assert _turn_term(math.pi, 0.0, velocity=(-1.0, 0.0)) == pytest.approx(0.0, abs=1e-12)
    # crossing upwards (estimate (0, 1): no closing) and turning left towards the robot at
    # 1 rad/s: heading now pi/2 + 0.1, then up to pi/2 + 0.3 before the robot's braking
    # acts; closing 1.0 cos(pi - pi/2 - 0.3)
    assert _turn_term(math.pi / 2, 1.0) == pytest.approx(math.cos(math.pi / 2 - 0.3))
    # the same turn to the right, away from the robot: nothing
    assert _turn_term(math.pi / 2, -1.0) == 0.0
    # the robot's bearing inside the swept headings: the full speed
    assert _turn_term(3.0, 1.0) == pytest.approx(1.0)
    # a turn rate above the largest counts as the largest (1.5 rad/s)
    assert _turn_term(math.pi / 2, 9.0) == pytest.approx(math.cos(math.pi / 2 - 0.45))
    # turn rate unknown: the heading now only (cos(pi - 2.0) closing, the estimate none)
    assert _turn_term(2.0, math.nan, age=0.0) == pytest.approx(math.cos(math.pi - 2.0))
    # heading unknown, or an obstacle: nothing (the speed-up term covers those)
    assert _turn_term(math.nan, 1.0) == 0.0
    assert _turn_term(math.pi / 2, 1.0, is_robot=False) == 0.0


@given(heading=st.floats(-10.0, 10.0), turn=st.floats(-5.0, 5.0),
       vx=st.floats(-1.1, 1.1), vy=st.floats(-1.1, 1.1), age=st.floats(0.0, 0.5),
       reaction=st.floats(0.0, 0.7))
def test_turn_term_is_between_zero_and_twice_the_speed(heading, turn, vx, vy, age, reaction):
    term = _turn_term(heading, turn, velocity=(vx, vy), age=age, reaction=reaction)
    assert 0.0 <= term <= 2.0 * math.hypot(vx, vy) + 1e-12


def _crosser(pose_age_s: float, turn: float | None, ahead_m: float = 1.6) -> Observation:
    """A robot at 1.0 m/s heading +x; another `ahead_m` ahead and 0.2 m to its left
    crossing at 1.0 m/s to the left (estimate (0, 1)), its heading already 0.3 rad into a
    left turn, back round towards the robot; its turn rate over the newest 0.1 s is `turn`
    (None: unknown)."""
    other = Others(ids=np.array([2]), position_m=np.array([[ahead_m, 0.2]]),
                   velocity_mps=np.array([[0.0, 1.0]]), radius_m=np.array([R]),
                   linearity=np.ones(1), track_start_m=np.array([[ahead_m, -0.3]]),
                   is_robot=np.ones(1, bool), heading_rad=np.array([math.pi / 2 + 0.3]),
                   recent_speed_mps=np.array([1.0]), recent_interval_s=np.array([0.1]),
                   recent_turn_rate_radps=None if turn is None else np.array([turn]))
    ego = EgoState(x_m=0.0, y_m=0.0, heading_rad=0.0, v_mps=1.0, omega_radps=0.0)
    return Observation(robot_id=1, ego=ego, goal_m=np.array([20.0, 0.0]), radius_m=R,
                       limits=RobotLimits(), others=other, pose_age_s=pose_age_s)


def test_the_guard_reads_the_others_turns_from_delayed_poses_only():
    planner = _planner(0.05)
    old = RECENT_SPEED_MAX_AGE_S + 0.05
    # delayed poses: one turning towards the robot's path limits the robot more than the
    # same other seen with no turn, and more still than one turning away
    towards = planner._braking_guard(_crosser(old, 1.5), 1.1, 0.0)[0]
    straight = planner._braking_guard(_crosser(old, 0.0), 1.1, 0.0)[0]
    away = planner._braking_guard(_crosser(old, -1.5), 1.1, 0.0)[0]
    assert towards < straight - 0.1  # 0.85 (the hardest braking) against 0.99
    assert straight < away  # 0.99 against 1.03: the heading alone already counts
    # fresh poses: the turn is not read (no-fault runs decide as before), also where the
    # guard binds
    fresh = planner._braking_guard(_crosser(0.0, 1.5, ahead_m=1.4), 1.1, 0.0)[0]
    assert fresh < 1.0
    assert fresh == planner._braking_guard(_crosser(0.0, None, ahead_m=1.4), 1.1, 0.0)[0]


def _behind_right(pose_age_s: float) -> Observation:
    """A robot at 1.0 m/s heading +x, a still obstacle behind it on the right (bearing
    -1.80 rad, gap 0.33 m): not faced now, faced once the robot has turned right by
    about 1.3 rad."""
    xy = np.array([[-0.3, -1.3]])
    others = Others(ids=np.array([-1]), position_m=xy, velocity_mps=np.zeros((1, 2)),
                    radius_m=np.array([R]), linearity=np.ones(1), track_start_m=xy,
                    is_robot=np.array([False]))
    ego = EgoState(x_m=0.0, y_m=0.0, heading_rad=0.0, v_mps=1.0, omega_radps=0.0)
    return Observation(robot_id=1, ego=ego, goal_m=np.array([20.0, 0.0]), radius_m=R,
                       limits=RobotLimits(), others=others, pose_age_s=pose_age_s)


def _stop_arc_cap(reaction_s: float, v_mps: float, omega_radps: float) -> float:
    """v_safe against `_behind_right`'s obstacle (bearing -1.80 rad, gap 0.33 m) for a robot
    turning at omega until stopped from v (decel 1.5, margin 0.05): the safety module's
    formula, v cos a tau + v^2 cos a / (2 decel) = room, solved for v."""
    bearing = math.atan2(-1.3, -0.3)
    heading = max(bearing, omega_radps * (reaction_s + v_mps / 1.5))  # right turn sweeps down
    cos_a = math.cos(bearing - heading)
    room = math.hypot(0.3, 1.3) - 2 * R - 0.05
    return 1.5 * (-reaction_s + math.sqrt(reaction_s ** 2 + 2.0 * room / (1.5 * cos_a)))


def test_the_guard_sweeps_its_own_turn_on_through_the_stop():
    # The world brakes a robot along its commanded arc, so the headings it faces are those
    # swept until it stands, from fresh poses too (pillar_circle 40, evaluation seed 6: two
    # robots escaping each other turned into each other while braking).
    planner = _planner(0.05)
    # fresh poses (reaction 0.1 s): turning right at 1.5 rad/s the robot faces the obstacle
    # behind it on the right before it stands; the cap is within one period's braking
    v, omega = planner._braking_guard(_behind_right(0.0), 1.1, -1.5)
    assert v == pytest.approx(_stop_arc_cap(0.1, 1.1, -1.5)) and 0.85 < v < 1.0
    assert omega == -1.5
    # turning left, away from it: no limit
    assert planner._braking_guard(_behind_right(0.0), 1.1, 1.5) == (1.1, 1.5)


def test_a_turn_no_braking_can_make_safe_gives_way_to_the_safest_reachable_turn():
    planner = _planner(0.05)
    # delayed (0.1 s, reaction 0.2 s): the cap under the right turn is below the hardest
    # braking from 1.0 m/s in one period (0.85), so the turn is the wrong one: of the turns
    # reachable in a period (the last, 0, or 0 -+ alpha_max dt = -+0.6 rad/s) the robot keeps
    # the last one, straight on, which never faces the obstacle, at the speed it asked for
    assert _stop_arc_cap(0.2, 1.1, -1.5) < 0.85
    assert planner._braking_guard(_behind_right(0.1), 1.1, -1.5) == (1.1, 0.0)
    # an obstacle straight ahead (gap 0.2 m) is faced under every reachable turn: no turn
    # allows more, so the robot keeps the turn it asked for and brakes as hard as it can
    xy = np.array([[1.0 + 0.2, 0.0]])
    ahead = replace(_behind_right(0.0), others=Others(
        ids=np.array([-1]), position_m=xy, velocity_mps=np.zeros((1, 2)), radius_m=np.array([R]),
        linearity=np.ones(1), track_start_m=xy, is_robot=np.array([False])))
    v, omega = planner._braking_guard(ahead, 1.1, 0.3)
    assert v == pytest.approx(1.0 - 1.5 * 0.1) and omega == 0.3
