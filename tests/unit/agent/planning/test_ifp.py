"""The IFP baseline: nearest threat, earliest feasible via-point, iterated legs."""

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from agent.core.config import PlannerConfig, ReferenceConfig, RobotLimits
from agent.core.types import EgoState, Observation, Others, PlanStatus, Side
from agent.planning.ifp import ESCAPE_STANDING_MPS, ViaPlan, plan_ifp, select_earliest
from agent.planning.kept_plan import KEEP_PLAN_RATIO
from agent.planning.mechanisms import VIA_MARGIN_M
from agent.planning.viapoints import ESCAPE_MARGIN_M, candidate_pair
from tests.examples import examples

R = 0.2  # robot and obstacle radius
CFG = PlannerConfig()  # d_safety 0.3 -> L = 0.7 between two 0.2 m discs
L = 2 * R + CFG.safety.d_safety_m


def others(pos, vel=None, ids=None, radius=R, linearity=1.0):
    pos = np.asarray(pos, dtype=float).reshape(-1, 2)
    k = pos.shape[0]
    vel = np.zeros((k, 2)) if vel is None else np.asarray(vel, dtype=float).reshape(-1, 2)
    return Others(
        ids=np.arange(1, k + 1) if ids is None else ids,
        position_m=pos,
        velocity_mps=vel,
        radius_m=np.full(k, radius),
        linearity=np.full(k, linearity),
        track_start_m=pos - 0.5 * vel,
        is_robot=np.ones(k, dtype=bool),
    )


def observe(o, x=0.0, y=0.0, heading=0.0, v=0.0, goal=(10.0, 0.0), v_max=1.1):
    return Observation(
        robot_id=0,
        ego=EgoState(x, y, heading, v),
        goal_m=np.array(goal, dtype=float),
        radius_m=R,
        limits=RobotLimits(v_max_mps=v_max),
        others=o,
    )


def segment_clearance(a, b, c):
    """Distance from point c to segment a-b."""
    a, b, c = map(np.asarray, (a, b, c))
    d = b - a
    t = np.clip((c - a) @ d / max(d @ d, 1e-300), 0.0, 1.0)
    return float(np.hypot(*(a + t * d - c)))


def test_nobody_around_goes_straight():
    plan = plan_ifp(observe(Others.empty(), v=1.0), CFG)
    assert plan.status is PlanStatus.OK
    np.testing.assert_array_equal(plan.waypoints_m, [[0, 0], [10, 0]])
    assert plan.via_point_m is None and plan.side is Side.NONE and plan.resolved_id is None
    assert plan.threats == ()


def test_clear_path_is_direct_even_with_others_around():
    plan = plan_ifp(observe(others([[5, 4], [-3, 0]]), v=1.0), CFG)
    assert plan.status is PlanStatus.OK and plan.waypoints_m.shape == (2, 2)


def test_head_on_threat_gets_the_earliest_tangent_via_point():
    o = others([[6, 0]], [[-1, 0]], ids=[7])
    plan = plan_ifp(observe(o, v=1.0), CFG)
    assert plan.status is PlanStatus.OK
    assert [t.other_id for t in plan.threats] == [7]
    assert plan.threats[0].tcpa_s == pytest.approx(3.0)
    # Symmetric head-on: both sides equally early -> RIGHT (y < 0).
    right, left = candidate_pair(0, 0, 6, 0, -1, 0, L, 1.1, VIA_MARGIN_M)
    assert right[2] == pytest.approx(left[2])
    assert plan.side is Side.RIGHT and plan.resolved_id == 7
    np.testing.assert_allclose(plan.via_point_m, right[:2], atol=1e-12)
    assert plan.via_point_m[1] < 0
    np.testing.assert_array_equal(plan.waypoints_m[[0, -1]], [[0, 0], [10, 0]])
    assert plan.resolved_sides == ((7, Side.RIGHT),)


