"""The four planners behind one interface: head-on in a closed loop, determinism, bounds."""

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agent.core.config import PLANNER_NAMES, PlannerConfig, RobotLimits
from agent.core.scenario import RobotSpec, Scenario
from agent.core.types import EgoState, Observation, Others, PlanStatus
from agent.planning.controller import RobotController
from agent.planning.mechanisms import EIFP_MPC_MECHANISMS, Mechanisms
from agent.planning.planners import make_planner
from world.sim.dynamics import WorldSim

LIMITS = RobotLimits()


def head_on(planner: str, offset_m: float = 0.0) -> Scenario:
    robots = (
        RobotSpec(0, (-12.0, 0.0, 0.0), (12.0, offset_m), planner=planner),
        RobotSpec(1, (12.0, offset_m, math.pi), (-12.0, 0.0), planner=planner),
    )
    return Scenario("head_on", "", 60.0, 0.25, PlannerConfig(), robots)


def run_loop(scenario: Scenario, seconds: float,
             mechanisms: Mechanisms | None = None) -> tuple[WorldSim, list]:
    """Lockstep: 50 Hz world, 10 Hz planning on the newest snapshot."""
    sim = WorldSim(scenario)
    ctrls = [RobotController(r, scenario.planner_config, scenario.goal_tolerance_m,
                             mechanisms=mechanisms)
             for r in scenario.robots]
    decisions = []
    for tick in range(int(seconds * 50)):
        if tick % 5 == 0:
            snap = sim.snapshot()
            for c in ctrls:
                c.observe(snap)
                res = c.plan(sim.t_s)
                decisions.append(res.decision())
                sim.set_command(c.spec.id, res.v_mps, res.omega_radps)
        sim.step(0.02)
        if sim.all_arrived():
            break
    return sim, decisions


@pytest.mark.parametrize("planner", PLANNER_NAMES)
def test_head_on_pair_passes_without_contact(planner):
    # Exactly symmetric head-on: every planner, IFP included, must resolve it (the paper's
    # IFP failures are in crowded symmetric scenes, not in a single head-on pair).
    sim, _ = run_loop(head_on(planner), 60.0)
    assert sim.contact_count == 0
    assert sim.min_gap_m > 0.0
    assert sim.all_arrived(), f"{planner}: arrived {sim.arrived.tolist()} at t={sim.t_s:.1f}"


@pytest.mark.parametrize("planner", PLANNER_NAMES)
def test_closed_loop_is_deterministic(planner):
    _, first = run_loop(head_on(planner, offset_m=0.3), 8.0)
    _, second = run_loop(head_on(planner, offset_m=0.3), 8.0)
    assert first == second


def observation(x, y, heading, v, others_xy, others_v, goal=(10.0, 0.0)):
    k = len(others_xy)
    return Observation(
        robot_id=0,
        ego=EgoState(x, y, heading, v),
        goal_m=np.array(goal),
        radius_m=0.5,
        limits=LIMITS,
        others=Others(
            ids=np.arange(1, k + 1),
            position_m=np.array(others_xy, dtype=float).reshape(k, 2),
            velocity_mps=np.array(others_v, dtype=float).reshape(k, 2),
            radius_m=np.full(k, 0.5),
            linearity=np.ones(k),
            track_start_m=np.array(others_xy, dtype=float).reshape(k, 2),
            is_robot=np.ones(k, dtype=bool),
        ),
    )


coord = st.floats(-15.0, 15.0, allow_nan=False)
speed = st.floats(-1.2, 1.2, allow_nan=False)


@pytest.mark.parametrize("planner", PLANNER_NAMES)
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    ego=st.tuples(coord, coord, st.floats(-math.pi, math.pi), st.floats(0.0, 1.1)),
    crowd=st.lists(st.tuples(coord, coord, speed, speed), min_size=0, max_size=12),
)
def test_finite_input_gives_finite_command_within_bounds(planner, ego, crowd):
    obs = observation(*ego, [c[:2] for c in crowd], [c[2:] for c in crowd])
    res = make_planner(planner, PlannerConfig()).plan(obs, 0.0)
    assert math.isfinite(res.v_mps) and math.isfinite(res.omega_radps)
    assert LIMITS.v_min_mps - 1e-9 <= res.v_mps <= LIMITS.v_max_mps + 1e-9
    assert abs(res.omega_radps) <= LIMITS.omega_max_radps + 1e-9
    assert res.waypoints_m.shape[1] == 2 and np.all(np.isfinite(res.waypoints_m))
    assert res.times.total_ms >= 0.0


