"""`orchestrator scale` end to end with real processes, robots on two addresses of the world.

Small N only: the figures are checked for presence and sanity, never against time budgets
(the measured table is in docs/scale.md).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from orchestrator.cli import main as cli_main
from orchestrator.experiments.distributed import collect_robot_exits, robot_starts

pytestmark = [pytest.mark.system, pytest.mark.timeout(180)]


def test_scale_run_with_robots_connecting_through_a_second_address(tmp_path: Path,
                                                                   capsys) -> None:
    """The world listens on 0.0.0.0 (mutual TLS: never without it); robots 0, 2 dial
    127.0.0.1 and robots 1, 3 dial 127.0.0.2, as robots on another host would dial the
    world's address, and check its name against its certificate."""
    out = tmp_path / "scale"
    assert cli_main(["scale", "--agents", "4", "--hosts", "127.0.0.1,127.0.0.2", "--insecure",
                     "--out", str(tmp_path / "insecure")]) == 2
    code = cli_main(["scale", "--agents", "4", "--family", "circles",
                     "--hosts", "127.0.0.1,127.0.0.2", "--startup-timeout-s", "60",
                     "--out", str(out), "--json"])
    assert code == 0
    row = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["rows"][0]
    run = out / "circles_4"
    for name in ("scale.csv", "scale.json", "scale.png"):
        assert (out / name).stat().st_size > 0, name
    for name in ("metrics.json", "trajectory.png", "trajectory.csv", "world.log", "robots.json"):
        assert (run / name).stat().st_size > 0, name

    assert row["success"] and row["contacts"] == 0 and row["arrived"] == 4
    assert row["world_status"] == 0
    # Both addresses carried robots: the world's established sockets, by local address.
    assert row["connections"].get("127.0.0.1", 0) >= 2, row["connections"]
    assert row["connections"].get("127.0.0.2", 0) >= 2, row["connections"]
    assert json.loads((run / "run.json").read_text())["hosts"] == ["127.0.0.1", "127.0.0.2"]
    exits = json.loads((run / "robots.json").read_text())["processes"]
    assert sorted(p["robot"] for p in exits) == [0, 1, 2, 3], exits
    assert all(p["reason"] == "end (all_arrived)" and p["code"] == 0 for p in exits), exits
    # Sane figures: present, positive, within physical bounds.
    assert 0.0 < row["alive_s"] < 60.0
    assert 0.0 < row["cpu_share_robots"] <= 1.0 and 0.0 < row["cpu_share_world"] <= 1.0
    assert 5.0 < row["mem_robot_mib"] < 1024.0
    assert row["mem_total_mib"] >= 4 * row["mem_robot_mib"] * 0.5
    assert row["plan_ms_p50"] > 0.0 and row["sim_latency_ms_p99"] >= 0.0
    assert 0.0 <= row["deadline_miss_rate"] <= 1.0
    assert row["sim_time_s"] > 0.0 and row["wall_s"] > row["sim_time_s"]
    # The robots' own CPU split, per plan: every part reported, planning is not free, and
    # the parts add up to no more than the robots' CPU share allows (sampled from outside).
    parts = [row[f"cpu_ms_per_plan_{p}"] for p in ("sense", "plan", "send", "loop", "threads")]
    assert all(x is not None and x >= 0.0 for x in parts), parts
    assert row["cpu_ms_per_plan_plan"] > 0.0 and row["cpu_ms_per_plan_sense"] > 0.0
    assert sum(parts) < 100.0  # ms per 100 ms control period: less than one core per robot


def _fleet(tmp_path: Path, ids: str):
    import subprocess
    import sys

    with open(tmp_path / "fleet.log", "wb") as log:
        return subprocess.Popen(
            [sys.executable, "-m", "agent.fleet", "--run", "t", "--ids", ids, "--connect",
             "tcp/127.0.0.1:9", "--connect-id", "1=tcp/127.0.0.2:9", "--log-dir",
             str(tmp_path), "--startup-timeout-s", "60", "--nice", "3"],
            stdout=subprocess.DEVNULL, stderr=log, cwd=Path(__file__).resolve().parents[2])


def _wait_children(proc, count: int, tmp_path: Path) -> list:
    import time

    import psutil

    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:
        kids = psutil.Process(proc.pid).children()
        logs = [tmp_path / f"robot_{k}.log" for k in range(count)]
        if len(kids) == count and all(p.exists() and p.stat().st_size for p in logs):
            return kids  # every robot is running its own loop (it has logged)
        assert proc.poll() is None, (tmp_path / "fleet.log").read_text()
        time.sleep(0.05)
    raise AssertionError(f"fleet did not fork {count} robots")


