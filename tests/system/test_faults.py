"""System tests of injected faults: real processes, the launcher's fault schedule, floods.

Same rules as test_distributed.py: unique run ids, free ports, deadlines on every wait,
events and files rather than sleeps.
"""

from __future__ import annotations

import json
import math
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import psutil
import pytest

from agent.process import ExitCode
from eifp_wire import CommandMsg, PosesMsg, ProtocolError, RunKeys
from orchestrator.experiments.distributed import free_tcp_endpoint, run_distributed
from tests.system.test_distributed import (
    RUN_S,
    STARTUP_S,
    client_session,
    garbage_commands,
    garbage_poses,
    launch,  # noqa: F401 - the fixture
    processes_of_run,
    read_events,
    unique_run_id,
    wait_exit,
    wait_for_event,
    wait_matching,
    write_scenario,
)
from world.node import LOST_GRACE_S
from world.sim.faults import build_plan

pytestmark = [pytest.mark.system, pytest.mark.timeout(240)]


def lanes(path: Path, n: int, length_m: float = 14.0) -> Path:
    """n robots on parallel lanes 3 m apart (no interaction): every run is easy to finish."""
    return write_scenario(path, [
        {"id": k, "start": [-length_m / 2, 3.0 * k, 0.0], "goal": [length_m / 2, 3.0 * k]}
        for k in range(n)], time_limit_s=60.0)


def by_kind(events: list[dict], kind: str, robot: int | None = None) -> list[dict]:
    return [e for e in events if e["kind"] == kind and (robot is None or e.get("robot") == robot)]


def test_links_with_latency_loss_duplication_and_reordering(tmp_path: Path) -> None:
    # Head-on at 100 ms ± 30 ms per link, 10 % loss, 5 % duplicates, 5 % reordered.
    scenario = write_scenario(tmp_path / "head_on.yaml", [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 1, "start": [3.0, 0.05, math.pi], "goal": [-3.0, 0.05]},
    ], time_limit_s=40.0)
    plan = build_plan(latency_ms=100, jitter_ms=30, drop=0.1, dup=0.05, reorder=0.05, seed=2)
    out = tmp_path / "run"
    code = run_distributed(scenario, out, unique_run_id("links"), time_scale=1.0,
                           startup_timeout_s=STARTUP_S, faults=plan)
    assert code == 0, (out / "world.log").read_text()
    events = read_events(out)
    start, end = by_kind(events, "start")[0], by_kind(events, "end")[0]
    assert start["cmd_link"]["latency_ms"] == 100.0
    assert end["contacts"] == 0 and end["success"]
    assert end["cmd_link"]["dropped"] > 0 and end["cmd_link"]["duplicated"] > 0
    assert end["stale"] > 0  # duplicates and overtaken commands dropped by seq
    rows = [r.split(",") for r in (out / "commands.csv").read_text().split()[1:]]
    latency_ms = np.median([(float(r[0]) - float(r[3])) * 1e3 for r in rows])
    assert 190.0 <= latency_ms <= 300.0, latency_ms  # two links of 100 ms (+ ticks, loop)
    robots = json.loads((out / "robots.json").read_text())
    assert len(robots["processes"]) == 2
    for p in robots["processes"]:
        assert p["code"] == 0 and p["link_dropped"] > 0 and p["stale"] > 0, p
    print(f"command latency p50 {latency_ms:.0f} ms; min gap {end['min_gap_m']} m")