@pytest.mark.parametrize("planner", PLANNER_NAMES)
def test_at_goal_the_planner_stops_braking_at_its_limit(planner):
    from agent.planning.planners import CONTROL_PERIOD_S

    # Arriving at 0.5 m/s: a stop at once would be a deceleration no robot makes (and the
    # others' braking guard assumes none does); the command brakes by accel_max per period.
    obs = observation(10.0, 0.05, 0.0, 0.5, [], [], goal=(10.0, 0.0))
    res = make_planner(planner, PlannerConfig()).plan(obs, 0.0)
    assert res.status == PlanStatus.ARRIVED and res.omega_radps == 0.0
    assert res.v_mps == pytest.approx(max(0.5 - LIMITS.accel_max_mps2 * CONTROL_PERIOD_S, 0.0))
    assert res.v_mps < 0.5
    standing = observation(10.0, 0.05, 0.0, 0.0, [], [], goal=(10.0, 0.0))
    res = make_planner(planner, PlannerConfig()).plan(standing, 0.0)
    assert res.status == PlanStatus.ARRIVED and res.v_mps == 0.0 and res.omega_radps == 0.0


def test_threat_ahead_gets_a_via_point_and_side():
    obs = observation(0.0, 0.0, 0.0, 1.0, [[6.0, 0.2]], [[-1.0, 0.0]])
    res = make_planner("eifp-mpc", PlannerConfig()).plan(obs, 0.0)
    assert res.threats and res.threats[0].other_id == 1
    assert res.via_point_m is not None and res.resolved_id == 1
    assert res.side != 0
    assert res.waypoints_m.shape[0] >= 3


def _reference(res, obs: Observation, *, lines_arcs: bool, corner_radius_m: float,
               start_radius_m: float, clamp_heading: bool = False) -> np.ndarray:
    """(N + 1, 2) the reference `build_reference` gives for `res`'s waypoints with these
    settings and the robot's state in `obs`."""
    from agent.planning.spline import build_reference

    mpc = PlannerConfig().mpc
    ref = build_reference(res.waypoints_m, obs.ego.heading_rad, LIMITS.v_max_mps,
                          LIMITS.accel_max_mps2, mpc.dt_s, mpc.horizon_steps,
                          v_start_mps=obs.ego.v_mps, clamp_heading=clamp_heading,
                          lines_arcs=lines_arcs, corner_radius_m=corner_radius_m,
                          start_radius_m=start_radius_m)
    return np.column_stack((ref.x_m, ref.y_m))


def test_lines_arcs_reference_is_the_default_and_reaches_the_reference():
    from agent.core.config import ReferenceConfig

    # Defaults R = 1 m, start arc 5 m; a standing robot turns on the spot (no start arc).
    # Moving at 1 m/s towards a still disc 6 m ahead: the start arc is within the horizon.
    moving = observation(0.0, 0.0, 0.0, 1.0, [[6.0, 0.2]], [[0.0, 0.0]])
    arcs = make_planner("eifp-mpc", PlannerConfig()).plan(moving, 0.0)
    assert arcs.waypoints_m.shape[0] >= 3  # a via-point: legs to join
    np.testing.assert_array_equal(arcs.debug.reference_m, _reference(
        arcs, moving, lines_arcs=True, corner_radius_m=1.0, start_radius_m=5.0))
    assert not np.allclose(arcs.debug.reference_m, _reference(
        arcs, moving, lines_arcs=True, corner_radius_m=1.0, start_radius_m=0.0))
    on_spline = make_planner("eifp-mpc", PlannerConfig(), mechanisms=replace(
        EIFP_MPC_MECHANISMS, lines_arcs=False))
    spline = on_spline.plan(moving, 0.0)
    np.testing.assert_array_equal(spline.debug.reference_m, _reference(
        spline, moving, lines_arcs=False, corner_radius_m=1.0, start_radius_m=5.0))
    np.testing.assert_array_equal(arcs.waypoints_m, spline.waypoints_m)  # same via-points
    assert not np.allclose(arcs.debug.reference_m, spline.debug.reference_m)
    assert (arcs.v_mps, arcs.omega_radps) != (spline.v_mps, spline.omega_radps)
    # Standing before a still disc 2 m ahead (two via-points, a corner within the horizon)
    # or 6 m ahead (the start leg within it): the configured corner radius, no start arc.
    wide = PlannerConfig(reference=ReferenceConfig(corner_radius_m=2.0))
    used = {"lines_arcs": True, "corner_radius_m": 2.0, "start_radius_m": 0.0}
    for disc_m, other in (([2.0, 0.0], {"corner_radius_m": 1.0}),
                          ([6.0, 0.2], {"start_radius_m": 5.0})):
        standing = observation(0.0, 0.0, 0.0, 0.0, [disc_m], [[0.0, 0.0]])
        still = make_planner("eifp-mpc", wide).plan(standing, 0.0)
        np.testing.assert_array_equal(still.debug.reference_m,
                                      _reference(still, standing, **used))
        assert not np.allclose(still.debug.reference_m,
                               _reference(still, standing, **(used | other)))
    # eifp's tracking law follows the spline, clamped to the heading when moving
    law = make_planner("eifp", PlannerConfig()).plan(moving, 0.0)
    np.testing.assert_array_equal(law.debug.reference_m, _reference(
        law, moving, lines_arcs=False, corner_radius_m=1.0, start_radius_m=5.0,
        clamp_heading=True))


