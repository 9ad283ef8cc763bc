"""The robot's sense -> estimate -> plan cycle: snapshot filtering, braking, latency
compensation, the control period and the four planners behind it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.config import PLANNER_NAMES, PlannerConfig, RobotLimits
from agent.core.scenario import RobotSpec
from agent.core.types import PlanStatus, PoseSnapshot
from agent.planning.controller import MAX_COMPENSATED_AGE_S, RobotController
from agent.planning.routing import StaticMap

RADIUS_M = 0.5
TOL_M = 0.25


def spec(planner: str = "ifp", start=(0.0, 0.0, 0.0), goal=(20.0, 0.0)) -> RobotSpec:
    return RobotSpec(id=0, start=start, goal=goal, radius_m=RADIUS_M, planner=planner)


def snap(stamp_s: float, tick: int, poses: dict[int, tuple[float, float, float]]) -> PoseSnapshot:
    """A snapshot of the given robots (id -> pose), all of radius RADIUS_M."""
    ids = np.array(list(poses), dtype=np.int64)
    return PoseSnapshot(stamp_s=stamp_s, tick=tick, ids=ids,
                        pose=np.array([poses[i] for i in ids.tolist()], dtype=float),
                        radius_m=np.full(ids.shape[0], RADIUS_M))


# --------------------------------------------------------------------------------------
# observe(): which snapshots are accepted
# --------------------------------------------------------------------------------------

def test_observe_drops_duplicate_out_of_order_stale_and_foreign_snapshots() -> None:
    ctrl = RobotController(spec(), PlannerConfig(), TOL_M)
    first = snap(1.0, 50, {0: (0.0, 0.0, 0.0), 1: (5.0, 0.0, math.pi)})
    assert ctrl.observe(first)
    assert ctrl.rejected_stale == 0

    rejected = [
        snap(1.0, 50, {0: (0.0, 0.0, 0.0), 1: (9.0, 9.0, 0.0)}),  # duplicate tick
        snap(0.9, 49, {0: (0.0, 0.0, 0.0), 1: (9.0, 9.0, 0.0)}),  # out of order
        snap(0.98, 51, {0: (0.0, 0.0, 0.0), 1: (9.0, 9.0, 0.0)}),  # newer tick, older stamp
        snap(1.1, 55, {1: (9.0, 9.0, 0.0), 2: (3.0, 3.0, 0.0)}),  # this robot not in it
    ]
    for k, s in enumerate(rejected, start=1):
        assert not ctrl.observe(s)
        assert ctrl.rejected_stale == k
    # Nothing of the rejected snapshots leaked into what the robot knows.
    assert ctrl.snapshot is first
    obs = ctrl.observation(1.0)
    assert obs.others.ids.tolist() == [1]
    np.testing.assert_array_equal(obs.others.position_m, [[5.0, 0.0]])

    # A genuinely newer snapshot (same stamp as the last is not enough: the tick must grow).
    newer = snap(1.02, 51, {0: (0.02, 0.0, 0.0), 1: (4.98, 0.0, math.pi)})
    assert ctrl.observe(newer)
    assert ctrl.snapshot is newer and ctrl.rejected_stale == 4


def test_the_robot_is_found_in_whatever_row_each_snapshot_lists_it() -> None:
    # The world may list the discs in any order; the controller finds its own row once per
    # accepted snapshot, and a rejected snapshot (this robot missing) does not move it.
    ctrl = RobotController(spec(), PlannerConfig(), TOL_M)
    assert ctrl.observe(snap(1.0, 50, {1: (5.0, 0.0, math.pi), 0: (0.5, 0.2, 0.1)}))
    ego = ctrl.observation(1.0).ego
    assert (ego.x_m, ego.y_m, ego.heading_rad) == (0.5, 0.2, 0.1)
    assert not ctrl.observe(snap(1.1, 55, {1: (9.0, 9.0, 0.0), 2: (3.0, 3.0, 0.0)}))
    ego = ctrl.observation(1.0).ego
    assert (ego.x_m, ego.y_m, ego.heading_rad) == (0.5, 0.2, 0.1)
    assert ctrl.observe(snap(1.2, 60, {2: (3.0, 3.0, 0.0), 1: (4.0, 0.0, math.pi),
                                       0: (0.7, 0.3, 0.2)}))
    obs = ctrl.observation(1.2)
    assert (obs.ego.x_m, obs.ego.y_m, obs.ego.heading_rad) == (0.7, 0.3, 0.2)
    assert sorted(obs.others.ids.tolist()) == [1, 2]
    np.testing.assert_array_equal(ctrl.brake().waypoints_m, [[0.7, 0.3], [0.7, 0.3]])


def test_plan_without_a_snapshot_brakes_as_stale() -> None:
    ctrl = RobotController(spec(), PlannerConfig(), TOL_M)
    ctrl.command = (0.8, 0.3)  # whatever it was doing, it must stop
    result = ctrl.plan(3.0)
    assert result.status == PlanStatus.STALE
    assert (result.v_mps, result.omega_radps) == (0.0, 0.0)
    assert ctrl.command == (0.0, 0.0)
    assert result.waypoints_m.shape == (2, 2)
    with pytest.raises(RuntimeError):
        ctrl.observation(3.0)


def test_brake_after_a_snapshot_holds_the_robot_where_it_was_seen() -> None:
    ctrl = RobotController(spec(), PlannerConfig(), TOL_M)
    ctrl.observe(snap(0.0, 0, {0: (1.5, -2.0, 0.3)}))
    result = ctrl.brake()
    assert result.status == PlanStatus.STALE
    np.testing.assert_array_equal(result.waypoints_m, [[1.5, -2.0], [1.5, -2.0]])


# --------------------------------------------------------------------------------------
# Latency compensation
# --------------------------------------------------------------------------------------

# The robot is seen at (1, 2) heading +y at t = 0.2 s; the other robot moves from (5, 1) at
# t = 0 to (4.8, 1.1) at t = 0.2, i.e. at (-1, 0.5) m/s (two samples: the least-squares slope
# is the exact difference quotient). The robot plans at t = 0.6, 0.4 s after the stamp.
EGO_SEEN = (1.0, 2.0, math.pi / 2.0)
AGE_S = 0.4
SIN02 = 0.19866933079506122  # sin(0.2)
COS02 = 0.9800665778412416  # cos(0.2)


def _latency_case(compensate: bool, command: tuple[float, float]) -> RobotController:
    ctrl = RobotController(spec(start=EGO_SEEN), PlannerConfig(), TOL_M,
                           compensate_latency=compensate)
    assert ctrl.observe(snap(0.0, 0, {0: EGO_SEEN, 1: (5.0, 1.0, 0.0)}))
    assert ctrl.observe(snap(0.2, 10, {0: EGO_SEEN, 1: (4.8, 1.1, 0.0)}))
    ctrl.command = command  # what the robot has been applying since the stamp
    return ctrl


@pytest.mark.parametrize(("command", "expected"), [
    # Arc of radius v / omega = 2 m turning left by omega * age = 0.2 rad from heading pi/2:
    # x = 1 + 2 (sin(pi/2 + 0.2) - 1) = 1 - 2 (1 - cos 0.2), y = 2 + 2 sin 0.2.
    ((1.0, 0.5), (1.0 - 2.0 * (1.0 - COS02), 2.0 + 2.0 * SIN02, math.pi / 2.0 + 0.2)),
    # Straight ahead (omega = 0): 0.4 m along +y.
    ((1.0, 0.0), (1.0, 2.4, math.pi / 2.0)),
])
def test_latency_compensation_moves_ego_along_its_arc_and_others_by_velocity_times_age(
        command, expected) -> None:
    now_s = 0.2 + AGE_S
    on = _latency_case(True, command).observation(now_s)
    off = _latency_case(False, command).observation(now_s)

    assert (off.ego.x_m, off.ego.y_m, off.ego.heading_rad) == EGO_SEEN
    np.testing.assert_allclose(off.others.position_m, [[4.8, 1.1]], rtol=0, atol=1e-12)

    assert on.ego.x_m == pytest.approx(expected[0], abs=1e-12)
    assert on.ego.y_m == pytest.approx(expected[1], abs=1e-12)
    assert on.ego.heading_rad == pytest.approx(expected[2], abs=1e-12)
    np.testing.assert_allclose(on.others.velocity_mps, [[-1.0, 0.5]], rtol=0, atol=1e-9)
    # (4.8, 1.1) + (-1, 0.5) * 0.4 = (4.4, 1.3)
    np.testing.assert_allclose(on.others.position_m, [[4.4, 1.3]], rtol=0, atol=1e-9)

    for obs in (on, off):  # odometry is the command either way; the rest is not moved
        assert (obs.ego.v_mps, obs.ego.omega_radps) == command
        assert obs.pose_age_s == pytest.approx(AGE_S, abs=1e-12)  # the planner's margin
        np.testing.assert_allclose(obs.others.track_start_m, [[5.0, 1.0]], atol=1e-12)


def test_latency_compensation_is_capped_and_never_runs_backwards() -> None:
    ctrl = _latency_case(True, (1.0, 0.0))
    far = ctrl.observation(0.2 + 10.0)  # 10 s old: extrapolated by the cap only
    assert far.ego.y_m == pytest.approx(2.0 + MAX_COMPENSATED_AGE_S, abs=1e-12)
    assert far.pose_age_s == MAX_COMPENSATED_AGE_S
    np.testing.assert_allclose(far.others.position_m,
                               [[4.8 - MAX_COMPENSATED_AGE_S, 1.1 + 0.5 * MAX_COMPENSATED_AGE_S]],
                               atol=1e-9)
    early = ctrl.observation(0.1)  # planning "before" the stamp: no prediction
    assert (early.ego.x_m, early.ego.y_m) == EGO_SEEN[:2] and early.pose_age_s == 0.0
    np.testing.assert_allclose(early.others.position_m, [[4.8, 1.1]], atol=1e-12)


# --------------------------------------------------------------------------------------
# The control period and the planners
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("planner", PLANNER_NAMES)
def test_control_period_reaches_the_planner(planner: str) -> None:
    assert RobotController(spec(planner), PlannerConfig(), TOL_M).planner.control_period_s \
        == pytest.approx(0.1)
    ctrl = RobotController(spec(planner), PlannerConfig(), TOL_M, control_period_s=0.04)
    assert ctrl.control_period_s == 0.04
    assert ctrl.planner.name == planner and ctrl.planner.control_period_s == 0.04


@pytest.mark.parametrize("planner", ["ifp", "eifp", "orca"])
@pytest.mark.parametrize("period_s", [0.04, 0.08])
def test_control_period_sets_the_acceleration_limit_of_the_first_command(
        planner: str, period_s: float) -> None:
    # At rest, facing a goal 20 m ahead, nobody around: the tracking law (and ORCA's heading
    # law) wants more than it may take, accel_max * period from standstill. (Periods below
    # the spline's 0.1 s step: the via-point planners' reference itself only reaches
    # accel_max * 0.1 s = 0.15 m/s at its first step.)
    ctrl = RobotController(spec(planner), PlannerConfig(), TOL_M, control_period_s=period_s)
    ctrl.observe(snap(0.0, 0, {0: (0.0, 0.0, 0.0)}))
    result = ctrl.plan(0.0)
    assert result.status == PlanStatus.OK
    assert result.v_mps == pytest.approx(RobotLimits().accel_max_mps2 * period_s, abs=1e-9)


@pytest.mark.parametrize("period_s", [0.0, -0.1, math.inf, math.nan])
def test_control_period_must_be_positive_and_finite(period_s: float) -> None:
    with pytest.raises(ValueError, match="control_period_s"):
        RobotController(spec(), PlannerConfig(), TOL_M, control_period_s=period_s)


def test_command_hold_is_a_number_of_periods() -> None:
    from agent.planning.controller import COMMAND_HOLD_PERIODS

    assert COMMAND_HOLD_PERIODS == 1.5
    for period_s in (0.1, 0.2):
        ctrl = RobotController(spec(), PlannerConfig(), TOL_M, control_period_s=period_s)
        assert ctrl.command_hold_s == pytest.approx(1.5 * period_s)


@pytest.mark.parametrize("planner", PLANNER_NAMES)
def test_every_planner_plans_a_finite_command_within_limits(planner: str) -> None:
    # The robot drives at 0.8 m/s towards its goal; three others converge on its path and
    # one sits still ahead: threats on both sides and a static disc.
    limits = RobotLimits()
    ctrl = RobotController(spec(planner), PlannerConfig(), TOL_M)
    others0 = {1: (6.0, 3.0, -math.pi / 2), 2: (6.0, -3.0, math.pi / 2),
               3: (9.0, 0.2, math.pi), 4: (3.0, 0.9, 0.0)}
    velocity = {1: (0.0, -1.0), 2: (0.0, 1.0), 3: (-1.0, 0.0), 4: (0.0, 0.0)}
    results = []
    for k in range(4):
        t = 0.1 * k
        poses = {0: (0.8 * t, 0.0, 0.0)}
        poses.update({i: (x + velocity[i][0] * t, y + velocity[i][1] * t, h)
                      for i, (x, y, h) in others0.items()})
        assert ctrl.observe(snap(t, 5 * k, poses))
        results.append(ctrl.plan(t))
    for result in results:
        assert result.status in (PlanStatus.OK, PlanStatus.NO_FEASIBLE, PlanStatus.ESCAPE,
                                 PlanStatus.SOLVER_INACCURATE)
        assert math.isfinite(result.v_mps) and math.isfinite(result.omega_radps)
        assert limits.v_min_mps <= result.v_mps <= limits.v_max_mps
        assert abs(result.omega_radps) <= limits.omega_max_radps
        assert np.all(np.isfinite(result.waypoints_m)) and result.waypoints_m.shape[1] == 2
        assert result.times.total_ms >= 0.0
    assert ctrl.command == (results[-1].v_mps, results[-1].omega_radps)
    # The others were seen ahead and closing: the via-point planners rank them as threats.
    if planner != "orca":
        assert len(results[-1].threats) > 0


def test_the_mpc_is_set_up_before_the_first_plan_and_plans_as_one_set_up_late(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # A fleet starting at once would otherwise pay every robot's QP set-up on its first
    # cycle together; built up front, it is the same tracker and the same commands.
    def drive(ctrl: RobotController) -> list[tuple[float, float]]:
        out = []
        for k in range(5):
            t = 0.1 * k
            ctrl.observe(snap(t, 5 * k, {0: (0.8 * t, 0.0, 0.0), 1: (6.0 - t, 0.3, math.pi)}))
            result = ctrl.plan(t)
            out.append((result.v_mps, result.omega_radps))
        return out

    early = RobotController(spec("eifp-mpc"), PlannerConfig(), TOL_M)
    trackers = early.planner._trackers  # type: ignore[attr-defined]
    assert list(trackers) == [early.spec.limits]
    built = trackers[early.spec.limits]
    early_commands = drive(early)
    assert trackers[early.spec.limits] is built and len(trackers) == 1

    from agent.planning.planners import ViaPointPlanner
    monkeypatch.setattr(ViaPointPlanner, "prepare_tracker", lambda self, limits: None)
    late = RobotController(spec("eifp-mpc"), PlannerConfig(), TOL_M)
    assert late.planner._trackers == {}  # type: ignore[attr-defined]
    assert drive(late) == early_commands
    # The planners without a tracker set none up.
    assert RobotController(spec("eifp"), PlannerConfig(), TOL_M).planner._trackers == {}  # type: ignore[attr-defined]


# --- stale and out-of-order input (through the seeded link model) --------------------------

@settings(max_examples=40, deadline=None, database=None)
@given(latency=st.floats(0, 200), jitter=st.floats(0, 150), drop=st.floats(0, 0.5),
       dup=st.floats(0, 0.5), reorder=st.floats(0, 0.5), seed=st.integers(0, 1000))
def test_controller_only_ever_accepts_newer_snapshots(latency, jitter, drop, dup, reorder,
                                                      seed) -> None:
    from agent.core.scenario import RobotSpec as Spec
    from agent.core.types import PoseSnapshot
    from world.sim.link import FaultyLink, LinkFaults, link_rng

    ctrl = RobotController(Spec(0, (0.0, 0.0, 0.0), (5.0, 0.0)), PlannerConfig(), 0.25)
    link = FaultyLink(LinkFaults(latency, jitter, drop, dup, reorder), link_rng(seed, 0, 0))
    accepted, released = [], 0
    for tick in range(300):
        t = tick * 0.02
        link.send(t, PoseSnapshot(stamp_s=t, tick=tick, ids=np.array([0, 1]),
                                  pose=np.array([[0.01 * tick, 0.0, 0.0], [3.0, 1.0, 0.0]]),
                                  radius_m=np.array([0.5, 0.5])))
        for snap in link.receive(t):
            released += 1
            if ctrl.observe(snap):
                accepted.append(snap.tick)
    assert accepted == sorted(set(accepted))  # strictly increasing: no stale, no copies
    assert ctrl.rejected_stale == released - len(accepted)


# --------------------------------------------------------------------------------------
# plan(): a robot at its goal is not given the others' estimates
# --------------------------------------------------------------------------------------

@pytest.mark.parametrize("planner", PLANNER_NAMES)
def test_a_robot_at_its_goal_stops_without_estimating_the_others(planner: str) -> None:
    from agent.planning.make_way import LINGER_VIEW_M, PRESS_VIEW_M

    ctrl = RobotController(spec(planner, start=(20.0, 0.0, 0.0)), PlannerConfig(), TOL_M)
    beyond = 20.0 + 2 * RADIUS_M + max(PRESS_VIEW_M, LINGER_VIEW_M) + 0.2  # out of view
    for k in range(3):
        ctrl.observe(snap(0.1 * k, 5 * k, {0: (20.0, 0.0, 0.0), 1: (beyond, 0.0, math.pi)}))

    def no_estimates(**kwargs):
        raise AssertionError("others estimated for a robot at its goal")

    ctrl.tracker.others = no_estimates  # type: ignore[method-assign]
    result = ctrl.plan(0.2)
    assert result.status == PlanStatus.ARRIVED and (result.v_mps, result.omega_radps) == (0, 0)
    assert len(ctrl.last_observation.others) == 0


def test_a_parked_robot_watches_the_others_only_while_a_moving_obstacle_is_in_view() -> None:
    """Obstacle ids the static map does not list move (`goal_guard`): with one in the
    poses a parked robot estimates the others; with only mapped obstacles it does not."""
    from agent.planning.routing import StaticMap

    static = StaticMap(np.array([[30.0, 5.0]]), np.array([RADIUS_M]), np.array([-1]))
    ctrl = RobotController(spec("eifp-mpc", start=(20.0, 0.0, 0.0)), PlannerConfig(), TOL_M,
                           static_map=static)
    ctrl.observe(snap(0.0, 0, {0: (20.0, 0.0, 0.0), -1: (30.0, 5.0, 0.0)}))
    assert not ctrl.movers_in_view
    ctrl.plan(0.0)
    assert len(ctrl.last_observation.others) == 0
    for k in range(1, 4):  # obstacle -2 crosses the goal from below at 1 m/s
        ctrl.observe(snap(0.1 * k, 5 * k, {0: (20.0, 0.0, 0.0), -1: (30.0, 5.0, 0.0),
                                          -2: (20.0, -4.0 + 0.1 * k, 0.0)}))
    assert ctrl.movers_in_view
    result = ctrl.plan(0.3)
    assert -2 in ctrl.last_observation.others.ids.tolist()
    assert result.status == PlanStatus.STAND_CLEAR


def test_a_parked_robot_with_make_way_estimates_the_others_only_while_a_robot_is_close() -> None:
    """`make_way` needs to see a robot pressed against a parked one, or (on a map with
    static discs, where a passage can be closed) lingering by it; farther off than the
    press gap, or with a map the larger of the press and linger gaps (plus
    `CLOSE_SLACK_M`), nobody is estimated."""
    from agent.planning.controller import CLOSE_SLACK_M
    from agent.planning.make_way import LINGER_GAP_M, PRESS_GAP_M

    wall = StaticMap(np.array([[20.0, 10.0]]), np.array([0.5]))
    for static, gap_m in ((None, PRESS_GAP_M), (wall, max(PRESS_GAP_M, LINGER_GAP_M))):
        ctrl = RobotController(spec("eifp-mpc", start=(20.0, 0.0, 0.0)), PlannerConfig(),
                               TOL_M, static_map=static)
        far = 20.0 + 2 * RADIUS_M + gap_m + CLOSE_SLACK_M + 0.05
        ctrl.observe(snap(0.0, 0, {0: (20.0, 0.0, 0.0), 1: (far, 0.0, math.pi)}))
        ctrl.plan(0.0)
        assert len(ctrl.last_observation.others) == 0
        ctrl.observe(snap(0.1, 5, {0: (20.0, 0.0, 0.0), 1: (far - 0.1, 0.0, math.pi)}))
        assert ctrl.plan(0.1).status == PlanStatus.ARRIVED
        assert ctrl.last_observation.others.ids.tolist() == [1]
    for name in ("ifp", "eifp"):  # no make_way: nobody is estimated
        other = RobotController(spec(name, start=(20.0, 0.0, 0.0)), PlannerConfig(), TOL_M)
        other.observe(snap(0.1, 5, {0: (20.0, 0.0, 0.0), 1: (20.6 + 2 * RADIUS_M, 0.0, 0.0)}))
        other.plan(0.1)
        assert len(other.last_observation.others) == 0


def test_a_robot_that_comes_within_the_press_gap_in_one_cycle_still_presses() -> None:
    """The parked robot's arrival is recorded on its first parked cycle, with nobody in
    view, not on the first cycle someone is close: a robot that shows up 0.2 m off in one
    step (a lost pose, a late one) is a presser, not a neighbour that was there first."""
    from agent.planning.make_way import PRESS_S

    ctrl = RobotController(spec("eifp-mpc", start=(20.0, 0.0, 0.0)), PlannerConfig(), TOL_M)
    ctrl.observe(snap(0.0, 0, {0: (20.0, 0.0, 0.0), 1: (30.0, 0.0, math.pi)}))
    assert ctrl.plan(0.0).status == PlanStatus.ARRIVED
    statuses = []
    for k in range(1, int(PRESS_S / 0.1) + 5):
        ctrl.observe(snap(0.1 * k, 5 * k, {0: (20.0, 0.0, 0.0), 1: (21.2, 0.0, math.pi)}))
        statuses.append(ctrl.plan(0.1 * k).status)
    assert statuses[0] == PlanStatus.ARRIVED and PlanStatus.ARRIVED not in statuses[-3:]
    assert ctrl.planner.make_way.steps == 1


@pytest.mark.parametrize("planner", PLANNER_NAMES)
def test_a_robot_away_from_its_goal_plans_on_the_full_observation(planner: str) -> None:
    ctrl = RobotController(spec(planner), PlannerConfig(), TOL_M)
    for k in range(3):
        ctrl.observe(snap(0.1 * k, 5 * k,
                          {0: (0.1 * k, 0.0, 0.0), 1: (4.0 - 0.1 * k, 0.0, math.pi)}))
    ctrl.command = (1.0, 0.1)
    full = ctrl.observation(0.25)  # 50 ms after the newest pose: compensated
    result = ctrl.plan(0.25)
    seen = ctrl.last_observation
    assert result.status != PlanStatus.ARRIVED
    assert seen.ego == full.ego and seen.ego.x_m > 0.2
    assert seen.others.ids.tolist() == full.others.ids.tolist() == [1]
    for field in ("position_m", "velocity_mps", "linearity", "track_start_m", "radius_m"):
        np.testing.assert_array_equal(getattr(seen.others, field), getattr(full.others, field))


def test_observe_finds_its_row_again_when_the_read_only_ids_repeat() -> None:
    """A decoded stream hands out one read-only id array while the ids repeat: the robot's
    row is looked up once, and again for a new array (the robot moved in the order)."""
    ctrl = RobotController(RobotSpec(3, (0.0, 0.0, 0.0), (5.0, 0.0)), PlannerConfig(), 0.25)
    first = np.array([1, 3, 2], dtype=np.int64)
    first.flags.writeable = False
    second = np.array([3, 1, 2], dtype=np.int64)
    second.flags.writeable = False
    pose = np.array([[0.0, 1.0, 0.0], [7.0, 8.0, 0.5], [4.0, 4.0, 0.0]])
    for tick, ids in enumerate((first, first, second, second), start=1):
        snap = PoseSnapshot.trusted(0.1 * tick, tick, ids, pose, np.full(3, 0.5))
        assert ctrl.observe(snap)
        assert ctrl.observation(0.1 * tick).ego.x_m == (7.0 if ids is first else 0.0)
