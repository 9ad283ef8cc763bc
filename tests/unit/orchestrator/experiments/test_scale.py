"""The scale benchmark's pure parts: rows, sampling, outputs, the world per-tick benchmark.

The real runs (processes over Zenoh) are in tests/system/test_scale.py.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator.cli import build_parser
from orchestrator.cli import main as cli_main
from orchestrator.experiments.scale import (
    COLUMNS,
    CPU_PARTS,
    PLOTTED,
    ResourceSampler,
    _cpu_at,
    cpu_per_plan_ms,
    format_rows,
    robot_endpoints,
    scale_row,
    write_outputs,
)
from orchestrator.experiments.world_bench import (
    WORLD_PLOTTED,
    WORLD_STAGES,
    plot_world_bench,
    world_tick_costs,
)


def fake_row(n: int, **extra: object) -> dict:
    sampler = ResourceSampler()
    row = scale_row({"success": True, "arrived": n, "contacts": 0, "plan_ms_p50": 1.0,
                     "plan_ms_p99": 5.0, "sim_latency_ms_p50": 0.0, "sim_latency_ms_p99": 20.0,
                     "deadline_miss_rate": 0.01, "sim_time_s": 10.0}, [], sampler,
                    n=n, family="circles", planner="eifp-mpc", spawn_wall=0.0, spawn_mono=0.0,
                    wall_s=12.0, time_scale=1.0, world_status=0)
    row.update(extra)
    return row


def test_robot_endpoints_round_robin_over_the_hosts() -> None:
    got = robot_endpoints(["127.0.0.1", "127.0.0.2"], 7447, [5, 6, 7])
    assert got == {5: "tcp/127.0.0.1:7447", 6: "tcp/127.0.0.2:7447", 7: "tcp/127.0.0.1:7447"}


def test_cpu_interpolates_between_samples_and_clamps() -> None:
    series = [(10.0, 1.0), (11.0, 1.5), (12.0, 3.5)]
    assert _cpu_at(series, 10.5) == pytest.approx(1.25)
    assert _cpu_at(series, 11.5) == pytest.approx(2.5)
    assert _cpu_at(series, 20.0) == 3.5  # the process is gone: its last reading
    assert _cpu_at(series, 1.0) == 0.0  # long before the first sample: not started yet


def test_scale_row_from_events_and_samples() -> None:
    sampler = ResourceSampler()
    from orchestrator.experiments.scale import _Proc

    # Two robots and the world; start at monotonic 102 (wall 1002), 10 s of sim time.
    sampler.procs = {
        1: _Proc("robot", [(100.0, 0.5), (102.0, 1.0), (112.0, 2.0)], mem_peak_b=40 * 2**20),
        2: _Proc("robot", [(100.0, 0.5), (102.0, 1.0), (112.0, 4.0)], mem_peak_b=60 * 2**20),
        3: _Proc("world", [(100.0, 0.1), (102.0, 0.2), (112.0, 1.2)], mem_peak_b=30 * 2**20),
    }
    sampler.mem_total_peak_b = 130 * 2**20
    events = [{"kind": "robot_joined", "robot": 0, "wall": 1001.0},
              {"kind": "robot_joined", "robot": 1, "wall": 1001.5},
              {"kind": "robot_rejoined", "robot": 1, "wall": 1030.0},  # not start-up
              {"kind": "start", "t": 0.0, "wall": 1002.0},
              {"kind": "robot_lost", "t": 1.0, "robot": 1, "wall": 1003.0},
              {"kind": "end", "t": 5.0, "overruns": 3},
              {"kind": "robot_left", "robot": 0, "wall": 1012.0}]
    # The world fell behind: 5 s of sim time took 10 s of wall time (start to robot_left).
    row = scale_row({"success": True, "sim_time_s": 5.0}, events, sampler, n=2,
                    family="circles", planner="eifp-mpc", spawn_wall=1000.0, spawn_mono=100.0,
                    wall_s=15.0, time_scale=1.0, world_status=0)
    assert row["alive_s"] == pytest.approx(1.5)
    cpus = __import__("psutil").cpu_count()
    assert row["cpu_share_robots"] == pytest.approx(4.0 / 10.0 / cpus)
    assert row["cpu_share_world"] == pytest.approx(1.0 / 10.0 / cpus)
    assert row["cpu_pct_per_robot"] == pytest.approx(20.0)  # 4 CPU s over 10 s, 2 robots
    assert row["mem_robot_mib"] == pytest.approx(50.0)
    assert row["mem_world_mib"] == pytest.approx(30.0)
    assert row["mem_total_mib"] == pytest.approx(130.0)
    assert row["world_overruns"] == 3 and row["robots_lost"] == 1
    assert set(row) == set(COLUMNS)


def test_cpu_per_plan_sums_the_robots_that_reported_and_divides_by_their_plans() -> None:
    cpu = {"cpu_sense_us": 300, "cpu_plan_us": 900, "cpu_send_us": 60, "cpu_loop_us": 30,
           "cpu_threads_us": 210}
    exits = {"processes": [
        {"robot": 0, "plans": 2, **cpu},
        {"robot": 1, "plans": 1, **{k: 2 * v for k, v in cpu.items()}},
        {"robot": 2, "plans": 50},  # an older robot build: no CPU split, left out
    ]}
    got = cpu_per_plan_ms(exits)
    assert got["cpu_ms_per_plan_sense"] == pytest.approx(0.9 / 3)  # (300 + 600) us / 3 plans
    assert got["cpu_ms_per_plan_plan"] == pytest.approx(2.7 / 3)
    assert got["cpu_ms_per_plan_threads"] == pytest.approx(0.63 / 3)
    assert set(got) == {f"cpu_ms_per_plan_{p}" for p in CPU_PARTS} | {"cpu_ms_per_plan_total"}
    assert got["cpu_ms_per_plan_total"] == pytest.approx(1.5 * 3 / 3)  # every part, summed
    assert all(v is None for v in cpu_per_plan_ms({"processes": exits["processes"][2:]}).values())
    assert all(v is None for v in cpu_per_plan_ms({}).values())
    row = {**{c: None for c in COLUMNS}, "agents": 4, **got}
    assert "0.30/0.90/0.06/0.03/0.21 = 1.50" in format_rows([row])


def test_alive_is_unknown_when_a_robot_never_joined() -> None:
    events = [{"kind": "robot_joined", "robot": 0, "wall": 1001.0}]
    row = scale_row({}, events, ResourceSampler(), n=2, family="circles", planner="eifp",
                    spawn_wall=1000.0, spawn_mono=0.0, wall_s=1.0, time_scale=1.0,
                    world_status=1)
    assert row["alive_s"] is None and row["success"] is False and row["cpu_share_robots"] is None


def test_sampler_reads_a_robot_process() -> None:
    """A real `python -m agent` child (waiting for a router that is not there)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "agent", "--run", "t", "--id", "0", "--connect",
         "tcp/127.0.0.1:9", "--startup-timeout-s", "20"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        cwd=Path(__file__).resolve().parents[4])
    sampler = ResourceSampler(memory_every=1)
    try:
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            sampler.sample(0)
            rec = sampler.procs.get(proc.pid)
            if rec is not None and rec.mem_peak_b > 10 * 2**20:  # imports under way
                break
            time.sleep(0.05)
    finally:
        proc.terminate()
        proc.wait(10)
    rec = sampler.procs[proc.pid]
    assert rec.role == "robot" and rec.cpu_s and rec.cpu_s[-1][1] > 0.0
    assert rec.mem_peak_b > 10 * 2**20
    assert sampler.mem_kind in ("pss", "rss")


