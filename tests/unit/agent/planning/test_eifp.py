"""eIFP: the cost of Eqs. (15)-(17), ghost-path discarding, hysteresis and tie-breaking."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.config import CostConfig, PlannerConfig, RobotLimits
from agent.core.types import EgoState, Observation, Others, PlanStatus, Side
from agent.planning.eifp import (
    LENGTH_EPS_M,
    MIN_PATH_DISTANCE_M,
    EifpSelector,
    GhostPaths,
    choose_side,
    plan_eifp,
    update_side_memory,
)
from agent.planning.ifp import ESCAPE_STANDING_MPS, ViaPlan
from agent.planning.mechanisms import EIFP_MECHANISMS
from agent.planning.threats import as_complex
from tests.examples import examples

R = 0.2
CFG = PlannerConfig()


def _eifp(observation, config=CFG, side_memory=None, **kw):
    """eIFP with eifp's mechanisms in the default profile (right-hand margin included)."""
    kw.setdefault("mech", EIFP_MECHANISMS)
    return plan_eifp(observation, config, side_memory, **kw)
RIGHT, LEFT = 0, 1  # index in SIDES


def others(pos, vel=None, ids=None, linearity=1.0, track_start=None, robot=True):
    pos = np.asarray(pos, dtype=float).reshape(-1, 2)
    k = pos.shape[0]
    vel = np.zeros((k, 2)) if vel is None else np.asarray(vel, dtype=float).reshape(-1, 2)
    lin = np.broadcast_to(np.asarray(linearity, dtype=float), (k,))
    return Others(
        ids=np.arange(1, k + 1) if ids is None else ids,
        position_m=pos,
        velocity_mps=vel,
        radius_m=np.full(k, R),
        linearity=lin,
        track_start_m=pos - 0.5 * vel if track_start is None else track_start,
        is_robot=np.broadcast_to(np.asarray(robot, dtype=bool), (k,)),
    )


def observe(o, x=0.0, y=0.0, heading=0.0, v=1.0, goal=(10.0, 0.0), robot_id=0):
    return Observation(
        robot_id=robot_id,
        ego=EgoState(x, y, heading, v),
        goal_m=np.array(goal, dtype=float),
        radius_m=R,
        limits=RobotLimits(v_max_mps=1.1),
        others=o,
    )


# --- the cost -------------------------------------------------------------------------


def test_cost_by_hand():
    # Other j at (0, 5) moving (1, 0): predicted path (0, 5) -> (4, 5) (horizon 4 s);
    # ghost path from s_j = (-1, 5) to g_j = (4, 5), direction (1, 0); w_j = 1.
    o = others([[0, 5]], [[1, 0]], track_start=np.array([[-1.0, 5.0]]))
    paths = GhostPaths(o, 4.0, np.array([1.0]))
    cost, clear = paths.evaluate((2 + 3j,), 0j, 4 + 0j, 1.0, 1.0, 0.3, skip=0)
    length = 2 * math.sqrt(13) / (4 + LENGTH_EPS_M)  # Eq. (16)
    distance = 1 / 2.0  # w_j / d_ij, d = 2
    angle = 1 - 2 / math.sqrt(13)  # Eq. (17)
    assert cost[0] == pytest.approx(length + distance + 0.3 * angle, rel=1e-12)
    assert clear == [True]


def test_clearance_to_ghost_paths_skips_the_resolved_threat():
    # Two others with ghost paths along y = 5 and y = -5 (x from -1 to 4).
    o = others([[0, 5], [0, -5]], [[1, 0], [1, 0]], track_start=np.array([[-1.0, 5], [-1, -5]]))
    paths = GhostPaths(o, 4.0, np.array([1.0, 1.0]))
    pts = (2 + 4.5j, 2 - 4.5j, 2 + 0j)
    assert paths.evaluate(pts, 0j, 4 + 0j, 1.0, 1.0, 0.3, skip=1)[1] == [False, True, True]
    assert paths.evaluate(pts, 0j, 4 + 0j, 1.0, 1.0, 0.3, skip=0)[1] == [True, False, True]