def test_the_paper_profile_runs_the_papers_tracker_without_the_guard():
    from agent.core.config import paper_config
    from agent.planning.mpc_qp import DEFAULT_TUNING, PAPER_TUNING

    obs = observation(0.0, 0.0, 0.0, 1.0, [[6.0, 0.2]], [[-1.0, 0.0]])
    default, paper = make_planner("eifp-mpc", PlannerConfig()), make_planner(
        "eifp-mpc", paper_config())
    assert default.tuning == DEFAULT_TUNING and default.mech.braking_guard
    assert paper.tuning == PAPER_TUNING and not paper.mech.braking_guard
    assert default._mpc(obs).tuning == DEFAULT_TUNING and paper._mpc(obs).tuning == PAPER_TUNING
    assert (PAPER_TUNING.q_terminal, PAPER_TUNING.r_dv, PAPER_TUNING.r_domega) == (1.0, 0.0, 0.0)


@pytest.mark.parametrize("config", [PlannerConfig(), PlannerConfig(profile="paper")])
def test_a_tuning_given_to_the_planner_is_the_one_its_tracker_runs(config):
    # The profile only picks the default: a tuning passed in wins under either profile, and
    # reaches the tracker a lockstep or robot-process controller builds.
    from agent.planning.mpc_qp import MpcTuning

    tuning = MpcTuning(max_constraints=1, q_heading=2.0)
    obs = observation(0.0, 0.0, 0.0, 1.0, [[6.0, 0.2]], [[-1.0, 0.0]])
    planner = make_planner("eifp-mpc", config, tuning=tuning)
    assert planner.tuning is tuning and planner._mpc(obs).tuning is tuning
    spec = RobotSpec(0, (0.0, 0.0, 0.0), (10.0, 0.0), planner="eifp-mpc")
    controller = RobotController(spec, config, 0.25, tuning=tuning)
    assert controller.planner.tuning is tuning
    # the braking guard allows for the lag of the estimates the controller makes
    assert controller.planner.estimation_window_s == controller.tracker.window_s


@pytest.mark.parametrize("planner", ["eifp-mpc", "eifp", "ifp"])
def test_spline_reference_head_on_pair_passes(planner):
    # eifp and ifp follow the spline; eifp-mpc here too, with the spline's clamped start.
    mech = None
    if planner == "eifp-mpc":
        mech = replace(EIFP_MPC_MECHANISMS, lines_arcs=False, clamp_heading=True)
    sim, _ = run_loop(head_on(planner, offset_m=0.3), 60.0, mech)
    assert sim.contact_count == 0 and sim.all_arrived()


def test_half_plane_clearance_grows_with_the_pose_age():
    from dataclasses import replace

    from agent.planning.planners import LATENCY_CLEARANCE_FACTOR

    # Head-on at 1 m/s each (relative speed 2 m/s) and a parked robot (relative 1 m/s).
    obs = observation(0.0, 0.0, 0.0, 1.0, [[6.0, 0.0], [0.0, 4.0]], [[-1.0, 0.0], [0.0, 0.0]])
    planner = make_planner("eifp-mpc", PlannerConfig())
    t = np.arange(21) * 0.1
    preds, fresh = planner._predictions(obs, t)
    assert fresh == pytest.approx([1.0 + PlannerConfig().mpc.clearance_margin_m] * 2)
    _, late = planner._predictions(replace(obs, pose_age_s=0.15), t)
    assert late - fresh == pytest.approx(LATENCY_CLEARANCE_FACTOR * 0.15 * np.array([2.0, 1.0]))
    np.testing.assert_allclose(preds[0, -1], [4.0, 0.0])  # predictions do not change
    with pytest.raises(ValueError, match="pose_age_s"):
        replace(obs, pose_age_s=-0.1)