def test_outputs_are_written(tmp_path: Path) -> None:
    rows = [fake_row(4), fake_row(8, success=False, contacts=2)]
    paths = write_outputs(rows, tmp_path, ["orchestrator", "scale"])
    assert [p.name for p in paths] == ["scale.csv", "scale.json", "scale.png"]
    assert all(p.stat().st_size > 0 for p in paths)
    with open(tmp_path / "scale.csv", encoding="utf-8") as f:
        table = list(csv.DictReader(f))
    assert [r["agents"] for r in table] == ["4", "8"] and table[1]["contacts"] == "2"
    content = json.loads((tmp_path / "scale.json").read_text())
    assert content["argv"] == ["orchestrator", "scale"] and len(content["rows"]) == 2
    text = format_rows(rows)
    assert text.splitlines()[0].startswith("N ") and len(text.splitlines()) == 4
    assert "20.0" in text.splitlines()[2]  # latency p99


def test_world_tick_costs_report_stages_and_the_cells_sizes(tmp_path: Path) -> None:
    rows = [world_tick_costs(n, 5, tmp_path / str(n)) for n in (16, 64)]
    for row in rows:
        assert row["tick_us_p50"] > 0.0 and row["step_us_p50"] > 0.0
        assert (tmp_path / str(row["agents"]) / "trajectory.csv").stat().st_size > 0
        assert 4 <= row["rx_msgs_per_robot"] <= 9 <= row["cells"]
        assert 36 * 8 < row["rx_bytes_per_robot"] <= row["poses_bytes"]
    # 36 bytes per robot (id int32 + x, y, theta, radius float64), and per cell an envelope
    # of 66 bytes unstamped (msgpack's bin headers grow by a byte or two past 256 bytes).
    small, large = rows
    extra = large["poses_bytes"] - small["poses_bytes"] - 36 * 48
    more_cells = large["cells"] - small["cells"]
    assert 66 * more_cells <= extra <= 70 * more_cells


