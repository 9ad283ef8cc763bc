"""System tests: the world and the robots as real OS processes talking Zenoh on loopback.

Every run has a unique run id and a free port; every process has a start and an exit
deadline; the tests wait on events (events.jsonl lines, poses on the wire, process exits),
never on fixed sleeps. The test process opens its own Zenoh session only after every child
has been spawned.
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import msgpack
import numpy as np
import psutil
import pytest

from agent.process import ExitCode
from eifp_wire import CommandMsg, ControlMsg, PosesMsg, ProtocolError, RunKeys, session_settings
from orchestrator.experiments.distributed import (
    free_tcp_endpoint,
    robot_command,
    robot_starts,
    run_distributed,
    spawn_logged,
    stop_processes,
    world_command,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(240)]

STARTUP_S = 60.0
"""Deadline for processes to start (imports on a loaded 2-core machine can be slow)."""
RUN_S = 90.0
"""Deadline for a run to reach an event once started."""
EXIT_S = 20.0
"""Deadline for a process to exit once asked to."""

EXIT_LINE = re.compile(r"robot (\d+) exit: reason='([^']*)' code=(\d+)(.*)$", re.MULTILINE)


def unique_run_id(tag: str) -> str:
    return f"test-{tag}-{uuid.uuid4().hex[:10]}"


def write_scenario(path: Path, robots: list[dict], time_limit_s: float = 60.0) -> Path:
    lines = [
        "name: system_test",
        "description: written by tests/system/test_distributed.py",
        f"time_limit: {time_limit_s}",
        "goal_tolerance: 0.25",
        "defaults: {radius: 0.3, v_max: 1.0, omega_max: 1.5}",
        "robots:",
    ]
    for r in robots:
        lines.append(f"  - {{id: {r['id']}, start: {list(r['start'])}, goal: {list(r['goal'])}}}")
    lines.append("obstacles: []")
    path.write_text("\n".join(lines) + "\n")
    return path


def read_events(out_dir: Path) -> list[dict]:
    try:
        text = (out_dir / "events.jsonl").read_text()
    except FileNotFoundError:
        return []
    return [json.loads(line) for line in text.splitlines() if line.endswith("}")]


def wait_for_event(out_dir: Path, match: Callable[[dict], bool], deadline_s: float,
                   world: subprocess.Popen | None = None) -> dict:
    """The first event satisfying `match`, polling events.jsonl until the deadline."""
    deadline = time.monotonic() + deadline_s
    while True:
        for event in read_events(out_dir):
            if match(event):
                return event
        if world is not None and world.poll() is not None:
            # The world is gone: its file is complete, one last look.
            for event in read_events(out_dir):
                if match(event):
                    return event
            pytest.fail(f"world exited ({world.returncode}) before the awaited event; "
                        f"events: {read_events(out_dir)}")
        if time.monotonic() > deadline:
            pytest.fail(f"no matching event within {deadline_s} s; events: {read_events(out_dir)}")
        time.sleep(0.02)


def wait_exit(proc: subprocess.Popen, deadline_s: float = EXIT_S) -> int:
    try:
        return proc.wait(timeout=deadline_s)
    except subprocess.TimeoutExpired:
        pytest.fail(f"process {proc.args[:4]} did not exit within {deadline_s} s")


def robot_exit_lines(out_dir: Path) -> dict[int, tuple[str, int, dict[str, int]]]:
    """robot id -> (reason, code, counters) from each robot log's exit line."""
    out = {}
    for log in out_dir.glob("robot_*.log"):
        for m in EXIT_LINE.finditer(log.read_text()):
            counters = {k: int(v) for k, v in re.findall(r"(\w+)=(\d+)", m.group(4))}
            out[int(m.group(1))] = (m.group(2), int(m.group(3)), counters)
    return out


def processes_of_run(run_id: str) -> list[psutil.Process]:
    found = []
    for p in psutil.process_iter(["cmdline"]):
        cmdline = p.info.get("cmdline") or []
        if run_id in cmdline:
            found.append(p)
    return found