def test_non_finite_input_is_a_clear_value_error():
    with pytest.raises(ValueError, match="non-finite"):
        observation(float("nan"), 0.0, 0.0, 1.0, [], [])
    with pytest.raises(ValueError, match="non-finite"):
        observation(0.0, 0.0, 0.0, 1.0, [[math.inf, 0.0]], [[0.0, 0.0]])


def test_unknown_planner_name():
    with pytest.raises(ValueError, match="unknown planner"):
        make_planner("rrt", PlannerConfig())


def test_mpc_solver_failure_is_counted_and_brakes():
    # A tuning OSQP cannot solve: a negative weight on the speed error (r_v = -10) makes the
    # QP's cost non-convex, which OSQP finds while it iterates (status OSQP_NON_CVX). The
    # tracker's failure path (each OSQP outcome is tested in test_mpc.py) must reach the
    # planner's result: the status, the count and a braking command.
    from agent.planning.mpc_qp import MpcTuning

    obs = observation(0.0, 0.0, 0.0, 1.0, [], [])
    assert make_planner("eifp-mpc", PlannerConfig()).plan(obs, 0.0).status is PlanStatus.OK
    planner = make_planner("eifp-mpc", PlannerConfig(), tuning=MpcTuning(r_v=-10.0))
    res = planner.plan(obs, 0.0)
    tracker = planner._mpc(obs)
    assert res.status is PlanStatus.SOLVER_FAILED
    assert tracker.failures == 1 and res.solver_iterations > 0  # OSQP ran and gave up
    # the tracker's braking: v falls at accel_max over one MPC step, omega stays 0
    dt_s = PlannerConfig().mpc.dt_s
    assert res.v_mps == pytest.approx(1.0 - LIMITS.accel_max_mps2 * dt_s)
    assert res.omega_radps == 0.0
    assert planner.plan(obs, dt_s).status is PlanStatus.SOLVER_FAILED and tracker.failures == 2


def test_stage_times_come_from_the_injected_timer():
    # A fake clock advancing 1 ms per reading: every stage gets a whole number of ms, the
    # threat assessment is timed on its own, and the stages add up to the total.
    ticks = iter(range(1000))
    planner = make_planner("eifp-mpc", PlannerConfig(), timer=lambda: next(ticks) * 1e-3)
    obs = observation(0.0, 0.0, 0.0, 1.0, [[6.0, 0.2]], [[-1.0, 0.0]])
    t = planner.plan(obs, 0.0).times
    assert t.threats_ms == pytest.approx(1.0)
    assert t.viapoints_ms >= 1.0 and t.spline_ms == pytest.approx(1.0)
    assert t.control_ms == pytest.approx(1.0)
    assert t.total_ms == pytest.approx(t.threats_ms + t.viapoints_ms + t.spline_ms
                                       + t.control_ms)


def test_robots_standing_inside_each_others_inflated_discs_get_out_and_arrive():
    # Setup E at 100 +- 30 ms with 10 % loss (lockstep, link seed 2) ended with robots 2 and
    # 3 standing 1.28 m apart (inside each other's inflated radius, 1.3 m) for 80 s, each
    # facing away, each goal behind the other: the escape plan [P, escape point, goal] made
    # a spline that leaves 7 cm one way and turns back through the other's disc, and the
    # MPC stood still. A standing robot now steers out first ([P, escape point]).
    robots = (
        RobotSpec(2, (-0.0632, 0.7357, -1.5841), (1.99, 0.26), planner="eifp-mpc"),
        RobotSpec(3, (1.2052, 0.9333, 1.6144), (-0.29, 1.5), planner="eifp-mpc"),
    )
    sim, decisions = run_loop(Scenario("escape", "", 30.0, 0.25, PlannerConfig(), robots), 30.0)
    assert decisions[0][2] is PlanStatus.ESCAPE
    assert sim.contact_count == 0
    assert sim.all_arrived(), f"arrived {sim.arrived.tolist()} at t={sim.t_s:.1f}"
