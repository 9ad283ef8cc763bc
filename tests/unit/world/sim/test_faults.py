"""Fault plans: flag parsing, validation against the scenario."""

from __future__ import annotations

import pytest

from world.sim.faults import (
    FaultPlan,
    FaultSpecError,
    ProcessFault,
    RobotTiming,
    build_plan,
    parse_process_fault,
    parse_robot_rate,
    parse_slow_robot,
)
from world.sim.link import LinkFaults


def test_build_plan_from_flag_values() -> None:
    plan = build_plan(latency_ms=100, jitter_ms=30, drop=0.1, dup=0.05, reorder=0.02, seed=4,
                      slow=["1:80"], rates=["2:5:0.05"], kill=["0@12.5"], stop=["1@3:2"],
                      restart=["2@20"], compensate_latency=False)
    assert plan.links == LinkFaults(100.0, 30.0, 0.1, 0.05, 0.02)
    assert plan.seed == 4 and not plan.compensate_latency and plan.active
    assert plan.timing_of(1) == RobotTiming(plan_delay_ms=80.0)
    assert plan.timing_of(2) == RobotTiming(control_rate_hz=5.0, phase_s=0.05)
    assert plan.timing_of(9) == RobotTiming()
    # Sorted by time.
    assert plan.process == (ProcessFault("stop", 1, 3.0, 2.0), ProcessFault("kill", 0, 12.5),
                            ProcessFault("restart", 2, 20.0))
    assert plan.to_json()["timing"]["1"]["plan_delay_ms"] == 80.0
    assert not FaultPlan().active


@pytest.mark.parametrize("parse, text, message", [
    (parse_slow_robot, "1", "expected I:MS"),
    (parse_slow_robot, "x:10", "robot id must be an int"),
    (parse_slow_robot, "1:-5", "must be >= 0"),
    (parse_robot_rate, "1:0", "must be > 0"),
    (parse_robot_rate, "1:10:2:3", "expected I:HZ"),
    (lambda t: parse_process_fault("kill", t), "3", "expected I@T"),
    (lambda t: parse_process_fault("kill", t), "-1@3", "must be >= 0"),
    (lambda t: parse_process_fault("stop", t), "1@3", "expected I@T:DUR"),
    (lambda t: parse_process_fault("stop", t), "1@3:0", "must be > 0"),
    (lambda t: parse_process_fault("restart", t), "1@nan", "must be >= 0"),
])
def test_bad_flags_are_rejected_with_the_flag_named(parse, text, message) -> None:
    with pytest.raises(FaultSpecError, match=message):
        parse(text)


def test_bad_link_values_and_unknown_robots_are_rejected() -> None:
    with pytest.raises(FaultSpecError, match="drop"):
        build_plan(drop=1.5)
    plan = build_plan(kill=["7@1"])
    with pytest.raises(FaultSpecError, match="no robot 7"):
        plan.check([0, 1])
    with pytest.raises(FaultSpecError, match="robot 5"):
        build_plan(slow=["5:10"]).check([0, 1])
    build_plan(kill=["1@1"]).check([0, 1])


def test_envelope_is_the_largest_level_with_all_smaller_ones_contact_free() -> None:
    from orchestrator.experiments.stress import (
        aggregate,
        envelope,
        level_faults,
        levels,
        parse_sweep,
    )

    sweep = parse_sweep(["latency_ms=200,0,100", "drop=0,0.2"])
    assert sweep == {"latency_ms": [0.0, 100.0, 200.0], "drop": [0.0, 0.2]}
    assert len(levels(sweep)) == 6
    assert level_faults({"latency_ms": 100.0}, LinkFaults(), 0.3).jitter_ms == pytest.approx(30)
    assert level_faults({"latency_ms": 100.0, "jitter_ms": 5.0}, LinkFaults(), 0.3
                        ).jitter_ms == 5.0
    contacts = {(0.0, 0.0): 0, (100.0, 0.0): 0, (200.0, 0.0): 1, (0.0, 0.2): 2,
                (100.0, 0.2): 0, (200.0, 0.2): 0}
    rows = [{"setup": "s", "planner": "p", "seed": seed, "latency_ms": lat, "drop": drop,
             "error": None, "success": not c, "contacts": c if seed == 0 else 0,
             "min_gap_m": 0.1, "time_ratio_mean": 1.2}
            for (lat, drop), c in contacts.items() for seed in range(2)]
    table = aggregate(rows, ["latency_ms", "drop"])
    assert len(table) == 6 and all(t["runs"] == 2 for t in table)
    (env,) = envelope(table, ["latency_ms", "drop"])
    assert env["max_latency_ms"] == 100.0  # 200 had a contact (drop at its smallest, 0)
    assert env["max_drop"] == 0.0          # drop 0.2 at latency 0 had contacts


def test_a_planner_that_never_arrives_is_not_contact_free() -> None:
    from orchestrator.experiments.stress import aggregate, envelope

    def row(lat: float, arrived: int, lost: int = 0) -> dict:
        return {"setup": "s", "planner": "p", "seed": 0, "latency_ms": lat, "error": None,
                "success": arrived == 4, "contacts": 0, "arrived": arrived, "robots": 4,
                "lost": lost, "min_gap_m": 1.0, "time_ratio_mean": None}

    # A deadlock (no contact, nobody arrives) is out of the envelope from the first level.
    (env,) = envelope(aggregate([row(0.0, 0), row(100.0, 0)], ["latency_ms"]), ["latency_ms"])
    assert env["max_latency_ms"] is None
    # Every robot arrives up to 100 ms, at 200 ms one does not: 100 is the envelope.
    rows = [row(0.0, 4), row(100.0, 4), row(200.0, 3)]
    (env,) = envelope(aggregate(rows, ["latency_ms"]), ["latency_ms"])
    assert env["max_latency_ms"] == 100.0
    # A robot lost to a robot fault does not count against the planner.
    (env,) = envelope(aggregate([row(0.0, 3, lost=1)], ["latency_ms"]), ["latency_ms"])
    assert env["max_latency_ms"] == 0.0


@pytest.mark.parametrize("hold", [0.0, -1.0, float("nan"), float("inf")])
def test_a_command_hold_that_is_not_a_positive_number_is_refused(hold):
    with pytest.raises(FaultSpecError, match="command_hold_periods"):
        FaultPlan(command_hold_periods=hold)


def test_a_command_hold_is_an_experiment_and_recorded():
    plan = FaultPlan(command_hold_periods=100.0)
    assert plan.active and plan.to_json()["command_hold_periods"] == 100.0
    assert not FaultPlan().active and FaultPlan().to_json()["command_hold_periods"] is None