def test_moving_threat_picks_the_smaller_lambda():
    # Crossing from the right (moving +y): the tangent points move up; the one that
    # comes towards the robot's cone first wins.
    o = others([[5, -3]], [[0, 0.6]])
    plan = plan_ifp(observe(o, v=1.0), CFG)
    cands = candidate_pair(0, 0, 5, -3, 0, 0.6, L, 1.1, VIA_MARGIN_M)
    best = int(np.argmin([t for _, _, t in cands]))
    assert cands[0][2] != pytest.approx(cands[1][2])
    assert plan.status is PlanStatus.OK
    np.testing.assert_allclose(plan.via_point_m, cands[best][:2], atol=1e-12)
    assert plan.side is (Side.RIGHT, Side.LEFT)[best]


def test_select_earliest_rule():
    pts = (0j, 1j)
    assert select_earliest(0, pts, (2.0, 1.0), 0j, 1 + 0j) == 1
    assert select_earliest(0, pts, (1.0, 1.0), 0j, 1 + 0j) == 0  # tie -> RIGHT
    assert select_earliest(0, pts, (1.0, math.inf), 0j, 1 + 0j) == 0
    assert select_earliest(0, pts, (math.inf, math.inf), 0j, 1 + 0j) is None


def test_stopped_robot_still_avoids_a_static_obstacle_on_its_way():
    # v = 0: Eq. (6) sees no threat (v_rel = 0), but the direct leg is checked too.
    plan = plan_ifp(observe(others([[5, 0.1]]), v=0.0), CFG)
    assert plan.threats == ()
    assert plan.status is PlanStatus.OK and plan.via_point_m is not None
    wps = plan.waypoints_m
    for a, b in zip(wps[:-1], wps[1:]):
        assert segment_clearance(a, b, [5, 0.1]) >= L - 1e-6


def test_iteration_resolves_a_second_obstacle_behind_the_first():
    # The via-point around the first disc leads straight into the second.
    o = others([[4, 0], [8, -0.6]])
    plan = plan_ifp(observe(o, v=1.0, goal=(14.0, 0.0)), CFG)
    assert plan.status is PlanStatus.OK
    wps = plan.waypoints_m
    assert 3 <= len(wps) <= CFG.reference.max_depth + 2
    for a, b in zip(wps[:-1], wps[1:]):
        for c in o.position_m:
            assert segment_clearance(a, b, c) >= L - 1e-6
    assert {i for i, _ in plan.resolved_sides} == {1, 2}


def test_depth_limit_is_respected():
    rng = np.random.default_rng(11)
    o = others(rng.uniform([2, -2], [12, 2], size=(12, 2)))
    for depth in (1, 2, 3):
        config = PlannerConfig(reference=ReferenceConfig(max_depth=depth))
        plan = plan_ifp(observe(o, v=1.0, goal=(14.0, 0.0)), config)
        assert len(plan.waypoints_m) - 2 <= depth


def test_inside_an_inflated_disc_escapes_straight_out():
    o = others([[0.5, 0.0], [6, 0]], ids=[3, 4])
    plan = plan_ifp(observe(o, v=1.0), CFG)
    assert plan.status is PlanStatus.ESCAPE
    assert plan.resolved_id == 3 and plan.side is Side.NONE
    np.testing.assert_allclose(plan.via_point_m, [0.5 - L - ESCAPE_MARGIN_M, 0.0])
    np.testing.assert_allclose(plan.waypoints_m, [[0, 0], plan.via_point_m, [10, 0]])


def test_a_standing_robot_escapes_without_the_goal_in_its_plan():
    # the goal lies back past the disc: [P, escape point] only, not a spline through it
    o = others([[0.5, 0.0]], ids=[3])
    for v in (0.0, ESCAPE_STANDING_MPS - 1e-3):
        plan = plan_ifp(observe(o, v=v), CFG)
        assert plan.status is PlanStatus.ESCAPE
        np.testing.assert_allclose(plan.waypoints_m, [[0, 0], [0.5 - L - ESCAPE_MARGIN_M, 0.0]])
    moving = plan_ifp(observe(o, v=ESCAPE_STANDING_MPS), CFG)
    assert len(moving.waypoints_m) == 3


