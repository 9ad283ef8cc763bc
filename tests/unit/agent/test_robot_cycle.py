"""A robot's per-cycle decisions (`agent.robot_cycle`), driven with payloads and times."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.config import PlannerConfig
from agent.core.scenario import RobotSpec
from agent.core.types import PlanResult, PlanStatus, PoseSnapshot
from agent.planning.controller import RobotController
from agent.robot_cycle import (
    COMPUTE_DECAY,
    REJOIN_GRACE_S,
    STALE_PLAN_S,
    SUSPEND_GAP_S,
    WORLD_BLIP_GRACE_S,
    RobotCounters,
    RobotCycle,
    WorldWatch,
    is_world,
    worth_logging,
)
from eifp_wire import CommandMsg, ControlMsg, PosesMsg, RunConfigMsg, RunKeys
from eifp_wire.pose_cells import cell_payloads
from world.sim.cells import Cell, CellRule
from world.sim.link import FaultyLink, LinkFaults, link_rng
from world.sim.schedule import PlanSchedule

SPEC = RobotSpec(0, (0.0, 0.0, 0.0), (10.0, 0.0))
CONFIG = RunConfigMsg(run_id="r-1", robot=SPEC, planner=PlannerConfig(), goal_tolerance_m=0.25,
                      control_rate_hz=10.0, world_rate_hz=50.0, time_scale=1.0,
                      time_limit_s=60.0, cmd_timeout_s=0.5, known_ids=(0, 1))


KEYS = RunKeys("r-1")
RULE = CellRule.of_config(PlannerConfig())
START_CELLS = RULE.needed(0.0, 0.0)
"""The cells robot 0 holds from its start at the origin (3 x 3 around cell (0, 0))."""


def _pose(tick: int, t_s: float, poses: dict[int, tuple[float, float, float]] | None = None,
          cells: frozenset[Cell] = START_CELLS) -> list[tuple[str, bytes]]:
    """One tick's pose samples as the world sends them: one per cell of `cells` (robots 0 at
    the origin and 1 at (5, 0) unless `poses` says), on slot 0."""
    poses = poses or {0: (0.0, 0.0, 0.0), 1: (5.0, 0.0, 3.1)}
    ids = sorted(poses)
    msg = PosesMsg(t_s=t_s, tick=tick, robot_ids=ids, robot_pose=[poses[i] for i in ids],
                   robot_radius_m=[0.5] * len(ids), obstacle_ids=[],
                   obstacle_xy_m=np.zeros((0, 2)), obstacle_radius_m=[])
    return [(KEYS.poses_cell(0, cell), payload)
            for cell, payload in cell_payloads(msg, cells, RULE.size_m)]


GARBAGE = (KEYS.poses_cell(0, (0, 0)), b"\x93garbage")


def _cycle(world_zid: str | None = None, **kwargs: object) -> RobotCycle:
    controller = RobotController(SPEC, PlannerConfig(), 0.25)
    return RobotCycle(CONFIG, controller, PlanSchedule(0.1), world_zid=world_zid,
                      **kwargs)


# --- sensing -----------------------------------------------------------------------------------

def test_a_pose_sets_the_clock_from_when_it_was_taken_off_the_queue() -> None:
    cycle = _cycle()
    assert not cycle.clock.started
    assert cycle.sense(_pose(10, 0.2), arrived_wall_s=100.0, wall_s=100.03) is True
    assert cycle.clock.tick == 10 and cycle.last_rx_wall_s == 100.0
    assert cycle.clock.now_s(100.03) == pytest.approx(0.23)  # the pose is 30 ms old
    assert cycle.newest is not None and cycle.newest.tick == 10
    assert cycle.newest_rx_ns == 100_000_000_000


def test_a_malformed_pose_is_rejected_and_counted_and_the_next_one_observed() -> None:
    cycle = _cycle()
    assert cycle.sense([GARBAGE], 1.0, 1.0) is False
    assert cycle.counts.rejected == 1
    # Oldest first: a valid tick, then a newer message that is malformed.
    assert cycle.sense([*_pose(10, 0.2), (GARBAGE[0], b"\x81\xa6schema\x04")], 1.0,
                       1.0) is True
    assert cycle.counts.rejected == 2 and cycle.newest is not None and cycle.newest.tick == 10
    notices = cycle.take_notices()
    assert [n.split(":")[1] for n in notices] == [" rejected pose message #1",
                                                  " rejected pose message #2"]
    assert cycle.take_notices() == []


def test_only_the_newest_valid_tick_is_observed_the_older_are_skipped() -> None:
    cycle = _cycle()
    assert cycle.sense(_pose(10, 0.2) + _pose(11, 0.22), 1.0, 1.0) is True
    assert cycle.newest is not None and cycle.newest.tick == 11
    assert cycle.counts.skipped == 1 and cycle.counts.stale == 0


def test_an_older_tick_after_a_newer_one_is_late() -> None:
    cycle = _cycle()
    cycle.sense(_pose(10, 0.2), 1.0, 1.0)
    assert cycle.sense(_pose(9, 0.18), 1.01, 1.01) is False
    assert cycle.assembler.counts.late == len(START_CELLS)
    assert cycle.newest is not None and cycle.newest.tick == 10


def test_a_tick_is_released_once_every_cell_of_it_is_in() -> None:
    cycle = _cycle()
    samples = _pose(10, 0.2)
    assert len(samples) == 9 and cycle.cells.cells == START_CELLS
    assert cycle.sense(samples[:4], 1.0, 1.0) is False  # five cells still to come
    assert cycle.nap_s(1.0, 0.25) == pytest.approx(0.01)  # half a tick: then go without
    assert cycle.sense(samples[4:], 1.001, 1.001) is True
    view = cycle.newest
    assert view is not None and (view.tick, view.parts, view.held, view.missing) == (10, 9, 0, 0)
    assert view.snapshot.ids.tolist() == [0, 1] and view.rx_wall_s == 1.001
    assert cycle.nap_s(1.001, 0.25) == 0.25


def test_a_lost_cell_is_filled_from_its_last_message_moved_on() -> None:
    """Robot 1 in cell (1, 0) moves 0.5 m per 0.1 s; tick 20's message of its cell is lost:
    after half a tick the view goes out with robot 1 dead reckoned to where it will be."""
    cycle = _cycle()
    at = {10: 20.0, 15: 20.5, 20: 21.0}
    for tick in (10, 15):
        assert cycle.sense(_pose(tick, tick * 0.02, {0: (0, 0, 0), 1: (at[tick], 0, 0)}),
                           tick * 0.02, tick * 0.02)
    lost = KEYS.poses_cell(0, (1, 0))
    tick20 = [s for s in _pose(20, 0.4, {0: (0, 0, 0), 1: (at[20], 0, 0)}) if s[0] != lost]
    assert cycle.sense(tick20, 0.4, 0.4) is False
    assert cycle.sense([], 0.4, 0.4 + 0.011) is True
    view = cycle.newest
    assert view is not None and (view.tick, view.parts, view.held) == (20, 8, 1)
    assert view.snapshot.ids.tolist() == [0, 1]
    assert view.snapshot.pose[1, :2].tolist() == pytest.approx([21.0, 0.0])
    assert view.rx_wall_s == pytest.approx(0.41)
    assert cycle.summary_fields()["cells_held"] == 1


def test_a_newer_tick_releases_the_one_still_waiting_for_a_cell() -> None:
    cycle = _cycle()
    assert cycle.sense(_pose(10, 0.2)[:8], 1.0, 1.0) is False
    assert cycle.sense(_pose(15, 0.3), 1.001, 1.001) is True  # 10 forced out, 15 complete
    assert cycle.newest is not None and cycle.newest.tick == 15
    assert cycle.counts.skipped == 1 and cycle.assembler.counts.partial == 1


def test_the_cells_follow_the_robot_subscribing_before_dropping() -> None:
    """Robot 0 drives from the origin along x: cell (2, 0) (x from 30 m) is added once within
    18.75 m, at 11.25 m; the cells of column -1 (x below -10 m) are dropped once wholly
    beyond 20 m (the corner cells from 7.3 m, (-1, 0) from 10 m)."""
    cycle = _cycle()
    assert cycle.sense(_pose(10, 0.2), 1.0, 1.0) and cycle.take_cell_changes() == []
    x = 2.0
    tick, added, dropped = 10, set(), set()
    while x < 12.0:
        tick += 5
        held = cycle.cells.cells
        assert held is not None
        assert cycle.sense(_pose(tick, tick * 0.02, {0: (x, 0, 0), 1: (x + 5, 0, 0)}, held),
                           tick * 0.02, tick * 0.02)
        for change in cycle.take_cell_changes():
            added |= change.added
            dropped |= change.dropped
            assert not change.added & change.dropped
        x += 0.5
    assert added == {(2, 0)}
    assert dropped == {(-1, -1), (-1, 0), (-1, 1)}
    assert cycle.cells.cells == RULE.needed(11.5, 0.0)


def test_a_robot_that_does_not_see_itself_searches_every_cell() -> None:
    """A robot restarted away from its start: its start cells do not show it, so it looks
    in every cell, and takes its own cells again once it sees itself."""
    cycle = _cycle()
    away = {0: (100.0, 0.0, 0.0), 1: (5.0, 0.0, 3.1)}
    assert cycle.sense(_pose(10, 0.2, away), 1.0, 1.0) is False
    (change,) = cycle.take_cell_changes()
    assert change.search and change.dropped == START_CELLS and cycle.cells.cells is None
    everywhere = RULE.needed(100.0, 0.0) | START_CELLS
    assert cycle.sense(_pose(15, 0.3, away, everywhere), 1.1, 1.1) is False  # waits it out
    assert cycle.sense([], 1.1, 1.1 + 0.011) is True
    (change,) = cycle.take_cell_changes()
    assert change.found and change.added == RULE.needed(100.0, 0.0)
    assert cycle.cells.cells == RULE.needed(100.0, 0.0)


def test_the_clock_moves_only_on_a_pose_that_passed_every_check() -> None:
    cycle = _cycle("aa")
    assert cycle.sense(_pose(10, 0.2), 1000.0, 1000.0) is True
    assert (cycle.clock.tick, cycle.clock.stamp_s) == (10, 0.2)
    # Far future, and ahead of the clock (tick and time consistent): refused, clock kept.
    for tick, t_s in ((50_000_000, 1.0e6), (1000, 20.0), (11, 5.0)):
        assert cycle.sense(_pose(tick, t_s)[:1], 1000.01, 1000.01) is False
        assert (cycle.clock.tick, cycle.clock.stamp_s) == (10, 0.2)
    assert cycle.counts.refused_poses == 3
    # The next genuine pose is observed as usual.
    assert cycle.sense(_pose(15, 0.3), 1000.1, 1000.1) is True and cycle.clock.tick == 15


def test_the_pose_link_delays_poses_in_sim_time_and_the_nap_waits_for_it() -> None:
    link = FaultyLink(LinkFaults(latency_ms=50.0), link_rng(0, 0, 0))
    cycle = _cycle(link=link)
    assert cycle.sense(_pose(10, 0.2), 100.0, 100.0) is False  # in flight
    assert cycle.clock.tick == 10  # the clock runs from the pose as it came from the world
    assert cycle.nap_s(100.0, 0.25) == pytest.approx(0.05)
    assert cycle.nap_s(100.04, 0.25) == pytest.approx(0.01)
    assert cycle.sense([], 100.0, 100.049) is False
    assert cycle.sense([], 100.0, 100.05) is True  # released, observed
    assert cycle.nap_s(100.05, 0.25) == 0.25  # nothing in flight


def test_a_dropping_link_counts_what_it_lost() -> None:
    link = FaultyLink(LinkFaults(drop=1.0), link_rng(0, 0, 0))
    cycle = _cycle(link=link)
    for k in range(3):
        assert cycle.sense(_pose(10 + k, 0.2 + 0.02 * k), 1.0, 1.0) is False
    assert cycle.counts.link_dropped == 3 and cycle.newest is None


# --- the world's messages and presence ---------------------------------------------------------

def test_control_is_obeyed_only_from_the_worlds_session() -> None:
    cycle = _cycle("aa")
    end = ControlMsg("end", 1.0, "all_arrived").encode()
    assert cycle.control(end, None) is None
    assert cycle.control(end, "bb") is None
    assert cycle.counts.refused_control == 2
    assert cycle.control(b"\x00", "aa") is None and cycle.counts.rejected == 1
    assert cycle.control(ControlMsg("start", 0.0).encode(), "aa") is None
    assert cycle.control(end, "aa") == "end (all_arrived)"


def test_without_the_worlds_id_every_source_is_taken_as_the_world() -> None:
    assert is_world(None, None) and is_world("bb", None)
    assert is_world("aa", "aa") and not is_world("bb", "aa") and not is_world(None, "aa")


def test_a_world_token_that_blinks_back_within_the_grace_keeps_the_robot() -> None:
    watch = WorldWatch()
    assert watch.appeared(99.0) is None and watch.alive and watch.seen
    assert watch.vanished(100.0) == WORLD_BLIP_GRACE_S and not watch.alive
    assert watch.lost(100.0 + 0.8 * WORLD_BLIP_GRACE_S) is None
    assert watch.appeared(100.0 + 0.9 * WORLD_BLIP_GRACE_S) == pytest.approx(
        0.9 * WORLD_BLIP_GRACE_S)
    assert watch.alive and watch.gone_wall_s is None
    assert watch.lost(110.0) is None  # long after: nothing pending


def test_a_world_token_gone_for_longer_than_the_grace_ends_the_robot() -> None:
    watch = WorldWatch()
    watch.appeared(99.0)
    watch.vanished(100.0)
    assert watch.vanished(100.1) is None  # gone already: the first disappearance counts
    assert watch.lost(100.0 + 1.01 * WORLD_BLIP_GRACE_S) == "world lost (liveliness token gone)"


def test_after_its_own_suspension_a_robot_waits_the_longer_rejoin_grace() -> None:
    cycle = _cycle()
    cycle.world.appeared(90.0)
    assert cycle.loop_stalled(0.9 * SUSPEND_GAP_S, 99.0) is False  # a nap, not a suspension
    assert cycle.counts.suspended == 0
    assert cycle.loop_stalled(SUSPEND_GAP_S + 0.1, 99.5) is True
    assert cycle.counts.suspended == 1 and cycle.world.resumed_wall_s == 99.5
    assert cycle.world.vanished(100.0) == REJOIN_GRACE_S
    assert cycle.world.lost(100.0 + 2.0 * WORLD_BLIP_GRACE_S) is None  # still waiting
    reason = cycle.world.lost(100.0 + 1.01 * REJOIN_GRACE_S)
    assert reason is not None and "not back within" in reason


def test_after_a_suspension_the_next_pose_sets_the_clock_even_far_ahead_of_it() -> None:
    # SIGSTOPped at sim 0.2 s for longer than the loop measured: the world is at 6.0 s, the
    # clock run on from the old pose says 3.2 s. Refused as ahead, no pose could ever set
    # the clock again (tests/system/test_faults.py, seen once in CI).
    stuck = _cycle()
    stuck.sense(_pose(10, 0.2), 1000.0, 1000.0)
    assert stuck.sense(_pose(300, 6.0), 1003.0, 1003.0) is False  # no suspension noticed
    cycle = _cycle()
    cycle.sense(_pose(10, 0.2), 1000.0, 1000.0)
    assert cycle.loop_stalled(3.0, 1003.0) is True
    assert not cycle.clock.started
    assert cycle.sense(_pose(300, 6.0), 1003.0, 1003.0) is True
    assert cycle.clock.tick == 300 and cycle.clock.now_s(1003.1) == pytest.approx(6.1)
    assert cycle.counts.refused_poses == 0


def test_the_pose_timeout_runs_from_the_last_pose_or_a_resumption() -> None:
    cycle = _cycle()
    assert not cycle.pose_timed_out(1e6, 5.0)  # no pose yet: the start-up deadline rules
    cycle.sense(_pose(10, 0.2), 10.0, 10.0)
    assert not cycle.pose_timed_out(14.9, 5.0)
    assert cycle.pose_timed_out(15.1, 5.0)
    cycle.loop_stalled(SUSPEND_GAP_S + 1.0, 15.0)  # back from a suspension at 15 s
    assert not cycle.pose_timed_out(19.9, 5.0) and cycle.pose_timed_out(20.1, 5.0)


# --- planning ----------------------------------------------------------------------------------

class _Controller:
    """Observes everything, plans (1, 0.5) recording the time it plans for, brakes to (0, 0)."""

    command_hold_s = 0.15

    def __init__(self, fail: bool = False) -> None:
        self.planned_for: list[float] = []
        self.fail = fail

    def observe(self, snapshot: PoseSnapshot) -> bool:
        return True

    def plan(self, now_s: float) -> PlanResult:
        if self.fail:
            raise RuntimeError("planner bug")
        self.planned_for.append(now_s)
        return PlanResult(v_mps=1.0, omega_radps=0.5, status=PlanStatus.OK,
                          waypoints_m=np.zeros((2, 2)))

    def brake(self) -> PlanResult:
        return PlanResult(v_mps=0.0, omega_radps=0.0, status=PlanStatus.STALE,
                          waypoints_m=np.zeros((2, 2)))


def _planning(controller: _Controller | None = None, **kwargs: object
              ) -> tuple[RobotCycle, _Controller]:
    """A cycle with a fake controller that has observed a pose stamped 9.98 s."""
    fake = controller or _Controller()
    cycle = RobotCycle(CONFIG, fake, PlanSchedule(0.1), **kwargs)
    assert cycle.sense(_pose(499, 9.98), 0.0, 0.0)
    return cycle, fake


def _send(cycle: RobotCycle, now_s: float, took_s: float) -> CommandMsg:
    """Plan at `now_s`; the plan takes `took_s`; the command as the world decodes it."""
    command = cycle.command(cycle.plan(now_s), took_s)
    return CommandMsg.decode(command.encode(1, 2, 3, 4))


@pytest.mark.parametrize(("took_s", "late"), [(0.002, False), (0.14, False), (0.16, True),
                                              (0.4, True)])
def test_a_plan_later_than_the_hold_is_sent_as_a_brake(took_s: float, late: bool) -> None:
    """With no slow plan before it, a plan that took longer than the command hold is sent as a
    stop, and counted."""
    cycle, _ = _planning()
    assert cycle.due()
    msg = _send(cycle, 10.0, took_s)
    assert (msg.v_mps, msg.omega_radps) == ((0.0, 0.0) if late else (1.0, 0.5))
    assert msg.status == ("stale" if late else "ok")
    assert cycle.counts.late_plans == int(late) and cycle.counts.plans == 1


def test_the_robot_plans_for_when_its_command_will_leave() -> None:
    """After a slow plan, the next is planned that much ahead and is not late for taking as
    long; the expectation decays by COMPUTE_DECAY per plan."""
    cycle, fake = _planning()
    now_s, times, statuses = 10.0, [], []
    for took_s in (0.2, 0.3, 0.01, 0.01):  # each plan lets that much sim time pass
        times.append(now_s)
        statuses.append(_send(cycle, now_s, took_s).status)
        now_s += took_s
    assert fake.planned_for[0] == pytest.approx(times[0])  # nothing expected yet
    assert fake.planned_for[1] == pytest.approx(times[1] + 0.2)
    assert fake.planned_for[2] == pytest.approx(times[2] + 0.3)
    assert fake.planned_for[3] == pytest.approx(times[3] + 0.3 * COMPUTE_DECAY)
    # 0.2 > 0 + 0.15: late; 0.3 <= 0.2 + 0.15: allowed for; the quick ones are on time.
    assert statuses == ["stale", "ok", "ok", "ok"]
    assert cycle.counts.late_plans == 1


def test_a_plan_stretched_by_a_stop_does_not_make_the_robot_plan_seconds_ahead() -> None:
    """A plan that took 3 s (the process stopped mid-plan) is late; what the robot expects
    of its next plans is capped at STALE_PLAN_S."""
    cycle, fake = _planning()
    assert _send(cycle, 10.0, 3.0).status == "stale"
    assert cycle.compute_s == STALE_PLAN_S
    assert cycle.sense(_pose(650, 13.0), 3.02, 3.02)  # a fresh pose after the stop
    _send(cycle, 13.02, 0.01)
    assert fake.planned_for[1] == pytest.approx(13.02 + STALE_PLAN_S)


def test_a_pose_too_old_to_plan_on_gives_a_brake() -> None:
    cycle, fake = _planning()
    msg = _send(cycle, 9.98 + STALE_PLAN_S + 0.01, 0.001)
    assert msg.status == "stale" and cycle.counts.stale_plans == 1 and not fake.planned_for


def test_a_planner_that_raises_gives_a_brake_and_is_counted() -> None:
    cycle, _ = _planning(_Controller(fail=True))
    planned = cycle.plan(10.0)
    assert isinstance(planned.error, RuntimeError)
    assert planned.result.status is PlanStatus.STALE and cycle.counts.plan_errors == 1
    assert cycle.command(planned, 0.001).result.v_mps == 0.0


def test_without_planning_every_command_is_a_brake() -> None:
    cycle, fake = _planning(plan=False)
    assert _send(cycle, 10.0, 0.001).status == "stale"
    assert not fake.planned_for and cycle.counts.stale_plans == 0


def test_the_command_carries_the_pose_it_was_planned_on_and_its_wall_stamps() -> None:
    cycle, _ = _planning()
    command = cycle.command(cycle.plan(10.0), 0.001)
    msg = CommandMsg.decode(command.encode(11, 12, 13, 14))
    assert (msg.robot_id, msg.pose_stamp_s, msg.hold_s) == (0, 9.98, 0.15)
    assert msg.seq == command.seq == cycle.seq >= 0
    assert msg.wall.clock_id == 11 and msg.wall.plan_start_ns == 12
    assert msg.wall.plan_end_ns == 13 and msg.wall.pub_ns == 14
    assert msg.wall.pose_rx_ns == cycle.newest_rx_ns == 0
    assert command.debug is None  # the fake planner reports no internals


def test_slots_already_passed_are_skipped_and_counted_as_overruns() -> None:
    cycle, _ = _planning()
    cycle.command(cycle.plan(10.0), 0.001)
    assert not cycle.due()  # the next slot is 10.08
    cycle.sense(_pose(517, 10.34), 0.36, 0.36)  # slots 10.08 .. 10.28 passed
    assert cycle.due()
    cycle.command(cycle.plan(10.35), 0.001)
    assert cycle.counts.overruns == 2 and cycle.counts.plans == 2


# --- counting ----------------------------------------------------------------------------------

def test_the_exit_line_lists_the_counters_in_their_order_then_the_seq() -> None:
    cycle = _cycle(refused_config=2)
    assert list(cycle.summary_fields()) == [
        "rejected", "stale", "skipped", "plans", "overruns", "plan_errors", "stale_plans",
        "late_plans", "link_dropped", "suspended", "token_timeouts", "refused_poses",
        "refused_control", "refused_config", "unheld_poses", "cells_views", "cells_partial",
        "cells_held", "cells_missing", "cells_late", "cell_changes", "seq"]
    assert cycle.summary_fields()["refused_config"] == 2
    assert cycle.summary_fields()["seq"] == -1
    assert RobotCounters().as_dict() == dict.fromkeys(RobotCounters().as_dict(), 0)


def test_refusals_are_logged_the_first_ten_then_every_hundredth() -> None:
    assert [n for n in range(1, 1001) if worth_logging(n)] == [
        *range(1, 11), 100, 200, 300, 400, 500, 600, 700, 800, 900, 1000]
    cycle = _cycle("aa")
    for _ in range(150):
        cycle.refuse_pose("from bb")
    assert cycle.counts.refused_poses == 150 and len(cycle.take_notices()) == 11


def test_pose_keys_are_parsed_once_and_the_memory_of_them_is_bounded() -> None:
    from agent.robot_cycle import MAX_KEYS_REMEMBERED

    cycle = _cycle()
    cycle.sense(_pose(10, 0.2), 1.0, 1.0)
    assert set(cycle._key_cells) == {KEYS.poses_cell(0, c) for c in START_CELLS}
    strangers = [(KEYS.poses_cell(0, (100 + k, 0)), b"") for k in range(2 * MAX_KEYS_REMEMBERED)]
    assert cycle.sense(strangers, 1.1, 1.1) is False
    assert cycle.counts.unheld_poses == len(strangers)
    assert len(cycle._key_cells) <= MAX_KEYS_REMEMBERED
    assert cycle.sense(_pose(15, 0.3), 1.2, 1.2) is True


def test_a_lost_cell_is_held_for_three_planning_periods_and_waited_for_half_a_tick() -> None:
    cycle = _cycle()
    assert cycle.assembler.hold_s == pytest.approx(0.3)
    assert cycle.assembler.wait_s == pytest.approx(0.01)  # 50 Hz, time scale 1
