"""LTV-MPC tracker (eIFP-MPC) on OSQP: tracking, bounds, soft half-planes, failures, warm start."""

import json
import math
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import osqp
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.config import MpcConfig, RobotLimits
from agent.core.types import PlanStatus
from agent.planning.mpc import MpcResult, MpcTracker
from agent.planning.mpc_qp import MpcTuning
from agent.planning.unicycle import step, wrap_angle
from tests.examples import examples

LIM = RobotLimits()
CFG = MpcConfig()
N, DT = CFG.horizon_steps, CFG.dt_s


@dataclass(frozen=True)
class HandReference:
    """The fields of agent.planning.spline.Reference the tracker reads, built by hand."""

    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    v_mps: np.ndarray
    omega_radps: np.ndarray


def line_ref(t0, v=1.0, y=0.0):
    """Along +x at speed v, at x = v t (time-based: the robot must also keep up)."""
    t = t0 + DT * np.arange(N + 1)
    return HandReference(
        v * t, np.full(N + 1, y), np.zeros(N + 1), np.full(N + 1, v), np.zeros(N + 1)
    )


def circle_ref(t0, radius=5.0, v=1.0):
    """Counter-clockwise circle centred at (0, radius), starting at the origin heading +x."""
    a = v * (t0 + DT * np.arange(N + 1)) / radius
    return HandReference(
        radius * np.sin(a),
        radius - radius * np.cos(a),
        a,
        np.full(N + 1, v),
        np.full(N + 1, v / radius),
    )


def assert_within_limits(cmd, last):
    """Bounds (Eq. 2) and rate limits over one control period."""
    v, w = cmd
    assert LIM.v_min_mps <= v <= LIM.v_max_mps
    assert abs(w) <= LIM.omega_max_radps
    assert abs(v - last[0]) <= LIM.accel_max_mps2 * DT + 1e-9
    assert abs(w - last[1]) <= LIM.alpha_max_radps2 * DT + 1e-9


def run(tracker, x0, ref_at, cycles, neighbours=None, clearance=None):
    """Closed loop: solve, check limits, apply the command for DT on the unicycle (Eq. 1)."""
    x, last = np.array(x0, dtype=float), np.zeros(2)
    states, results = [x], []
    for i in range(cycles):
        preds = None if neighbours is None else neighbours(i)
        res = tracker.solve(x, last, ref_at(i * DT), preds, clearance)
        cmd = np.array([res.v_mps, res.omega_radps])
        assert_within_limits(cmd, last)
        x, last = step(x, cmd, DT), cmd
        states.append(x)
        results.append(res)
    return np.array(states), results


def test_tracks_a_straight_line_from_an_offset():
    tracker = MpcTracker(LIM, CFG)
    states, results = run(tracker, [0.0, 0.5, 0.3], line_ref, 150)
    assert all(r.status is PlanStatus.OK for r in results[5:])
    settled = states[60:]  # after 6 s
    assert np.abs(settled[:, 1]).max() < 0.05  # cross-track [m]
    assert np.abs(wrap_angle(settled[:, 2])).max() < 0.05
    t = DT * np.arange(states.shape[0])[60:]
    assert np.abs(settled[:, 0] - t).max() < 0.05  # along-track: it keeps up with x = t


def test_tracks_a_circle_of_radius_5m_at_1mps():
    tracker = MpcTracker(LIM, CFG)
    states, results = run(tracker, [0.0, 0.5, 0.0], circle_ref, 400)
    radial = np.hypot(states[:, 0], states[:, 1] - 5.0) - 5.0
    assert abs(radial[0]) == pytest.approx(0.5)
    assert np.abs(radial[80:]).max() < 0.02  # after 8 s
    commands = np.array([[r.v_mps, r.omega_radps] for r in results[80:]])
    np.testing.assert_allclose(commands, np.tile([1.0, 0.2], (320, 1)), atol=0.02)