class Launch:
    """Processes of one hand-launched run; whatever is still alive is killed at teardown."""

    def __init__(self, tmp_path: Path, tag: str) -> None:
        self.run_id = unique_run_id(tag)
        self.endpoint = free_tcp_endpoint()
        self.out_dir = tmp_path / "run"
        self.out_dir.mkdir()
        self.world: subprocess.Popen | None = None
        self.robots: dict[int, subprocess.Popen] = {}

    def start(self, scenario: Path, robot_ids: list[int], time_scale: float) -> None:
        self.world = spawn_logged(
            world_command(self.run_id, scenario, self.out_dir, self.endpoint,
                          time_scale=time_scale, wait_robots_s=STARTUP_S),
            self.out_dir / "world.log")
        for rid in robot_ids:
            self.robots[rid] = spawn_logged(
                robot_command(self.run_id, rid, self.endpoint, startup_timeout_s=STARTUP_S),
                self.out_dir / f"robot_{rid}.log")

    def kill_all(self) -> None:
        procs = [p for p in (self.world, *self.robots.values()) if p is not None]
        stop_processes(procs, 0.0, 5.0)


@pytest.fixture
def launch(tmp_path: Path) -> Iterator[Callable[[str], Launch]]:
    launches: list[Launch] = []

    def make(tag: str) -> Launch:
        launches.append(Launch(tmp_path, tag))
        return launches[-1]

    yield make
    for launched in launches:
        launched.kill_all()
        assert not processes_of_run(launched.run_id), "orphan processes left behind"


def client_session(endpoint: str):
    import zenoh

    conf = zenoh.Config()
    for key, value in session_settings(mode="client", connect=[endpoint],
                                       connect_timeout_ms=int(STARTUP_S * 1000)).items():
        conf.insert_json5(key, value)
    return zenoh.open(conf)


def wait_matching(publisher, deadline_s: float = STARTUP_S) -> None:
    deadline = time.monotonic() + deadline_s
    while not publisher.matching_status.matching:
        if time.monotonic() > deadline:
            pytest.fail("rogue publisher never matched a subscriber")
        time.sleep(0.01)


# --- (a) a head-on run to completion ----------------------------------------------------------


def test_head_on_run_completes_without_contact(tmp_path: Path) -> None:
    scenario = write_scenario(tmp_path / "head_on.yaml", [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 1, "start": [3.0, 0.05, math.pi], "goal": [-3.0, 0.05]},
    ], time_limit_s=40.0)
    run_id = unique_run_id("headon")
    out_dir = tmp_path / "run"
    progress = []
    t0 = time.monotonic()
    code = run_distributed(scenario, out_dir, run_id, time_scale=2.0,
                           startup_timeout_s=STARTUP_S, on_progress=progress.append)
    wall_s = time.monotonic() - t0

    assert code == 0, (out_dir / "world.log").read_text()
    events = read_events(out_dir)
    end = [e for e in events if e["kind"] == "end"]
    assert len(end) == 1 and end[0]["reason"] == "all_arrived" and end[0]["success"]
    assert end[0]["contacts"] == 0 and end[0]["rejected"] == 0
    assert not [e for e in events if e["kind"] == "contact"]
    assert {e["robot"] for e in events if e["kind"] == "arrived"} == {0, 1}
    assert end[0]["commands"] > 0
    exits = robot_exit_lines(out_dir)
    assert set(exits) == {0, 1}
    for reason, rcode, counters in exits.values():
        assert rcode == 0 and reason == "end (all_arrived)"
        assert counters["rejected"] == 0 and counters["plans"] > 0
    for name in ("scenario.yaml", "trajectory.csv", "commands.csv", "world.log"):
        assert (out_dir / name).stat().st_size > 0
    assert progress and progress[-1].arrived == {0, 1} and progress[-1].started
    # Every applied command carries its wall stamps; on one host every stage is measured.
    from orchestrator.analysis.latency import TRANSPORT_STAGE, WALL_STAGES
    from orchestrator.analysis.rundir import metrics_from_run_dir, read_timing

    assert read_timing(out_dir).shape[0] == end[0]["commands"]
    metrics = metrics_from_run_dir(out_dir)
    wall = metrics.wall_latency_ms
    assert set(wall) == {stage for stage, *_ in WALL_STAGES} | {TRANSPORT_STAGE}
    for stage, w in wall.items():
        assert 0.0 <= w["p50"] <= w["p99"] <= w["max"] < 5000.0, (stage, w)
    assert wall["sense_to_act"]["p50"] >= wall["plan"]["p50"]
    assert wall["sense_to_act"]["p50"] >= wall[TRANSPORT_STAGE]["p50"]
    assert metrics.wall_latency_ms_by_router == {}  # one router: no groups
    assert not processes_of_run(run_id), "orphan processes left behind"
    print(f"head-on run: {wall_s:.1f} s wall, sim t={end[0]['t']} s")