@pytest.mark.parametrize("how", ["sigterm", "sigkill"])
def test_fleet_robots_leave_with_the_fleet(tmp_path: Path, how: str) -> None:
    """Robots forked by agent.fleet (waiting for a router that is not there) are real
    processes with their own logs and niceness; SIGTERM is passed on, SIGKILL takes them
    along."""
    import signal

    import psutil

    proc = _fleet(tmp_path, "0,1")
    try:
        kids = _wait_children(proc, 2, tmp_path)
        assert all(k.nice() == psutil.Process(proc.pid).nice() + 3 for k in kids)
        proc.send_signal(signal.SIGTERM if how == "sigterm" else signal.SIGKILL)
        gone, alive = psutil.wait_procs(kids, timeout=20.0)
        assert not alive, alive
        code = proc.wait(20.0)
        assert code == (0 if how == "sigterm" else -signal.SIGKILL)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    # No world, so no run files: which address each robot dialled is in its start line.
    (start_1,) = robot_starts((tmp_path / "robot_1.log").read_text())
    assert (start_1["robot"], start_1["run"], start_1["connect"]) == (1, "t", "tcp/127.0.0.2:9")
    if how == "sigterm":
        (start_0,) = robot_starts((tmp_path / "robot_0.log").read_text())
        assert (start_0["robot"], start_0["connect"]) == (0, "tcp/127.0.0.1:9")
        exits = collect_robot_exits(tmp_path)["processes"]  # robots.json's form
        assert sorted((p["robot"], p["reason"], p["code"], p["connect"]) for p in exits) == [
            (0, "signal", 0, "tcp/127.0.0.1:9"), (1, "signal", 0, "tcp/127.0.0.2:9")], exits


def test_bench_process_prints_a_robots_cpu_per_cycle_by_part(tmp_path: Path, capsys) -> None:
    """`orchestrator bench --process`: real robot processes that do not plan; the figures
    are printed, complete and consistent, never compared with a budget."""
    out = tmp_path / "process"
    assert cli_main(["bench", "--process", "--robots", "3", "--seconds", "3", "--insecure",
                     "--out", str(out), "--json"]) == 0
    text = capsys.readouterr().out
    row = json.loads(text.strip().splitlines()[-1])
    assert "CPU ms per cycle: sense" in text and "Zenoh threads" in text
    assert row["agents"] == 3 and row["transport"] == "plain TCP" and row["robots_lost"] == 0
    parts = [row[f"cpu_ms_per_plan_{p}"] for p in ("sense", "plan", "send", "loop", "threads")]
    assert all(x is not None and x > 0.0 for x in parts), parts
    assert abs(sum(parts) - row["cpu_ms_per_plan_total"]) < 1e-9
    assert sum(parts) < 100.0  # ms per 100 ms cycle: less than a core per robot
    assert (out / "scale.json").stat().st_size > 0
    # Every robot braked every cycle and left on the world's end (robots.json).
    exits = json.loads((out / "circles_3" / "robots.json").read_text())["processes"]
    assert sorted(p["robot"] for p in exits) == [0, 1, 2], exits
    assert all(p["reason"] == "end (time_limit)" and p["code"] == 0 and p["plans"] > 0
               for p in exits), exits


def test_bench_floor_prints_the_cpu_of_a_client_that_only_does_a_robots_io(capsys) -> None:
    """`orchestrator bench --floor`: every client received poses and reported its CPU per
    cycle, split in two parts that add up (figures printed, never compared with a budget)."""
    assert cli_main(["bench", "--floor", "--robots", "3", "--seconds", "2", "--json"]) == 0
    text = capsys.readouterr().out
    row = json.loads(text.strip().splitlines()[-1])
    assert "transport floor, 3 clients" in text and "Zenoh threads" in text
    assert row["robots"] == 3 and row["cycles"] >= 5  # 10 poses a second each
    assert row["main_ms"] > 0.0 and row["zenoh_ms"] > 0.0
    assert abs(row["main_ms"] + row["zenoh_ms"] - row["total_ms"]) < 1e-9
    assert row["pose_bytes"] > 3 * 32  # three discs of four float64 each, and the envelope