def test_predicted_states_are_a_rollout_from_the_state():
    tracker = MpcTracker(LIM, CFG)
    res = tracker.solve(np.array([0.0, 0.1, 0.0]), np.array([0.5, 0.0]), line_ref(0.0))
    assert res.predicted_states.shape == (N + 1, 3)
    np.testing.assert_array_equal(res.predicted_states[0], [0.0, 0.1, 0.0])
    first = step(np.array([0.0, 0.1, 0.0]), np.array([res.v_mps, res.omega_radps]), DT)
    np.testing.assert_allclose(res.predicted_states[1], first, atol=1e-12)


def test_without_neighbour_slots_it_tracks_and_ignores_neighbours():
    # max_constraints = 0 is a valid configuration (a scenario may set it): no half-plane
    # rows, no slack. It once failed while building the QP.
    tracker = MpcTracker(LIM, CFG, MpcTuning(max_constraints=0))
    preds = np.broadcast_to(np.array([2.0, 0.0]), (1, N + 1, 2))  # on the line: not a constraint
    states, results = run(tracker, [0.0, 0.3, 0.0], line_ref, 80, lambda i: preds,
                          np.array([0.8]))
    assert all(r.status is PlanStatus.OK for r in results[5:])
    assert all(r.max_slack_m == 0.0 for r in results)
    assert np.abs(states[60:, 1]).max() < 0.05  # tracked straight through the neighbour


def test_large_heading_error_turns_within_limits():
    tracker = MpcTracker(LIM, CFG)
    states, _ = run(tracker, [0.0, 0.0, math.pi], line_ref, 150)  # facing backwards
    assert np.abs(states[100:, 1]).max() < 0.05


@pytest.mark.parametrize("offset_m", [0.0, 0.05, -0.3])
def test_static_neighbour_ahead_keeps_its_half_plane(offset_m):
    tracker = MpcTracker(LIM, CFG)
    centre, clearance = np.array([4.0, offset_m]), 0.8
    preds = np.broadcast_to(centre, (1, N + 1, 2))
    states, results = run(
        tracker, [0.0, 0.0, 0.0], line_ref, 120, lambda i: preds, np.array([clearance])
    )
    for r in results:
        gap = np.hypot(*(r.predicted_states[:, :2] - centre).T).min()
        assert gap >= clearance - 0.02
        assert r.max_slack_m < 1e-3  # feasible: the soft constraint holds
    assert np.hypot(*(states[:, :2] - centre).T).min() >= clearance - 0.02


def test_oncoming_neighbour_is_avoided():
    tracker = MpcTracker(LIM, CFG)
    clearance = 0.8
    times = DT * np.arange(N + 1)

    def oncoming(i):  # from (10, 0.1) toward -x at 0.8 m/s, predicted at constant velocity
        start = np.array([10.0 - 0.8 * i * DT, 0.1])
        return (start + np.outer(times, [-0.8, 0.0]))[None]

    states, results = run(tracker, [0.0, 0.0, 0.0], line_ref, 120, oncoming, np.array([clearance]))
    actual = np.array([oncoming(i)[0, 0] for i in range(120)])
    assert np.hypot(*(states[1:, :2] - actual).T).min() >= clearance - 0.05
    assert max(r.max_slack_m for r in results) < 0.05


def test_a_corridor_between_two_neighbours_costs_no_slack():
    # Two parked neighbours 1.0 m either side of the line, clearance 0.8: both half-planes
    # can hold at once, so the shared per-step slack stays (numerically) zero.
    tracker = MpcTracker(LIM, CFG)
    centres = np.array([[4.0, 1.0], [4.0, -1.0]])
    preds = np.broadcast_to(centres[:, None, :], (2, N + 1, 2))
    states, results = run(tracker, [0.0, 0.0, 0.0], line_ref, 80, lambda i: preds, np.full(2, 0.8))
    assert states[-1, 0] > 6.0  # through the gap
    for c in centres:
        assert np.hypot(*(states[:, :2] - c).T).min() >= 0.8 - 0.02
    assert max(r.max_slack_m for r in results) < 1e-3


