"""Tests of `eifp_wire.clock`: a command's seq follows the sim time of its poses and is bounded
by the world's, and a pose's stamp is checked against its tick and the robot's clock."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from eifp_wire.clock import (
    MAX_CMD_AHEAD_S,
    MAX_POSE_AHEAD_S,
    SEQ_PER_S,
    check_pose_time,
    check_seq,
    max_seq,
    next_seq,
)
from tests.examples import examples

# --- sequence numbers -----------------------------------------------------------------------


def test_a_robots_seq_follows_the_time_of_its_poses() -> None:
    assert next_seq(-1, 0.0) == 0
    assert next_seq(-1, 1.5) == 1500  # a robot's first plan, or a restarted robot's
    assert next_seq(1500, 1.5) == 1501  # a second plan on the same pose
    assert next_seq(1530, 1.5) == 1531
    assert next_seq(1501, 1.6) == 1600


def test_a_seq_is_bounded_by_the_worlds_time_not_by_its_step() -> None:
    assert max_seq(0.0) == MAX_CMD_AHEAD_S * SEQ_PER_S
    assert check_seq(max_seq(2.0), None, world_t_s=2.0) is None
    assert check_seq(max_seq(2.0) + 1, None, world_t_s=2.0) == "seq_jump"
    assert check_seq(max_seq(2.0) + 1, max_seq(2.0), world_t_s=2.0) == "seq_jump"
    assert check_seq(2**63 - 1, None, world_t_s=1e6) == "seq_jump"
    assert check_seq(11, 10, world_t_s=0.0) is None
    assert check_seq(10, 10, world_t_s=0.0) == "stale"
    assert check_seq(3, 10, world_t_s=0.0) == "stale"


def test_the_64_step_walk_is_stopped_and_the_robot_passes_it_a_second_later() -> None:
    """A forger with robot 1's key sends 300 commands stepping seq by 64 in 1.5 s. Were every
    step accepted, the genuine robot's seq would never catch up; the world accepts only what
    its time allows, and the genuine robot's next seq, taken from the time of its poses, is
    above every forged one within MAX_CMD_AHEAD_S of the walk's end."""
    t0_s, last, accepted = 14.5, 145, []
    for k in range(300):
        t_s = t0_s + 1.5 * k / 300
        seq = 145 + 64 * (k + 1)
        if check_seq(seq, last, world_t_s=t_s) is None:
            accepted.append(seq)
            last = seq
    assert len(accepted) < 300 and last <= max_seq(t0_s + 1.5)
    genuine = next_seq(145, t0_s + 1.5 + MAX_CMD_AHEAD_S + 0.02)  # its next pose
    assert check_seq(genuine, last, world_t_s=t0_s + 1.5 + MAX_CMD_AHEAD_S + 0.02) is None


@settings(max_examples=examples(200), deadline=None)
@given(steps=st.lists(st.tuples(st.floats(0.0, 0.5), st.integers(1, 2**40)), max_size=60),
       t0_s=st.floats(0.0, 600.0))
def test_no_forged_walk_outruns_the_genuine_robot_by_more_than_the_bound(
        steps: list[tuple[float, int]], t0_s: float) -> None:
    """Whatever a forger sends (any step at any time), what the world accepted is passed by
    the genuine robot's seq on the first pose `MAX_CMD_AHEAD_S` after the forger stopped."""
    t_s, last = t0_s, next_seq(-1, t0_s)
    for dt_s, step in steps:
        t_s += dt_s
        if check_seq(last + step, last, world_t_s=t_s) is None:
            last += step
    later_s = t_s + MAX_CMD_AHEAD_S + 0.02
    assert check_seq(next_seq(next_seq(-1, t0_s), later_s), last, world_t_s=later_s) is None


# --- pose time --------------------------------------------------------------------------------


def pose_check(tick: int, t_s: float, clock_s: float | None, **kw) -> str | None:
    return check_pose_time(tick, t_s, world_rate_hz=50.0, time_limit_s=60.0, clock_s=clock_s,
                           **kw)


def test_a_genuine_pose_passes() -> None:
    assert pose_check(0, 0.0, None) is None
    assert pose_check(500, 10.0, 9.98) is None
    assert pose_check(500, 10.0, 10.5) is None  # older than the clock: the controller decides


def test_a_pose_whose_time_is_not_its_tick_is_refused() -> None:
    assert pose_check(500, 10.5, 10.0) == "tick_time"
    assert pose_check(2**40, 10.0, 10.0) == "tick_time"


def test_a_pose_beyond_the_time_limit_is_refused_even_before_the_clock_is_set() -> None:
    assert pose_check(50_000_000, 1.0e6, None) == "beyond_limit"
    assert pose_check(3050, 61.0, None) is None
    assert pose_check(3100, 62.0, None) == "beyond_limit"


def test_a_pose_far_ahead_of_the_clock_is_refused() -> None:
    assert pose_check(1500, 30.0, 10.0) == "ahead"
    assert pose_check(int((10.0 + MAX_POSE_AHEAD_S) * 50), 10.0 + MAX_POSE_AHEAD_S,
                      10.0) is None
    # A faster run gets a proportionally wider bound (wall jitter x time scale).
    assert pose_check(1000, 20.0, 16.0, time_scale=5.0) is None
    assert pose_check(1000, 20.0, 14.0, time_scale=5.0) == "ahead"