def test_escape_from_the_deepest_disc_and_coincident_is_finite():
    o = others([[0.0, 0.0], [0.6, 0.0]], ids=[5, 6])
    plan = plan_ifp(observe(o, heading=0.0, v=1.0), CFG)
    assert plan.status is PlanStatus.ESCAPE and plan.resolved_id == 5
    # Coincident: out to the right of the heading (+x -> -y).
    np.testing.assert_allclose(plan.via_point_m, [0.0, -(L + ESCAPE_MARGIN_M)], atol=1e-12)
    assert np.all(np.isfinite(plan.waypoints_m))


def test_no_feasible_candidate_for_the_nearest_threat():
    # A slow robot (v_max 0.1) facing a fast head-on obstacle: the tangent points sweep
    # past faster than the robot's cone can meet them.
    o = others([[5, 0]], [[-2, 0]])
    plan = plan_ifp(observe(o, v=0.1, v_max=0.1), CFG)
    assert plan.status is PlanStatus.NO_FEASIBLE
    assert len(plan.threats) == 1
    np.testing.assert_array_equal(plan.waypoints_m, [[0, 0], [10, 0]])
    assert plan.via_point_m is None


def test_deterministic_and_independent_of_the_order_of_others():
    rng = np.random.default_rng(2)
    pos = rng.uniform([1, -4], [12, 4], size=(10, 2))
    vel = rng.uniform(-1, 1, size=(10, 2))
    ids = np.arange(10, 20)
    a = plan_ifp(observe(others(pos, vel, ids), v=1.0), CFG)
    b = plan_ifp(observe(others(pos, vel, ids), v=1.0), CFG)
    perm = rng.permutation(10)
    c = plan_ifp(observe(others(pos[perm], vel[perm], ids[perm]), v=1.0), CFG)
    assert _decision(a) == _decision(b) == _decision(c)


def _decision(plan: ViaPlan):
    return (
        plan.status,
        plan.waypoints_m.round(12).tolist(),
        plan.side,
        plan.resolved_id,
        plan.threats,
        plan.resolved_sides,
    )


@pytest.mark.parametrize(
    "setting, value",
    [
        ("safety.d_safety_m", math.nan),
        ("threats.t_max_s", math.inf),
        ("cost.w_length", math.nan),
        ("reference.max_depth", 0),
    ],
)
def test_bad_configuration_raises(setting, value):
    # Refused when the configuration is built, so no planner ever runs with it.
    with pytest.raises(ValueError, match=f"^{setting.split('.')[1]}: "):
        plan_ifp(observe(others([[5, 0]]), v=1.0), CFG.with_settings(**{setting: value}))


def test_non_finite_observation_raises():
    with pytest.raises(ValueError):
        plan_ifp(observe(others([[5, 0]]), v=1.0, v_max=math.inf), CFG)
    with pytest.raises(ValueError):
        plan_ifp(observe(others([[5, 0]]), v=1.0, v_max=0.0), CFG)
    obs = observe(others([[5, 0]]), v=1.0)
    object.__setattr__(obs.ego, "x_m", math.nan)  # bypassing the constructor's check
    with pytest.raises(ValueError):
        plan_ifp(obs, CFG)
    with pytest.raises(ValueError):
        observe(others([[5, math.nan]]))  # the constructor already refuses


def test_sensing_radius_and_neighbour_cap_apply():
    o = others([[5, 0]], [[-1, 0]])
    plan = plan_ifp(observe(o, v=1.0), CFG.with_settings(**{"threats.sensing_radius_m": 4.0}))
    assert plan.threats == () and plan.waypoints_m.shape == (2, 2)


coord = st.floats(-15, 15, allow_nan=False)