def test_a_gap_too_narrow_stops_the_robot_centred_before_it():
    # The gap (2 x 0.7 m) is narrower than the clearances (2 x 0.8 m) and the reference
    # pulls 0.3 m to one side and on through: the exact penalty holds the robot where both
    # half-planes still hold, centred in front of the gap, instead of trading one gap away.
    tracker = MpcTracker(LIM, CFG)
    centres = np.array([[4.0, 0.7], [4.0, -0.7]])
    preds = np.broadcast_to(centres[:, None, :], (2, N + 1, 2))
    states, results = run(tracker, [0.0, 0.0, 0.0], lambda t: line_ref(t, y=0.3), 80,
                          lambda i: preds, np.full(2, 0.8))
    end = states[-1]
    assert 3.0 < end[0] < 4.0 and abs(end[1]) < 0.03
    for c in centres:
        assert np.hypot(*(states[:, :2] - c).T).min() >= 0.8 - 0.02
    assert max(r.max_slack_m for r in results) < 1e-3


def test_nearest_neighbours_become_the_constraints():
    tracker = MpcTracker(LIM, CFG, MpcTuning(max_constraints=2))
    far = np.array([[40.0 + 3 * j, 30.0] for j in range(15)])
    centres = np.vstack([far[:7], [[3.0, 0.0]], far[7:]])  # the one ahead is 8th of 16
    preds = np.broadcast_to(centres[:, None, :], (16, N + 1, 2))
    states, results = run(tracker, [0.0, 0.0, 0.0], line_ref, 80, lambda i: preds, np.full(16, 0.8))
    assert np.hypot(*(states[:, :2] - [3.0, 0.0]).T).min() >= 0.8 - 0.02


def test_neighbour_on_top_of_the_robot_gives_a_bounded_command():
    tracker = MpcTracker(LIM, CFG)
    x = np.array([1.0, 1.0, 0.4])
    preds = np.broadcast_to(x[:2], (3, N + 1, 2))
    last = np.array([0.8, 0.3])
    res = tracker.solve(x, last, line_ref(0.0, y=1.0), preds, np.full(3, 0.8))
    assert res.status in (PlanStatus.OK, PlanStatus.SOLVER_INACCURATE)
    assert np.isfinite(res.predicted_states).all()
    assert_within_limits((res.v_mps, res.omega_radps), last)
    assert res.max_slack_m > 0.1  # the slack absorbs what cannot be satisfied


class ScriptedOSQP(osqp.OSQP):
    """`osqp.OSQP` that fails on demand, through the public API the tracker calls: the next
    solves report the (status, iterations) in `script` without a solution, and `update`
    raises while `refuse_update` is set. Otherwise it is OSQP."""

    def __init__(self) -> None:
        super().__init__()
        self.script: list[tuple[int, int]] = []
        self.refuse_update = False

    def update(self, **kwargs):
        if self.refuse_update:
            raise osqp.OSQPException(7)
        return super().update(**kwargs)

    def solve(self, raise_error=None):
        if not self.script:
            return super().solve(raise_error=raise_error)
        status, iterations = self.script.pop(0)
        return SimpleNamespace(info=SimpleNamespace(status_val=status, iter=iterations),
                               x=None, y=None)


def scripted_tracker() -> tuple[MpcTracker, ScriptedOSQP]:
    solver = ScriptedOSQP()
    return MpcTracker(LIM, CFG, solver_factory=lambda: solver), solver


def test_forced_solver_failure_brakes_and_is_counted():
    tracker, solver = scripted_tracker()
    x, last = np.array([0.0, 0.0, 0.0]), np.array([0.9, 1.2])
    ok = tracker.solve(x, last, line_ref(0.0))
    assert ok.status is PlanStatus.OK and tracker.failures == 0
    solver.script = [(int(osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE), 9)]
    res = tracker.solve(x, last, line_ref(0.0))
    assert res.status is PlanStatus.SOLVER_FAILED
    assert tracker.failures == 1
    assert res.iterations == 9
    # v falls at accel_max; omega decays toward 0 at alpha_max (0.6 per 0.1 s).
    assert res.v_mps == pytest.approx(0.9 - LIM.accel_max_mps2 * DT)
    assert res.omega_radps == pytest.approx(1.2 - LIM.alpha_max_radps2 * DT)
    assert_within_limits((res.v_mps, res.omega_radps), last)
    assert np.diff(res.predicted_states[:, 0]).min() >= 0.0  # braking forward, not reversing
    again = tracker.solve(x, last, line_ref(0.0))  # OSQP solves again
    assert again.status is PlanStatus.OK and tracker.failures == 1


