"""Progress monitoring and the strategies of a stuck robot (`agent.planning.liveness`)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.types import Others
from agent.planning.liveness import (
    Liveness,
    LivenessConfig,
    ProgressMonitor,
    Strategy,
    knot,
    lower_id_moving_near,
    squeezed,
)

CFG = LivenessConfig(stuck_after_s=4.0, progress_m=0.5, slow_mps=0.3, yield_s=3.0,
                     yield_radius_m=5.0)


def others(ids: list[int], xy: list[tuple[float, float]], v: list[tuple[float, float]],
           robot: list[bool] | None = None) -> Others:
    n = len(ids)
    return Others(ids=np.array(ids), position_m=np.array(xy, dtype=float).reshape(n, 2),
                  velocity_mps=np.array(v, dtype=float).reshape(n, 2),
                  radius_m=np.full(n, 0.5), linearity=np.ones(n),
                  track_start_m=np.array(xy, dtype=float).reshape(n, 2),
                  is_robot=np.array(robot if robot is not None else [True] * n))


def test_progress_resets_the_clock_and_standing_still_is_stuck_after_the_delay() -> None:
    m = ProgressMonitor(CFG)
    assert not m.stuck(0.0, 10.0)
    assert not m.stuck(3.9, 9.8)  # 0.2 m is not progress yet
    assert m.stuck(4.0, 9.7)
    assert not m.stuck(4.1, 9.4)  # 0.6 m better than the best: progress, clock restarts
    assert not m.stuck(8.0, 9.4)
    assert m.stuck(8.1, 9.4)


def test_helpers_pick_slow_robots_and_moving_lower_ids() -> None:
    o = others([1, 2, -1, 7], [(2, 0), (3, 0), (1, 1), (20, 0)],
               [(0, 0), (1, 0), (0, 0), (0, 0)], [True, True, False, True])
    here = np.zeros(2)
    assert knot(here, o, 10.0, 0.3).tolist() == [0]  # robot 1 only: -1 is no robot, 7 far
    assert lower_id_moving_near(5, here, o, 5.0, 0.3)  # robot 2 moves, id 2 < 5
    assert not lower_id_moving_near(2, here, o, 5.0, 0.3)  # 1 stands; 2 is itself
    assert not lower_id_moving_near(5, here, o, 2.5, 0.3)  # robot 2 is 3 m away


def test_a_stuck_robot_reroutes_then_squeezes_then_yields_to_a_moving_lower_id() -> None:
    live = Liveness(CFG)
    here = np.zeros(2)
    mover = others([1], [(2.0, 0.0)], [(0.5, 0.0)])
    assert live.decide(0.0, 4, here, 10.0, mover) is Strategy.GO
    assert live.decide(4.0, 4, here, 10.0, mover) is Strategy.REROUTE
    assert live.rerouted(4.0, True) is Strategy.GO and live.reroutes == 1
    assert not live.squeezing(4.0)
    # the re-route did not help: another stuck spell, then rule 2 for squeeze_s
    assert live.decide(7.9, 4, here, 10.0, mover) is Strategy.GO
    assert live.decide(8.0, 4, here, 10.0, mover) is Strategy.GO
    assert live.squeezes == 1 and live.squeezing(8.0) and live.squeezing(15.9)
    assert not live.squeezing(16.0)
    # still stuck: rule 3
    assert live.decide(11.9, 4, here, 10.0, mover) is Strategy.GO
    assert live.decide(12.0, 4, here, 10.0, mover) is Strategy.YIELD
    assert live.yields == 1
    assert live.decide(14.9, 4, here, 10.0, mover) is Strategy.YIELD
    assert live.decide(15.0, 4, here, 10.0, mover) is Strategy.GO  # yield_s is over
    # and round again: rule 1
    assert live.decide(19.0, 4, here, 10.0, mover) is Strategy.REROUTE


def test_a_reroute_that_finds_no_route_squeezes_at_once_and_progress_restarts_the_rules() -> None:
    live = Liveness(CFG)
    here = np.zeros(2)
    parked = others([1], [(2.0, 0.0)], [(0.0, 0.0)])
    live.decide(0.0, 4, here, 10.0, parked)
    assert live.decide(4.0, 4, here, 10.0, parked) is Strategy.REROUTE
    assert live.rerouted(4.0, False) is Strategy.GO
    assert live.squeezing(4.0) and live.reroutes == 0 and live.squeezes == 1
    # stuck again: rule 3, but nobody lower moves, so it squeezes again instead
    assert live.decide(8.0, 4, here, 10.0, parked) is Strategy.GO and live.squeezes == 2
    # progress: the rotation starts again at rule 1
    assert live.decide(9.0, 4, here, 9.0, parked) is Strategy.GO
    assert live.decide(13.0, 4, here, 9.0, parked) is Strategy.REROUTE


def test_squeezed_shrinks_only_still_discs_by_the_margin_difference() -> None:
    o = others([1, 2, -1], [(2, 0), (3, 0), (1, 1)], [(0.1, 0), (1, 0), (0, 0)],
               [True, True, False])
    o = o.with_radius(np.array([0.5, 0.5, 0.1]))
    s = squeezed(o, 0.3, 0.1, 0.3)
    # the slow robot and the obstacle lose 0.2 m (the obstacle not below 0); the mover keeps
    assert s.radius_m.tolist() == pytest.approx([0.3, 0.5, 0.0])
    assert s.ids.tolist() == o.ids.tolist() and np.array_equal(s.position_m, o.position_m)
    assert squeezed(o, 0.3, 0.3, 0.3) is o  # no smaller margin: unchanged
    assert squeezed(Others.empty(), 0.3, 0.1, 0.3) is not None
    with pytest.raises(ValueError, match="radius_m"):
        o.with_radius(np.array([0.5, -0.1, 0.1]))


def test_the_lowest_id_never_yields_and_a_yield_ends_when_nobody_moves() -> None:
    live = Liveness(CFG)
    here = np.zeros(2)
    higher = others([9], [(2.0, 0.0)], [(0.5, 0.0)])
    for t in np.arange(0.0, 30.0, 0.1):
        assert live.decide(float(t), 4, here, 10.0, higher) is not Strategy.YIELD
    live = Liveness(CFG)
    mover = others([1], [(2.0, 0.0)], [(0.5, 0.0)])
    for t in (0.0, 4.0, 8.0, 12.0):
        live.decide(t, 4, here, 10.0, mover)
    assert live.decide(12.1, 4, here, 10.0, mover) is Strategy.YIELD
    parked = others([1], [(2.0, 0.0)], [(0.0, 0.0)])
    assert live.decide(8.2, 4, here, 10.0, parked) is Strategy.GO


def test_fallback_yields_only_with_a_moving_lower_id_near() -> None:
    live = Liveness(CFG)
    here = np.zeros(2)
    assert live.fallback(1.0, 3, here, others([1], [(1, 1)], [(0.4, 0)])) is Strategy.YIELD
    live = Liveness(CFG)
    assert live.fallback(1.0, 3, here, others([5], [(1, 1)], [(0.4, 0)])) is Strategy.GO
    assert live.squeezing(1.0) and live.yields == 0  # rule 2 instead


def test_two_robots_that_block_each_other_do_not_both_yield() -> None:
    """The rule that stops mirroring: of two stuck robots, only the higher id stands."""
    a, b = Liveness(CFG), Liveness(CFG)
    pa, pb = np.array([0.0, 0.0]), np.array([1.5, 0.0])
    sa, sb = [], []
    for t in np.arange(0.0, 20.0, 0.1):
        # both shuffle on the spot at the slow speed limit, making no progress
        oa = others([7], [tuple(pb)], [(0.35, 0.0)])
        ob = others([3], [tuple(pa)], [(-0.35, 0.0)])
        sa.append(a.decide(float(t), 3, pa, 10.0, oa))
        sb.append(b.decide(float(t), 7, pb, 10.0, ob))
    assert Strategy.YIELD not in sa
    assert Strategy.YIELD in sb


def test_config_refuses_non_positive_thresholds() -> None:
    with pytest.raises(ValueError, match="yield_s"):
        LivenessConfig(yield_s=0.0)
    with pytest.raises(ValueError, match="stuck_after_s"):
        LivenessConfig(stuck_after_s=float("nan"))
    with pytest.raises(ValueError, match="squeeze_margin_m"):
        LivenessConfig(squeeze_margin_m=-0.1)


def test_stuck_now_marks_the_stuck_cycle_and_the_yield_it_began_only() -> None:
    """What `turning` reads to start a committed turn: set on the cycle the monitor finds
    the robot stuck and through a yield that cycle began (a robot that must escape instead
    of standing may turn then), and clear again once the robot plans as usual."""
    live = Liveness(CFG)
    here = np.zeros(2)
    mover = others([1], [(2.0, 0.0)], [(0.5, 0.0)])
    live.decide(0.0, 4, here, 10.0, mover)
    assert live.decide(4.0, 4, here, 10.0, mover) is Strategy.REROUTE and live.stuck_now
    assert live.decide(4.1, 4, here, 10.0, mover) is Strategy.GO and not live.stuck_now
    live.decide(8.0, 4, here, 10.0, mover)  # rule 2
    assert live.decide(12.0, 4, here, 10.0, mover) is Strategy.YIELD and live.stuck_now
    assert live.decide(12.1, 4, here, 10.0, mover) is Strategy.YIELD and live.stuck_now
    # the lower id has gone: the yield ends and the robot plans as usual
    assert live.decide(12.2, 4, here, 10.0, Others.empty()) is Strategy.GO
    assert not live.stuck_now
    assert live.decide(12.3, 4, here, 10.0, mover) is Strategy.GO and not live.stuck_now
