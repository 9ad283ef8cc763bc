"""System test: robots behind a relay router (`world.router`), real processes on loopback.

The world is the router of "host A" (robots 0 and 1 dial it); a relay router stands for
"host B" (robots 2 and 3 dial it, it dials the world), as in compose.routers.yaml without
Docker. Mutual TLS and access control on both routers, robots behind the relay given the
world's fixed Zenoh id. The run completes, every process exits 0 (the relay once the run is
over), and metrics.json splits the wall latency by router. The latency comparison itself is
asserted by the Docker test (tests/docker), where the hosts are separate network namespaces.
Everything is read from the run's structured output (events.jsonl, robots.json as the
launcher writes it, metrics.json) and the exit statuses, not from the logs.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

from agent.process import ExitCode
from agent.security import make_run_pki
from eifp_wire import tls_endpoint
from orchestrator.analysis.rundir import metrics_from_run_dir, write_metrics
from orchestrator.experiments.distributed import (
    collect_robot_exits,
    free_tcp_endpoint,
    robot_command,
    spawn_logged,
    stop_processes,
    world_command,
)
from tests.system.test_distributed import (
    processes_of_run,
    read_events,
    unique_run_id,
    wait_exit,
    wait_for_event,
    write_scenario,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(180)]

STARTUP_S = 60.0
RUN_S = 90.0
WORLD_ZID = "e1f5"
ROBOTS = (0, 1, 2, 3)
BEHIND_RELAY = (2, 3)


def test_robots_behind_a_relay_router_complete_the_run(tmp_path: Path) -> None:
    run_id = unique_run_id("relay")
    out = tmp_path / "run"
    scenario = write_scenario(tmp_path / "crossing.yaml", [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 1, "start": [0.0, -3.0, math.pi / 2], "goal": [0.0, 3.0]},
        {"id": 2, "start": [3.0, 8.0, math.pi], "goal": [-3.0, 8.0]},
        {"id": 3, "start": [0.0, 11.0, -math.pi / 2], "goal": [0.0, 5.0]},
    ], time_limit_s=40.0)
    tls = tmp_path / "tls"
    make_run_pki(tls, run_id, ROBOTS, relays={"b": ()})
    host_a = tls_endpoint(free_tcp_endpoint())
    host_b = tls_endpoint(free_tcp_endpoint())
    procs = []
    try:
        world = spawn_logged(world_command(
            run_id, scenario, out, host_a, time_scale=2.0, wait_robots_s=STARTUP_S,
            tls_dir=tls, extra_args=["--relay", "b=2,3", "--zid", WORLD_ZID]),
            tmp_path / "world.log")
        relay = spawn_logged(
            [sys.executable, "-m", "world.router", "--run", run_id, "--name", "b",
             "--robots", "2,3", "--listen", host_b, "--connect", host_a, "--tls", str(tls),
             "--wait-world-s", repr(STARTUP_S)], tmp_path / "router.log")
        procs = [world, relay]
        robots = {}
        for rid in ROBOTS:
            robots[rid] = spawn_logged(robot_command(
                run_id, rid, host_b if rid in BEHIND_RELAY else host_a,
                startup_timeout_s=STARTUP_S, tls_dir=tls,
                extra_args=["--world-zid", WORLD_ZID]), tmp_path / f"robot_{rid}.log")
            procs.append(robots[rid])
        end = wait_for_event(out, lambda e: e["kind"] == "end", RUN_S, world)
        assert end["reason"] == "all_arrived" and end["contacts"] == 0, end
        assert end["rejected"] == 0 and end["lost"] == []
        # Robots 2 and 3 dial only the relay: arriving, they were served through it.
        assert sorted(end["arrived"]) == list(ROBOTS), end
        assert wait_exit(world) == ExitCode.OK, (tmp_path / "world.log").read_text()
        for rid, proc in robots.items():
            assert wait_exit(proc) == ExitCode.OK, (tmp_path / f"robot_{rid}.log").read_text()
        # OK: the relay left because the world had come and gone and its robots had left
        # (`world.router.RunFollower`), not at its deadline (TRANSPORT).
        assert wait_exit(relay) == ExitCode.OK, (tmp_path / "router.log").read_text()
    finally:
        stop_processes(procs, 0.0, 5.0)
    assert not processes_of_run(run_id), "orphan processes left behind"
    ready = next(e for e in read_events(out) if e["kind"] == "world_ready")
    assert ready["tls"] is True, ready
    # robots.json as the launcher writes it: every robot left on the world's end, and took
    # every pose it read as the world's (the world's id reached them through the relay).
    exits = collect_robot_exits(tmp_path)
    (out / "robots.json").write_text(json.dumps(exits))
    assert sorted(p["robot"] for p in exits["processes"]) == list(ROBOTS), exits
    assert {p["robot"]: p["connect"] for p in exits["processes"]} == {
        rid: host_b if rid in BEHIND_RELAY else host_a for rid in ROBOTS}, exits
    assert all(p["reason"] == "end (all_arrived)" and p["code"] == 0
               for p in exits["processes"]), exits
    assert exits["refused_poses"] == 0 and exits["refused_control"] == 0, exits
    write_metrics(out, metrics_from_run_dir(out))
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["success"] and metrics["arrived"] == len(ROBOTS)
    assert metrics["end"]["refused_poses"] == 0, metrics["end"]
    by = metrics["wall_latency_ms_by_router"]
    assert sorted(by) == ["router-b", "world"]
    for group in by.values():
        assert group["transport"]["n"] > 0 and group["sense_to_act"]["p50"] > 0.0
    assert (by["world"]["sense_to_act"]["n"] + by["router-b"]["sense_to_act"]["n"]
            == metrics["wall_latency_ms"]["sense_to_act"]["n"])