def test_braking_command_from_standstill_stays_stopped():
    tracker, solver = scripted_tracker()
    solver.script = [(int(osqp.SolverStatus.OSQP_NON_CVX), 1)]
    res = tracker.solve(np.zeros(3), np.zeros(2), line_ref(0.0))
    assert (res.v_mps, res.omega_radps, res.status) == (0.0, 0.0, PlanStatus.SOLVER_FAILED)
    assert tracker.failures == 1


def test_osqp_error_brakes():
    tracker, solver = scripted_tracker()
    solver.refuse_update = True
    res = tracker.solve(np.zeros(3), np.array([0.5, -0.3]), line_ref(0.0))
    assert res.status is PlanStatus.SOLVER_FAILED and tracker.failures == 1
    assert res.v_mps == pytest.approx(0.35) and res.omega_radps == 0.0


def test_a_qp_whose_cost_overflows_brakes_without_calling_osqp():
    # A finite state 1e307 m from the reference: the state weights (2 q_position q_terminal
    # = 40) times the error overflow the QP's linear cost term (numpy warns); the cycle brakes.
    tracker = MpcTracker(LIM, CFG)
    with pytest.warns(RuntimeWarning, match="overflow"):
        res = tracker.solve(np.array([1e307, 0.0, 0.0]), np.array([0.5, 0.0]), line_ref(0.0))
    assert res.status is PlanStatus.SOLVER_FAILED and res.iterations == 0
    assert tracker.failures == 1 and res.v_mps == pytest.approx(0.35)


REFERENCE = json.loads((Path(__file__).parent / "data" / "mpc_reference.json").read_text())
"""One fixed QP and its solution (written and cross-checked by data/make_mpc_reference.py)."""


def _solve_the_reference_qp(tuning: MpcTuning) -> MpcResult:
    assert REFERENCE["reference"].startswith("x = t, y = 0, heading 0, v 1 m/s")
    times = DT * np.arange(N + 1)
    preds = (np.array(REFERENCE["neighbour_start_m"])
             + np.outer(times, REFERENCE["neighbour_velocity_mps"]))[None]
    tracker = MpcTracker(LIM, CFG, tuning, REFERENCE["trust_weight"])
    return tracker.solve(np.array(REFERENCE["state"]), np.array(REFERENCE["last_command"]),
                         line_ref(0.0), preds, np.array([REFERENCE["clearance_m"]]))


def test_the_tracker_reproduces_the_stored_reference_solution():
    expected = np.array(REFERENCE["planned_inputs"])
    tolerance = REFERENCE["tolerance"]
    assert REFERENCE["cross_check"]["max_abs_difference"] < 1e-5
    tight = _solve_the_reference_qp(MpcTuning(eps_abs=1e-9, eps_rel=1e-9, settle_chunk_iter=0,
                                              max_iter=200_000))
    assert tight.status is PlanStatus.OK
    np.testing.assert_allclose(tight.planned_inputs, expected, rtol=0,
                               atol=tolerance["tight"]["atol"])
    default = _solve_the_reference_qp(MpcTuning())
    assert default.status in (PlanStatus.OK, PlanStatus.SOLVER_INACCURATE)
    np.testing.assert_allclose(default.planned_inputs, expected, rtol=0,
                               atol=tolerance["default"]["atol"])
    np.testing.assert_allclose([default.v_mps, default.omega_radps], expected[0], rtol=0,
                               atol=tolerance["default"]["atol_first_command"])


def test_iteration_cap_gives_an_inaccurate_but_bounded_command():
    tracker = MpcTracker(LIM, CFG, MpcTuning(max_iter=1, eps_abs=1e-12, eps_rel=1e-12))
    last = np.array([0.3, -0.2])
    res = tracker.solve(np.array([0.0, 0.5, 0.2]), last, circle_ref(0.0))
    assert res.status is PlanStatus.SOLVER_INACCURATE
    assert res.iterations == 1
    assert tracker.failures == 0
    assert_within_limits((res.v_mps, res.omega_radps), last)