# --- (b) a robot SIGKILLed mid-run ---------------------------------------------------------------


def test_killed_robot_is_detected_and_avoided(tmp_path: Path, launch) -> None:
    import zenoh

    # Robot 1 crosses robot 0's path well ahead of it; it is killed on that path, so robot 0
    # must go around a braked, silent robot.
    scenario = write_scenario(tmp_path / "crossing.yaml", [
        {"id": 0, "start": [-6.0, 0.0, 0.0], "goal": [5.0, 0.0]},
        {"id": 1, "start": [0.0, -2.0, math.pi / 2], "goal": [0.0, 4.0]},
    ], time_limit_s=60.0)
    run = launch("kill")
    run.start(scenario, [0, 1], time_scale=1.0)
    keys = RunKeys(run.run_id)
    with client_session(run.endpoint) as session:
        # Both robots are in pose cell (0, 0) (within 10 m of the origin), on every slot.
        poses = session.declare_subscriber(keys.poses_cell(None, (0, 0)),
                                           zenoh.handlers.RingChannel(1))
        deadline = time.monotonic() + STARTUP_S + RUN_S
        while True:
            sample = poses.try_recv()
            if sample is not None:
                msg = PosesMsg.decode(sample.payload.to_bytes())
                row = int(np.flatnonzero(msg.robot_ids == 1)[0])
                if msg.robot_pose[row, 1] >= -0.3:
                    break
            assert run.world.poll() is None, "world exited early"
            assert time.monotonic() < deadline, "robot 1 never reached robot 0's path"
            time.sleep(0.005)
        x0 = msg.robot_pose[int(np.flatnonzero(msg.robot_ids == 0)[0]), 0]
        kill_wall = time.time()
        run.robots[1].send_signal(signal.SIGKILL)
    lost = wait_for_event(run.out_dir, lambda e: e["kind"] == "robot_lost", 5.0, run.world)
    detect_s = lost["wall"] - kill_wall
    assert lost["robot"] == 1
    assert detect_s < 1.0, f"robot_lost logged {detect_s:.3f} s after SIGKILL"

    # Robot 0 arrives, robot 1 is lost: the world ends the run by itself (it used to run
    # on to the 60 s time limit), once robot 1 has been lost for its grace.
    assert wait_exit(run.world, STARTUP_S + RUN_S) == ExitCode.ROBOT_LOST
    assert wait_exit(run.robots[0]) == 0
    events = read_events(run.out_dir)
    assert not [e for e in events if e["kind"] == "contact"], events
    end = [e for e in events if e["kind"] == "end"][0]
    assert end["reason"] == "arrived_or_lost" and end["contacts"] == 0 and end["lost"] == [1]
    assert end["arrived"] == [0] and end["t"] < 60.0 - 10.0
    reason, code, _ = robot_exit_lines(run.out_dir)[0]
    assert code == 0 and reason == "end (arrived_or_lost)"
    assert x0 < -1.5, f"robot 0 was already at x={x0:.2f} when robot 1 was killed"
    print(f"robot_lost logged {detect_s * 1e3:.1f} ms after SIGKILL (robot 0 at x={x0:.2f}); "
          f"min gap {end['min_gap_m']} m")


