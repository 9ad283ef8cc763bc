"""`agent.planning.make_way`: where a parked robot steps aside for a robot pressed against
it, and when (the press clocks: who counts as a presser, how long, when it returns)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.types import Others
from agent.planning.make_way import (
    ASIDE_MARGIN_M,
    HOLD_MAX_S,
    LINGER_GAP_M,
    LINGER_GONE_M,
    LINGER_S,
    PASSED_M,
    PRESENT_DRIFT_M,
    PRESENT_PATH_M,
    PRESS_GAP_M,
    PRESS_S,
    WALL_GAP_M,
    MakeWay,
    aside_point,
    closes_passage,
)
from agent.planning.routing import StaticMap

R = 0.5
D_SAFETY = 0.3
WANT = R + R + D_SAFETY + ASIDE_MARGIN_M  # the full step across
GOAL = np.zeros(2)


def robots(*rows: tuple[int, float, float]) -> Others:
    """Others: robots of radius R at (id, x, y), standing."""
    a = np.array(rows, dtype=float).reshape(-1, 3)
    n = len(a)
    return Others(ids=a[:, 0].astype(int), position_m=a[:, 1:3], velocity_mps=np.zeros((n, 2)),
                  radius_m=np.full(n, R), linearity=np.ones(n), track_start_m=a[:, 1:3],
                  is_robot=np.ones(n, dtype=bool))


def walls(*centres: tuple[float, float], radius: float = 0.5) -> StaticMap:
    c = np.array(centres, dtype=float).reshape(-1, 2)
    return StaticMap(center_m=c, radius_m=np.full(len(c), radius),
                     ids=-np.arange(1, len(c) + 1))


def test_in_the_open_the_robot_steps_to_the_pressers_left_by_its_whole_inflated_disc():
    # The presser stands 0.2 m off on the -x side, facing the goal along +x: its left is +y.
    point = aside_point(GOAL, R, np.array([-1.2, 0.0]), R, robots((7, -1.2, 0.0)), 0, D_SAFETY)
    assert point is not None
    np.testing.assert_allclose(point, [0.0, WANT], atol=1e-9)


def test_a_wall_on_one_side_sends_it_to_the_other():
    static = walls((0.0, 1.5))  # 0.5 m above the robot's edge: no room on the left
    point = aside_point(GOAL, R, np.array([-1.2, 0.0]), R, robots((7, -1.2, 0.0)), 0,
                        D_SAFETY, static)
    np.testing.assert_allclose(point, [0.0, -WANT], atol=1e-9)


def test_in_a_corridor_it_goes_as_far_as_the_wall_allows_and_no_farther():
    # Corridor walls (discs of 0.5 m) centred at y = +-1.9: 2.8 m clear.
    static = walls(*[(x, s * 1.9) for x in np.arange(-3.0, 3.1, 0.8) for s in (1, -1)])
    point = aside_point(GOAL, R, np.array([-1.2, 0.0]), R, robots((7, -1.2, 0.0)), 0,
                        D_SAFETY, static)
    assert point is not None and abs(point[0]) < 1e-9
    gap = np.min(np.hypot(*(static.center_m - point).T) - static.radius_m - R)
    assert WALL_GAP_M - 1e-9 <= gap < WALL_GAP_M + 0.05 + 1e-9  # to the wall, step 0.05 m
    assert point[1] > 0.0  # equal room both sides: the presser's left


def test_a_third_robot_in_the_way_is_not_pressed_on_and_no_room_means_no_step():
    # 0.6 m gaps either side and ahead: every step would press on a neighbour.
    others = robots((7, -1.2, 0.0), (8, 0.0, 1.6), (9, 0.0, -1.6), (10, 1.6, 0.0))
    assert aside_point(GOAL, R, np.array([-1.2, 0.0]), R, others, 0, D_SAFETY) is None


def test_packed_across_it_steps_on_along_the_line_away_from_the_presser():
    """Goals 1.5 m apart (0.5 m gaps): no room across, but nobody ahead. The robot steps
    on by the presser's whole inflated disc, away from it, and so opens its spot (a step
    away from a neighbour closer than `ROOM_GAP_M` is room; one towards it is not)."""
    others = robots((7, -1.2, 0.0), (8, 0.0, 1.5), (9, 0.0, -1.5))
    point = aside_point(GOAL, R, np.array([-1.2, 0.0]), R, others, 0, D_SAFETY)
    assert point is not None
    np.testing.assert_allclose(point, [WANT, 0.0], atol=1e-9)
    # A neighbour parked 0.5 m off on one side does not keep it from stepping away from
    # it, across, on the other side.
    one_side = robots((7, -1.2, 0.0), (8, 0.0, 1.5))
    point = aside_point(GOAL, R, np.array([-1.2, 0.0]), R, one_side, 0, D_SAFETY)
    np.testing.assert_allclose(point, [0.0, -WANT], atol=1e-9)


def press(way: MakeWay, t: float, others: Others, at_goal: bool = True,
          here: tuple[float, float] = (0.0, 0.0)) -> np.ndarray | None:
    return way.refuge(t, GOAL, R, np.array(here), at_goal, others, D_SAFETY)


def test_a_robot_that_comes_up_and_stays_sends_the_parked_robot_aside_until_it_has_gone_by():
    way = MakeWay()
    assert press(way, 0.0, robots((7, -6.0, 0.0))) is None  # arrives: nobody close
    close = robots((7, -1.2, 0.0))
    for k in range(int(PRESS_S / 0.1)):  # pressed, but not yet for PRESS_S
        assert press(way, 1.0 + 0.1 * k, close) is None
    refuge = press(way, 1.0 + PRESS_S, close)
    assert refuge is not None and way.steps == 1
    # It stands aside (not at its goal) while the presser goes past it ...
    for x in (-1.2, 0.0, 1.0):
        np.testing.assert_allclose(press(way, 5.0, robots((7, x, 0.0)), at_goal=False,
                                         here=tuple(refuge)), refuge)
    # ... and returns once the presser is PASSED_M beyond L from the goal.
    assert press(way, 6.0, robots((7, 2.0, 0.0)), at_goal=False) is None


def test_neighbours_already_there_on_arrival_never_press():
    way = MakeWay()
    neighbour = robots((3, 1.2, 0.0))  # parked 0.2 m off before this robot arrived
    for k in range(200):
        assert press(way, 0.1 * k, neighbour) is None
    assert way.steps == 0


def test_a_presser_that_never_goes_by_sends_the_robot_aside_once():
    way = MakeWay()
    press(way, 0.0, robots((7, -6.0, 0.0)))
    stays = robots((7, -1.2, 0.0))  # comes up, then parks there for good
    t, asides = 0.0, 0
    while t < 5 * HOLD_MAX_S:
        refuge = press(way, t, stays, at_goal=way._aside is None)
        asides += refuge is not None
        t += 0.1
    assert way.steps == 1
    assert asides == pytest.approx(HOLD_MAX_S / 0.1, abs=2)


def test_pressers_that_came_up_while_it_stood_aside_count_when_it_is_back():
    way = MakeWay()
    press(way, 0.0, robots((7, -6.0, 0.0), (8, -8.0, 0.0)))
    first = robots((7, -1.2, 0.0), (8, -3.5, 0.0))
    t = 0.0
    while press(way, t, first) is None:
        t += 0.1
    assert way.steps == 1
    # 7 goes by; 8 came up behind it but stands back (2.3 m from the goal, 1.7 m from the
    # refuge): going back presses on nobody, so the robot returns.
    refuge = press(way, t, first, at_goal=False)
    assert press(way, t + 2.0, robots((7, 3.0, 0.0), (8, -2.3, 0.0)), at_goal=False,
                 here=tuple(refuge)) is None
    assert way.handovers == 0
    t += 3.0
    second = robots((7, 6.0, 0.0), (8, -1.2, 0.0))  # then 8 presses on it at its goal
    while press(way, t, second) is None and t < 30.0:
        t += 0.1
    assert way.steps == 2


def test_a_queue_is_let_through_without_going_back_in_between():
    """When its presser has gone by and the next robot already stands where going back
    would press on it (within L of the goal), the robot stays aside for that one too."""
    way = MakeWay()
    press(way, 0.0, robots((7, -6.0, 0.0), (8, -8.0, 0.0)))
    first = robots((7, -1.2, 0.0), (8, -3.5, 0.0))
    t = 0.0
    while (refuge := press(way, t, first)) is None:
        t += 0.1
    here = tuple(refuge)
    # 7 goes by; 8 is 1.0 m from the goal (L = 1.3 m): the robot stays where it is.
    queue = robots((7, 3.0, 0.0), (8, -1.0, 0.0))
    np.testing.assert_allclose(press(way, t + 2.0, queue, at_goal=False, here=here), refuge)
    assert way.handovers == 1 and way.steps == 1
    # 8 goes by too, and nobody is left: back to the goal.
    gone = robots((7, 6.0, 0.0), (8, 3.0, 0.0))
    assert press(way, t + 4.0, gone, at_goal=False, here=here) is None
    # Each robot gets one turn per spell aside: 8 coming back does not hold it again.
    assert way.handovers == 1


def test_a_robot_kept_off_its_goal_by_a_crowd_still_makes_way():
    """Back from a step aside but 0.3 m short of its goal (outside the arrival tolerance,
    a robot standing on the way back), the robot is home: a robot pressed against it
    there sends it aside as at the goal."""
    way = MakeWay()
    press(way, 0.0, robots((7, -6.0, 0.0)))  # parked once
    short = (0.3, 0.0)
    crowd = robots((7, -0.9, 0.8))  # 0.29 m gap to the robot where it stands
    t = 0.0
    while press(way, t, crowd, at_goal=False, here=short) is None and t < 10.0:
        t += 0.1
    assert way.steps == 1 and t == pytest.approx(PRESS_S, abs=0.11)
    # Farther than its radius from the goal it is not home: no clock runs.
    away = MakeWay()
    press(away, 0.0, robots((7, -6.0, 0.0)))
    for k in range(100):
        assert press(away, 0.1 * k, robots((7, -0.3, 0.9)), at_goal=False,
                     here=(0.6, 0.0)) is None


def test_a_robot_there_on_arrival_that_shuffles_against_it_becomes_a_presser():
    """Stuck against the robot when it parked (`cross_corridors` 12, seed 112): present on
    arrival, but it moves about within the press gap, as no parked neighbour does."""
    way = MakeWay()
    assert press(way, 0.0, robots((7, -1.3, 0.0))) is None  # there on arrival, 0.3 m off
    t = 0.1
    for k in range(50):  # it stays in the gap, shuffling less than PRESENT_DRIFT_M
        assert press(way, t, robots((7, -1.3, 0.2 * np.sin(k)))) is None
        t += 0.1
    assert way.steps == 0
    drifted, refuge = t, None
    while refuge is None and t < 10.0:  # now 0.6 m from where it stood on arrival
        refuge = press(way, t, robots((7, -1.2, 0.6)))
        t += 0.1
    assert refuge is not None and way.steps == 1
    assert t - 0.1 == pytest.approx(drifted + PRESS_S, abs=0.11)  # pressed since it drifted


def corridor(clear_m: float, radius: float = 0.6) -> StaticMap:
    """Two walls of touching discs along x (from -12 to 12 m), `clear_m` apart edge to
    edge (the `dead_end` corridors: discs of 0.6 m, 2.6-3.2 m clear)."""
    y = clear_m / 2 + radius
    xs = np.arange(-12.0, 12.01, 2 * radius * 0.95)
    return walls(*[(x, s * y) for x in xs for s in (1, -1)], radius=radius)


def test_a_parked_robot_closes_a_corridor_too_narrow_to_pass_it_but_not_the_open():
    lingerer = np.array([-2.0, 0.0])
    assert closes_passage(GOAL, R, lingerer, R, corridor(2.86))  # dead_end 6, seed 102
    assert closes_passage(GOAL, R, lingerer, R, corridor(2.6))
    assert not closes_passage(GOAL, R, lingerer, R, corridor(4.4))  # room beside it
    assert not closes_passage(GOAL, R, lingerer, R, None)  # no map: in the open
    assert not closes_passage(GOAL, R, lingerer, R, walls((0.0, 1.5)))  # one wall only
    # Across the corridor (a robot coming from the wall's side) the way is open along it.
    assert not closes_passage(GOAL, R, np.array([0.0, -1.2]), R, corridor(2.86))


def linger(way: MakeWay, t0: float, t1: float, at: tuple[float, float], static: StaticMap,
           shuffle_m: float = 0.25) -> tuple[float, np.ndarray | None]:
    """Robot 7 shuffles along x about `at` (amplitude `shuffle_m`, period about 3 s) from
    t0 until the parked robot steps aside, or t1."""
    t, refuge = t0, None
    while refuge is None and t < t1 + 1e-9:
        x = at[0] + shuffle_m * math.sin(2.0 * (t - t0))
        refuge = way.refuge(t, GOAL, R, GOAL, True, robots((7, x, at[1])), D_SAFETY, static)
        t += 0.1
    return t - 0.1, refuge


def test_in_a_corridor_a_robot_that_lingers_outside_the_press_gap_sends_it_aside():
    """`dead_end` 6, tuning seed 102: the blocked robot loops 0.4-1.7 m off, within the
    press gap at most a second at a time; within `LINGER_GAP_M` for `LINGER_S` in a
    corridor the parked robot closes, it steps aside (to the wall: room for one robot)."""
    static = corridor(2.86)
    way = MakeWay()
    assert way.refuge(0.0, GOAL, R, GOAL, True, robots((7, -8.0, 0.0)), D_SAFETY,
                      static) is None  # arrives: nobody near
    gap = 0.9  # outside the press gap, inside the linger gap, shuffling 0.25 m either way
    assert gap - 0.25 > PRESS_GAP_M and gap + 0.25 < LINGER_GAP_M
    t, refuge = linger(way, 1.0, 20.0, (-(2 * R + gap), 0.0), static)
    assert refuge is not None and way.steps == 1
    assert t == pytest.approx(1.0 + LINGER_S, abs=0.11)
    assert abs(refuge[1]) > 0.5 and abs(refuge[0]) < 1e-9  # across, towards a wall


def test_in_the_open_lingering_is_not_pressing():
    """A robot 0.8 m off in the open has room to go round: only a press sends the robot
    aside there (goals 1.5 m apart in a block keep neighbours 0.5 m off all the time)."""
    way = MakeWay()
    way.refuge(0.0, GOAL, R, GOAL, True, robots((7, -8.0, 0.0)), D_SAFETY, None)
    _, refuge = linger(way, 1.0, 30.0, (-2.0, 0.0), walls((0.0, 1.5)))
    assert refuge is None and way.steps == 0


def test_a_neighbour_within_the_linger_gap_on_arrival_does_not_linger():
    static = corridor(2.86)
    way = MakeWay()
    _, refuge = linger(way, 0.0, 30.0, (-1.9, 0.0), static)  # there when it arrived
    assert refuge is None and way.steps == 0


def test_a_neighbour_that_parks_in_the_linger_gap_after_it_does_not_linger():
    """`dead_end`: goals 2.4 m apart along the corridor, a 1.4 m gap. A neighbour that
    drives up after the robot parked and parks at its own goal stands still: not a
    lingerer, though it stays within `LINGER_GAP_M` for good."""
    static = corridor(2.86)
    way = MakeWay()
    way.refuge(0.0, GOAL, R, GOAL, True, robots((7, -9.0, 0.0)), D_SAFETY, static)
    t, parked_at = 0.1, -2.4
    assert parked_at + 2 * R + LINGER_GAP_M > 0.0  # its spot is within the linger gap
    for k in range(400):  # drives in at 1 m/s from -6 m, then stands at -2.4 m
        x = min(-6.0 + 0.1 * k, parked_at)
        assert way.refuge(t, GOAL, R, GOAL, True, robots((7, x, 0.0)), D_SAFETY,
                          static) is None
        t += 0.1
    assert way.steps == 0


def test_a_lingerer_that_loops_out_and_back_has_not_gone_by():
    """The first version counted the lingerer as gone once it was `PASSED_M` beyond L from
    the goal: the looping robot was, 1.7 s later, and the parked robot went back in front
    of it. Now only the far side of the goal, or `LINGER_GONE_M` beyond L, counts."""
    static = corridor(2.86)
    way = MakeWay()
    way.refuge(0.0, GOAL, R, GOAL, True, robots((7, -8.0, 0.0)), D_SAFETY, static)
    t, refuge = linger(way, 1.0, 20.0, (-2.0, 0.0), static)
    assert refuge is not None
    big_l = 2 * R + D_SAFETY
    here = tuple(refuge)
    # Loops out 0.2 m short of LINGER_GONE_M beyond L, behind: not gone, it stays aside.
    out = (-(big_l + LINGER_GONE_M - 0.2), 0.0)
    assert big_l + PASSED_M < -out[0]
    np.testing.assert_allclose(way.refuge(t + 1.0, GOAL, R, np.array(here), False,
                                          robots((7, *out)), D_SAFETY, static), refuge)
    # Goes past the goal on the far side: gone, the robot returns.
    past = (big_l + PASSED_M + 0.05, 0.0)
    assert way.refuge(t + 3.0, GOAL, R, np.array(here), False, robots((7, *past)),
                      D_SAFETY, static) is None


def wedged(way: MakeWay, static: StaticMap | None, t1: float) -> tuple[float, np.ndarray | None]:
    """Robot 7, 0.2 m off when the robot arrived, shuffles 0.1 m back and forth along the
    corridor (a robot turning on the spot between two parked ones) until t1."""
    t, refuge, k = 0.0, None, 0
    while refuge is None and t < t1 + 1e-9:
        x = -1.2 - 0.1 * ((k // 5) % 2)  # 0.1 m every half second
        refuge = way.refuge(t, GOAL, R, GOAL, True, robots((7, x, 0.0)), D_SAFETY, static)
        t, k = t + 0.1, k + 1
    return t - 0.1, refuge


def test_in_a_corridor_a_robot_wedged_against_it_on_arrival_becomes_a_presser():
    """`cross_corridors` 12, tuning seed 111: a robot wedged between two parked robots
    turns on the spot and shuffles 0.1-0.2 m about one place for 70 s; it never drifts
    `PRESENT_DRIFT_M`, but it travels, where a parked neighbour stays put."""
    assert PRESENT_DRIFT_M > 0.1
    t, refuge = wedged(MakeWay(), corridor(2.86), 60.0)
    assert refuge is not None
    # 0.1 m every 0.5 s: PRESENT_PATH_M after 5 s, then a press of PRESS_S.
    assert t == pytest.approx(PRESENT_PATH_M / 0.2 + PRESS_S, abs=0.6)


def test_in_the_open_a_robot_shuffling_against_it_on_arrival_stays_a_neighbour():
    """Without a passage it closes (goals packed in a block), only the drift rule frees
    a robot present on arrival: neighbours stepping about the block are not pressers."""
    _, refuge = wedged(MakeWay(), None, 60.0)
    assert refuge is None
