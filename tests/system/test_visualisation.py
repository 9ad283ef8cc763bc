"""System test of run.mcap and the live view with real processes: a distributed head-on run
(world + 2 robots on loopback) whose world records every robot's plan internals, watched
through the launcher's passive live bridge by a Foxglove WebSocket client."""

from __future__ import annotations

import asyncio
import json
import math
import struct
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from orchestrator.experiments.distributed import run_distributed
from tests.system.test_distributed import (
    STARTUP_S,
    processes_of_run,
    read_events,
    unique_run_id,
    write_scenario,
)
from world.mcap_log import SCENE_TOPIC, LiveView, command_topic, plan_raw_topic, plan_topic

pytestmark = [pytest.mark.system, pytest.mark.timeout(240)]


async def _watch(port: int, topics: list[str], stop: threading.Event, got: dict) -> None:
    """Subscribe to `topics` as they are advertised; count the messages per topic.

    Connects at once, while the launcher starts the world and the bridge makes its channels
    (`LiveView(robot_ids=...)` made them first: no "unknown channel" refusal)."""
    import websockets

    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"],
                                  open_timeout=10) as ws:
        subscribed: dict[int, str] = {}
        while not stop.is_set():
            try:
                frame = await asyncio.wait_for(ws.recv(), 0.2)
            except TimeoutError:
                continue
            if isinstance(frame, bytes):
                if frame[0] == 0x01:
                    sub_id, _ = struct.unpack_from("<IQ", frame, 1)
                    topic = subscribed[sub_id]
                    got[topic] = got.get(topic, 0) + 1
                continue
            msg = json.loads(frame)
            if msg["op"] != "advertise":
                continue
            subs = []
            for c in msg["channels"]:
                if c["topic"] in topics:
                    subscribed[c["id"]] = c["topic"]
                    subs.append({"id": c["id"], "channelId": c["id"]})
            if subs:
                await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))


def test_distributed_run_records_plans_of_every_robot_and_serves_them_live(
        tmp_path: Path) -> None:
    scenario = write_scenario(tmp_path / "head_on.yaml", [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 1, "start": [3.0, 0.05, math.pi], "goal": [-3.0, 0.05]},
    ], time_limit_s=40.0)
    run_id = unique_run_id("viz")
    out_dir = tmp_path / "run"
    watched = [SCENE_TOPIC, plan_topic(0), plan_topic(1), command_topic(1)]
    got: dict[str, int] = {}
    stop = threading.Event()
    with LiveView("127.0.0.1", 0, robot_ids=[0, 1]) as live:
        client = threading.Thread(
            target=lambda: asyncio.run(_watch(live.port, watched, stop, got)), daemon=True)
        client.start()
        try:
            code = run_distributed(scenario, out_dir, run_id, time_scale=2.0,
                                   startup_timeout_s=STARTUP_S, live=live)
        finally:
            time.sleep(0.3)
            stop.set()
            client.join(10)
    assert code == 0, (out_dir / "world.log").read_text()
    end = next(e for e in read_events(out_dir) if e["kind"] == "end")
    assert end["rejected"] == 0 and end["plans"] > 0

    with open(out_dir / "run.mcap", "rb") as f:
        summary = make_reader(f, validate_crcs=True).get_summary()
    counts = {summary.channels[cid].topic: n
              for cid, n in summary.statistics.channel_message_counts.items()}
    for rid in (0, 1):
        assert counts.get(plan_topic(rid), 0) > 10, counts
        assert counts[plan_raw_topic(rid)] == counts[plan_topic(rid)]
        assert counts[command_topic(rid)] > 10
    assert sum(counts[plan_topic(r)] for r in (0, 1)) == end["plans"]
    assert counts[SCENE_TOPIC] > 50
    with open(out_dir / "run.mcap", "rb") as f:
        plans = [json.loads(m.data) for _, _, m in
                 make_reader(f).iter_messages(topics=[plan_raw_topic(1)])]
    assert all(p["robot"] == 1 for p in plans)
    assert any(p["threats"] == [0] for p in plans)  # head-on: robot 0 is robot 1's threat

    # The live view: the passive bridge republished the scene, plans and commands.
    assert got.get(SCENE_TOPIC, 0) > 20, got
    assert got.get(plan_topic(0), 0) > 5 and got.get(plan_topic(1), 0) > 5, got
    assert got.get(command_topic(1), 0) > 5, got
    assert not processes_of_run(run_id), "orphan processes left behind"