@settings(max_examples=examples(150), deadline=None)
@given(
    st.lists(st.tuples(coord, coord, st.floats(-1.5, 1.5), st.floats(-1.5, 1.5)), max_size=10),
    st.floats(0, 1.1),
    st.floats(-math.pi, math.pi),
    st.tuples(coord, coord),
)
# a goal 2.2e-313 m away (a denormal leg): found by hypothesis in CI, NaN in legs_threats
@example([(1.0, 0.0, 0.0, 0.0)], 0.0, 0.0, (0.0, 2.2250738585e-313))
@example([(0.0, 1.0, 0.0, 0.0)], 0.0, 0.0, (0.0, 2.2250738585e-313))
def test_property_finite_inputs_give_a_finite_well_formed_plan(rows, v, heading, goal):
    arr = np.array(rows).reshape(-1, 4)
    o = others(arr[:, :2], arr[:, 2:]) if len(rows) else Others.empty()
    plan = plan_ifp(observe(o, v=v, heading=heading, goal=goal), CFG)
    wps = plan.waypoints_m
    assert np.all(np.isfinite(wps))
    assert 2 <= len(wps) <= CFG.reference.max_depth + 2
    np.testing.assert_array_equal(wps[0], [0, 0])
    if plan.status is PlanStatus.ESCAPE and v < ESCAPE_STANDING_MPS:
        assert len(wps) == 2  # out of the disc first, the goal next cycle
    else:
        np.testing.assert_array_equal(wps[-1], goal)
    assert plan.status in (PlanStatus.OK, PlanStatus.ESCAPE, PlanStatus.NO_FEASIBLE)
    if plan.via_point_m is not None:
        np.testing.assert_array_equal(plan.via_point_m, wps[1])


def test_ignored_others_are_neither_resolved_nor_on_any_leg_but_still_escaped():
    from agent.planning.ifp import Decisions, plan_via_points
    from agent.planning.mechanisms import IFP_MECHANISMS

    # Two discs on the way: ignoring 1 (a stand-on encounter) resolves only 2.
    o = others([[4, 0], [8, -0.6]])
    obs = observe(o, v=1.0, goal=(14.0, 0.0))
    plan = plan_via_points(obs, CFG, lambda _o: select_earliest,
                           Decisions(ignored_ids=frozenset({1})), mech=IFP_MECHANISMS)
    assert {i for i, _ in plan.resolved_sides} == {2}
    assert 1 in [t.other_id for t in plan.threats]  # still reported
    # Ignoring both: the direct line.
    both = plan_via_points(obs, CFG, lambda _o: select_earliest,
                           Decisions(ignored_ids=frozenset({1, 2})), mech=IFP_MECHANISMS)
    assert both.waypoints_m.shape == (2, 2) and both.resolved_sides == ()
    # Inside an ignored disc: still the escape.
    inside = plan_via_points(observe(others([[0.5, 0]]), v=1.0), CFG,
                             lambda _o: select_earliest,
                           Decisions(ignored_ids=frozenset({1})), mech=IFP_MECHANISMS)
    assert inside.status is PlanStatus.ESCAPE


# The mechanisms (`Mechanisms`): each against the paper's cycle.


def _rules(**kw):
    from agent.planning.mechanisms import Mechanisms

    return Mechanisms(**kw)


def _plan(obs, mech, config=CFG, **kw):
    from agent.planning.ifp import Decisions, plan_via_points

    return plan_via_points(obs, config, lambda _o: select_earliest, Decisions(**kw), mech=mech)


def test_inflated_threats_drop_a_pass_outside_l_but_inside_d_thresh():
    from agent.planning.mechanisms import PAPER_MECHANISMS

    # Head-on, DCPA 1.0 m: outside L = 0.7, inside the paper's D_thresh = 5 r + d = 1.3.
    wide = observe(others([[5.0, 1.0]], [[-1.0, 0.0]]), v=1.0)
    assert [t.other_id for t in _plan(wide, PAPER_MECHANISMS).threats] == [1]
    inside_l = _plan(wide, _rules(inflated_threats=True))
    assert inside_l.threats == () and inside_l.waypoints_m.shape == (2, 2)
    # DCPA 0.5 m < L: a threat either way, resolved by a via-point.
    near = observe(others([[5.0, 0.5]], [[-1.0, 0.0]]), v=1.0)
    plan = _plan(near, _rules(inflated_threats=True))
    assert [t.other_id for t in plan.threats] == [1] and plan.resolved_id == 1