def test_killed_robot_restarted_with_the_same_id_rejoins_and_finishes(tmp_path: Path,
                                                                     launch) -> None:
    # Robot 1 is SIGKILLed a few metres into its run, then a new process with the same id
    # starts: the world logs robot_rejoined, accepts its commands (its seq starts over) and
    # the run ends with both robots arrived and no contact.
    scenario = write_scenario(tmp_path / "pair.yaml", [
        {"id": 0, "start": [-8.0, 0.0, 0.0], "goal": [8.0, 0.0]},
        {"id": 1, "start": [-8.0, 4.0, 0.0], "goal": [8.0, 4.0]},
    ], time_limit_s=60.0)
    run = launch("rejoin")
    run.start(scenario, [0, 1], time_scale=1.0)
    wait_for_event(run.out_dir, lambda e: e["kind"] == "start", STARTUP_S, run.world)
    lines_before = len(read_events(run.out_dir))
    run.robots[1].send_signal(signal.SIGKILL)
    wait_for_event(run.out_dir, lambda e: e["kind"] == "robot_lost" and e["robot"] == 1, 5.0,
                   run.world)
    assert wait_exit(run.robots[1]) == -signal.SIGKILL
    run.robots[1] = spawn_logged(
        robot_command(run.run_id, 1, run.endpoint, startup_timeout_s=STARTUP_S),
        run.out_dir / "robot_1_restarted.log")
    back = wait_for_event(run.out_dir,
                          lambda e: e["kind"] == "robot_rejoined" and e["robot"] == 1,
                          STARTUP_S, run.world)
    assert back["t"] >= 0.0
    assert wait_exit(run.world, STARTUP_S + RUN_S) == 0  # all arrived, no contact
    events = read_events(run.out_dir)
    assert len(events) > lines_before
    end = [e for e in events if e["kind"] == "end"][0]
    assert end["reason"] == "all_arrived" and end["contacts"] == 0
    assert sorted(end["arrived"]) == [0, 1]


# --- (c) a rogue publisher --------------------------------------------------------------------


