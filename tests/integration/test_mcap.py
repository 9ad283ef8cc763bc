"""run.mcap read back with the real readers (`mcap`, `mcap-protobuf-support`), the live
Foxglove WebSocket view of a lockstep run (`websockets`), and the optional MP4."""

from __future__ import annotations

import asyncio
import base64
import csv
import dataclasses
import hashlib
import json
import socket
import struct
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import Schema as McapSchema
from mcap_protobuf.decoder import DecoderFactory

from orchestrator.cli import main
from orchestrator.experiments.families import resolve
from orchestrator.experiments.lockstep import run_lockstep
from world.mcap_log import (
    SCENE_EVERY_TICKS,
    SCENE_TOPIC,
    command_topic,
    plan_raw_topic,
    plan_topic,
)

pytestmark = pytest.mark.integration

ROBOTS = (0, 1)


@pytest.fixture(scope="module")
def setup_a_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A whole lockstep run of setup_a (2 robots, eIFP-MPC)."""
    out = tmp_path_factory.mktemp("setup_a")
    run_lockstep(resolve("setup_a"), out)
    return out


def _ticks(out: Path) -> int:
    with open(out / "trajectory.csv") as f:
        return len({row["t"] for row in csv.DictReader(f)})


def _rows(path: Path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


def test_channels_schemas_and_counts(setup_a_run: Path) -> None:
    with open(setup_a_run / "run.mcap", "rb") as f:
        summary = make_reader(f, validate_crcs=True).get_summary()
    assert summary is not None
    counts = summary.statistics.channel_message_counts
    by_topic = {c.topic: (cid, c) for cid, c in summary.channels.items()}
    expected = {SCENE_TOPIC: ("protobuf", "foxglove.SceneUpdate")}
    for rid in ROBOTS:
        expected[command_topic(rid)] = ("json", "eifp.Command")
        expected[plan_topic(rid)] = ("protobuf", "foxglove.SceneUpdate")
        expected[plan_raw_topic(rid)] = ("json", "eifp.PlanDebug")
    assert set(by_topic) == set(expected)
    for topic, (encoding, schema) in expected.items():
        _, channel = by_topic[topic]
        assert (channel.message_encoding, summary.schemas[channel.schema_id].name) == (
            encoding, schema), topic
    # The scene on every SCENE_EVERY_TICKS-th recorded tick (tick 0 included).
    ticks = _ticks(setup_a_run)
    assert counts[by_topic[SCENE_TOPIC][0]] == -(-ticks // SCENE_EVERY_TICKS)
    commands = _rows(setup_a_run / "commands.csv")
    for rid in ROBOTS:
        n_cmds = sum(int(r["robot"]) == rid for r in commands)
        assert counts[by_topic[command_topic(rid)][0]] == n_cmds
        # Every plan made it (lockstep without faults: one command applied per plan).
        assert counts[by_topic[plan_topic(rid)][0]] == n_cmds
        assert counts[by_topic[plan_raw_topic(rid)][0]] == n_cmds
    assert sum(counts[by_topic[command_topic(r)][0]] for r in ROBOTS) == len(commands)
    # Log times are sim times: 0 .. the last tick.
    last_t = max(float(r["t"]) for r in _rows(setup_a_run / "trajectory.csv"))
    assert summary.statistics.message_start_time == 0
    assert summary.statistics.message_end_time <= round(last_t * 1e9)


def test_scene_and_plan_decode(setup_a_run: Path) -> None:
    with open(setup_a_run / "run.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        scenes = [(m.log_time, d) for _, _, m, d in
                  reader.iter_decoded_messages(topics=[SCENE_TOPIC])]
        plan = next(d for _, _, _, d in reader.iter_decoded_messages(topics=[plan_topic(0)]))
    log_time, scene = scenes[1]
    ids = [e.id for e in scene.entities]
    robots = [e for e in scene.entities if e.id.startswith("robot/")]
    assert [e.id for e in robots] == [f"robot/{r}" for r in ROBOTS]
    assert "obstacles" in ids
    disc = robots[0].cylinders[0]
    assert disc.size.x == pytest.approx(2 * resolve("setup_a").robots[0].radius_m)
    assert robots[0].arrows[0].pose.orientation.w != 0.0  # a rotation, not the zero quaternion
    assert robots[0].timestamp.seconds * 10**9 + robots[0].timestamp.nanos == log_time
    # Each robot's goal disc (made once per goal and reused) is at its own goal, every scene.
    goals = {f"robot/{spec.id}": spec.goal for spec in resolve("setup_a").robots}
    for _, s in scenes:
        for e in s.entities:
            if e.id in goals:
                at = e.cylinders[1].pose.position
                assert (at.x, at.y) == pytest.approx(goals[e.id])
    # Trails come as entities of their own, in some scenes only.
    assert any(e.id == "trail/0" for _, s in scenes for e in s.entities)
    entity = plan.entities[0]
    assert entity.id == "robot/0/plan"
    assert len(entity.lines) >= 2  # reference path and MPC prediction (eIFP-MPC)
    with open(setup_a_run / "run.mcap", "rb") as f:  # JSON: no decoder in mcap; json.loads
        raw = [json.loads(m.data) for _, _, m in
               make_reader(f).iter_messages(topics=[plan_raw_topic(1), command_topic(1)])]
    plans = [r for r in raw if "reference_path" in r]
    cmds = [r for r in raw if "reference_path" not in r]
    assert plans and cmds
    assert {"t", "robot", "ego", "threats", "via_points", "reference_path", "mpc_prediction",
            "v", "omega", "status"} == set(plans[0])
    assert len(plans[0]["mpc_prediction"]) == 21  # horizon 20, from the robot's own pose
    assert any(p["threats"] for p in plans)  # setup A: the two robots threaten each other
    assert {"t", "robot", "seq", "v", "omega", "status", "side", "resolved"} == set(cmds[0])


def test_lockstep_recording_is_deterministic(tmp_path: Path) -> None:
    scenario = dataclasses.replace(resolve("setup_a"), time_limit_s=6.0)
    digests = []
    for k in range(2):
        run_lockstep(scenario, tmp_path / str(k))
        digests.append(hashlib.sha256((tmp_path / str(k) / "run.mcap").read_bytes()).digest())
    assert digests[0] == digests[1]


# --- live view -------------------------------------------------------------------------------


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


async def _receive_scenes(port: int, want: int, deadline_s: float) -> tuple[dict, list]:
    """Foxglove WebSocket protocol: serverInfo + advertise -> subscribe -> binary message
    frames (opcode 0x01, u32 subscription id, u64 log time, payload)."""
    import websockets

    end = time.monotonic() + deadline_s
    while True:  # the server starts with the CLI in the other thread
        try:
            ws = await websockets.connect(f"ws://127.0.0.1:{port}",
                                          subprotocols=["foxglove.sdk.v1",
                                                        "foxglove.websocket.v1"],
                                          open_timeout=2.0)
            break
        except OSError:
            if time.monotonic() > end:
                raise
            await asyncio.sleep(0.05)
    async with ws:
        assert ws.subprotocol == "foxglove.sdk.v1"
        channels: dict[str, dict] = {}
        while SCENE_TOPIC not in channels:
            msg = json.loads(await asyncio.wait_for(ws.recv(), end - time.monotonic()))
            if msg["op"] == "advertise":
                channels.update({c["topic"]: c for c in msg["channels"]})
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 7, "channelId": channels[SCENE_TOPIC]["id"]}]}))
        got = []
        while len(got) < want:
            frame = await asyncio.wait_for(ws.recv(), end - time.monotonic())
            if isinstance(frame, bytes) and frame[0] == 0x01:
                sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                assert sub_id == 7
                got.append((log_time, frame[13:]))
        return channels[SCENE_TOPIC], got


def test_live_view_of_a_lockstep_run(tmp_path: Path) -> None:
    """`orchestrator run --mode lockstep --live`: a client receives the scene while the run
    goes (paced at --time-scale, so that there is time to connect)."""
    scenario = tmp_path / "short.yaml"
    scenario.write_text(
        "name: live_test\ntime_limit: 3.0\ngoal_tolerance: 0.25\n"
        "robots:\n  - {id: 0, start: [0, 0, 0], goal: [20, 0]}\n"
        "  - {id: 1, start: [20, 1, 3.14], goal: [0, 1]}\n")
    port = _free_port()
    result: dict[str, int] = {}

    def run() -> None:
        result["rc"] = main(["run", str(scenario), "--mode", "lockstep", "--live",
                             "--live-port", str(port), "--time-scale", "1", "--quiet",
                             "--out", str(tmp_path / "run")])

    thread = threading.Thread(target=run)
    thread.start()
    try:
        channel, got = asyncio.run(_receive_scenes(port, want=5, deadline_s=20.0))
    finally:
        thread.join(30)
    assert result.get("rc") is not None
    assert channel["schemaName"] == "foxglove.SceneUpdate"
    times = [t for t, _ in got]
    assert times == sorted(times) and len(set(times)) == len(times)  # sim-time log times
    schema = McapSchema(id=1, name=channel["schemaName"], encoding="protobuf",
                        data=base64.b64decode(channel["schema"]))
    scene = DecoderFactory().decoder_for("protobuf", schema)(got[-1][1])
    assert sum(e.id.startswith("robot/") for e in scene.entities) == 2
    assert (tmp_path / "run" / "run.mcap").stat().st_size > 0  # recorded as well


# --- MP4 (optional) ---------------------------------------------------------------------------


def test_mp4_of_a_run(setup_a_run: Path, tmp_path: Path) -> None:
    from orchestrator.analysis.plots import animate, mp4_available
    from orchestrator.analysis.rundir import read_run_dir

    why = mp4_available()
    if why is not None:
        pytest.skip(why)
    import imageio_ffmpeg

    path = animate(read_run_dir(setup_a_run), tmp_path / "run.mp4", max_frames=40)
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(path))
    assert frames == 40