def test_distance_floor_and_zero_weight_terms():
    o = others([[0, 5]], [[1, 0]], track_start=np.array([[-1.0, 5.0]]))
    a, b = 0j, 4 + 0j
    on_path = GhostPaths(o, 4.0, np.array([0.0])).evaluate((2 + 5j,), a, b, 0.0, 1.0, 0.0, 0)[0]
    assert on_path[0] == pytest.approx(1 / MIN_PATH_DISTANCE_M)
    # w_j = 0: only the length term is left.
    quiet = others([[0, 5]], [[1, 0]], linearity=0.0)
    cost = GhostPaths(quiet, 4.0, np.array([0.0])).evaluate((2 + 3j,), a, b, 1.0, 1.0, 0.3, 0)[0]
    assert cost[0] == pytest.approx(2 * math.sqrt(13) / (4 + LENGTH_EPS_M))


def test_ghost_path_without_length_has_no_angle_term():
    # Static, never moved: s_j = g_j, so phi = 0; the distance is to the point.
    o = others([[0, 5]], linearity=1.0)
    cost = GhostPaths(o, 4.0, np.array([0.0])).evaluate((3j,), 0j, 6j, 0.0, 1.0, 1.0, 0)[0]
    assert cost[0] == pytest.approx(1 / 2.0)


def point_segment_distance(point, start, end):
    """|point - closest point of the segment start -> end|, one pair in plain floats; a
    segment shorter than 1 nm is its start point."""
    (px, py), (ax, ay), (bx, by) = point, start, end
    sx, sy = bx - ax, by - ay
    seg_sq = sx * sx + sy * sy
    t = 0.0 if seg_sq <= 1e-18 else min(max(((px - ax) * sx + (py - ay) * sy) / seg_sq, 0.0), 1.0)
    return math.hypot(px - ax - t * sx, py - ay - t * sy)


def test_ghost_distances_match_the_point_to_segment_distance():
    # Columns 0..K-1: predicted paths p_j -> p_j + 3 s v_j; K..2K-1: ghost paths s_j -> g_j.
    rng = np.random.default_rng(4)
    o = others(rng.uniform(-5, 5, (6, 2)), rng.uniform(-1, 1, (6, 2)), linearity=0.5)
    paths = GhostPaths(o, 3.0, np.zeros(6))
    pts = rng.uniform(-6, 6, (5, 2))
    got = paths.distances(as_complex(pts))
    goal = o.position_m + 3.0 * o.velocity_mps
    for i, j in np.ndindex(5, 6):
        assert got[i, j] == pytest.approx(
            point_segment_distance(pts[i], o.position_m[j], goal[j]), abs=1e-12)
        assert got[i, 6 + j] == pytest.approx(
            point_segment_distance(pts[i], o.track_start_m[j], goal[j]), abs=1e-12)


def test_ghost_distances_by_hand():
    # Other 1 moves along +x at 1 m/s: predicted path (0, 0) -> (4, 0) (4 s), ghost path
    # from (-1, 0). Other 2 stands at (1, 1): both of its paths are that point.
    o = others([[0.0, 0.0], [1.0, 1.0]], [[1.0, 0.0], [0.0, 0.0]],
               track_start=np.array([[-1.0, 0.0], [1.0, 1.0]]))
    d = GhostPaths(o, 4.0, np.zeros(2)).distances(np.array([2 + 3j, -1 + 0j, 5 + 4j, -3 + 1j]))
    np.testing.assert_allclose(d[:, 0], [3.0, 1.0, math.hypot(1, 4), math.hypot(3, 1)])
    np.testing.assert_allclose(d[:, 1], [math.hypot(1, 2), math.hypot(2, 1), 5.0, 4.0])
    np.testing.assert_allclose(d[:, 2], [3.0, 0.0, math.hypot(1, 4), math.hypot(2, 1)])
    np.testing.assert_allclose(d[:, 3], d[:, 1])


# --- side choice ----------------------------------------------------------------------