def garbage_commands(valid: CommandMsg) -> list[tuple[int, bytes, str]]:
    """(robot key id, payload, what) for malformed commands."""
    data = valid.encode()
    body = msgpack.unpackb(data)
    rng = np.random.default_rng(11)
    nan_body = {**body, "v": float("nan")}
    extra_body = {**body, "turbo": True}
    version_body = {**body, "schema": 99}
    return [
        (0, rng.bytes(40), "random bytes"),
        (0, data[: len(data) // 2], "truncated"),
        (0, msgpack.packb(nan_body), "NaN speed"),
        (1, msgpack.packb(extra_body), "extra key"),
        (1, msgpack.packb(version_body), "bad schema version"),
        (1, data, "robot 0's command on robot 1's key"),
        (7, CommandMsg(7, 1, 0.0, 0.5, 0.0, 1.0, "ok").encode(), "unknown robot"),
        (0, ControlMsg("end", 1.0, "forged").encode(), "control message on a command key"),
        (1, b"", "empty"),
        (0, msgpack.packb([1, 2, 3]), "not a map"),
    ]


def garbage_poses(valid: PosesMsg) -> list[bytes]:
    body = msgpack.unpackb(valid.encode())
    nan_x = np.frombuffer(body["discs"], "<f8").copy()
    nan_x[0] = np.nan  # the first robot's x
    unknown = PosesMsg(valid.t_s, valid.tick + 10**6, [0, 1, 42], np.zeros((3, 3)),
                       [0.3, 0.3, 0.3], [], np.zeros((0, 2)), [])
    data = valid.encode()
    return [
        np.random.default_rng(5).bytes(64),
        data[:-7],
        msgpack.packb({**body, "discs": nan_x.tobytes()}),
        msgpack.packb({**body, "schema": 0}),
        unknown.encode(),  # valid shape but an id outside the run
        CommandMsg(0, 1, 0.0, 1.0, 0.0, 1.0, "ok").encode(),
    ]


def test_rogue_publisher_is_rejected_and_counted(tmp_path: Path, launch) -> None:
    import zenoh

    scenario = write_scenario(tmp_path / "head_on.yaml", [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 1, "start": [3.0, 0.05, math.pi], "goal": [-3.0, 0.05]},
    ], time_limit_s=40.0)
    run = launch("rogue")
    run.start(scenario, [0, 1], time_scale=1.0)
    keys = RunKeys(run.run_id)
    sent_cmds = 0
    with client_session(run.endpoint) as session:
        wait_for_event(run.out_dir, lambda e: e["kind"] == "start", STARTUP_S, run.world)
        # Robot 0's pose slot (robots subscribe to theirs only) and pose cell (both robots
        # are in cell (0, 0) and hold it); the garbage goes to that cell on both robots'
        # slots (robot k plans on slot k), once per period, right after robot 0's pose.
        poses = session.declare_subscriber(keys.poses_cell(0, (0, 0)),
                                           zenoh.handlers.RingChannel(1))
        rogue_poses = [session.declare_publisher(keys.poses_cell(slot, (0, 0)))
                       for slot in (0, 1)]
        rogue_cmds = {rid: session.declare_publisher(keys.cmd(rid)) for rid in (0, 1, 7)}
        for pub in (*rogue_poses, *rogue_cmds.values()):
            wait_matching(pub)

        def next_real_pose() -> PosesMsg:
            """The next pose from the world (our own garbage reaches us too: skip it)."""
            deadline = time.monotonic() + RUN_S
            while True:
                assert time.monotonic() < deadline, "no poses from the world"
                sample = poses.try_recv()
                if sample is None:
                    time.sleep(0.002)
                    continue
                try:
                    msg = PosesMsg.decode(sample.payload.to_bytes(), known_ids={0, 1})
                except ProtocolError:
                    continue
                world_source.append(sample.source_info)
                return msg

        world_source: list = []
        real = next_real_pose()
        valid_cmd = CommandMsg(0, 0, real.t_s, 0.0, 0.0, 1.0, "ok")
        for rid, payload, _what in garbage_commands(valid_cmd):
            rogue_cmds[rid].put(payload)
            sent_cmds += 1
        # One garbage pose right after each real one: it lands between two real poses in
        # the robots' rings, so it is read (and rejected), not overwritten.
        bad_poses = garbage_poses(real)
        for payload in bad_poses:
            next_real_pose()
            # With the world's source info copied, past the robots' source check and on to
            # their decoder.
            for pub in rogue_poses:
                pub.put(payload, source_info=world_source[-1])

        end = wait_for_event(run.out_dir, lambda e: e["kind"] == "end", RUN_S, run.world)
    assert wait_exit(run.world) == 0, (run.out_dir / "world.log").read_text()
    for proc in run.robots.values():
        assert wait_exit(proc) == 0

    assert end["reason"] == "all_arrived" and end["contacts"] == 0
    assert end["rejected"] == sent_cmds
    rejected_events = [e for e in read_events(run.out_dir) if e["kind"] == "rejected"]
    assert len(rejected_events) == sent_cmds
    assert all(e["reason"] for e in rejected_events)
    exits = robot_exit_lines(run.out_dir)
    for rid in (0, 1):
        reason, code, counters = exits[rid]
        assert code == 0 and reason == "end (all_arrived)"
        assert 1 <= counters["rejected"] <= len(bad_poses), counters
    print(f"world rejected {end['rejected']}/{sent_cmds} commands; robots rejected "
          f"{[exits[r][2]['rejected'] for r in (0, 1)]} of {len(bad_poses)} poses each")


# --- (d) the world disappears ---------------------------------------------------------------


def test_robots_stop_and_fail_when_the_world_is_killed(tmp_path: Path, launch) -> None:
    scenario = write_scenario(tmp_path / "head_on.yaml", [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 1, "start": [3.0, 0.05, math.pi], "goal": [-3.0, 0.05]},
    ], time_limit_s=40.0)
    run = launch("worldkill")
    run.start(scenario, [0, 1], time_scale=1.0)
    wait_for_event(run.out_dir, lambda e: e["kind"] == "start", STARTUP_S, run.world)
    run.world.send_signal(signal.SIGKILL)
    t0 = time.monotonic()
    codes = [wait_exit(run.robots[rid], 10.0) for rid in (0, 1)]
    exit_s = time.monotonic() - t0
    assert codes == [ExitCode.WORLD_LOST, ExitCode.WORLD_LOST]
    assert exit_s < 3.0, f"robots took {exit_s:.2f} s to leave (README states < 3 s)"
    for reason, code, _ in robot_exit_lines(run.out_dir).values():
        assert code == ExitCode.WORLD_LOST and reason.startswith("world lost")
    print(f"robots exited {exit_s:.2f} s after the world was SIGKILLed")