def test_inflated_threats_use_each_pairs_own_l():
    # Two head-on others at DCPA 1.0 m: radius 0.2 (L = 0.7) and 0.6 (L = 1.1).
    o = Others(ids=np.array([1, 2]), position_m=np.array([[5.0, 1.0], [8.0, -1.0]]),
               velocity_mps=np.array([[-1.0, 0.0], [-1.0, 0.0]]),
               radius_m=np.array([0.2, 0.6]), linearity=np.ones(2),
               track_start_m=np.array([[5.5, 1.0], [8.5, -1.0]]), is_robot=np.ones(2, bool))
    plan = _plan(observe(o, v=1.0), _rules(inflated_threats=True))
    assert [t.other_id for t in plan.threats] == [2]


@pytest.mark.parametrize("margin_m", [0.05, 0.3])
def test_via_margin_sets_how_far_out_of_the_disc_the_via_point_lies(margin_m):
    obs = observe(others([[5.0, 0.0]]), v=1.0)
    plan = _plan(obs, _rules(via_margin_m=margin_m))
    assert plan.resolved_id == 1
    assert math.hypot(plan.via_point_m[0] - 5.0, plan.via_point_m[1]) == pytest.approx(
        L + margin_m, abs=1e-9)


def test_escape_band_keeps_escaping_until_a_band_clear():
    band = 0.1
    rules = _rules(escape_band_m=band)
    # 0.05 m outside the disc of other 1 (L = 0.7), beside the robot's path.
    o = others([[0.0, L + 0.05]])
    obs = observe(o, v=1.0)
    assert _plan(obs, rules).status is PlanStatus.OK  # not escaping before: plans on
    held = _plan(obs, rules, escape_id=1)
    assert held.status is PlanStatus.ESCAPE and held.resolved_id == 1
    # The escape point lies the band further out, straight away from the centre.
    np.testing.assert_allclose(held.via_point_m, [0.0, (L + 0.05) - (L + band + ESCAPE_MARGIN_M)],
                               atol=1e-9)
    # Past the band, or escaping from someone else: the plain cycle.
    far = observe(others([[0.0, L + 0.15]]), v=1.0)
    assert _plan(far, rules, escape_id=1).status is PlanStatus.OK
    assert _plan(obs, rules, escape_id=7).status is PlanStatus.OK
    # The paper's cycle has no band.
    assert _plan(obs, _rules(), escape_id=1).status is PlanStatus.OK


def test_commitment_keeps_a_head_on_primary_first_and_no_other():
    from agent.planning.mechanisms import PRIMARY_HOLD_S

    def wps(plan):
        return plan.waypoints_m.tolist()

    # Head-on, TCPA 2.0 s (id 1) and 4.5 s (id 2): 2.5 s apart, within PRIMARY_HOLD_S.
    assert PRIMARY_HOLD_S > 2.5
    head_on = others([[4, 0.3], [9, -0.3]], [[-1, 0], [-1, 0]])
    obs = observe(head_on, v=1.0, goal=(30.0, 0.0))
    rules = _rules(commitment=True)
    plain = _plan(obs, rules)
    assert wps(_plan(obs, rules, primary_id=1)) == wps(plain)
    # Id 2 taken first: another plan (the leg to its via-point then meets id 1).
    assert wps(_plan(obs, rules, primary_id=2)) != wps(plain)
    # Without commitment (the paper's cycle), or a hold shorter than the 2.5 s between
    # them: the ranking stands.
    assert wps(_plan(obs, _rules(), primary_id=2)) == wps(plain)
    assert wps(_plan(obs, _rules(commitment=True, primary_hold_s=2.0), primary_id=2)) == wps(plain)
    # Id 2 crossing from the right (course 90 degrees off reciprocal), TCPA 4.5 s: not held.
    crossing = others([[4, 0.3], [4.5, -4.5]], [[-1, 0], [0, 1]])
    obs = observe(crossing, v=1.0, goal=(30.0, 0.0))
    assert [t.other_id for t in _plan(obs, rules).threats] == [1, 2]
    assert wps(_plan(obs, rules, primary_id=2)) == wps(_plan(obs, rules))


