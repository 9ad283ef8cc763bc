"""Metrics on hand-made trajectories with known answers, and the run-directory reader."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from agent.core.config import PlannerConfig, RobotLimits
from agent.core.scenario import ObstacleSpec, RobotSpec, Scenario
from orchestrator.analysis.metrics import (
    ARRIVAL_RECORD_EPS_M,
    Commands,
    RunSpec,
    Trajectory,
    arrival_index,
    compute_metrics,
    deadline_misses,
    side_flips,
)
from orchestrator.analysis.rundir import metrics_from_run_dir, read_trajectory, write_metrics
from orchestrator.analysis.turns import (
    REVERSAL_CAUSES,
    PlanInForce,
    count_reversals,
    find_turns,
    oscillations,
    reversal_causes,
)
from tests.unit.orchestrator.analysis.test_latency import stamps_row
from world.recorder import RunRecorder

DT = 0.1


def heading_from_rates(rates_radps: list[float], dt: float = DT) -> tuple[np.ndarray, np.ndarray]:
    """(t, heading) whose rate over interval k is rates_radps[k]."""
    t = np.arange(len(rates_radps) + 1) * dt
    heading = np.concatenate([[0.0], np.cumsum(np.asarray(rates_radps) * dt)])
    return t, heading


def hold(rate: float, seconds: float) -> list[float]:
    return [rate] * round(seconds / DT)


# --- oscillations --------------------------------------------------------------------

def test_zig_zag_gives_exact_reversal_count():
    rates = hold(0.5, 1.0) + hold(-0.5, 1.0) + hold(0.5, 1.0) + hold(-0.5, 1.0)
    t, heading = heading_from_rates(rates)
    turns = find_turns(t, heading)
    assert [x.sign for x in turns] == [1, -1, 1, -1]
    assert turns[0].angle_rad == pytest.approx(0.5)
    assert turns[1].start_s == pytest.approx(1.0) and turns[1].end_s == pytest.approx(2.0)
    assert oscillations(t, heading) == 3


def test_wrapped_headings_are_unwrapped():
    rates = hold(1.0, 2.0) + hold(-1.0, 2.0)
    t, heading = heading_from_rates(rates)
    wrapped = np.angle(np.exp(1j * (heading + 2.5)))  # crosses +-pi
    assert oscillations(t, wrapped) == 1


def test_a_turn_of_0_09_rad_does_not_count():
    rates = hold(0.09, 1.0) + hold(-0.5, 1.0)  # 0.09 rad, then 0.5 rad back
    t, heading = heading_from_rates(rates)
    assert len(find_turns(t, heading)) == 1
    assert oscillations(t, heading) == 0
    rates = hold(0.2, 1.0) + hold(-0.5, 1.0)
    assert oscillations(*heading_from_rates(rates)) == 1


def test_slow_drift_below_the_rate_threshold_is_not_a_turn():
    rates = hold(0.04, 10.0) + hold(-0.5, 1.0) + hold(0.04, 10.0)  # 0.4 rad at 0.04 rad/s
    t, heading = heading_from_rates(rates)
    assert [x.sign for x in find_turns(t, heading)] == [-1]
    assert oscillations(t, heading) == 0


def test_reversal_needs_to_start_within_3_s():
    near = hold(0.5, 1.0) + hold(0.0, 2.9) + hold(-0.5, 1.0)
    far = hold(0.5, 1.0) + hold(0.0, 3.5) + hold(-0.5, 1.0)
    assert oscillations(*heading_from_rates(near)) == 1
    assert oscillations(*heading_from_rates(far)) == 0


def test_same_direction_turns_and_skipped_small_runs():
    same = hold(0.5, 1.0) + hold(0.0, 1.0) + hold(0.5, 1.0)
    assert oscillations(*heading_from_rates(same)) == 0
    # A tiny opposite wiggle between two left turns is not a turn, so no reversal.
    wiggle = hold(0.5, 1.0) + hold(-0.5, 0.1) + hold(0.5, 1.0)
    turns = find_turns(*heading_from_rates(wiggle))
    assert [x.sign for x in turns] == [1, 1] and count_reversals(turns) == 0


# --- side flips and deadline misses ------------------------------------------------

# --- reversal causes --------------------------------------------------------------

# A left turn over [0, 1) s and a right turn over [1.5, 2.5) s: one reversal, whose turns
# start at 0 and 1.5 s.
S_TURN = hold(0.5, 1.0) + hold(0.0, 0.5) + hold(-0.5, 1.0)


def plans(rows, with_side=True):
    """PlanInForce from (t_applied, status, side, resolved) rows."""
    t, status, side, resolved = zip(*rows)
    return PlanInForce(np.array(t, float), np.array(status, str),
                       np.array(side) if with_side else None,
                       np.array(resolved, float) if with_side else None)


@pytest.mark.parametrize("second, speed, expected", [
    (("ok", 1, 7.0), 1.0, "same_via_point"),
    (("ok", -1, 7.0), 1.0, "side_flip"),
    (("ok", 1, 8.0), 1.0, "threat_switch"),
    (("ok", 0, math.nan), 1.0, "no_via_point"),
    (("escape", 0, 8.0), 1.0, "escape"),
    (("ok", 1, 7.0), 0.3, "slow"),  # slow wins over everything
    (("escape", 0, 8.0), 0.49, "slow"),
])
def test_each_reversal_gets_the_first_cause_that_fits(second, speed, expected):
    t, heading = heading_from_rates(S_TURN)
    # The first plan is in force from t = 0, the second from 1.4 s (before the right turn).
    in_force = plans([(0.0, "ok", 1, 7.0), (1.4, *second)])
    counts = reversal_causes(t, heading, np.full(t.size, speed), in_force)
    assert counts == {c: int(c == expected) for c in REVERSAL_CAUSES}


def test_the_plan_in_force_is_the_last_one_applied_at_or_before_the_turn():
    t, heading = heading_from_rates(S_TURN)
    # A switch applied after the right turn started does not explain it.
    late = plans([(0.0, "ok", 1, 7.0), (1.6, "ok", 1, 8.0)])
    assert reversal_causes(t, heading, np.ones(t.size), late)["same_via_point"] == 1
    on_time = plans([(0.0, "ok", 1, 7.0), (1.5, "ok", 1, 8.0)])
    assert reversal_causes(t, heading, np.ones(t.size), on_time)["threat_switch"] == 1


def test_without_plan_columns_or_commands_the_cause_is_unknown():
    t, heading = heading_from_rates(S_TURN)
    no_side = plans([(0.0, "ok", 1, 7.0), (1.4, "ok", 1, 8.0)], with_side=False)
    assert reversal_causes(t, heading, np.ones(t.size), no_side)["unknown"] == 1
    # Escapes are still recognised from the status alone.
    esc = plans([(0.0, "ok", 1, 7.0), (1.4, "escape", 0, 8.0)], with_side=False)
    assert reversal_causes(t, heading, np.ones(t.size), esc)["escape"] == 1
    none = PlanInForce(np.zeros(0), np.zeros(0, str), None, None)
    assert reversal_causes(t, heading, np.ones(t.size), none)["unknown"] == 1


def test_reversal_causes_sum_to_the_oscillations_of_a_random_history():
    rng = np.random.default_rng(3)
    rates = rng.choice([-0.6, -0.2, 0.0, 0.2, 0.6], size=600).repeat(3).tolist()
    t, heading = heading_from_rates(rates)
    rows = [(float(x), str(rng.choice(["ok", "escape"])), int(rng.choice([-1, 0, 1])),
             float(rng.choice([1.0, 2.0, math.nan]))) for x in np.arange(0.0, t[-1], 0.1)]
    counts = reversal_causes(t, heading, rng.uniform(0.0, 1.1, t.size), plans(rows))
    assert oscillations(t, heading) > 20
    assert sum(counts.values()) == oscillations(t, heading)
    assert set(counts) == set(REVERSAL_CAUSES)


def test_side_flips_count_consecutive_opposite_sides_while_resolving():
    seq = np.array([5, 0, 1, 2, 3, 4])  # out of order on purpose
    side = np.array([1, 1, -1, 1, 0, -1])
    resolved = np.array([3.0, 3.0, 4.0, 4.0, np.nan, 3.0])
    # by seq: sides 1,-1,1,0,-1,1 ; resolved 3,4,4,-,3,3
    assert side_flips(seq, side, resolved) == (3, 2)
    none = np.array([np.nan] * 6)
    assert side_flips(seq, side, none) == (0, 0)


def test_deadline_misses_use_period_plus_one_tick():
    stamps = np.array([0.0, 0.1, 0.22, 0.36, 0.46])  # gaps .1, .12 (ok), .14 (miss), .1
    assert deadline_misses(np.arange(5), stamps, 0.1, 0.02) == (1, 4)
    assert deadline_misses(np.arange(1), stamps[:1], 0.1, 0.02) == (0, 0)


# --- whole-run metrics on hand-made trajectories -----------------------------------

def spec(starts, goals, radius=0.5, v_max=1.0, tol=0.25, limit=100.0, obstacles=()):
    n = len(starts)
    ob = list(obstacles)
    return RunSpec(
        robot_ids=np.arange(n), start_m=np.array(starts, float), goal_m=np.array(goals, float),
        radius_m=np.full(n, radius), v_max_mps=np.full(n, v_max), goal_tolerance_m=tol,
        time_limit_s=limit,
        obstacle_ids=-np.arange(1, len(ob) + 1),
        obstacle_center_m=np.array([o[0] for o in ob], float).reshape(-1, 2),
        obstacle_velocity_mps=np.array([o[1] for o in ob], float).reshape(-1, 2),
        obstacle_radius_m=np.array([o[2] for o in ob], float),
    )


def trajectory(t, xy, heading=None):
    """xy: (T, n, 2)."""
    xy = np.asarray(xy, float)
    pose = np.zeros(xy.shape[:2] + (3,))
    pose[..., :2] = xy
    if heading is not None:
        pose[..., 2] = heading
    return Trajectory(np.asarray(t, float), np.arange(xy.shape[1]), pose,
                      np.zeros(xy.shape[:2] + (2,)))


def metrics(traj, sp, commands=None, **kw):
    return compute_metrics(traj, commands or Commands.empty(), sp,
                           control_period_s=0.1, world_dt_s=DT, **kw)


def test_straight_path_has_ratio_one_and_known_time():
    t = np.arange(0, 121) * DT  # 12 s at 1 m/s along x
    xy = np.stack([np.stack([t, np.zeros_like(t)], axis=1)], axis=1)
    m = metrics(trajectory(t, xy), spec([(0, 0)], [(10, 0)]))
    r = m.per_robot[0]
    assert r.arrived and m.success and m.arrived == 1
    assert r.time_to_goal_s == pytest.approx(9.8)  # first sample within 0.25 m
    assert r.path_length_m == pytest.approx(9.8)
    assert r.path_ratio == pytest.approx(1.0) and m.path_ratio_mean == pytest.approx(1.0)
    assert r.straight_m == 10.0 and r.ideal_time_s == 10.0
    assert r.time_ratio == pytest.approx(0.98) and m.time_ratio_mean == pytest.approx(0.98)
    assert r.oscillations == 0 and m.contacts == 0 and m.min_gap_m is None


def test_mixed_speeds_ideal_time_and_time_ratio_use_each_robots_own_v_max():
    # Two robots 10 m from their goals at v_max 0.5 and 2.0 m/s; both move at 1 m/s.
    t = np.arange(0, 121) * DT
    xy = np.stack([np.stack([t, np.zeros_like(t)], axis=1),
                   np.stack([t, np.full_like(t, 5.0)], axis=1)], axis=1)
    sp = spec([(0, 0), (0, 5)], [(10, 0), (10, 5)])
    sp = dataclasses.replace(sp, v_max_mps=np.array([0.5, 2.0]))
    m = metrics(trajectory(t, xy), sp)
    slow, fast = m.per_robot
    assert slow.ideal_time_s == 20.0 and fast.ideal_time_s == 5.0
    assert slow.time_ratio == pytest.approx(9.8 / 20.0)
    assert fast.time_ratio == pytest.approx(9.8 / 5.0)
    assert m.time_ratio_mean == pytest.approx((9.8 / 20.0 + 9.8 / 5.0) / 2.0)
    assert slow.straight_m == fast.straight_m == 10.0
    assert slow.path_ratio == pytest.approx(1.0) and fast.path_ratio == pytest.approx(1.0)


def test_detour_path_ratio():
    # Start (0, 0) -> (5, 5) -> (10, 0): sqrt(2) detour, arrival exactly at the goal.
    t = np.arange(3.0)
    xy = np.array([[[0, 0]], [[5, 5]], [[10, 0]]], float)
    r = metrics(trajectory(t, xy), spec([(0, 0)], [(10, 0)])).per_robot[0]
    assert r.path_ratio == pytest.approx(math.sqrt(2.0))
    assert r.path_length_m == pytest.approx(10 * math.sqrt(2.0))


def test_missing_t0_sample_starts_the_path_at_the_scenario_start():
    t = np.array([1.0, 2.0])
    xy = np.array([[[1, 0]], [[2, 0]]], float)
    r = metrics(trajectory(t, xy), spec([(0, 0)], [(2, 0)])).per_robot[0]
    assert r.path_length_m == pytest.approx(2.0) and r.time_to_goal_s == 2.0


def test_overlapping_discs_are_one_contact_episode_and_fail_the_run():
    # Two robots 0.998 m apart (2 mm overlap) for three samples, apart, then again.
    d = [3.0, 0.998, 0.998, 0.998, 3.0, 0.998, 3.0]
    t = np.arange(len(d)) * DT
    xy = np.array([[[0.0, 0.0], [x, 0.0]] for x in d])
    m = metrics(trajectory(t, xy), spec([(0, 0), (3, 0)], [(0, 0), (3, 0)]))
    assert m.contacts == 2 and m.contact_pairs == [[0, 1]]
    assert m.arrived == 2 and not m.success
    assert m.min_gap_m == pytest.approx(-0.002)
    assert [r.contacts for r in m.per_robot] == [2, 2]


def test_overlap_below_one_millimetre_is_not_a_contact():
    t = np.arange(3) * DT
    xy = np.array([[[0.0, 0.0], [x, 0.0]] for x in (3.0, 0.9995, 3.0)])
    m = metrics(trajectory(t, xy), spec([(0, 0), (3, 0)], [(0, 0), (3, 0)]))
    assert m.contacts == 0 and m.success
    assert m.min_gap_m == pytest.approx(-0.0005)


def test_min_gap_and_moving_obstacle_contact():
    t = np.arange(4) * 1.0
    xy = np.zeros((4, 1, 2))  # a robot sitting at its goal
    # Obstacle radius 0.5 starts 4 m away and moves at 1 m/s towards it: gaps 3, 2, 1, 0 ...
    sp = spec([(0, 0)], [(0, 0)], obstacles=[((4.0, 0.0), (-1.0, 0.0), 0.5)])
    m = metrics(trajectory(t, xy), sp)
    assert m.min_gap_m == pytest.approx(0.0) and m.contacts == 0
    t5 = np.arange(5) * 1.0
    m5 = metrics(trajectory(t5, np.zeros((5, 1, 2))), sp)
    assert m5.contacts == 1 and m5.contact_pairs == [[-1, 0]]


def test_min_gap_is_also_split_into_robot_robot_and_robot_obstacle():
    # Robot-robot gaps 0.4, 0.5, 0.3 m; robot 1 to the obstacle 0.204, 0.2, 0.217 m.
    t = np.arange(3) * DT
    xy = np.array([[[0.0, 0.0], [1.4, 0.0]], [[0.0, 0.0], [1.5, 0.0]],
                   [[0.0, 0.0], [1.3, 0.0]]])
    sp = spec([(0, 0), (1.4, 0)], [(0, 0), (1.4, 0)],
              obstacles=[((1.5, 1.2), (0.0, 0.0), 0.5)])
    m = metrics(trajectory(t, xy), sp)
    assert m.min_gap_robots_m == pytest.approx(0.3)
    assert m.min_gap_obstacles_m == pytest.approx(0.2)
    assert m.min_gap_m == pytest.approx(0.2)
    # Without obstacles the robot-obstacle figure does not exist.
    m = metrics(trajectory(t, xy), spec([(0, 0), (1.4, 0)], [(0, 0), (1.4, 0)]))
    assert m.min_gap_obstacles_m is None and m.min_gap_robots_m == pytest.approx(0.3)
    # One robot alone by an obstacle: no robot-robot figure.
    one = metrics(trajectory(t, xy[:, :1]), spec([(0, 0)], [(0, 0)],
                                                 obstacles=[((0.0, 2.0), (0.0, 0.0), 1.0)]))
    assert one.min_gap_robots_m is None and one.min_gap_obstacles_m == pytest.approx(0.5)
    assert one.to_json_dict()["min_gap_robots_m"] is None


def test_unconfirmed_contact_event_counts_but_a_confirmed_one_does_not_double():
    d = [3.0, 0.99, 3.0]
    t = np.arange(3) * DT
    xy = np.array([[[0.0, 0.0], [x, 0.0]] for x in d])
    sp = spec([(0, 0), (3, 0)], [(0, 0), (3, 0)])
    assert metrics(trajectory(t, xy), sp, contact_events=[(0.1, 0, 1)]).contacts == 1
    assert metrics(trajectory(t, xy), sp, contact_events=[(0.2, 1, 0)]).contacts == 1
    assert metrics(trajectory(t, xy), sp, contact_events=[(5.0, 0, 1)]).contacts == 2


def test_arrival_after_the_time_limit_is_a_time_out():
    t = np.arange(0, 121) * DT
    xy = np.stack([np.stack([t, np.zeros_like(t)], axis=1)], axis=1)
    m = metrics(trajectory(t, xy), spec([(0, 0)], [(10, 0)], limit=9.0))
    assert m.arrived == 0 and not m.success
    assert m.per_robot[0].time_to_goal_s is None and m.time_ratio_mean is None
    assert m.per_robot[0].path_length_m == pytest.approx(12.0)  # the whole run


def test_a_robot_the_world_found_at_the_tolerance_has_arrived_in_the_record():
    """The world stopped a run as all arrived with robot 2 at 0.25 m of its goal (16.2, 0)
    on the last tick; recorded to 10 um, its position lies 7 um outside the tolerance."""
    recorded = np.array([[15.5, -0.3], [15.99686, -0.14572]])
    assert math.hypot(15.99686 - 16.2, -0.14572) > 0.25  # the rounding's doing
    t = np.array([74.08, 74.10])
    assert arrival_index(t, recorded, np.array([16.2, 0.0]), 0.25, 150.0) == 1
    # A millimetre out is still out.
    outside = recorded + [[0.0, 0.0], [-0.001, 0.0]]
    assert arrival_index(t, outside, np.array([16.2, 0.0]), 0.25, 150.0) is None
    assert ARRIVAL_RECORD_EPS_M < 1e-4


def test_oscillations_counted_per_robot_until_arrival():
    rates = hold(0.5, 1.0) + hold(-0.5, 1.0) + hold(0.5, 1.0)
    t, heading = heading_from_rates(rates)
    x = np.linspace(0.0, 10.0, t.size)
    xy = np.stack([np.stack([x, np.zeros_like(x)], axis=1),
                   np.stack([x, np.full_like(x, 5.0)], axis=1)], axis=1)
    h = np.stack([heading, np.zeros_like(heading)], axis=1)
    m = metrics(trajectory(t, xy, h), spec([(0, 0), (0, 5)], [(10, 0), (10, 5)]))
    assert [r.oscillations for r in m.per_robot] == [2, 0]
    assert m.oscillations_per_robot == 1.0 and m.oscillations_total == 2
    assert m.oscillations_max == 2  # the worst robot (the benchmark table's max)
    # No commands: both of robot 0's reversals have no plan to explain them. The trajectory
    # applies no speed, so they are slow.
    assert m.per_robot[0].reversal_causes["slow"] == 2
    assert m.reversal_causes_per_robot["slow"] == 1.0
    assert sum(m.reversal_causes_per_robot.values()) == m.oscillations_per_robot
    # Arriving half way cuts the count: only the first reversal happens before arrival.
    m2 = metrics(trajectory(t, xy, h), spec([(0, 0), (0, 5)], [(6.0, 0), (10, 5)]))
    assert m2.per_robot[0].oscillations == 1


def make_commands(with_side=True):
    rows = [
        # t_applied, robot, seq, pose_stamp, plan_ms, status, side, resolved
        (0.10, 0, 0, 0.08, 10.0, "ok", 1, 1.0),
        (0.20, 0, 1, 0.18, 20.0, "ok", -1, 1.0),
        (0.45, 0, 2, 0.43, 30.0, "ok", 1, 1.0),  # stamp gap 0.25 > period + tick: a miss
        (0.55, 0, 3, 0.53, 0.01, "arrived", 0, np.nan),
        (0.10, 1, 0, 0.06, 40.0, "no_feasible", 0, np.nan),
        (0.20, 1, 1, 0.16, 50.0, "ok", -1, 0.0),
    ]
    cols = list(zip(*rows))
    return Commands(
        t_applied_s=cols[0], robot=cols[1], seq=cols[2], pose_stamp_s=cols[3],
        v=np.zeros(6), omega=np.zeros(6), plan_ms=cols[4], status=cols[5],
        side=cols[6] if with_side else None, resolved=cols[7] if with_side else None,
    )


def test_command_metrics_planning_latency_flips_and_misses():
    t = np.arange(2) * DT
    xy = np.array([[[0.0, 0.0], [0.0, 5.0]]] * 2)
    m = metrics(trajectory(t, xy), spec([(0, 0), (0, 5)], [(0, 0), (0, 5)]), make_commands())
    assert m.plan_cycles == 5  # the "arrived" cycle is not a planning cycle
    assert m.plan_ms_p50 == pytest.approx(30.0) and m.plan_ms_max == 50.0
    assert m.plan_ms_mean == pytest.approx(30.0)
    assert m.plan_ms_p99 == pytest.approx(np.percentile([10, 20, 30, 40, 50], 99))
    assert m.sim_latency_ms_p50 == pytest.approx(20.0)
    assert m.sim_latency_ms_p99 == pytest.approx(np.percentile([20, 20, 20, 20, 40, 40], 99))
    assert [r.side_flips for r in m.per_robot] == [2, 0]
    assert m.side_flips_per_robot == 1.0
    assert m.deadline_misses == 1 and m.deadline_miss_rate == pytest.approx(1 / 4)
    assert [r.cycles for r in m.per_robot] == [3, 1]


def test_without_side_columns_flips_are_none():
    t = np.arange(2) * DT
    xy = np.array([[[0.0, 0.0], [0.0, 5.0]]] * 2)
    m = metrics(trajectory(t, xy), spec([(0, 0), (0, 5)], [(0, 0), (0, 5)]),
                make_commands(with_side=False))
    assert m.side_flips_per_robot is None and m.per_robot[0].side_flips is None


def test_json_has_the_documented_keys_and_no_nan():
    t = np.arange(3) * DT
    xy = np.zeros((3, 1, 2))
    m = metrics(trajectory(t, xy), spec([(0, 0)], [(5, 0)]))
    content = m.to_json_dict()
    text = json.dumps(content, allow_nan=False)
    for key in ("robots", "arrived", "success", "contacts", "min_gap_m", "min_gap_robots_m",
                "min_gap_obstacles_m", "path_ratio_mean",
                "time_ratio_mean", "oscillations_per_robot", "side_flips_per_robot",
                "plan_ms_p50", "plan_ms_p99", "sim_latency_ms_p50", "sim_latency_ms_p99",
                "deadline_miss_rate", "per_robot", "reversal_causes_per_robot",
                "encounters_per_robot", "reversals_per_encounter"):
        assert key in content, key
    assert isinstance(content["per_robot"], list) and content["per_robot"][0]["id"] == 0
    assert content["per_robot"][0]["encounters"] == 0
    assert content["path_ratio_mean"] is None and "NaN" not in text
    assert content["encounters_per_robot"] == 0.0 and content["reversals_per_encounter"] is None


def test_encounters_counted_over_the_whole_trajectory_and_reversals_per_encounter():
    # Robot 0 zig-zags along y = 0 (two reversals) and meets robot 1 head-on at t = 1.5 s;
    # robot 2 drives beside robot 1, 3 m away (no encounter between them), and passes robot 0
    # 3.5 m away. Robot 1 arrives before t = 1 s; its encounter comes later.
    rates = hold(0.5, 1.0) + hold(-0.5, 1.0) + hold(0.5, 1.0)
    t, heading = heading_from_rates(rates)
    x0 = np.linspace(0.0, 3.0, t.size)
    x1 = 3.0 - x0
    xy = np.stack([np.stack([x0, np.zeros_like(x0)], axis=1),
                   np.stack([x1, np.full_like(x1, 0.5)], axis=1),
                   np.stack([x1, np.full_like(x1, 3.5)], axis=1)], axis=1)
    h = np.stack([heading, np.full_like(heading, math.pi), np.full_like(heading, math.pi)],
                 axis=1)
    m = metrics(trajectory(t, xy, h),
                spec([(0, 0), (3, 0.5), (3, 3.5)], [(50, 0), (2, 0.5), (-50, 3.5)]))
    assert [r.encounters for r in m.per_robot] == [1, 1, 0]
    assert m.per_robot[1].time_to_goal_s == pytest.approx(0.8)  # within 0.25 m
    assert m.oscillations_total == 2
    assert m.encounters_per_robot == pytest.approx(2 / 3)
    assert m.reversals_per_encounter == pytest.approx(2 / 2)
    content = m.to_json_dict()
    assert [r["encounters"] for r in content["per_robot"]] == [1, 1, 0]
    assert content["reversals_per_encounter"] == pytest.approx(1.0)


# --- the run-directory reader ------------------------------------------------------

def test_metrics_from_a_recorded_run_directory(tmp_path):
    scenario = Scenario(
        name="rd", description="", time_limit_s=30.0, goal_tolerance_m=0.25,
        planner_config=PlannerConfig(),
        robots=(RobotSpec(0, (0.0, 0.0, 0.0), (2.0, 0.0), limits=RobotLimits(v_max_mps=1.0)),
                RobotSpec(1, (0.0, 3.0, 0.0), (2.0, 3.0), limits=RobotLimits(v_max_mps=1.0))),
        obstacles=(ObstacleSpec(-1, (10.0, 10.0), 1.0),),
    )
    with RunRecorder(tmp_path, scenario) as rec:
        rec.event("run_start", 0.0, world_rate_hz=10.0, control_rate_hz=10.0)
        for k in range(31):
            t = k * 0.1
            x = min(t, 2.0)
            pose = np.array([[x, 0.0, 0.0], [x, 3.0, 0.0]])
            rec.record_tick(t, np.array([0, 1]), pose, np.array([[1.0, 0.0], [1.0, 0.0]]))
            for rid in (0, 1):
                rec.record_command(t, rid, k, t, 1.0, 0.0, 5.0 + rid, "ok",
                                   side=1 if k % 2 else -1, resolved=7 if rid else None)
        rec.event("contact", 1.0, a=0, b=1, overlap_m=0.01)  # not in the trajectory
    with open(tmp_path / "trajectory.csv", "a") as f:
        f.write("3.1000,0,2.0,0.0,0.0,0.0,0.0\n3.2000,1,2.0")  # a killed run's tail
    m = metrics_from_run_dir(tmp_path)
    assert m.robots == 2 and m.arrived == 2
    assert m.sim_time_s == pytest.approx(3.0)  # incomplete ticks dropped
    assert m.per_robot[0].time_to_goal_s == pytest.approx(1.8)
    assert m.contacts == 1 and not m.success
    assert m.plan_ms_p50 == pytest.approx(5.5)
    assert m.world_dt_s == pytest.approx(0.1) and m.control_period_s == pytest.approx(0.1)
    assert m.deadline_misses == 0
    assert [r.side_flips for r in m.per_robot] == [0, 30]
    path = write_metrics(tmp_path, m)
    written = json.loads(path.read_text())
    assert written["arrived"] == 2
    # Side by side, 3 m apart: no crossing encounter.
    assert written["encounters_per_robot"] == 0.0 and written["reversals_per_encounter"] is None
    assert [r["encounters"] for r in written["per_robot"]] == [0, 0]


def test_metrics_of_a_run_with_a_relay_split_the_wall_latency_by_router(tmp_path):
    scenario = Scenario(
        name="rd", description="", time_limit_s=30.0, goal_tolerance_m=0.25,
        planner_config=PlannerConfig(),
        robots=tuple(RobotSpec(i, (0.0, 3.0 * i, 0.0), (2.0, 3.0 * i)) for i in range(3)))
    ms = 1_000_000
    with RunRecorder(tmp_path, scenario) as rec:
        rec.event("world_ready", 0.0, relays={"router-b": [2]})
        for k in range(3):
            rec.record_tick(0.1 * k, np.array([0, 1, 2]), np.zeros((3, 3)), np.zeros((3, 2)))
        for rid in (0, 1, 2):
            extra = ms if rid == 2 else 0
            for seq in range(4):
                rec.record_command(0.1, rid, seq, 0.0, 0.0, 0.0, 1.0, "ok")
                rec.record_timing(rid, seq, stamps_row(7, 7, 10**9 + seq * 10**8)[:7]
                                  + [10**9 + seq * 10**8 + 6 * ms + extra, 10**9 + seq * 10**8
                                     + 20 * ms + extra])
    m = metrics_from_run_dir(tmp_path)
    by = m.wall_latency_ms_by_router
    assert sorted(by) == ["router-b", "world"]
    assert by["world"]["sense_to_act"]["n"] == 8 and by["router-b"]["sense_to_act"]["n"] == 4
    assert by["router-b"]["sense_to_act"]["p50"] == pytest.approx(7.0)
    assert by["world"]["sense_to_act"]["p50"] == pytest.approx(6.0)
    assert m.wall_latency_ms["sense_to_act"]["n"] == 12
    assert json.loads(write_metrics(tmp_path, m).read_text())["wall_latency_ms_by_router"][
        "router-b"]["transport"]["p50"] == pytest.approx(2.9)


def test_read_trajectory_pivots_rows_by_robot_id(tmp_path):
    path = tmp_path / "trajectory.csv"
    path.write_text("t,robot,x,y,theta,v,omega\n"
                    "0.0,5,1,2,0.1,0,0\n0.0,2,3,4,0.2,0,0\n"
                    "0.1,2,3.5,4,0.2,1,0\n0.1,5,1.5,2,0.1,1,0\n")
    traj = read_trajectory(path, np.array([5, 2]))
    np.testing.assert_allclose(traj.t_s, [0.0, 0.1])
    np.testing.assert_allclose(traj.pose[:, 0, 0], [1.0, 1.5])
    np.testing.assert_allclose(traj.pose[:, 1, 0], [3.0, 3.5])


def test_compute_metrics_explains_reversals_with_the_applied_speed_and_commands():
    t, heading = heading_from_rates(S_TURN)
    x = np.linspace(0.0, 2.5, t.size)
    xy = np.stack([x, np.zeros_like(x)], axis=1)[:, None, :]
    pose = np.concatenate([xy, heading[:, None, None]], axis=2)
    applied = np.zeros((t.size, 1, 2))
    applied[..., 0] = 1.0  # moving: not slow
    traj = Trajectory(t, np.arange(1), pose, applied)
    c = 2
    commands = Commands(
        t_applied_s=[1.4, 0.0], robot=[0] * c, seq=[1, 0], pose_stamp_s=[1.4, 0.0],
        v=np.ones(c), omega=np.zeros(c), plan_ms=np.ones(c), status=["ok"] * c,
        side=[1, 1], resolved=[8.0, 7.0],  # out of order on purpose
    )
    m = metrics(traj, spec([(0, 0)], [(50, 0)]), commands)
    assert m.per_robot[0].oscillations == 1
    assert m.per_robot[0].reversal_causes["threat_switch"] == 1
    stopped = Trajectory(t, np.arange(1), pose, np.zeros((t.size, 1, 2)))
    assert metrics(stopped, spec([(0, 0)], [(50, 0)]), commands).per_robot[0] \
        .reversal_causes["slow"] == 1


# --- wall-clock latency by stage ------------------------------------------------------------