def test_stopped_robot_brakes_is_lost_resumes_and_a_restarted_one_rejoins(tmp_path) -> None:
    # Robot 1 is SIGSTOPped for 3 s of sim time, robot 2 SIGKILLed and restarted, both at 3 s.
    scenario = lanes(tmp_path / "lanes.yaml", 3)
    plan = build_plan(stop=["1@3:3"], restart=["2@3"])
    out = tmp_path / "run"
    code = run_distributed(scenario, out, unique_run_id("stop"), time_scale=1.0,
                           startup_timeout_s=STARTUP_S, faults=plan)
    events = read_events(out)
    assert code == 0, (events, (out / "world.log").read_text())
    actions = [json.loads(x) for x in (out / "faults.jsonl").read_text().splitlines()]
    assert [(a["robot"], a["action"]) for a in actions] == [
        (1, "SIGSTOP"), (2, "SIGKILL"), (2, "restarted"), (1, "SIGCONT")] or [
        (a["robot"], a["action"]) for a in actions] == [
        (2, "SIGKILL"), (2, "restarted"), (1, "SIGSTOP"), (1, "SIGCONT")]
    stop = next(a for a in actions if a["action"] == "SIGSTOP")
    assert 3.0 <= stop["t"] < 3.5
    # The world brakes robot 1 on the command time-out, loses it after the lease, and
    # takes it back after SIGCONT; robot 2 is lost at once and re-joins as a new process.
    timeout = by_kind(events, "cmd_timeout", 1)[0]
    lost1 = by_kind(events, "robot_lost", 1)[0]
    back1 = by_kind(events, "robot_rejoined", 1)[0]
    assert stop["t"] + 0.4 <= timeout["t"] <= stop["t"] + 1.2  # 0.5 s after its last command
    assert 0.8 <= lost1["wall"] - stop["wall"] <= 3.0
    assert back1["t"] > lost1["t"]
    assert by_kind(events, "robot_lost", 2) and by_kind(events, "robot_rejoined", 2)
    end = by_kind(events, "end")[0]
    assert end["reason"] == "all_arrived" and end["contacts"] == 0 and end["lost"] == []
    # Robot 1 stood still while stopped: no progress between the time-out + braking and
    # the SIGCONT.
    cont = next(a for a in actions if a["action"] == "SIGCONT")
    xs = [float(r.split(",")[2]) for r in (out / "trajectory.csv").read_text().split()[1:]
          if r.split(",")[1] == "1"
          and timeout["t"] + 1.0 <= float(r.split(",")[0]) <= cont["t"]]
    assert xs and max(xs) - min(xs) < 1e-6
    robots = json.loads((out / "robots.json").read_text())
    mine = [p for p in robots["processes"] if p["robot"] == 1]
    assert mine[0]["code"] == 0 and mine[0]["suspended"] >= 1
    assert len([p for p in robots["processes"] if p["robot"] == 2]) == 1  # the restarted one
    print(f"stop: cmd_timeout +{timeout['t'] - stop['t']:.2f} s sim, robot_lost "
          f"+{lost1['wall'] - stop['wall']:.2f} s wall, rejoined +{back1['t'] - stop['t']:.2f} s")


def test_killed_robot_is_avoided_by_the_launchers_schedule(tmp_path: Path) -> None:
    scenario = write_scenario(tmp_path / "crossing.yaml", [
        {"id": 0, "start": [-6.0, 0.0, 0.0], "goal": [5.0, 0.0]},
        {"id": 1, "start": [0.0, -3.0, math.pi / 2], "goal": [0.0, 4.0]},
    ], time_limit_s=20.0)
    out = tmp_path / "run"
    code = run_distributed(scenario, out, unique_run_id("skill"), time_scale=1.0,
                           startup_timeout_s=STARTUP_S, faults=build_plan(kill=["1@3"]))
    assert code == ExitCode.ROBOT_LOST  # robot 1 was killed and never arrives
    events = read_events(out)
    end = by_kind(events, "end")[0]
    assert end["contacts"] == 0 and end["lost"] == [1] and end["arrived"] == [0]
    # Robot 0 arrived, robot 1 was lost: the run ends once the lost robot's grace is over
    # (`world.world_cycle.LOST_GRACE_S` of sim time after the loss), not at the 20 s limit.
    lost = by_kind(events, "robot_lost", 1)[0]
    assert 3.0 <= lost["t"] < 3.5
    arrived_t = by_kind(events, "arrived", 0)[0]["t"]
    assert end["reason"] == "arrived_or_lost"
    assert end["t"] == pytest.approx(max(arrived_t, lost["t"] + LOST_GRACE_S), abs=0.1)
    assert end["t"] < 20.0 - 1.0