def test_is_head_on():
    from agent.planning.ifp import HEAD_ON_MAX_DEG, is_head_on

    def course(deg):
        return np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))])

    assert is_head_on(0.0, 1.0, course(180.0))
    assert is_head_on(0.0, 1.0, course(180.0 - HEAD_ON_MAX_DEG + 1.0))
    assert not is_head_on(0.0, 1.0, course(180.0 - HEAD_ON_MAX_DEG - 1.0))
    assert not is_head_on(0.0, 1.0, course(0.0))
    assert not is_head_on(0.0, 0.1, course(180.0))  # the robot barely moves
    assert not is_head_on(0.0, 1.0, 0.1 * course(180.0))  # nor does the other


def _alongside_and_head_on():
    """Ego at the origin heading +x at 1.08 m/s; both others' discs give L = 1.6 m.

    Other 1 runs alongside, just ahead, at nearly the robot's speed: TCPA 1.6 s, DCPA 2.1 m
    (a threat only while a commitment keeps it); its tangent points recede
    almost as fast as the robot can close, so its candidates take 24 s and 11 s to meet.
    Other 2 comes head-on: TCPA 4.4 s, DCPA 0.3 m, candidates at about 4.3 s.
    """
    o = others([[2.20, 0.04], [9.5, -0.3]], [[0.97, -0.38], [-1.1, 0.0]], radius=1.1)
    return observe(o, v=1.08, goal=(30.0, 0.0), v_max=1.1)


def test_horizon_via_points_drop_far_candidates_and_resolve_the_next_threat():
    obs = _alongside_and_head_on()
    base = dict(inflated_threats=True, via_margin_m=0.3)
    kept = frozenset({1})
    # Without the cap, other 1 is resolved (after other 2, which its first leg met) by a
    # via-point over 10 m away, down its track.
    plan = _plan(obs, _rules(**base), committed_ids=kept)
    assert [t.other_id for t in plan.threats] == [1, 2]
    assert plan.status is PlanStatus.OK
    assert [i for i, _ in plan.resolved_sides] == [2, 1]
    assert math.hypot(*plan.waypoints_m[2]) > 10.0
    # Capped at T_max = 8 s, other 1 has no candidate and the next threat in rank order
    # that has one gets the first via-point.
    rules = _rules(**base, horizon_via_points=True)
    fallback = _plan(obs, rules, committed_ids=kept)
    assert fallback.status is PlanStatus.OK and fallback.resolved_id == 2
    assert [i for i, _ in fallback.resolved_sides] == [2]
    assert fallback.waypoints_m.shape == (3, 2) and math.hypot(*fallback.via_point_m) < 5.0
    assert [t.other_id for t in fallback.threats] == [1, 2]  # still reported
    # With no threat resolvable within the horizon (T_max 4 s) the cycle gives up.
    short = CFG.with_settings(**{"threats.t_max_s": 4.0})
    none = _plan(obs, rules, short, committed_ids=kept)
    assert none.status is PlanStatus.NO_FEASIBLE
    np.testing.assert_array_equal(none.waypoints_m, [[0, 0], [30, 0]])


def test_mechanisms_follow_the_planner_and_the_profile():
    from agent.core.config import paper_config
    from agent.planning.mechanisms import PAPER_MECHANISMS, Mechanisms, mechanisms

    paper = paper_config()
    for name in ("ifp", "eifp", "eifp-mpc"):
        assert mechanisms(name, paper) == PAPER_MECHANISMS == Mechanisms()
    mpc = mechanisms("eifp-mpc", CFG)
    assert mpc.inflated_threats and mpc.commitment and mpc.horizon_via_points
    assert mpc.lines_arcs and mpc.encounter_rules and mpc.escape_band_m > 0.0
    assert mpc.keep_plan
    eifp = mechanisms("eifp", CFG)
    assert eifp.encounter_rules and not eifp.lines_arcs and not eifp.commitment
    ifp_ = mechanisms("ifp", CFG)
    assert ifp_.direct_leg_check and ifp_.goal_tcpa_filter and not ifp_.encounter_rules


