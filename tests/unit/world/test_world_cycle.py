"""The world's per-tick decisions (`world.world_cycle`), driven with keys, payloads and ticks."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.types import PlanDebug, PlanResult, PlanStatus
from eifp_wire import (
    MAX_CMD_AHEAD_S,
    CommandMsg,
    ControlMsg,
    PlanDebugMsg,
    RunKeys,
    max_seq,
)
from world.scenario_file import scenario_from_dict
from world.sim.link import LinkFaults
from world.world_cycle import (
    MAX_REJECT_EVENTS,
    MAX_TALLY_KEYS,
    WorldCounters,
    WorldCycle,
    tally,
)

TWO_ROBOTS = {
    "name": "node_test",
    "time_limit": 20,
    "defaults": {"radius": 0.3},
    "robots": [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 4, "start": [3.0, 1.0, 3.14], "goal": [-3.0, 1.0]},
    ],
    "obstacles": [{"center": [0.0, 5.0], "radius": 0.5}],
}
"""Two robots crossing and a disc (the world's process tests use it too)."""
SCENARIO = scenario_from_dict({**TWO_ROBOTS, "time_limit": 2}, "test")
KEYS = RunKeys("r-1")
DT_S = 0.02


def _cycle(**kwargs: object) -> WorldCycle:
    return WorldCycle(SCENARIO, "r-1", cmd_timeout_s=0.5, **kwargs)


def _kinds(cycle: WorldCycle) -> list[str]:
    return [e.kind for e in cycle.take_events()]


def _cmd(rid: int, seq: int, v: float, stamp_s: float = 0.0) -> bytes:
    return CommandMsg(rid, seq, stamp_s, v, 0.1, 2.0, "ok", 1, -1).encode()


# --- liveliness and configuration --------------------------------------------------------------

def test_liveliness_join_loss_and_rejoin() -> None:
    cycle = _cycle()
    cycle.liveliness(KEYS.alive_robot(0), True)
    cycle.liveliness(KEYS.alive_robot(0), True)  # a repeat changes nothing
    cycle.liveliness(KEYS.alive_robot(99), True)  # not in the run
    cycle.liveliness(KEYS.alive_robot(99), False)
    cycle.liveliness("eifp/other-run/alive/robot/0", True)
    events = cycle.take_events()
    assert [(e.kind, e.wall) for e in events] == [
        ("robot_joined", True), ("unknown_robot", False), ("unknown_robot", False)]
    assert cycle.alive == {0}
    cycle.step(DT_S)
    cycle.liveliness(KEYS.alive_robot(0), False)
    assert cycle.lost == {0} and cycle.lost_at_s == {0: pytest.approx(DT_S)}
    assert bool(cycle.sim.offline[cycle.sim.index_of(0)])
    assert _kinds(cycle) == ["robot_lost"]
    assert cycle.take_notices() == ["robot 0 lost (liveliness token gone): braking it"]
    cycle.liveliness(KEYS.alive_robot(0), True)
    assert not cycle.lost and not cycle.sim.offline[cycle.sim.index_of(0)]
    assert _kinds(cycle) == ["robot_rejoined"] and cycle.take_notices() == ["robot 0 rejoined"]


def test_after_the_end_a_vanishing_robot_has_left_not_been_lost() -> None:
    cycle = _cycle()
    cycle.liveliness(KEYS.alive_robot(4), True)
    cycle.take_events()
    cycle.end("time_limit")
    cycle.liveliness(KEYS.alive_robot(4), False)
    assert _kinds(cycle) == ["robot_left"] and not cycle.lost and not cycle.alive


def test_configuration_queries_are_answered_for_the_runs_robots_only() -> None:
    cycle = _cycle(configs={0: b"zero", 4: b"four"})
    assert cycle.config_reply(KEYS.config(4)) == (KEYS.config(4), b"four")
    assert cycle.config_reply(KEYS.config(9)) is None
    assert cycle.config_reply("eifp/r-1/config/x") is None
    assert (cycle.counts.queries, cycle.counts.bad_queries) == (1, 2)


# --- commands ----------------------------------------------------------------------------------

def test_commands_applied_stale_dropped_garbage_rejected() -> None:
    cycle = _cycle()
    for key, payload in ((KEYS.cmd(0), _cmd(0, 5, 0.7)),
                         (KEYS.cmd(0), _cmd(0, 5, 0.1)),  # same seq: stale
                         (KEYS.cmd(0), _cmd(0, 3, 0.2)),  # older seq: stale
                         (KEYS.cmd(0), _cmd(4, 9, 0.3)),  # robot 4's on robot 0's key
                         (KEYS.cmd(4), b"\xc1garbage"),  # not msgpack
                         (KEYS.cmd(4), ControlMsg("end", 0.0).encode()),  # wrong type
                         ("eifp/r-1/cmd/x", _cmd(0, 6, 0.1)),  # not a robot's key
                         (KEYS.cmd(4), _cmd(4, 0, 9.0))):  # clamped to v_max by the world
        cycle.admit_command(key, payload, rx_ns=7)
    applied = cycle.release_commands()
    assert [(a.robot_id, a.msg.seq, a.rx_ns) for a in applied] == [(0, 5, 7), (4, 0, 7)]
    counts = cycle.counts
    assert (counts.commands, counts.stale, counts.rejected) == (2, 2, 4)
    assert cycle.sim.command[cycle.sim.index_of(0)].tolist() == [0.7, 0.1]
    assert cycle.sim.command[cycle.sim.index_of(4)][0] == pytest.approx(1.1)  # default v_max
    rejected = [e for e in cycle.take_events() if e.kind == "rejected"]
    assert len(rejected) == 4 and any("key of robot" in e.fields["reason"] for e in rejected)
    assert cycle.rejected_by_key[KEYS.cmd(4)] == 2 and sum(cycle.rejected_by_key.values()) == 4


def test_a_seq_jump_or_a_plan_from_the_future_is_refused_not_stored() -> None:
    cycle = _cycle()
    bound = max_seq(cycle.sim.t_s)
    for payload in (_cmd(0, 2**63 - 1, 0.9), _cmd(0, 1, 0.5), _cmd(0, bound + 1, 0.9),
                    _cmd(0, 2, 0.4, stamp_s=MAX_CMD_AHEAD_S + 5.0), _cmd(0, bound, 0.3)):
        cycle.admit_command(KEYS.cmd(0), payload, 0)
    cycle.release_commands()
    assert (cycle.counts.seq_jumps, cycle.counts.future_cmds) == (2, 1)
    assert cycle.counts.commands == 2 and cycle.last_seq[0] == bound
    assert cycle.sim.command[cycle.sim.index_of(0)][0] == pytest.approx(0.3)
    assert cycle.rejected_by_reason == {"cmd.seq": 2, "cmd.pose_stamp": 1}
    cycle.sim.step(0.5)  # half a second later, half a second more of seq
    cycle.admit_command(KEYS.cmd(0), _cmd(0, bound + 500, 0.2), 0)
    assert len(cycle.release_commands()) == 1 and cycle.last_seq[0] == bound + 500


def test_a_robot_back_after_a_loss_keeps_its_last_seq_and_loses_what_was_in_flight() -> None:
    cycle = _cycle(link=LinkFaults(latency_ms=100.0))
    cycle.liveliness(KEYS.alive_robot(0), True)
    cycle.admit_command(KEYS.cmd(0), _cmd(0, 10, 0.5), 0)
    for _ in range(5):
        cycle.step(DT_S)
    assert [a.msg.seq for a in cycle.release_commands()] == [10]  # after 0.1 s of sim time
    cycle.admit_command(KEYS.cmd(0), _cmd(0, 11, 0.5), 0)  # in flight when the robot is lost
    cycle.liveliness(KEYS.alive_robot(0), False)
    cycle.liveliness(KEYS.alive_robot(0), True)
    for _ in range(10):
        cycle.step(DT_S)
    assert cycle.release_commands() == []  # its link was cleared on the rejoin
    cycle.admit_command(KEYS.cmd(0), _cmd(0, 9, 0.5), 0)  # replayed from before the loss
    for _ in range(5):
        cycle.step(DT_S)
    assert cycle.release_commands() == [] and cycle.counts.stale == 1


def test_only_the_first_rejections_are_events_and_tallies_are_bounded() -> None:
    cycle = _cycle()
    for k in range(MAX_REJECT_EVENTS + 50):
        cycle.reject(f"reason{k}: x", f"key{k}")
    assert cycle.counts.rejected == MAX_REJECT_EVENTS + 50
    assert len(cycle.take_events()) == MAX_REJECT_EVENTS
    assert len(cycle.rejected_by_key) == MAX_TALLY_KEYS + 1  # ... and "other"
    assert cycle.rejected_by_key["other"] == MAX_REJECT_EVENTS + 50 - MAX_TALLY_KEYS
    assert len(cycle.take_notices()) == 3  # the 1st, 10th and 100th
    counts: dict[str, int] = {}
    for name in ("a", "b", "a"):
        tally(counts, name)
    assert counts == {"a": 2, "b": 1}


def test_a_plans_internals_are_recorded_or_rejected() -> None:
    cycle = _cycle()
    result = PlanResult(v_mps=1.0, omega_radps=0.0, status=PlanStatus.OK,
                        waypoints_m=np.zeros((2, 2)),
                        debug=PlanDebug(ego=(0.0, 0.0, 0.0), threat_ids=(4,),
                                        via_points_m=np.zeros((0, 2)),
                                        reference_m=np.zeros((2, 2)),
                                        predicted_m=np.zeros((2, 2))))
    msg = PlanDebugMsg.from_result(0, 3, 0.1, result)
    assert msg is not None
    got = cycle.plan_debug(KEYS.debug(0), msg.encode())
    assert got is not None and got[0] == 0 and got[1].seq == 3
    assert cycle.plan_debug(KEYS.debug(4), msg.encode()) is None  # robot 0's on 4's key
    assert (cycle.counts.plans, cycle.counts.rejected) == (1, 1)


# --- stepping and the end ----------------------------------------------------------------------

def test_the_run_ends_at_the_time_limit_with_the_counters_in_the_end_event() -> None:
    cycle = _cycle()
    ticks = 0
    while (reason := cycle.end_reason()) is None:
        cycle.step(DT_S)
        ticks += 1
    assert reason == "time_limit" and ticks == 100
    kinds = _kinds(cycle)
    assert kinds.count("cmd_timeout") == 0  # no command was ever held
    end = cycle.end(reason, tick_ms=None)
    assert end.kind == "end" and end.fields["reason"] == "time_limit"
    assert end.fields["success"] is False and end.fields["ticks"] == 100
    keys = list(end.fields)
    counters = list(WorldCounters().as_dict())
    assert keys[keys.index("cmd_hold_expiries") + 1:][:len(counters)] == counters
    assert keys[-4:] == ["rejected_by_key", "rejected_by_reason", "cmd_link", "tick_ms"]


def test_a_lost_robot_holds_the_run_open_for_its_grace_only() -> None:
    cycle = _cycle(lost_grace_s=0.5)
    for rid in (0, 4):
        cycle.liveliness(KEYS.alive_robot(rid), True)
    cycle.liveliness(KEYS.alive_robot(0), False)
    cycle.liveliness(KEYS.alive_robot(4), False)
    steps = 0
    while cycle.end_reason() is None:
        cycle.step(DT_S)
        steps += 1
    assert cycle.end_reason() == "arrived_or_lost" and steps == 25  # 0.5 s of sim time


def test_a_contact_is_an_event_and_a_notice() -> None:
    scenario = scenario_from_dict({
        "name": "contact", "time_limit": 5, "defaults": {"radius": 0.5},
        "robots": [{"id": 0, "start": [0.0, 0.0, 0.0], "goal": [3.0, 0.0]},
                   {"id": 1, "start": [1.3, 0.0, 3.14], "goal": [-3.0, 0.0]}]}, "test")
    cycle = WorldCycle(scenario, "r-1", cmd_timeout_s=0.5)
    for rid in (0, 1):  # head-on, 30 cm apart
        cycle.admit_command(KEYS.cmd(rid), _cmd(rid, 0, 1.0), 0)
    assert len(cycle.release_commands()) == 2
    for _ in range(15):
        cycle.step(DT_S)
    contacts = [e for e in cycle.take_events() if e.kind == "contact"]
    assert [(e.fields["a"], e.fields["b"]) for e in contacts] == [(0, 1)]
    assert cycle.take_notices()[0].startswith("contact 0-1, overlap ")
    assert cycle.end("all_arrived").fields["success"] is False


# --- poses -------------------------------------------------------------------------------------

def test_the_tick_goes_out_one_message_per_cell_within_reach_of_a_robot() -> None:
    """Every disc of the scenario is near the origin, in cell (0, 0); the cells around it
    are sent empty, so a robot holding them can tell a lost message from an empty cell."""
    from eifp_wire import PosesMsg

    cycle = _cycle()
    out = dict(cycle.pose_cells(pub_ns=9, clock_id=3))
    assert sorted(out) == [(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    for cell, payload in out.items():
        msg = PosesMsg.decode(payload)
        assert (msg.tick, msg.pub_ns, msg.clock_id) == (0, 9, 3)
        if cell == (0, 0):
            assert msg.robot_ids.tolist() == [0, 4] and msg.obstacle_ids.tolist() == [-1]
        else:
            assert msg.robot_ids.size == 0 and msg.obstacle_ids.size == 0
    held = cycle.cell_rule.needed(-3.0, 0.0)  # robot 0's cells at its start
    assert held <= set(out)