# --- (e) Ctrl-C on the launcher ----------------------------------------------------------------


def test_ctrl_c_on_the_launcher_leaves_no_orphans(tmp_path: Path) -> None:
    scenario = write_scenario(tmp_path / "head_on.yaml", [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 1, "start": [3.0, 0.05, math.pi], "goal": [-3.0, 0.05]},
    ], time_limit_s=40.0)
    run_id = unique_run_id("ctrlc")
    out_dir = tmp_path / "run"
    code = (
        # A shell's background job inherits SIGINT ignored: give the launcher Ctrl-C back.
        "import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
        "import sys; from pathlib import Path; "
        "from orchestrator.experiments.distributed import run_distributed; "
        f"sys.exit(run_distributed(Path({str(scenario)!r}), Path({str(out_dir)!r}), "
        f"{run_id!r}, startup_timeout_s={STARTUP_S}))"
    )
    launcher = subprocess.Popen([sys.executable, "-c", code], start_new_session=True,
                                cwd=Path(__file__).resolve().parents[2],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        wait_for_event(out_dir, lambda e: e["kind"] == "start", STARTUP_S)
        assert len(processes_of_run(run_id)) == 3  # world + 2 robots
        launcher.send_signal(signal.SIGINT)
        try:
            _, stderr = launcher.communicate(timeout=30.0)
        except subprocess.TimeoutExpired:
            pytest.fail("launcher did not exit within 30 s of Ctrl-C")
        assert launcher.returncode != 0 and b"KeyboardInterrupt" in stderr
        assert not processes_of_run(run_id), "orphan processes left behind"
        end = [e for e in read_events(out_dir) if e["kind"] == "end"]
        assert len(end) == 1 and end[0]["reason"] == "signal"
        for reason, rcode, _ in robot_exit_lines(out_dir).values():
            assert rcode == 0 and reason == "end (signal)"
    finally:
        if launcher.poll() is None:
            os.killpg(launcher.pid, signal.SIGKILL)
            launcher.wait()
        for proc in processes_of_run(run_id):
            proc.kill()


# --- (f) a robot without a world ----------------------------------------------------------------


def test_robot_without_world_gives_up_at_its_startup_deadline(tmp_path: Path) -> None:
    run_id = unique_run_id("noworld")
    endpoint = free_tcp_endpoint()  # nobody listens there
    log = tmp_path / "robot_0.log"
    robot = spawn_logged(robot_command(run_id, 0, endpoint, startup_timeout_s=2.0), log)
    try:
        assert wait_exit(robot, STARTUP_S) == ExitCode.TRANSPORT
    finally:
        stop_processes([robot], 0.0, 5.0)
    reason, code, _ = robot_exit_lines(tmp_path)[0]
    assert code == ExitCode.TRANSPORT and reason.startswith("cannot connect")


def test_robot_exits_cleanly_on_sigterm(tmp_path: Path) -> None:
    run_id = unique_run_id("sigterm")
    robot = spawn_logged(robot_command(run_id, 0, free_tcp_endpoint(), startup_timeout_s=60.0),
                         tmp_path / "robot_0.log")
    try:
        # Wait for its start line (its signal handlers are in place), then stop it.
        deadline = time.monotonic() + STARTUP_S
        while not robot_starts((tmp_path / "robot_0.log").read_text()):
            assert time.monotonic() < deadline and robot.poll() is None
            time.sleep(0.02)
        robot.send_signal(signal.SIGTERM)
        assert wait_exit(robot, 10.0) == 0
    finally:
        stop_processes([robot], 0.0, 5.0)
    reason, code, _ = robot_exit_lines(tmp_path)[0]
    assert code == 0 and reason == "signal"