def test_ten_thousand_malformed_messages_are_counted_and_survived(tmp_path: Path) -> None:
    import zenoh

    scenario = lanes(tmp_path / "lanes.yaml", 2, length_m=16.0)
    run_id = unique_run_id("flood")
    endpoint = free_tcp_endpoint()
    out = tmp_path / "run"
    result: dict[str, int] = {}
    launcher = threading.Thread(target=lambda: result.setdefault("code", run_distributed(
        scenario, out, run_id, time_scale=1.0, endpoint=endpoint,
        startup_timeout_s=STARTUP_S, tls=False)), daemon=True)  # a client without a
    # certificate could not even connect with TLS (tests/system/test_rogue.py)
    launcher.start()
    keys = RunKeys(run_id)
    n_cmd, rate_hz, burst = 10_000, 1000.0, 20
    sent_poses = 0
    with client_session(endpoint) as session:
        wait_for_event(out, lambda e: e["kind"] == "start", STARTUP_S)
        # Both lanes' robots are in pose cell (0, 0) (within 10 m of the origin).
        poses = session.declare_subscriber(keys.poses_cell(None, (0, 0)),
                                           zenoh.handlers.RingChannel(1))
        # Reliable and blocking: nothing of ours may be dropped on the way, so the world's
        # count can be compared exactly.
        pubs = {k: session.declare_publisher(
                    k, congestion_control=zenoh.CongestionControl.BLOCK,
                    reliability=zenoh.Reliability.RELIABLE)
                for k in (keys.cmd(0), keys.cmd(1), keys.cmd(7), f"{keys.prefix}/cmd/abc")}
        # Cell (0, 0) on each robot's pose slot (robot k plans on slot k): each robot gets
        # every forged pose once, and its decoder sees it.
        pose_pubs = [session.declare_publisher(keys.poses_cell(slot, (0, 0))) for slot in (0, 1)]
        for pub in (*pubs.values(), *pose_pubs):
            wait_matching(pub)
        real = None
        deadline = time.monotonic() + RUN_S
        while real is None:
            assert time.monotonic() < deadline, "no poses from the world"
            sample = poses.try_recv()
            if sample is None:
                time.sleep(0.005)
                continue
            try:
                real = PosesMsg.decode(sample.payload.to_bytes(), known_ids={0, 1})
            except ProtocolError:
                continue
            # The world's source info, copied: the garbage gets past the robots' source
            # check and reaches their decoder.
            world_source = sample.source_info
        valid = CommandMsg(0, 0, real.t_s, 0.0, 0.0, 1.0, "ok")
        cmd_garbage = [payload for _, payload, _ in garbage_commands(valid)]
        body = msgpack.unpackb(valid.encode())
        cmd_garbage += [msgpack.packb({**body, "v": float("inf")}),
                        msgpack.packb({**body, "seq": -1}),
                        msgpack.packb({**body, "status": "x" * 10_000}),
                        msgpack.packb([0.0] * 50_000)]
        pose_garbage = garbage_poses(real)
        rng = np.random.default_rng(0)
        key_list = list(pubs)
        t0 = time.monotonic()
        for k in range(n_cmd):
            pubs[key_list[k % len(key_list)]].put(
                cmd_garbage[k % len(cmd_garbage)] if k % 3 else rng.bytes(int(rng.integers(200))))
            if k % burst == burst - 1:
                if sent_poses < 200:
                    for pose_pub in pose_pubs:
                        pose_pub.put(pose_garbage[sent_poses % len(pose_garbage)],
                                     source_info=world_source)
                    sent_poses += 1
                pause = t0 + (k + 1) / rate_hz - time.monotonic()
                if pause > 0:
                    time.sleep(pause)
        flood_s = time.monotonic() - t0
        end = wait_for_event(out, lambda e: e["kind"] == "end", RUN_S)
    launcher.join(STARTUP_S + RUN_S)
    assert not launcher.is_alive(), "the launcher did not return"
    assert result["code"] == 0, (out / "world.log").read_text()
    assert end["reason"] == "all_arrived" and end["success"] and end["contacts"] == 0
    # Every one of them rejected and counted: the exact total, and by key and by reason.
    assert end["rejected"] == n_cmd, end
    assert sum(end["rejected_by_key"].values()) == n_cmd
    assert sum(end["rejected_by_reason"].values()) == n_cmd
    assert set(end["rejected_by_key"]) == set(key_list)
    assert len(by_kind(read_events(out), "rejected")) == 100  # the first 100 in detail
    robots = json.loads((out / "robots.json").read_text())
    assert [p["code"] for p in robots["processes"]] == [0, 0]
    assert 1 <= robots["rejected_poses"] <= 2 * sent_poses
    assert not processes_of_run(run_id)
    print(f"{n_cmd} malformed commands in {flood_s:.1f} s, {sent_poses} malformed poses: "
          f"world rejected {end['rejected']}, robots {robots['rejected_poses']}; "
          f"by reason {end['rejected_by_reason']}")


