"""The lockstep runner: files, determinism, stopping rules."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from agent.core.config import PlannerConfig
from agent.core.scenario import RobotSpec, Scenario
from orchestrator.experiments.lockstep import LockstepProgress, run_lockstep
from world.scenario_file import load_scenario
from world.sim.faults import build_plan


def two_lanes(time_limit_s: float = 30.0, planner: str = "ifp") -> Scenario:
    """Two robots on parallel lanes 6 m apart, 5 m runs: no interaction."""
    return Scenario(
        name="lanes", description="", time_limit_s=time_limit_s, goal_tolerance_m=0.25,
        planner_config=PlannerConfig(),
        robots=(RobotSpec(0, (0.0, 0.0, 0.0), (5.0, 0.0), planner=planner),
                RobotSpec(1, (0.0, 6.0, 0.0), (5.0, 6.0), planner=planner)),
    )


def test_lockstep_run_writes_the_run_directory(tmp_path):
    seen: list[LockstepProgress] = []
    out = run_lockstep(two_lanes(), tmp_path / "run", on_progress=seen.append)
    run = tmp_path / "run"
    for name in ("scenario.yaml", "trajectory.csv", "commands.csv", "events.jsonl",
                 "metrics.json"):
        assert (run / name).stat().st_size > 0, name
    assert load_scenario(run / "scenario.yaml") == two_lanes()
    assert out.reason == "all_arrived" and out.success and out.metrics.arrived == 2
    # 5 m at <= 1.1 m/s: at least 4.5 s, and the straight lanes take well under 10 s.
    assert 4.5 <= out.sim_time_s < 10.0
    assert out.ticks == round(out.sim_time_s * 50)
    rows = (run / "trajectory.csv").read_text().splitlines()
    assert len(rows) == 1 + 2 * (out.ticks + 1)  # header, then both robots per tick from t=0
    cmds = (run / "commands.csv").read_text().splitlines()
    cycles = (out.ticks - 1) // 5 + 1
    assert len(cmds) == 1 + 2 * cycles  # one command per robot per 0.1 s
    events = [json.loads(x) for x in (run / "events.jsonl").read_text().splitlines()]
    kinds = [e["kind"] for e in events]
    assert kinds[0] == "start" and kinds[-1] == "end" and kinds.count("arrived") == 2
    assert events[0]["world_rate_hz"] == 50.0 and events[0]["control_rate_hz"] == 10.0
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["sim_latency_ms_p50"] == 0.0 and metrics["deadline_miss_rate"] == 0.0
    assert seen and seen[-1].arrived == frozenset({0, 1})


def test_lockstep_is_deterministic(tmp_path):
    run_lockstep(two_lanes(), tmp_path / "a")
    run_lockstep(two_lanes(), tmp_path / "b")
    traj_a = (tmp_path / "a" / "trajectory.csv").read_text()
    assert traj_a == (tmp_path / "b" / "trajectory.csv").read_text()

    def decisions(path):  # everything but the wall-time plan_ms column
        return [line.split(",")[:6] + line.split(",")[7:]
                for line in (path / "commands.csv").read_text().splitlines()]

    assert decisions(tmp_path / "a") == decisions(tmp_path / "b")


def test_lockstep_stops_at_the_time_limit(tmp_path):
    out = run_lockstep(two_lanes(time_limit_s=1.0), tmp_path / "run")
    assert out.reason == "time_limit" and not out.success
    assert out.ticks == 50 and out.metrics.arrived == 0


def test_control_rate_must_divide_the_world_rate(tmp_path):
    with pytest.raises(ValueError, match="must divide"):
        run_lockstep(two_lanes(), tmp_path / "run", world_rate_hz=50.0, control_rate_hz=15.0)


# --- the fault-injected (streaming) loop ---------------------------------------------------

def crossing(time_limit_s: float = 40.0) -> Scenario:
    """Robot 1 crosses robot 0's lane ahead of it (as the distributed kill test)."""
    return Scenario(
        name="crossing", description="", time_limit_s=time_limit_s, goal_tolerance_m=0.25,
        planner_config=PlannerConfig(),
        robots=(RobotSpec(0, (-6.0, 0.0, 0.0), (5.0, 0.0), radius_m=0.3),
                RobotSpec(1, (0.0, -3.0, 1.5707963), (0.0, 4.0), radius_m=0.3)),
    )


def events_of(run) -> list[dict]:
    return [json.loads(x) for x in (run / "events.jsonl").read_text().splitlines()]


def test_faulty_loop_without_faults_succeeds_and_is_deterministic(tmp_path):
    plan = build_plan()
    a = run_lockstep(two_lanes(), tmp_path / "a", faults=plan)
    run_lockstep(two_lanes(), tmp_path / "b", faults=plan)
    assert a.success and a.metrics.sim_latency_ms_p50 == 0.0
    assert ((tmp_path / "a" / "trajectory.csv").read_text()
            == (tmp_path / "b" / "trajectory.csv").read_text())


def test_link_latency_is_the_measured_command_latency(tmp_path):
    # A robot receives only its pose slot (every 100 ms), as a distributed robot does: with
    # 60 ms on the pose link it plans on the slot pose of the previous period (100 ms old),
    # and its command takes another 60 ms: 160 ms per command.
    out = run_lockstep(two_lanes(), tmp_path / "run", faults=build_plan(latency_ms=60))
    assert out.success
    assert out.metrics.sim_latency_ms_p50 == pytest.approx(160.0)