def _setup_a_at_8s():
    """Setup A (two robots crossing at right angles, mirrored), 8.1 s in: the other's TCPA
    is about 8.7 s, past T_max = 8 s, so Eq. (6) declares no threat, but the gap at the
    horizon's end (8 s) is below L = 1.3 m."""
    o = others([(-6.83, -6.79)], vel=[(0.78, 0.78)], radius=0.5)
    return Observation(robot_id=0, ego=EgoState(-6.80, 6.84, -math.pi / 4, 1.1),
                       goal_m=np.array([12.73, -12.73]), radius_m=0.5,
                       limits=RobotLimits(v_max_mps=1.1), others=o)


def test_paper_config_declares_threats_by_eq6_alone():
    """IFP's check of the direct leg declares the other a threat while Eq. (6) does not (its
    TCPA is past T_max); in the paper profile a cycle without an Eq. (6) threat plans
    straight to the goal."""
    from agent.core.config import paper_config
    from agent.planning.eifp import plan_eifp

    obs = _setup_a_at_8s()
    paper = paper_config()
    for plan in (plan_ifp(obs, paper), plan_eifp(obs, paper)):
        assert plan.threats == ()
        assert plan.status == PlanStatus.OK
        assert plan.waypoints_m.shape == (2, 2)  # [P, goal]: no via-point
        assert plan.via_point_m is None
    # with the direct-leg check (the default profile's) the leg declares a threat
    old = _plan(obs, _rules(direct_leg_check=True), paper)
    assert old.threats == () and old.via_point_m is not None


def test_paper_config_still_resolves_an_eq6_threat():
    from agent.core.config import paper_config

    o = others([(5.0, 0.3)], vel=[(-1.0, 0.0)])
    plan = plan_ifp(observe(o, v=1.1), paper_config())
    assert [t.other_id for t in plan.threats] == [1]
    assert plan.via_point_m is not None


def test_goal_tcpa_filter_is_off_in_the_paper_config():
    from agent.core.config import paper_config

    # a threat whose TCPA (about 5.5 s) is past the time to the goal (1.8 s at 1.1 m/s)
    o = others([(6.0, 0.2)], vel=[(0.0, 0.0)])
    obs = observe(o, v=1.1, goal=(2.0, 0.0))
    default = plan_ifp(obs, PlannerConfig())
    assert default.threats and default.via_point_m is None
    assert plan_ifp(obs, paper_config()).via_point_m is not None


# keep_plan: last cycle's via-points are kept while they hold.


def _previous(via, side=Side.LEFT, other_id=1, start=(0.0, 0.0), goal=(10.0, 0.0)):
    return ViaPlan(status=PlanStatus.OK, waypoints_m=np.array([start, via, goal], dtype=float),
                   via_point_m=np.array(via, dtype=float), side=side, resolved_id=other_id,
                   resolved_sides=((other_id, side),))


def test_keep_plan_keeps_last_cycles_via_point_while_it_holds():
    # A static disc on the straight line: by symmetry both tangents are as long, IFP takes
    # RIGHT (y < 0). Last cycle went LEFT; that plan still clears the disc, so it stays.
    obs = observe(others([(5.0, 0.0)]), v=1.0)
    fresh = _plan(obs, _rules())
    assert fresh.side is Side.RIGHT and fresh.via_point_m[1] < 0.0
    prev = _previous((5.0, 0.8))
    kept = _plan(obs, _rules(keep_plan=True), previous=prev)
    assert kept.status is PlanStatus.OK
    np.testing.assert_allclose(kept.waypoints_m, [[0, 0], [5.0, 0.8], [10, 0]])
    assert kept.side is Side.LEFT and kept.resolved_id == 1
    assert kept.resolved_sides == ((1, Side.LEFT),)
    # Without the mechanism the previous plan is ignored.
    assert _plan(obs, _rules(), previous=prev).side is Side.RIGHT