def test_orchestrator_reports_a_killed_world_as_failed_not_hung(tmp_path: Path) -> None:
    out = tmp_path / "run"
    cli = subprocess.Popen(
        [sys.executable, "-m", "orchestrator", "run", str(lanes(tmp_path / "l.yaml", 2)),
         "--out", str(out), "--quiet"], cwd=Path(__file__).resolve().parents[2],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        wait_for_event(out, lambda e: e["kind"] == "start", STARTUP_S)
        world = [p for p in psutil.process_iter(["cmdline"])
                 if "world" in (p.info["cmdline"] or []) and str(out.resolve())
                 in (p.info["cmdline"] or [])]
        assert len(world) == 1
        killed = time.monotonic()
        world[0].send_signal(signal.SIGKILL)
        try:
            stdout, stderr = cli.communicate(timeout=30.0)
        except subprocess.TimeoutExpired:
            pytest.fail("the orchestrator hung after the world was killed")
        took_s = time.monotonic() - killed
    finally:
        if cli.poll() is None:
            cli.kill()
            cli.wait()
    assert cli.returncode == ExitCode.WORLD_LOST, stderr.decode()
    # "the world exited with status 137" (or, killed before any row was written, "the
    # distributed run left no trajectory (world exit status 137)").
    assert re.search(rb"world exit(ed with)? status 137", stderr), stderr
    robots = json.loads((out / "robots.json").read_text())
    for p in robots["processes"]:
        assert p["code"] == ExitCode.WORLD_LOST and p["reason"].startswith("world lost"), p
    assert took_s < 10.0
    print(f"orchestrator exited {took_s:.2f} s after the world was SIGKILLed")


def test_robots_stop_and_fail_when_the_world_hangs(tmp_path: Path, launch) -> None:  # noqa: F811
    # A SIGSTOPped world: no token change at first; the transport lease (1 s) closes the
    # robots' link, the world's token vanishes, and they leave with status 3.
    run = launch("worldstop")
    run.start(lanes(tmp_path / "lanes.yaml", 2), [0, 1], time_scale=1.0)
    wait_for_event(run.out_dir, lambda e: e["kind"] == "start", STARTUP_S, run.world)
    run.world.send_signal(signal.SIGSTOP)
    t0 = time.monotonic()
    try:
        codes = [wait_exit(run.robots[rid], 10.0) for rid in (0, 1)]
        exit_s = time.monotonic() - t0
    finally:
        run.world.send_signal(signal.SIGCONT)
    assert codes == [ExitCode.WORLD_LOST, ExitCode.WORLD_LOST]
    assert exit_s < 5.0, f"robots took {exit_s:.2f} s to leave (README states < 5 s)"
    print(f"robots exited {exit_s:.2f} s after the world was SIGSTOPped")


def test_stress_in_distributed_mode_runs_real_processes_with_the_links(tmp_path: Path) -> None:
    from orchestrator.cli import main

    out = tmp_path / "stress"
    assert main(["stress", str(lanes(tmp_path / "lanes.yaml", 2, length_m=6.0)),
                 "--mode", "distributed", "--sweep", "latency_ms=60", "--planners", "ifp",
                 "--seeds", "1", "--out", str(out)]) == 0
    (row,) = json.loads((out / "stress.json").read_text())["rows"]
    assert row["error"] is None and row["success"] and row["contacts"] == 0
    assert 115.0 <= row["sim_latency_ms_p50"] <= 200.0  # 60 ± 18 ms on each of the two links
    run = out / row["dir"]
    assert (run / "robots.json").exists() and (run / "world.log").exists()
    start = next(e for e in read_events(run) if e["kind"] == "start")
    assert start["cmd_link"]["jitter_ms"] == pytest.approx(18.0)