def test_lost_commands_give_way_to_braking_after_their_hold(tmp_path):
    # Half of all messages lost: a command not followed within 1.5 periods brakes the robot
    # (the end event counts it); a hold of 100 periods (longer than the 0.5 s time-out)
    # turns that off, and the robot keeps driving on its last command instead.

    def run(hold_periods: float, name: str) -> tuple[dict, list[float]]:
        faults = replace(build_plan(drop=0.5, seed=1), command_hold_periods=hold_periods)
        out = run_lockstep(two_lanes(), tmp_path / name, faults=faults)
        assert out.success, out.metrics
        end = events_of(tmp_path / name)[-1]
        rows = (tmp_path / name / "trajectory.csv").read_text().splitlines()
        header = rows[0].split(",")
        v = [float(r.split(",")[header.index("v")]) for r in rows[1:]
             if r.split(",")[header.index("robot")] == "0"]
        return end, v

    short, v_short = run(1.5, "short")
    long_, v_long = run(100.0, "long")
    assert short["cmd_hold_expiries"] > 0 and long_["cmd_hold_expiries"] == 0
    # braking ticks show as a speed below the previous tick's while cruising
    dips = sum(1 for a, b in zip(v_short, v_short[1:]) if 0.3 < b < a - 0.02)
    assert dips > 0 and dips > sum(1 for a, b in zip(v_long, v_long[1:]) if 0.3 < b < a - 0.02)


def test_faulty_runs_are_repeatable_per_seed(tmp_path):
    def traj(seed, name):
        run_lockstep(crossing(), tmp_path / name,
                     faults=build_plan(latency_ms=50, jitter_ms=40, drop=0.2, dup=0.1,
                                       reorder=0.1, seed=seed))
        return (tmp_path / name / "trajectory.csv").read_text()

    assert traj(3, "a") == traj(3, "b")
    assert traj(3, "a-again") != traj(4, "c")  # a run directory is written once


def test_killed_robot_is_avoided_where_it_stopped(tmp_path):
    # Killed at 3 s, when it is about on robot 0's lane: it brakes and stays an obstacle.
    out = run_lockstep(crossing(), tmp_path / "run", faults=build_plan(kill=["1@3"]))
    events = events_of(tmp_path / "run")
    lost = [e for e in events if e["kind"] == "robot_lost"]
    assert [(e["robot"], e["t"]) for e in lost] == [(1, pytest.approx(3.0, abs=0.03))]
    assert out.metrics.contacts == 0
    assert [e["robot"] for e in events if e["kind"] == "arrived"] == [0]
    assert events[-1]["lost"] == [1]
    # Robot 0 arrived and robot 1 is gone for good: the run ends then, not at its limit.
    arrived_t = next(e["t"] for e in events if e["kind"] == "arrived")
    assert out.reason == "arrived_or_lost" and events[-1]["reason"] == "arrived_or_lost"
    assert events[-1]["t"] == pytest.approx(arrived_t, abs=0.05)
    assert events[-1]["t"] < 40.0
    rows = [r.split(",") for r in (tmp_path / "run" / "trajectory.csv").read_text().split()[1:]]
    y1 = [(float(r[0]), float(r[3])) for r in rows if r[1] == "1"]
    after = [y for t, y in y1 if t > 5.0]  # braked to a stop within 2 s of the kill
    assert max(after) - min(after) < 1e-9 and abs(after[0]) < 1.0, after[0]


def test_stopped_robot_is_lost_after_the_lease_braked_and_rejoins(tmp_path):
    out = run_lockstep(crossing(), tmp_path / "run", faults=build_plan(stop=["1@2:3"]))
    events = events_of(tmp_path / "run")
    kinds = {e["kind"]: e for e in reversed(events)}  # first of each kind
    assert kinds["cmd_timeout"]["robot"] == 1
    assert 2.4 < kinds["cmd_timeout"]["t"] < 2.7  # the world's 0.5 s command time-out
    assert kinds["robot_lost"]["t"] == pytest.approx(3.0, abs=0.03)  # after the 1 s lease
    assert kinds["robot_rejoined"]["t"] == pytest.approx(5.0, abs=0.03)
    assert out.success, out.metrics
    assert out.reason == "all_arrived"  # a stopped robot comes back: it held the run open


def test_restarted_robot_rejoins_and_finishes(tmp_path):
    out = run_lockstep(crossing(), tmp_path / "run", faults=build_plan(restart=["1@2"]))
    events = events_of(tmp_path / "run")
    assert [e["kind"] for e in events if e["kind"].startswith("robot_")] == [
        "robot_lost", "robot_rejoined"]
    assert out.success
    seqs = [int(r.split(",")[2]) for r in
            (tmp_path / "run" / "commands.csv").read_text().split()[1:] if r.split(",")[1] == "1"]
    assert seqs.count(0) == 2  # the new controller numbers from 0 again


def test_slow_robot_and_its_own_rate(tmp_path):
    plan = build_plan(slow=["0:80"], rates=["1:5:0.1"])
    out = run_lockstep(two_lanes(), tmp_path / "run", faults=plan)
    assert out.success
    rows = [r.split(",") for r in (tmp_path / "run" / "commands.csv").read_text().split()[1:]]
    lat0 = [(float(r[0]) - float(r[3])) for r in rows if r[1] == "0"]
    t1 = [float(r[0]) for r in rows if r[1] == "1"]
    assert min(lat0) == pytest.approx(0.08, abs=0.021)  # applied one tick after the delay
    assert t1[0] == pytest.approx(0.1) and all(
        b - a == pytest.approx(0.2) for a, b in zip(t1, t1[1:]))

