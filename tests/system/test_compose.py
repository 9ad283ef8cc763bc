"""`orchestrator compose await`, the orchestrator's container role, against real processes on
loopback (the world and robots the containers run, without Docker). The scenario step and
the certificates are in tests/integration/test_compose.py."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.experiments.compose import SCENARIO_FILE
from orchestrator.experiments.distributed import (
    free_tcp_endpoint,
    robot_command,
    spawn_logged,
    stop_processes,
    world_command,
)

TWO_LANES = """\
name: two_lanes
description: two robots on parallel lanes (tests/system/test_compose.py)
time_limit: 40
goal_tolerance: 0.25
defaults: {radius: 0.3, v_max: 1.0, omega_max: 1.5}
robots:
  - {id: 0, start: [0.0, 0.0, 0.0], goal: [3.0, 0.0]}
  - {id: 1, start: [0.0, 3.0, 0.0], goal: [3.0, 3.0]}
obstacles: []
"""


@pytest.mark.system
@pytest.mark.timeout(120)
def test_await_without_a_world_gives_up_at_the_deadline(tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "orchestrator", "compose", "await", "--setup", "setup_a",
           "--run", "nobody", "--runs-dir", str(tmp_path), "--connect", free_tcp_endpoint(),
           "--startup-timeout-s", "2"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 6, proc.stderr  # ExitCode.TRANSPORT: no world to connect to
    assert "cannot connect" in proc.stderr
    assert not (tmp_path / "nobody" / "metrics.json").exists()


@pytest.mark.system
@pytest.mark.timeout(240)
def test_await_follows_a_real_run_and_writes_the_report(tmp_path: Path) -> None:
    """The orchestrator's container role, started before the world as Compose may do."""
    setup = tmp_path / "two_lanes.yaml"
    setup.write_text(TWO_LANES)
    runs = tmp_path / "runs"
    run_id = f"test-compose-{uuid.uuid4().hex[:8]}"
    endpoint = free_tcp_endpoint()
    common = ["--setup", str(setup), "--robots", "2", "--run", run_id, "--runs-dir", str(runs)]
    assert main(["compose", "scenario", *common]) == 0
    run_dir = runs / run_id
    procs: list[subprocess.Popen] = []
    try:
        orchestrator = spawn_logged(
            [sys.executable, "-m", "orchestrator", "compose", "await", *common, "--connect",
             endpoint, "--startup-timeout-s", "60"], tmp_path / "orchestrator.log")
        procs.append(orchestrator)
        procs.append(spawn_logged(world_command(run_id, run_dir / SCENARIO_FILE, run_dir,
                                                endpoint, wait_robots_s=60.0),
                                  tmp_path / "world.log"))
        for rid in (0, 1):
            procs.append(spawn_logged(robot_command(run_id, rid, endpoint,
                                                    startup_timeout_s=60.0),
                                      tmp_path / f"robot_{rid}.log"))
        try:
            status = orchestrator.wait(timeout=180)
        except subprocess.TimeoutExpired:
            pytest.fail("the orchestrator did not exit within 180 s:\n"
                        + (tmp_path / "orchestrator.log").read_text()[-3000:])
    finally:
        stop_processes(procs, 10.0, 5.0)
    log = (tmp_path / "orchestrator.log").read_text()
    assert status == 0, log[-3000:]
    assert "every robot is alive" in log and "world left" in log
    for name in ("metrics.json", "report.txt", "run.json", "trajectory.png"):
        assert (run_dir / name).stat().st_size > 0, name
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["success"] is True and metrics["arrived"] == 2 and metrics["contacts"] == 0
    run = json.loads((run_dir / "run.json").read_text())
    assert run["mode"] == "docker-compose" and run["run_id"] == run_id
    # The same ending fields as `orchestrator run` writes (`rundir.run_ending`).
    assert (run["status"], run["exit_code"], run["end_reason"], run["lost"]) == (
        "complete", 0, "all_arrived", [])
    report = (run_dir / "report.txt").read_text()
    assert "end reason all_arrived" in report
    # The summary table reads the ending from metrics.json, as a local run's summary does.
    assert re.search(r"end reason\s+all_arrived", report.split("\n\n")[0]), report