def test_choose_side_rules():
    both = np.array([True, True])
    assert choose_side(np.array([2.0, 1.0]), both, None, 0.15) == LEFT  # cheaper
    assert choose_side(np.array([1.0, 1.0]), both, None, 0.15) == RIGHT  # exact tie
    assert choose_side(np.array([1.0, 1.0 - 1e-12]), both, None, 0.15) == RIGHT  # ~tie
    assert choose_side(np.array([1.0, 0.999]), both, None, 0.15) == LEFT  # not a tie
    # Kept LEFT: RIGHT must be below (1 - 0.15) of LEFT's cost to take over.
    assert choose_side(np.array([0.9, 1.0]), both, Side.LEFT, 0.15) == LEFT
    assert choose_side(np.array([0.84, 1.0]), both, Side.LEFT, 0.15) == RIGHT
    # Only one allowed / none.
    assert choose_side(np.array([5.0, 1.0]), np.array([True, False]), Side.LEFT, 0.15) == RIGHT
    assert choose_side(np.array([1.0, 1.0]), np.array([False, False]), None, 0.15) is None


def test_head_on_robots_both_pass_on_their_right_and_separate():
    a = observe(others([[8, 0]], [[-1, 0]], ids=[2]), robot_id=1, goal=(10, 0))
    b = observe(
        others([[0, 0]], [[1, 0]], ids=[1]), x=8.0, heading=math.pi, robot_id=2, goal=(-2, 0)
    )
    plan_a, plan_b = _eifp(a, CFG), _eifp(b, CFG)
    assert plan_a.side is Side.RIGHT and plan_b.side is Side.RIGHT
    assert plan_a.via_point_m[1] < -0.5 and plan_b.via_point_m[1] > 0.5
    # Driving their first legs at full speed, they never come closer than 2 R.
    t = np.linspace(0.0, 1.0, 201)[:, None]
    path_a = plan_a.waypoints_m[0] + t * (plan_a.waypoints_m[1] - plan_a.waypoints_m[0])
    path_b = plan_b.waypoints_m[0] + t * (plan_b.waypoints_m[1] - plan_b.waypoints_m[0])
    assert np.min(np.hypot(*(path_a - path_b).T)) > 2 * R


def test_right_hand_margin_on_a_first_choice():
    both = (True, True)
    assert choose_side((1.0, 0.97), both, None, 0.15, right_margin=0.05) == RIGHT
    assert choose_side((1.0, 0.94), both, None, 0.15, right_margin=0.05) == LEFT
    assert choose_side((0.97, 1.0), both, None, 0.15, right_margin=0.05) == RIGHT
    # The memory's hysteresis, not the margin, rules once a side was chosen.
    assert choose_side((1.0, 0.97), both, Side.LEFT, 0.15, right_margin=0.05) == LEFT


def test_nearly_head_on_robots_still_pass_on_opposite_sides():
    # One cycle into a closed-loop run of two robots swapping 10 m apart, B started 1 cm
    # above A's line (goals: each one's start mirrored through the origin). By cost alone
    # A would pass below (its LEFT) and B below too (its RIGHT): the same world side, a
    # dance. The right-hand margin sends A above: they pass on opposite sides.
    a = observe(
        others([[-4.89, 0.0098]], [[1.1, -0.0022]], ids=[2], track_start=np.array([[-5.0, 0.01]])),
        x=4.89,
        heading=math.pi,
        v=1.1,
        goal=(-5.0, 0.0),
    )
    b = observe(
        others([[4.89, 0.0]], [[-1.1, 0.0]], ids=[1], track_start=np.array([[5.0, 0.0]])),
        x=-4.89,
        y=0.0098,
        heading=-0.002,
        v=1.1,
        goal=(5.0, -0.01),
    )
    plan_a, plan_b = _eifp(a, CFG), _eifp(b, CFG)
    assert plan_a.side is Side.RIGHT and plan_b.side is Side.RIGHT
    assert plan_a.via_point_m[1] > 0.5 and plan_b.via_point_m[1] < -0.5


def test_right_hand_margin_applies_to_robots_not_obstacles():
    # Slightly below the line: LEFT (above) is a little shorter.
    robot = _eifp(observe(others([[5, -0.05]], linearity=0.0, robot=True)), CFG)
    obstacle = _eifp(observe(others([[5, -0.05]], linearity=0.0, robot=False)), CFG)
    assert robot.side is Side.RIGHT and obstacle.side is Side.LEFT


