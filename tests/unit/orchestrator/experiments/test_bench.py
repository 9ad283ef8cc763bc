"""`orchestrator bench`: the crowd it builds, what it counts and its JSON output.

No timing thresholds: only that the figures exist, are finite and ordered."""

from __future__ import annotations

import json
import math

import pytest

from agent.core.config import PLANNER_NAMES, PlannerConfig
from agent.core.scenario import RobotSpec, Scenario
from orchestrator.cli import main
from orchestrator.experiments import bench

REQUIRED = ("planner", "robots", "cycles", "plan_ms_p50", "plan_ms_p99", "plan_ms_max",
            *(f"{s}_ms_{q}" for s in ("threats", "viapoints", "spline", "control")
              for q in ("p50", "p99")))


def last_json(out: str) -> dict:
    return json.loads(out.strip().splitlines()[-1])


def check_row(row: dict, planner: str, robots: int, cycles: int) -> None:
    for key in REQUIRED:
        assert key in row, key
    assert (row["planner"], row["robots"], row["cycles"]) == (planner, robots, cycles)
    for name in ("plan", "cpu"):  # wall and thread CPU time of the cycle
        for q in ("p50", "p99", "max"):
            assert math.isfinite(row[f"{name}_ms_{q}"]) and row[f"{name}_ms_{q}"] >= 0.0
        assert row[f"{name}_ms_p50"] <= row[f"{name}_ms_p99"] <= row[f"{name}_ms_max"]
    assert row["plan_ms_p50"] > 0.0 and math.isfinite(row["cpu_ms_mean"])
    for stage in ("threats", "viapoints", "spline", "control", "obs"):
        p50, p99 = row[f"{stage}_ms_p50"], row[f"{stage}_ms_p99"]
        assert math.isfinite(p50) and math.isfinite(p99) and 0.0 <= p50 <= p99
    # Counted cycles are exactly the timed, non-excluded ones.
    assert sum(row["statuses"].values()) == row["cycles"]
    assert "arrived" not in row["statuses"] and "stale" not in row["statuses"]
    assert row["excluded"] == sum(row["excluded_statuses"].values())
    if planner == "eifp-mpc":  # OSQP's iterations: ordered, within the cap
        assert 0 < row["solver_iterations_p50"] <= row["solver_iterations_p99"] \
            <= row["solver_iterations_max"] <= row["solver_max_iter"]
        assert 0.0 <= row["solver_at_cap_frac"] <= 1.0
    else:
        assert "solver_iterations_p50" not in row
    assert row["warmup_cycles"] == bench.WARMUP_ROUNDS * robots * row["episodes"]
    assert 0 <= row["neighbors_mean"] <= row["neighbors_max"] <= row["max_neighbors"]
    assert row["neighbors_max"] <= row["neighbors_in_range_max"] <= robots - 1


def test_bench_one_row_json_is_the_last_line(capsys):
    assert main(["bench", "--planner", "eifp-mpc", "--robots", "4", "--cycles", "40",
                 "--json"]) == 0
    out = capsys.readouterr().out
    row = last_json(out)
    check_row(row, "eifp-mpc", 4, 40)
    assert row["circle_radius_m"] == pytest.approx(5.0)  # half the 10 m sensing radius
    assert "cycle ms p50/p99/max" in out and "eifp-mpc" in out.splitlines()[2]
    assert "cycle CPU ms p50/p99/max" in out


