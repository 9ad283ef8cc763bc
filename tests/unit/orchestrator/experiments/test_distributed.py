"""Tests of the distributed launcher's pure parts (the process tests are in tests/system)."""

from __future__ import annotations

import socket
import sys
from pathlib import Path

import pytest

from eifp_wire import ProtocolError
from orchestrator.experiments.distributed import (
    collect_robot_exits,
    fleet_command,
    free_tcp_endpoint,
    robot_command,
    robot_starts,
    run_distributed,
    world_command,
)
from world.scenario_file import ScenarioError


def test_free_tcp_endpoint_is_bindable() -> None:
    endpoint = free_tcp_endpoint()
    assert endpoint.startswith("tcp/127.0.0.1:")
    port = int(endpoint.rsplit(":", 1)[1])
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", port))


def test_commands(tmp_path: Path) -> None:
    world = world_command("r1", tmp_path / "s.yaml", tmp_path / "out", "tcp/127.0.0.1:9",
                          time_scale=2.0, extra_args=["--cmd-timeout-s", "0.3"])
    assert world[:3] == [sys.executable, "-m", "world"]
    assert world[world.index("--time-scale") + 1] == "2.0"
    assert world[world.index("--listen") + 1] == "tcp/127.0.0.1:9"
    assert world[-2:] == ["--cmd-timeout-s", "0.3"]
    robot = robot_command("r1", 3, "tcp/127.0.0.1:9")
    assert robot[:3] == [sys.executable, "-m", "agent"]
    assert robot[robot.index("--id") + 1] == "3"


def test_fleet_command_passes_ids_and_per_robot_endpoints(tmp_path: Path) -> None:
    from agent.fleet import build_parser

    cmd = fleet_command("r1", [0, 1, 2], "tcp/127.0.0.1:9", tmp_path,
                        robot_endpoints={2: "tcp/127.0.0.2:9"})
    assert cmd[:3] == [sys.executable, "-m", "agent.fleet"]
    args = build_parser().parse_args(cmd[3:])
    assert args.ids == [0, 1, 2] and args.connect == "tcp/127.0.0.1:9"
    assert args.connect_id == [(2, "tcp/127.0.0.2:9")] and args.log_dir == tmp_path.resolve()
    assert args.cpu_tokens == 0 and args.max_starting >= 1  # the fleet's defaults
    tokens = fleet_command("r1", [0], "tcp/127.0.0.1:9", tmp_path, cpu_tokens=2)
    assert build_parser().parse_args(tokens[3:]).cpu_tokens == 2
    for bad in (["--ids", "1,1"], ["--ids", "-1"], ["--ids", "0", "--connect-id", "x"]):
        with pytest.raises(SystemExit):
            build_parser().parse_args(["--run", "r", "--connect", "c", "--log-dir", "d", *bad])


def test_run_distributed_rejects_an_unknown_launcher(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="robot_launcher"):
        run_distributed(tmp_path / "s.yaml", tmp_path, "r1", robot_launcher="thread")


def test_bad_inputs_fail_before_anything_is_spawned(tmp_path: Path) -> None:
    with pytest.raises(ProtocolError):
        run_distributed(tmp_path / "missing.yaml", tmp_path / "out", "bad/run")
    with pytest.raises(ScenarioError):
        run_distributed(tmp_path / "missing.yaml", tmp_path / "out", "ok-run")
    assert not (tmp_path / "out").exists()


def test_robot_args_reach_every_robot_through_the_fleet(tmp_path: Path) -> None:
    from agent.fleet import build_parser, robot_argv
    from agent.startup import parse_args

    cmd = fleet_command("r1", [0, 1], "tcp/127.0.0.1:9", tmp_path, robot_args=["--no-plan"])
    fleet_args = build_parser().parse_args(cmd[3:])
    assert fleet_args.robot_arg == ["--no-plan"]
    argv = robot_argv("r1", 1, "tcp/127.0.0.1:9", "30.0", fleet_args.robot_arg)
    assert parse_args(argv).plan is False
    assert parse_args(robot_argv("r1", 1, "tcp/127.0.0.1:9", "30.0")).plan is True


def test_the_default_startup_deadline_grows_with_the_robot_count() -> None:
    from orchestrator.experiments.distributed import (
        STARTUP_S_MIN,
        STARTUP_S_PER_ROBOT,
        default_startup_timeout_s,
    )

    assert default_startup_timeout_s(4) == STARTUP_S_MIN
    assert default_startup_timeout_s(128) == 128 * STARTUP_S_PER_ROBOT > STARTUP_S_MIN
    assert default_startup_timeout_s(256) > default_startup_timeout_s(128)


def test_start_lines_give_where_each_robot_dialled_and_robots_json_keeps_it(tmp_path: Path):
    # As agent.node logs them (the system tests check the real processes' lines).
    start = ('2026-01-01 00:00:00,000 agent INFO robot 2 start: '
             '{"run": "r1", "connect": "tls/10.0.0.2:7447"}')
    exit_line = "2026-01-01 00:00:09,000 agent INFO robot 2 exit: reason='signal' code=0 plans=7"
    assert robot_starts(start + "\r\n") == [
        {"robot": 2, "run": "r1", "connect": "tls/10.0.0.2:7447"}]
    assert robot_starts("robot 2 start: {not json}\nrobot 2 start: [1]\n") == []
    (tmp_path / "robot_2.log").write_text(f"{start}\nplanning\n{exit_line}\n")
    (tmp_path / "robot_3.log").write_text("robot 3 exit: reason='signal' code=0\n")
    (two, three) = collect_robot_exits(tmp_path)["processes"]
    assert (two["robot"], two["connect"], two["plans"]) == (2, "tls/10.0.0.2:7447", 7)
    assert (three["robot"], three["connect"]) == (3, None)  # no start line: not known