def test_world_bench_command_writes_json_and_the_plot(tmp_path: Path, capsys) -> None:
    assert cli_main(["scale", "--agents", "4,8", "--world-bench", "--ticks", "3",
                     "--out", str(tmp_path), "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    last = json.loads(out[-1])
    assert [r["agents"] for r in last["rows"]] == [4, 8]
    assert json.loads((tmp_path / "world_bench.json").read_text())["rows"] == last["rows"]
    assert (tmp_path / "world_bench.png").stat().st_size > 0
    assert str(tmp_path / "world_bench.png") in out


def world_row(n: int) -> dict:
    """A world-bench row with made-up times (the plot reads only these columns)."""
    return {"agents": n, "rx_bytes_per_robot_s": 20_000.0, "rx_msgs_per_robot_s": 75.0,
            "tick_us_per_robot": 18.0, **{f"{k}_us_per_robot": 4.5 for k in WORLD_STAGES}}


def test_world_bench_plot_has_a_panel_per_per_robot_quantity(tmp_path: Path) -> None:
    from PIL import Image

    for ns, name in (((64, 128, 1024), "many.png"), ((64,), "one.png")):
        path = plot_world_bench([world_row(n) for n in ns], tmp_path / name)
        with Image.open(path) as im:
            assert im.format == "PNG" and im.size[0] >= 500
    with pytest.raises(ValueError):
        plot_world_bench([], tmp_path / "none.png")
    assert not (tmp_path / "none.png").exists()


def test_world_bench_per_second_columns_follow_the_pose_slot(tmp_path: Path) -> None:
    """A robot takes one tick in five (its slot) at 50 Hz: 10 of its cells' ticks a second."""
    row = world_tick_costs(16, 2, tmp_path / "16")
    assert row["rx_bytes_per_robot_s"] == pytest.approx(10.0 * row["rx_bytes_per_robot"])
    assert row["rx_msgs_per_robot_s"] == pytest.approx(10.0 * row["rx_msgs_per_robot"])
    assert row["tick_us_per_robot"] == pytest.approx(row["tick_us_p50"] / 16)
    assert set(row) >= {f"{k}_us_per_robot" for k in WORLD_STAGES}
    assert {k for panel in WORLD_PLOTTED for k in panel.keys} <= set(row)  # no empty panel


def test_every_plotted_scale_column_is_a_column() -> None:
    assert {k for panel in PLOTTED for k in panel.keys} <= set(COLUMNS)


@pytest.mark.parametrize("argv", [
    ["--agents", "1", "--out", "x"], ["--agents", "a", "--out", "x"], ["--agents", "4"],
    ["--agents", "4", "--out", "x", "--family", "nope"],
    ["--agents", "4", "--out", "x", "--time-scale", "0"],
    ["--agents", "4", "--out", "x", "--hosts", ","],
])
def test_parser_rejects(argv: list[str]) -> None:
    with pytest.raises(SystemExit):
        build_parser().parse_args(["scale", *argv])


def test_received_bytes_and_the_worlds_tick_per_robot() -> None:
    """From the robots' exit lines (robots.json) and the world's ``end`` event."""
    from orchestrator.experiments.scale import received_per_robot

    exits = {"processes": [
        {"robot": 0, "rx_pose_bytes": 1000, "rx_pose_msgs": 10, "cells_views": 8,
         "cells_partial": 1},
        {"robot": 1, "rx_pose_bytes": 3000, "rx_pose_msgs": 30, "cells_views": 8,
         "cells_partial": 0},
        {"robot": 2, "plans": 3},  # an older exit line: not counted
    ]}
    got = received_per_robot(exits, 10.0)
    assert got == {"rx_bytes_per_robot_s": 200.0, "rx_msgs_per_robot_s": 2.0,
                   "cells_partial_rate": 1 / 16}
    assert set(received_per_robot({}, 10.0).values()) == {None}
    row = scale_row({"sim_time_s": 10.0}, [{"kind": "end", "tick_ms": {"mean": 2.5}}],
                    ResourceSampler(), n=50, family="circles", planner="eifp-mpc",
                    spawn_wall=0.0, spawn_mono=0.0, wall_s=12.0, time_scale=1.0,
                    world_status=0, exits=exits)
    assert row["world_tick_ms_mean"] == 2.5 and row["world_tick_us_per_robot"] == 50.0
    assert row["rx_bytes_per_robot_s"] == 200.0
    assert "0.2 / 2" in format_rows([row])