def _crowded_solve(tuning):
    """One cycle with three neighbours closing in (a QP with several active half-planes)."""
    tracker = MpcTracker(LIM, CFG, tuning)
    times = DT * np.arange(N + 1)
    starts = np.array([[2.0, 0.4], [2.5, -0.6], [1.5, 1.2]])
    vels = np.array([[-0.8, 0.0], [-0.6, 0.3], [-0.3, -0.7]])
    preds = starts[:, None, :] + times[None, :, None] * vels[:, None, :]
    last = np.array([0.9, 0.0])
    return tracker.solve(np.array([0.0, 0.0, 0.0]), last, line_ref(0.0), preds,
                         np.full(3, 1.1)), last


def test_chunks_are_one_admm_run():
    # Never "settled" (tolerances 0): chunks of 25 (and 30, rounded up to 50) give the very
    # result of one call, iterations included. A warm start between chunks would not (it
    # resets OSQP's z = A x: slower every 25 iterations, diverging every 5).
    whole, _ = _crowded_solve(MpcTuning(settle_chunk_iter=0))
    assert whole.status is PlanStatus.OK and whole.iterations > 50
    for chunk in (25, 30):
        chunked, _ = _crowded_solve(MpcTuning(
            settle_chunk_iter=chunk, settle_v_tol_mps=0.0, settle_omega_tol_radps=0.0))
        assert chunked.status is PlanStatus.OK
        assert chunked.iterations == whole.iterations
        np.testing.assert_array_equal(chunked.planned_inputs, whole.planned_inputs)


def test_a_settled_first_command_stops_the_solve_before_the_cap():
    # Tolerances of 1e-12: one run needs 655 iterations; with the settle rule the solve
    # stops at the first chunk boundary at which the first command moved < 0.01 over a
    # chunk (at least two chunks), with a first command close to that of the long run.
    tight = dict(eps_abs=1e-12, eps_rel=1e-12, max_iter=2000)
    long_run, _ = _crowded_solve(MpcTuning(settle_chunk_iter=0, **tight))
    settled, last = _crowded_solve(MpcTuning(settle_chunk_iter=50, **tight))
    assert long_run.status is PlanStatus.OK and long_run.iterations > 300
    assert settled.status is PlanStatus.SOLVER_INACCURATE
    assert 100 <= settled.iterations < long_run.iterations and settled.iterations % 50 == 0
    assert settled.v_mps == pytest.approx(long_run.v_mps, abs=0.02)
    assert settled.omega_radps == pytest.approx(long_run.omega_radps, abs=0.02)
    assert_within_limits((settled.v_mps, settled.omega_radps), last)


def test_warm_start_needs_fewer_iterations_than_cold():
    """Replay one closed-loop run; cold = the same inputs with no memory (reset each cycle)."""
    warm = MpcTracker(LIM, CFG)
    times = DT * np.arange(N + 1)
    inputs, warm_iters = [], []
    x, last = np.array([0.0, 0.5, 0.0]), np.zeros(2)
    for i in range(80):
        centre = np.array([3.0 - 0.2 * i * DT, 4.0])
        preds = (centre + np.outer(times, [-0.2, 0.0]))[None]
        args = (x, last, circle_ref(i * DT), preds, np.array([0.8]))
        res = warm.solve(*args)
        inputs.append(args)
        warm_iters.append(res.iterations)
        last = np.array([res.v_mps, res.omega_radps])
        x = step(x, last, DT)
    cold = MpcTracker(LIM, CFG)
    cold_iters = []
    for args in inputs:
        cold.reset()
        cold_iters.append(cold.solve(*args).iterations)
    assert sum(warm_iters[1:]) < 0.5 * sum(cold_iters[1:])