def test_bench_all_planners_and_several_sizes_make_one_table(capsys):
    assert main(["bench", "--planner", "all", "--robots", "2,3", "--cycles", "12",
                       "--json"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    rows = last_json("\n".join(lines))["rows"]
    assert len(rows) == 8
    assert [(r["planner"], r["robots"]) for r in rows] == \
        [(p, n) for p in PLANNER_NAMES for n in (2, 3)]
    assert [json.loads(line) for line in lines[-9:-1]] == rows  # one line per row first
    for r in rows:
        check_row(r, r["planner"], r["robots"], 12)
    table = lines[: lines.index("")]
    assert len(table) == 2 + 8  # header, rule, one line per row


def test_small_crowds_repeat_episodes_until_enough_cycles():
    # Two robots 10 m apart pass the centre within ~50 rounds: 150 cycles need more episodes.
    samples = bench.run_bench("ifp", 2, cycles=150, seed=1)
    assert len(samples) == 150 and samples.episodes >= 2
    assert samples.passed_centre >= 2 * (samples.episodes - 1)  # every finished episode


def test_bench_scenario_is_a_dense_circle():
    big = bench.bench_scenario(64, "orca")
    starts = [r.start[:2] for r in big.robots]
    assert all(r.planner == "orca" for r in big.robots)
    # Neighbouring starts SPACING_M apart; goals antipodal; headings at the goal.
    assert math.dist(starts[0], starts[1]) == pytest.approx(bench.SPACING_M, rel=1e-9)
    for r in big.robots:
        assert r.goal == pytest.approx((-r.start[0], -r.start[1]), abs=1e-9)
        toward_goal = math.atan2(-r.start[1], -r.start[0])
        assert math.remainder(r.start[2] - toward_goal, math.tau) == pytest.approx(0.0, abs=1e-5)
    small = bench.bench_scenario(3, "ifp")
    assert bench.circle_radius_m(small) == pytest.approx(
        small.planner_config.threats.sensing_radius_m / 2.0)


def test_arrived_cycles_are_excluded_and_counted():
    # Robot 0 sits on its goal (ARRIVED every cycle); robot 1 crosses 10 m.
    at_goal = Scenario(
        name="at_goal", description="", time_limit_s=60.0, goal_tolerance_m=0.25,
        planner_config=PlannerConfig(),
        robots=(RobotSpec(0, (0.0, 4.0, 0.0), (0.0, 4.0), planner="eifp"),
                RobotSpec(1, (-5.0, 0.0, 0.0), (5.0, 0.0), planner="eifp")))
    samples = bench.time_cycles(at_goal, cycles=30, jitter_m=0.0)
    assert len(samples) == 30 and set(samples.statuses) <= {"ok", "escape", "no_feasible"}
    # Robot 0 was excluded once per timed round: as often as robot 1 was counted.
    assert samples.excluded == {"arrived": 30}


@pytest.mark.parametrize("argv", [
    ["--planner", "foo", "--robots", "2"],
    ["--planner", "ifp", "--robots", "1"],
    ["--planner", "ifp", "--robots", "2", "--cycles", "0"],
    ["--robots", "2"],
])
def test_bad_arguments_exit_2(argv, capsys):
    assert main(["bench", *argv]) == 2
    assert "orchestrator bench" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [
    ["bench", "--robots", "4"],  # no planner, no --process
    ["bench", "--process", "--planner", "orca", "--robots", "4"],
    ["bench", "--planner", "orca", "--robots", "4", "--seconds", "3"],
    ["bench", "--floor", "--process", "--robots", "4"],
    ["bench", "--floor", "--planner", "orca", "--robots", "4"],
    ["bench", "--floor", "--insecure", "--robots", "4"],
])
def test_bench_refuses_options_of_the_other_mode(argv, capsys):
    assert main(argv) == 2
    assert "bench" in capsys.readouterr().err


def test_process_figures_are_printed_by_part():
    from orchestrator.experiments.scale import format_process_row

    row = {"agents": 64, "sim_time_s": 20.0, "transport": "TLS", "cpu_pct_per_robot": 0.5,
           "cpu_ms_per_plan_sense": 0.1, "cpu_ms_per_plan_plan": 0.02,
           "cpu_ms_per_plan_send": 0.05, "cpu_ms_per_plan_loop": 0.06,
           "cpu_ms_per_plan_threads": 0.12, "cpu_ms_per_plan_total": 0.35,
           "sense_to_act_ms_p50": 4.0, "sense_to_act_ms_p99": 12.0, "threads_per_robot": 3,
           "robots_lost": 0}
    text = format_process_row(row)
    for figure in ("sense 0.100", "brake 0.020", "send 0.050", "loop 0.060",
                   "Zenoh threads 0.120", "= 0.350", "64 robots", "0.500 ms per 100 ms"):
        assert figure in text, figure