def test_side_hysteresis_keeps_the_side_through_a_small_change():
    def scene(dy):  # a static obstacle a little above (dy > 0) or below the direct line
        return observe(others([[5, dy]], linearity=0.0, robot=False, ids=[-3]))

    selector = EifpSelector(CFG, EIFP_MECHANISMS)
    first = selector.select(scene(-0.1))  # obstacle below: passing above (LEFT) is shorter
    assert first.side is Side.LEFT and selector.side_memory == {-3: Side.LEFT}
    second = selector.select(scene(+0.1))  # now RIGHT is shorter, but by less than 15 %
    assert second.side is Side.LEFT
    assert _eifp(scene(+0.1), CFG).side is Side.RIGHT  # without memory
    selector.reset()
    assert selector.side_memory == {}
    assert selector.select(scene(+0.1)).side is Side.RIGHT
    # No hysteresis: the memory does not hold the side.
    loose = EifpSelector(PlannerConfig(cost=CostConfig(side_hysteresis=0.0)), EIFP_MECHANISMS)
    loose.select(scene(-0.1))
    assert loose.select(scene(+0.1)).side is Side.RIGHT


def test_side_memory_forgets_others_no_longer_sensed():
    plan = ViaPlan(
        status=PlanStatus.OK,
        waypoints_m=np.zeros((3, 2)),
        resolved_sides=((4, Side.LEFT), (6, Side.RIGHT)),
    )
    memory = update_side_memory(
        {4: Side.RIGHT, 5: Side.LEFT, 9: Side.LEFT}, plan, np.array([4, 6, 9])
    )
    assert memory == {4: Side.LEFT, 6: Side.RIGHT, 9: Side.LEFT}


# --- ghost paths ----------------------------------------------------------------------


def threat_and_flankers(flankers):
    """A static obstacle dead ahead (a tie between sides) and robots cruising alongside."""
    pos = [[5, 0]] + [[3, y] for y in flankers]
    vel = [[0, 0]] + [[1, 0]] * len(flankers)  # same velocity as ours: never threats
    return others(pos, vel, ids=list(range(1, len(pos) + 1)), linearity=0.0)


def test_candidate_near_a_ghost_path_is_discarded():
    assert _eifp(observe(threat_and_flankers([])), CFG).side is Side.RIGHT  # the tie
    # A robot's ghost path along y = -1.2 passes ~0.45 m from the RIGHT candidate (< L).
    plan = _eifp(observe(threat_and_flankers([-1.2])), CFG)
    assert plan.resolved_id == 1 and plan.side is Side.LEFT


def test_all_candidates_near_ghost_paths_still_gives_a_plan():
    plan = _eifp(observe(threat_and_flankers([-1.2, 1.2])), CFG)
    assert plan.status is PlanStatus.OK and plan.resolved_id == 1
    assert plan.side is Side.RIGHT  # the full set, tie -> RIGHT


def test_the_resolved_threat_own_ghost_path_does_not_discard_its_candidates():
    # A head-on robot's ghost path runs through both of its own tangent candidates' area.
    plan = _eifp(observe(others([[6, 0]], [[-1, 0]], track_start=np.array([[8.0, 0.0]]))), CFG)
    assert plan.status is PlanStatus.OK and plan.side is Side.RIGHT


def test_interaction_terms_change_the_choice():
    # A robot above the direct line, moving left to right: its path pushes the choice
    # below (RIGHT) even though the obstacle ahead sits slightly below the line.
    o = others([[5, -0.05], [1, 2.0]], [[0, 0], [1, 0]], linearity=[0.0, 1.0], robot=[False, True])
    no_terms = PlannerConfig(cost=CostConfig(w_distance=0.0, w_angle=0.0))
    assert _eifp(observe(o), no_terms).side is Side.LEFT
    assert _eifp(observe(o), PlannerConfig(cost=CostConfig(w_distance=3.0))).side is Side.RIGHT


# --- determinism, bad input, properties -----------------------------------------------