def test_same_inputs_give_the_same_results():
    a, b = MpcTracker(LIM, CFG), MpcTracker(LIM, CFG)
    preds = np.broadcast_to([3.0, 0.2], (1, N + 1, 2))
    for i in range(20):
        x = np.array([0.1 * i, 0.05, 0.0])
        ra = a.solve(x, np.array([0.5, 0.0]), line_ref(i * DT), preds, np.array([0.8]))
        rb = b.solve(x, np.array([0.5, 0.0]), line_ref(i * DT), preds, np.array([0.8]))
        assert (ra.v_mps, ra.omega_radps, ra.iterations) == (
            rb.v_mps,
            rb.omega_radps,
            rb.iterations,
        )
        np.testing.assert_array_equal(ra.predicted_states, rb.predicted_states)


def test_invalid_inputs_raise():
    tracker = MpcTracker(LIM, CFG)
    ref = line_ref(0.0)
    with pytest.raises(ValueError):
        tracker.solve(np.zeros(2), np.zeros(2), ref)
    with pytest.raises(ValueError):
        tracker.solve(np.array([0.0, np.nan, 0.0]), np.zeros(2), ref)
    short = HandReference(*(np.zeros(N) for _ in range(5)))
    with pytest.raises(ValueError):
        tracker.solve(np.zeros(3), np.zeros(2), short)
    with pytest.raises(ValueError):
        tracker.solve(np.zeros(3), np.zeros(2), ref, np.zeros((2, N, 2)), np.ones(2))
    with pytest.raises(ValueError):
        tracker.solve(np.zeros(3), np.zeros(2), ref, np.zeros((2, N + 1, 2)), np.ones(3))


def test_result_is_frozen():
    res = MpcTracker(LIM, CFG).solve(np.zeros(3), np.zeros(2), line_ref(0.0))
    assert isinstance(res, MpcResult)
    with pytest.raises(AttributeError):
        res.v_mps = 0.0


_SHARED: dict[str, MpcTracker] = {}
coord = st.floats(-20.0, 20.0, allow_nan=False)


@settings(max_examples=examples(60), deadline=None)
@given(
    state=st.tuples(coord, coord, st.floats(-10.0, 10.0)),
    last=st.tuples(st.floats(-3.0, 3.0), st.floats(-5.0, 5.0)),
    ref=st.lists(
        st.tuples(coord, coord, st.floats(-10.0, 10.0), st.floats(-2.0, 2.0), st.floats(-3.0, 3.0)),
        min_size=N + 1,
        max_size=N + 1,
    ),
    centres=st.lists(
        st.tuples(coord, coord, st.floats(-2.0, 2.0), st.floats(-2.0, 2.0)), max_size=6
    ),
    clearance=st.floats(0.0, 3.0),
)
def test_finite_random_inputs_give_a_finite_bounded_command(state, last, ref, centres, clearance):
    tracker = _SHARED.setdefault("t", MpcTracker(LIM, CFG))
    tracker.reset()
    r = np.array(ref)
    reference = HandReference(r[:, 0], r[:, 1], r[:, 2], r[:, 3], r[:, 4])
    c = np.array(centres, dtype=float).reshape(-1, 4)
    preds = c[:, None, :2] + c[:, None, 2:] * (DT * np.arange(N + 1))[None, :, None]
    clear = np.full(len(c), clearance)
    last = np.array(last)
    # The rate limits apply relative to the last command brought within the bounds.
    last_in = np.array(
        [
            np.clip(last[0], LIM.v_min_mps, LIM.v_max_mps),
            np.clip(last[1], -LIM.omega_max_radps, LIM.omega_max_radps),
        ]
    )
    x = np.array(state)
    for _ in range(2):  # a cold then a warm-started cycle
        res = tracker.solve(x, last, reference, preds, clear)
        assert math.isfinite(res.v_mps) and math.isfinite(res.omega_radps)
        assert np.isfinite(res.predicted_states).all()
        assert math.isfinite(res.max_slack_m) and res.max_slack_m >= 0.0
        assert_within_limits((res.v_mps, res.omega_radps), last_in)
        last = last_in = np.array([res.v_mps, res.omega_radps])
        x = step(x, last, DT)
