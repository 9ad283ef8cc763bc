"""Narrow passages: centring, tracking the centre line, and one way at a time
(`agent.planning.passages`, and its use by `agent.planning.guidance`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from agent.core.config import PlannerConfig, profile_config
from agent.core.types import Others
from agent.planning import passages as P
from agent.planning.guidance import RouteGuide
from agent.planning.liveness import LivenessConfig, Strategy
from agent.planning.mechanisms import EIFP_MPC_MECHANISMS, mechanisms
from agent.planning.planners import make_planner
from agent.planning.routing import (
    ROUTE_MARGIN_M,
    StaticMap,
    route_or_tight,
    segment_disc_distance,
)
from tests.unit.agent.planning.test_guidance import as_others, closed_loop, observation

RADIUS, D_SAFETY = 0.5, 0.3
FULL = RADIUS + D_SAFETY + ROUTE_MARGIN_M


def walled_corridor(half_clear_m: float = 0.65) -> StaticMap:
    """A wall across x in [-4, 4] pierced by a corridor along y = 0, `2 half_clear_m`
    clear between its disc walls (0.6 m discs), closed to y = +-8 (the way round is long:
    the route is tight)."""
    y_wall = half_clear_m + 0.6
    pts = [(x, s * y_wall) for x in np.linspace(-4.0, 4.0, 8) for s in (-1.0, 1.0)]
    pts += [(x, s * y) for x in (-4.0, 4.0) for s in (-1.0, 1.0)
            for y in np.arange(y_wall + 1.2, 8.0, 1.2)]
    centers = np.array(pts)
    return StaticMap(centers, np.full(len(pts), 0.6), -(np.arange(len(pts)) + 1))


def corridor_passage(start: tuple[float, float] = (-9.0, 0.4)
                     ) -> tuple[StaticMap, P.Passage, np.ndarray]:
    static = walled_corridor()
    route = route_or_tight(np.array(start), np.array([9.0, 0.0]), static, RADIUS, D_SAFETY)
    assert route is not None and route.tight
    centred, found = P.centre_route(route, static, RADIUS, D_SAFETY, FULL)
    assert len(found) == 1
    return static, found[0], centred.waypoints_m


def test_a_tight_route_is_centred_in_its_gap_with_a_lead_in_on_the_centre_line() -> None:
    static, passage, wps = corridor_passage()
    inside = passage.line_m[passage.mouth_index:]
    assert np.abs(inside[:, 1]).max() <= P.THIN_TOLERANCE_M + 1e-9  # on the axis (y = 0)
    assert inside[0, 0] < -4.0 < 4.0 < inside[-1, 0]  # mouth to far mouth
    assert passage.mouth_index == 1  # a lead-in, LEAD_IN_M before the mouth, on the axis
    assert math.isclose(inside[0, 0] - passage.line_m[0, 0], P.LEAD_IN_M, abs_tol=0.05)
    assert abs(passage.line_m[0, 1]) <= P.THIN_TOLERANCE_M
    assert math.isclose(passage.width_m, 1.3, abs_tol=0.02)
    assert passage.one_lane  # 1.3 m: one 1 m robot at a time
    # the margin it leaves: half the width, less the radius and the tracking tube
    assert math.isclose(passage.margin_m, 0.65 - RADIUS - P.TRACKING_TUBE_M, abs_tol=0.02)
    # the discs that bound it are the corridor's walls, not the far ends of the wall
    bound = static.center_m[passage.disc_index]
    assert (np.abs(bound[:, 1]) < 2.0).all() and len(bound) >= 16
    # the centred route still keeps its clearance, and starts and ends where it did
    assert np.allclose(wps[0], (-9.0, 0.4)) and np.allclose(wps[-1], (9.0, 0.0))
    d = segment_disc_distance(wps[:-1], wps[1:], static.center_m) - static.radius_m
    assert d.min() >= RADIUS - 1e-6


def test_a_route_with_full_clearance_is_left_alone() -> None:
    """A corridor 3 m clear, without lanes (the default profile); and 4 m clear, with
    lanes too (wider than `two_lane_width_m`: robots pass in it at will)."""
    for half, lanes in ((1.5, False), (2.0, False), (2.0, True)):
        static = walled_corridor(half_clear_m=half)
        route = route_or_tight(np.array([-9.0, 0.4]), np.array([9.0, 0.0]), static, RADIUS,
                               D_SAFETY)
        assert route is not None and not route.tight
        centred, found = P.centre_route(route, static, RADIUS, D_SAFETY, FULL, lanes=lanes)
        assert centred is route and found == ()


def test_on_track_aims_along_the_line_and_joins_it_short_of_the_mouth() -> None:
    _, passage, _ = corridor_passage()
    lead, mouth, far = passage.line_m[0], passage.mouth_m, passage.far_mouth_m
    assert P.on_track(passage, lead + (-0.5, 0.0)) is None  # before the lead-in
    assert P.on_track(passage, far + (0.5, 0.0)) is None  # past the far mouth
    assert P.on_track(passage, np.array([0.0, 1.5])) is None  # too far off the line
    # just past the lead-in, well off the line: the aim stops ALIGN_M short of the mouth
    aim = P.on_track(passage, lead + (0.3, 0.6))
    assert aim is not None
    carrot, rest = aim
    assert math.isclose(carrot[0], mouth[0] - P.ALIGN_M, abs_tol=0.01)
    assert abs(carrot[1]) <= P.THIN_TOLERANCE_M and np.allclose(rest[-1], far)
    # inside: TRACK_LOOKAHEAD_M ahead on the line
    carrot, _ = P.on_track(passage, np.array([0.0, 0.08])) or (None, None)
    assert carrot is not None and math.isclose(carrot[0], P.TRACK_LOOKAHEAD_M, abs_tol=0.05)


def robots(*rows: tuple[int, tuple[float, float], tuple[float, float]]) -> Others:
    ids = np.array([r[0] for r in rows])
    pos = np.array([r[1] for r in rows], dtype=float)
    vel = np.array([r[2] for r in rows], dtype=float)
    n = len(rows)
    return Others(ids=ids, position_m=pos, velocity_mps=vel, radius_m=np.full(n, 0.5),
                  linearity=np.zeros(n), track_start_m=pos, is_robot=np.ones(n, dtype=bool))


def test_one_way_at_a_time_inside_first_then_nearer_mouth_then_lower_id() -> None:
    _, passage, _ = corridor_passage()
    mouth, far = passage.mouth_m, passage.far_mouth_m
    me = mouth + (-2.0, 0.0)  # at my hold line

    def hold(others: Others, robot_id: int = 5, now_s: float = 0.0,
             state: P.HoldState | None = None) -> bool:
        return P.must_hold(passage, robot_id, me, others, now_s, state or P.HoldState())

    # in it and coming at me: wait; in it going my way: follow
    assert hold(robots((9, (0.0, 0.0), (-1.0, 0.0))))
    assert not hold(robots((9, (0.0, 0.0), (1.0, 0.0))))
    # waiting at the far mouth: nearer its mouth goes first, whatever its id
    assert hold(robots((9, tuple(far + (1.0, 0.0)), (0.0, 0.0))))
    assert not hold(robots((1, tuple(far + (3.5, 0.0)), (-1.0, 0.0))))
    # a tie goes to the lower id
    assert hold(robots((1, tuple(far + (2.0, 0.0)), (0.0, 0.0))))
    assert not hold(robots((9, tuple(far + (2.0, 0.0)), (0.0, 0.0))))
    # past its hold line (within HOLD_M) goes before one that is not: a tie by distance
    # that the lower id would otherwise win
    assert not P._ahead_of(2.7, 1, 2.4, 5) and P._ahead_of(2.4, 5, 2.7, 1)
    assert P._ahead_of(2.7, 1, 2.9, 5)  # neither past it: the tie goes to the lower id
    # one moving away from its mouth (it came out) is no reason to wait
    assert not hold(robots((1, tuple(far + (1.0, 0.0)), (1.0, 0.0))))
    # far from either mouth: nobody to wait for
    assert not hold(robots((1, tuple(far + (6.0, 0.0)), (-1.0, 0.0))))


def test_a_wait_for_robots_that_stand_still_ends() -> None:
    _, passage, _ = corridor_passage()
    me = passage.mouth_m + (-2.0, 0.0)
    still = robots((9, (0.0, 0.0), (0.0, 0.0)))  # stands in the passage (stuck, parked)
    state = P.HoldState()
    assert P.must_hold(passage, 5, me, still, 10.0, state)
    assert P.must_hold(passage, 5, me, still, 10.0 + P.HOLD_STILL_S - 0.1, state)
    assert not P.must_hold(passage, 5, me, still, 10.0 + P.HOLD_STILL_S, state)
    moving = robots((9, (0.0, 0.0), (-1.0, 0.0)))  # it moves: the wait starts afresh
    assert P.must_hold(passage, 5, me, moving, 30.0, state)
    wide = dataclasses.replace(passage, one_lane=False)
    assert not P.must_hold(wide, 5, me, moving, 30.0, P.HoldState())


def test_the_wait_for_a_still_robot_is_not_restarted_by_the_order_flickering() -> None:
    # Found on `rooms` 10 (structured tuning seed 100): a robot parked 1.5 m past the far
    # mouth is ahead in the order from the hold line but not from nearer the mouth; the
    # waiting robot walking between its spot and the lead-in restarted the wait each time.
    _, passage, _ = corridor_passage()
    far_out = robots((9, tuple(passage.far_mouth_m + (1.5, 0.0)), (0.0, 0.0)))
    back, near = passage.mouth_m + (-2.4, 0.0), passage.mouth_m + (-1.0, 0.0)
    state = P.HoldState()
    assert P.must_hold(passage, 5, back, far_out, 10.0, state)
    assert not P.must_hold(passage, 5, near, far_out, 12.0, state)  # not ahead from here
    assert P.must_hold(passage, 5, back, far_out, 14.0, state)
    assert not P.must_hold(passage, 5, back, far_out, 10.0 + P.HOLD_STILL_S, state)
    # once it moves, its stillness counts afresh
    coming = robots((9, tuple(passage.far_mouth_m + (1.5, 0.0)), (-0.5, 0.0)))
    assert P.must_hold(passage, 5, back, coming, 20.0, state)
    assert P.must_hold(passage, 5, back, far_out, 21.0, state)
    assert P.must_hold(passage, 5, back, far_out, 21.0 + P.HOLD_STILL_S - 0.1, state)
    assert not P.must_hold(passage, 5, back, far_out, 21.0 + P.HOLD_STILL_S, state)


distance = st.floats(0.0, 4.0, allow_nan=False)


@given(distance, distance, st.integers(0, 50), st.integers(0, 50))
def test_right_of_way_is_a_strict_order(a_m: float, b_m: float, a_id: int, b_id: int
                                        ) -> None:
    """Of two robots at opposite mouths (distinct ids) exactly one goes first, so they
    never both wait nor both go (module docstring, "Why the one-way rule cannot
    deadlock")."""
    if a_id == b_id:
        b_id += 1
    assert P._ahead_of(a_m, a_id, b_m, b_id) != P._ahead_of(b_m, b_id, a_m, a_id)


def test_a_lone_robot_crosses_a_corridor_it_fits_with_0_15_m_either_side() -> None:
    """Found on the probe `rooms_lane_2` (docs/results.md): without the passage rules a
    lone robot stood at the mouth of a corridor 1.3 m clear (its diameter 1 m) until the
    time limit: the tight route hugs one wall, and eIFP's discs inflated by d_safety close
    the gap."""
    static = walled_corridor()
    goal = (9.0, 0.0)

    def drive(mech: object) -> tuple[np.ndarray, float]:
        planner = make_planner("eifp-mpc", PlannerConfig(), static_map=static,
                               mechanisms=mech)  # type: ignore[arg-type]
        return closed_loop(planner, as_others(static), (-9.0, 0.4, 0.0), goal, 40.0)

    path, gap = drive(EIFP_MPC_MECHANISMS)
    assert math.dist(path[-1], goal) < 0.25
    assert gap >= 0.05  # the margin it keeps, by design
    path, _ = drive(dataclasses.replace(EIFP_MPC_MECHANISMS, passages=False))
    assert (path[:, 0] < -3.0).all()  # never into the corridor


def test_the_guide_holds_before_a_one_lane_passage_and_waiting_is_not_being_stuck() -> None:
    static = walled_corridor()
    guide = RouteGuide(static, D_SAFETY, liveness=LivenessConfig(), passages=True)
    walls = as_others(static)
    coming = robots((1, (0.0, 0.0), (-1.0, 0.0)))  # in the corridor, coming this way
    start = (-9.0, 0.0)
    guide.guide(observation(*start, 0.0, 0.0, (9.0, 0.0), walls, robot_id=5), 0.0)
    passage = guide._passages[0]
    here = passage.mouth_m + (-2.0, 0.0)
    for k in range(100):  # 10 s at the hold line: it holds, and never goes stuck
        g = guide.guide(observation(*here, 0.0, 0.0, (9.0, 0.0), walls, robot_id=5),
                        k * 0.1, coming)
        assert g.hold and not g.stuck
    g = guide.guide(observation(*here, 0.0, 0.0, (9.0, 0.0), walls, robot_id=5), 10.0,
                    walls)  # the corridor is clear
    assert not g.hold and g.passage_ids and math.isclose(g.passage_margin_m,
                                                         passage.margin_m)


def test_a_robot_that_gives_way_waits_off_the_line_on_its_own_side() -> None:
    """Waiting on the line out of the mouth, robots stood in the way of those coming
    out; the waiting spot is turned off it, to the side the robot is on, clear of the
    walls."""
    static, passage, _ = corridor_passage()
    mouth = passage.mouth_m  # the west mouth; the line leaves it towards -x
    above = P.waiting_spot(passage, mouth + (-2.0, 0.5), static, RADIUS)
    below = P.waiting_spot(passage, mouth + (-2.0, -0.5), static, RADIUS)
    for spot in (above, below):
        assert math.isclose(math.dist(spot, mouth), P.SPOT_M, abs_tol=1e-9)
        gap = np.hypot(*(static.center_m - spot).T) - static.radius_m
        assert gap.min() >= RADIUS + P.SPOT_CLEAR_M
        assert spot[0] < mouth[0]  # on the robot's side of the mouth
    assert above[1] > mouth[1] + 1.0 and below[1] < mouth[1] - 1.0  # off the line
    # the guide sends a robot that gives way to the spot, then stands it there
    guide = RouteGuide(static, D_SAFETY, liveness=LivenessConfig(), passages=True)
    walls = as_others(static)
    coming = robots((1, (0.0, 0.0), (-1.0, 0.0)))
    guide.guide(observation(-9.0, 0.4, 0.0, 0.0, (9.0, 0.0), walls, robot_id=5), 0.0)
    here = passage.mouth_m + (-2.0, 0.3)
    g = guide.guide(observation(*here, 0.0, 0.0, (9.0, 0.0), walls, robot_id=5), 1.0, coming)
    assert g.hold and g.strategy is Strategy.GO
    assert math.dist(g.goal_m, P.waiting_spot(passage, here, static, RADIUS)) < 1e-9
    spot = g.goal_m
    g = guide.guide(observation(*spot, 0.0, 0.0, (9.0, 0.0), walls, robot_id=5), 1.1, coming)
    assert g.hold and g.strategy is Strategy.YIELD


def test_a_door_two_robots_cannot_pass_in_is_one_lane_on_a_full_route() -> None:
    """A door 2.2 m clear admits the full route clearance (1.8 m), so the route is not
    tight; but two 1 m robots with d_safety between them do not pass each other in it
    (`one_lane_width_m`: 2.5 m), and 16 robots crossing it both ways jammed it
    (`wide_door_crowd`, docs/results.md). The stretch is a one-lane passage with the
    usual margin; a door 3 m clear is not."""
    static = walled_corridor(half_clear_m=1.1)
    route = route_or_tight(np.array([-9.0, 0.6]), np.array([9.0, 0.0]), static, RADIUS,
                           D_SAFETY)
    assert route is not None and not route.tight
    centred, found = P.centre_route(route, static, RADIUS, D_SAFETY, FULL)
    assert len(found) == 1 and not centred.tight
    passage = found[0]
    assert passage.one_lane and math.isclose(passage.width_m, 2.2, abs_tol=0.02)
    assert math.isclose(passage.margin_m, D_SAFETY)  # the gap leaves the usual margin
    inside = passage.line_m[passage.mouth_index:]
    assert np.abs(inside[:, 1]).max() <= P.THIN_TOLERANCE_M + 1e-9  # centred
    assert math.isclose(P.one_lane_width_m(RADIUS, D_SAFETY), 2.5)


def lanes(start: tuple[float, float], goal: tuple[float, float], half_clear_m: float = 1.5
          ) -> tuple[StaticMap, tuple[P.Passage, ...]]:
    static = walled_corridor(half_clear_m=half_clear_m)
    route = route_or_tight(np.array(start), np.array(goal), static, RADIUS, D_SAFETY)
    assert route is not None and not route.tight
    _, found = P.centre_route(route, static, RADIUS, D_SAFETY, FULL, lanes=True)
    return static, found


def test_a_corridor_two_robots_barely_pass_in_is_driven_in_lanes_each_on_its_right() -> None:
    """A corridor 3 m clear is wider than one lane (2.5 m) but narrower than two robots
    on routes along opposite walls (`two_lane_width_m`, 3.3 m). Routes round inner
    corners put robots going both ways on the same side of such a corridor, and 9 of 12
    robots stood at a door of a maze of them (`maze_counterflow`, docs/results.md). Each
    robot's route runs in the lane on its right: going +x at y = -0.75, going -x at
    y = +0.75, 1.5 m apart (more than the inflated radius L = 1.3 m), 0.25 m from the
    walls; it is not one-lane, and the walls get the margin the lane leaves."""
    assert math.isclose(P.two_lane_width_m(RADIUS, D_SAFETY, FULL), 3.3)
    _, east = lanes((-9.0, 0.4), (9.0, 0.0))
    _, west = lanes((9.0, -0.4), (-9.0, 0.0))
    for found, y_lane in ((east, -0.75), (west, 0.75)):
        assert len(found) == 1
        lane = found[0]
        assert lane.lane and not lane.one_lane and math.isclose(lane.width_m, 3.0, abs_tol=0.02)
        line = lane.line_m[np.argsort(lane.line_m[:, 0])]
        assert line[0, 0] < -3.5 and line[-1, 0] > 3.5  # through it
        inside = np.interp(np.linspace(-3.5, 3.5, 15), line[:, 0], line[:, 1])
        assert np.abs(inside - y_lane).max() <= P.THIN_TOLERANCE_M + 1e-9
        assert math.isclose(lane.margin_m, 1.5 - 0.75 - RADIUS - P.TRACKING_TUBE_M, abs_tol=1e-3)
    apart = 2 * 0.75
    assert apart >= 2 * RADIUS + D_SAFETY + 2 * P.LANE_SLACK_M
    assert 1.5 - 0.75 - RADIUS >= P.TRACKING_TUBE_M


def test_lanes_narrow_with_the_corridor_but_keep_the_robots_apart_and_off_the_walls() -> None:
    """From one lane's width to two: the lanes' offset from the middle never brings two
    robots in opposite lanes within L (+ slack) of each other, unless the corridor
    cannot hold that and the robot's radius plus the tracking tube from the wall."""
    one = P.one_lane_width_m(RADIUS, D_SAFETY)
    for width in np.linspace(one, P.two_lane_width_m(RADIUS, D_SAFETY, FULL), 9):
        offset = float(P._lane_offset_m(np.array(width), RADIUS, D_SAFETY))
        wall = width / 2.0 - offset - RADIUS
        assert wall >= P.TRACKING_TUBE_M - 1e-9
        assert 2 * offset >= 2 * RADIUS + D_SAFETY - 1e-9  # never within L
        assert P.MIN_MARGIN_M <= P._lane_margin(width, RADIUS, D_SAFETY) <= D_SAFETY


def test_a_lane_is_drawn_only_between_walls_that_face_each_other_across_the_route() -> None:
    """Where the nearest discs either side are both behind the point (just out of a door)
    or the route crosses the gap at a slant, "the middle" is not a place to drive: a lane
    drawn from them ran a metre off the route, beside the door, and a robot stood there
    aiming back at its end (`maze_counterflow`)."""
    xs = [x for x in np.arange(-12.0, 12.5, 1.0) if abs(x) > 1.6]
    static = StaticMap(np.array([(x, 0.0) for x in xs]), np.full(len(xs), 0.5))  # door 3 m
    tree = P.cKDTree(static.center_m)
    north, slant = np.array([0.0, 1.0]), np.array([math.sin(0.7), math.cos(0.7)])
    east = np.array([1.0, 0.0])
    pts = np.array([(0.3, 0.0), (0.3, 1.2), (0.3, 0.0), (0.3, 0.0)])
    dirs = np.stack((north, north, slant, east))
    across = P._walls_across(pts, dirs, static, tree)
    assert across.tolist() == [True, False, False, False]


def test_a_robot_that_cuts_the_corner_at_a_lanes_end_has_left_it() -> None:
    """A lane does not hold a robot in: one that left it short of the far mouth, towards
    the route's next waypoint, no longer aims back at the far mouth; one still on the
    line does."""
    static = walled_corridor(half_clear_m=1.5)
    guide = RouteGuide(static, D_SAFETY, liveness=LivenessConfig(), passages=True, lanes=True)
    walls = as_others(static)
    goal = (6.5, -7.0)  # out of the corridor's east end, then round its wall to the south
    guide.guide(observation(-9.0, 0.4, 0.0, 0.0, goal, walls), 0.0)
    assert len(guide._passages) == 1 and guide._passages[0].lane
    lane, end = guide._passages[0], guide._passage_ends[0]
    assert guide._follower is not None
    after = guide._follower.route.waypoints_m[end + 1]
    far = lane.far_mouth_m
    back = lane.line_m[-2] - far
    back /= np.hypot(*back)
    on_line = far + 0.6 * back
    g = guide.guide(observation(*on_line, 0.0, 0.5, goal, walls), 0.1)
    assert guide._left == 0 and math.dist(g.goal_m, far) < 1e-6
    beside = far + 0.6 * back + 0.7 * (after - far) / math.dist(after, far)
    assert math.dist(beside, after) < math.dist(far, after)
    g = guide.guide(observation(*beside, 0.0, 0.5, goal, walls), 0.2)
    assert guide._left == 1 and math.dist(g.goal_m, far) > 0.5


def test_lanes_are_the_lanes_profile_s_alone() -> None:
    """Lanes are an experiment (docs/results.md, "Lanes in corridors: an opt-in
    profile"): eIFP-MPC drives in them in the ``lanes`` profile only, with every default
    mechanism as well; the default profile and the other planners never do."""
    lanes = mechanisms("eifp-mpc", profile_config("lanes"))
    assert lanes.lanes and dataclasses.replace(lanes, lanes=False) == EIFP_MPC_MECHANISMS
    assert not mechanisms("eifp-mpc", PlannerConfig()).lanes
    assert not mechanisms("eifp", profile_config("lanes")).lanes
    planner = make_planner("eifp-mpc", profile_config("lanes"), static_map=walled_corridor())
    assert planner.guide.lanes_on  # type: ignore[attr-defined]


def test_a_corridor_keeps_its_lanes_through_notches_and_the_doors_next_to_it() -> None:
    """A wall of discs is scalloped, so the lane test comes and goes along a corridor:
    notches up to `FILL_SAMPLES` are filled; a short stretch (a door) within that of a
    corridor at least `LANE_MIN_M` long joins it, one farther off (a gap between two
    pillars) does not."""
    mask = np.zeros(120, dtype=bool)
    mask[10:20] = mask[23:50] = True  # a corridor with a 3-sample notch
    mask[60:65] = True  # a door 10 samples past its end
    mask[100:105] = True  # a gap between pillars, far off
    gap = P.FILL_SAMPLES
    closed = P._closed(mask, gap)
    assert closed[10:50].all() and closed[50:60].any()  # notch and door gap filled
    assert not P._closed(mask, 2)[20:23].any()  # a notch wider than the fill stays
    long_m = math.ceil(P.LANE_MIN_M / P.SAMPLE_STEP_M)
    kept = P._corridors(closed, long_m, gap)
    assert kept[10:65].all() and not kept[:10].any()
    assert not kept[65:].any()  # the far gap is dropped
    assert not P._corridors(mask, long_m, gap).any()  # unfilled: no run long enough
    assert not P._corridors(closed, 100, gap).any()  # no corridor long enough: no lanes