def test_selector_is_deterministic():
    rng = np.random.default_rng(8)
    seq = []
    for _ in range(6):
        pos = rng.uniform([1, -3], [10, 3], (8, 2))
        seq.append(observe(others(pos, rng.uniform(-1, 1, (8, 2)), linearity=0.7)))
    a, b = EifpSelector(CFG, EIFP_MECHANISMS), EifpSelector(CFG, EIFP_MECHANISMS)
    plans_a = [a.select(o) for o in seq]
    plans_b = [b.select(o) for o in seq]
    for pa, pb in zip(plans_a, plans_b):
        np.testing.assert_array_equal(pa.waypoints_m, pb.waypoints_m)
        assert (pa.side, pa.resolved_id, pa.resolved_sides) == (
            pb.side,
            pb.resolved_id,
            pb.resolved_sides,
        )
    assert a.side_memory == b.side_memory


@pytest.mark.parametrize(
    "setting, value",
    [
        ("cost.w_angle", math.nan),
        ("cost.side_hysteresis", math.nan),
        ("cost.w_distance", math.inf),
    ],
)
def test_bad_configuration_raises(setting, value):
    # Refused when the configuration is built, so no planner ever runs with it.
    with pytest.raises(ValueError, match=f"^{setting.split('.')[1]}: "):
        _eifp(observe(others([[5, 0]])), CFG.with_settings(**{setting: value}))


coord = st.floats(-15, 15, allow_nan=False)


@settings(max_examples=examples(120), deadline=None)
@given(
    st.lists(
        st.tuples(coord, coord, st.floats(-1.5, 1.5), st.floats(-1.5, 1.5), st.floats(0, 1)),
        max_size=10,
    ),
    st.floats(0, 1.1),
    st.floats(-math.pi, math.pi),
)
def test_property_finite_inputs_give_finite_plans(rows, v, heading):
    arr = np.array(rows).reshape(-1, 5)
    o = others(arr[:, :2], arr[:, 2:4], linearity=arr[:, 4]) if len(rows) else Others.empty()
    selector = EifpSelector(CFG, EIFP_MECHANISMS)
    for step in range(2):
        plan = selector.select(observe(o, v=v, heading=heading + 0.1 * step))
        assert np.all(np.isfinite(plan.waypoints_m))
        assert 2 <= len(plan.waypoints_m) <= CFG.reference.max_depth + 2
        if plan.status is PlanStatus.ESCAPE and v < ESCAPE_STANDING_MPS:
            assert len(plan.waypoints_m) == 2  # out of the disc first, the goal next cycle
        else:
            np.testing.assert_array_equal(plan.waypoints_m[-1], [10, 0])
    assert set(selector.side_memory) <= set(o.ids.tolist())


# --- the mechanisms of eifp-mpc ---------------------------------------------------------


def test_selector_carries_an_escape_into_the_next_cycle_under_the_band():
    from agent.planning.eifp import EifpSelector
    from agent.planning.mechanisms import PAPER_MECHANISMS, Mechanisms

    inflated = 2 * R + CFG.safety.d_safety_m
    inside = observe(others([[0.0, inflated - 0.02]]))
    just_out = observe(others([[0.0, inflated + 0.05]]))
    banded = EifpSelector(CFG, Mechanisms(escape_band_m=0.1))
    assert banded.select(inside).status is PlanStatus.ESCAPE
    assert banded.select(just_out).status is PlanStatus.ESCAPE  # still in the band
    far = observe(others([[0.0, inflated + 0.2]]))
    assert banded.select(far).status is PlanStatus.OK
    assert banded.select(just_out).status is PlanStatus.OK  # not escaping any more
    banded.select(inside)
    banded.reset()
    assert banded.select(just_out).status is PlanStatus.OK  # reset forgets the escape
    paper = EifpSelector(CFG, PAPER_MECHANISMS)
    paper.select(inside)
    assert paper.select(just_out).status is PlanStatus.OK


def test_each_planner_runs_its_mechanisms():
    from agent.core.config import paper_config
    from agent.planning.mechanisms import EIFP_MPC_MECHANISMS, PAPER_MECHANISMS
    from agent.planning.planners import make_planner

    assert make_planner("eifp-mpc", CFG)._selector.mech == EIFP_MPC_MECHANISMS
    assert make_planner("eifp", CFG)._selector.mech == EIFP_MECHANISMS
    assert make_planner("eifp-mpc", paper_config())._selector.mech == PAPER_MECHANISMS