def test_keep_plan_drops_a_plan_whose_leg_is_no_longer_clear():
    # A second disc now sits on the first leg of last cycle's plan.
    obs = observe(others([(5.0, 0.0), (2.5, 0.4)]), v=1.0)
    plan = _plan(obs, _rules(keep_plan=True), previous=_previous((5.0, 0.8)))
    assert not np.allclose(plan.waypoints_m[1], [5.0, 0.8])
    for a, b in zip(plan.waypoints_m, plan.waypoints_m[1:]):
        assert segment_clearance(a, b, (2.5, 0.4)) >= L - 1e-6 or plan.status is not PlanStatus.OK


def test_keep_plan_drops_a_much_longer_plan_and_passed_or_unsensed_via_points():
    obs = observe(others([(5.0, 0.0)]), v=1.0)
    rules = _rules(keep_plan=True)
    # A detour far above the disc: more than KEEP_PLAN_RATIO longer than the new plan.
    fresh = _plan(obs, _rules())
    fresh_m = float(np.hypot(*np.diff(fresh.waypoints_m, axis=0).T).sum())
    detour = (5.0, 6.0)
    assert 2.0 * math.hypot(*detour) > (1.0 + KEEP_PLAN_RATIO) * fresh_m
    assert _plan(obs, rules, previous=_previous(detour)).side is Side.RIGHT
    # The via-point resolves someone no longer sensed.
    assert _plan(obs, rules, previous=_previous((5.0, 0.8), other_id=7)).side is Side.RIGHT
    # The robot is past the via-point along the next leg: it is dropped, nothing is left.
    past = observe(others([(5.0, 0.0)]), x=5.5, y=0.9, v=1.0)
    plan = _plan(past, rules, previous=_previous((5.0, 0.8)))
    assert not any(np.allclose(w, [5.0, 0.8]) for w in plan.waypoints_m)


def test_keep_plan_sees_a_pass_through_while_it_costs_less_than_the_ratio_more():
    # Last cycle passed the disc wide on the LEFT: 10-30 % longer than this cycle's plan
    # (the RIGHT tangent). The pass still clears the disc, so it is seen through.
    obs = observe(others([(5.0, 0.0)]), v=1.0)
    fresh = _plan(obs, _rules())
    fresh_m = float(np.hypot(*np.diff(fresh.waypoints_m, axis=0).T).sum())
    wide = (5.0, 3.0)
    wide_m = 2.0 * math.hypot(*wide)
    assert 1.1 * fresh_m < wide_m <= (1.0 + KEEP_PLAN_RATIO) * fresh_m
    kept = _plan(obs, _rules(keep_plan=True), previous=_previous(wide))
    assert kept.side is Side.LEFT and np.allclose(kept.waypoints_m[1], wide)


def test_keep_plan_keeps_the_remaining_via_points_of_a_longer_plan():
    # Two discs, two via-points last cycle; the robot has passed the first.
    o = others([(3.0, 0.0), (7.0, 0.0)])
    prev = ViaPlan(status=PlanStatus.OK,
                   waypoints_m=np.array([[0, 0], [3.0, 0.8], [7.0, 0.8], [10, 0]], float),
                   via_point_m=np.array([3.0, 0.8]), side=Side.LEFT, resolved_id=1,
                   resolved_sides=((1, Side.LEFT), (2, Side.LEFT)))
    obs = observe(o, x=3.4, y=0.85, v=1.0)
    plan = _plan(obs, _rules(keep_plan=True), previous=prev)
    np.testing.assert_allclose(plan.waypoints_m, [[3.4, 0.85], [7.0, 0.8], [10, 0]])
    assert plan.resolved_id == 2 and plan.resolved_sides == ((2, Side.LEFT),)
