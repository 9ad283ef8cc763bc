"""Tests of the world process's Zenoh edge, in-process: a `WorldNode` on a router session and a
client session playing the robots, on a free loopback port. The test drives the node's
drain methods itself (no loop thread), waiting on outcomes with deadlines."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from agent.process import StopFlag
from eifp_wire import (
    MAX_CMD_AHEAD_S,
    CommandMsg,
    ControlMsg,
    PosesMsg,
    RunConfigMsg,
    RunKeys,
    max_seq,
    scoped_cn,
)
from orchestrator.experiments.distributed import free_tcp_endpoint
from tests.integration.sessions import open_session
from tests.unit.world.test_world_cycle import TWO_ROBOTS
from world.node import WorldNode, WorldOptions, parse_args, run_configs
from world.recorder import RunRecorder
from world.scenario_file import scenario_from_dict

pytestmark = pytest.mark.timeout(60)

DEADLINE_S = 10.0
SCENARIO = TWO_ROBOTS


def until(condition: Callable[[], bool], step: Callable[[], None], what: str) -> None:
    """Run `step` until `condition` holds; fail after DEADLINE_S."""
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        step()
        time.sleep(0.005)


class Rig:
    def __init__(self, tmp_path: Path) -> None:
        self.endpoint = free_tcp_endpoint()
        self.options = WorldOptions(run_id="node-test", scenario_path=tmp_path / "unused.yaml",
                                    listen=self.endpoint, out_dir=tmp_path / "run")
        self.scenario = scenario_from_dict(SCENARIO, "test")
        self.keys = RunKeys(self.options.run_id)
        self.recorder = RunRecorder(self.options.out_dir, self.scenario)
        self.router = open_session("router", self.endpoint)
        self.node = WorldNode(self.router, self.scenario, self.options, self.recorder,
                              StopFlag())
        self.client = open_session("client", self.endpoint)

    def events(self, kind: str) -> list[dict]:
        self.recorder.flush()
        lines = (self.options.out_dir / "events.jsonl").read_text().splitlines()
        return [e for e in map(json.loads, lines) if e["kind"] == kind]

    def close(self) -> None:
        self.client.close()
        self.router.close()
        self.recorder.close()


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[Rig]:
    r = Rig(tmp_path)
    try:
        yield r
    finally:
        r.close()


def test_serves_each_robot_its_configuration(rig: Rig) -> None:
    replies = rig.client.get(rig.keys.config(4), timeout=DEADLINE_S)
    got: list = []
    until(lambda: bool(got), lambda: (rig.node.serve_queries(),
                                      got.extend(filter(None, [replies.try_recv()]))),
          "the configuration reply")
    config = RunConfigMsg.decode(got[0].ok.payload.to_bytes(), expected_run_id="node-test",
                                 expected_robot_id=4)
    assert config.robot == rig.scenario.robot(4)
    assert config.planner == rig.scenario.planner_config
    assert set(config.known_ids) == {0, 4, -1}
    assert config.world_rate_hz == 50.0 and config.cmd_timeout_s == 0.5

    replies = rig.client.get(rig.keys.config(9), timeout=DEADLINE_S)  # not in the scenario
    got.clear()
    until(lambda: bool(got), lambda: (rig.node.serve_queries(),
                                      got.extend(filter(None, [replies.try_recv()]))),
          "the error reply")
    assert got[0].ok is None and b"no robot" in got[0].err.payload.to_bytes()
    assert rig.node.cycle.counts.bad_queries == 1


def test_liveliness_join_loss_and_rejoin(rig: Rig) -> None:
    node = rig.node
    token = rig.client.liveliness().declare_token(rig.keys.alive_robot(0))
    until(lambda: 0 in node.cycle.alive, node.poll_liveliness, "robot 0 to join")
    assert rig.events("robot_joined")[0]["robot"] == 0
    stray = rig.client.liveliness().declare_token(rig.keys.alive_robot(99))
    until(lambda: bool(rig.events("unknown_robot")), node.poll_liveliness, "unknown robot")

    token.undeclare()
    until(lambda: 0 in node.cycle.lost, node.poll_liveliness, "robot 0 to be lost")
    assert bool(node.sim.offline[node.sim.index_of(0)])
    assert rig.events("robot_lost")[0]["robot"] == 0 and "wall" in rig.events("robot_lost")[0]

    token = rig.client.liveliness().declare_token(rig.keys.alive_robot(0))
    until(lambda: 0 in node.cycle.alive, node.poll_liveliness, "robot 0 to rejoin")
    assert not node.sim.offline[node.sim.index_of(0)] and not node.cycle.lost
    assert rig.events("robot_rejoined")[0]["robot"] == 0
    token.undeclare()
    stray.undeclare()


def test_a_robot_back_after_a_loss_numbers_on_from_time_and_old_commands_stay_stale(
        rig: Rig) -> None:
    """The lease closed a robot's link and it came back: its seq follows time
    (`eifp_wire.clock.next_seq`), so the world keeps its last seq as the bar: a command replayed
    from before the loss is stale, one beyond what the time allows is refused."""
    node = rig.node
    pub0 = rig.client.declare_publisher(rig.keys.cmd(0))
    token = rig.client.liveliness().declare_token(rig.keys.alive_robot(0))
    until(lambda: 0 in node.cycle.alive and pub0.matching_status.matching, node.poll_liveliness,
          "robot 0 to join")

    def cmd(seq: int, v: float) -> bytes:
        return CommandMsg(0, seq, 0.0, v, 0.0, 2.0, "ok").encode()

    for seq in range(0, 640, 32):  # up to seq 608
        pub0.put(cmd(seq, 0.2))
    until(lambda: node.cycle.counts.commands == 20, node.apply_commands, "twenty commands")
    token.undeclare()
    until(lambda: 0 in node.cycle.lost, node.poll_liveliness, "robot 0 to be lost")
    token = rig.client.liveliness().declare_token(rig.keys.alive_robot(0))
    until(lambda: 0 in node.cycle.alive, node.poll_liveliness, "robot 0 to rejoin")
    pub0.put(cmd(max_seq(node.sim.t_s) + 1, 0.9))  # beyond what the time allows
    pub0.put(cmd(512, 0.1))  # replayed from before the loss
    pub0.put(cmd(612, 0.5))
    pub0.put(cmd(613, 0.6))
    counts = node.cycle.counts
    until(lambda: counts.commands + counts.rejected + counts.stale == 24,
          node.apply_commands, "four more commands")
    assert node.cycle.counts.seq_jumps == 1 and node.cycle.counts.commands == 22
    assert node.cycle.counts.stale == 1 and node.cycle.last_seq[0] == 613
    assert node.sim.command[node.sim.index_of(0)][0] == pytest.approx(0.6)
    token.undeclare()


def test_commands_applied_stale_dropped_garbage_rejected(rig: Rig) -> None:
    node = rig.node
    pub0 = rig.client.declare_publisher(rig.keys.cmd(0))
    pub4 = rig.client.declare_publisher(rig.keys.cmd(4))
    until(lambda: pub0.matching_status.matching and pub4.matching_status.matching,
          lambda: None, "command publishers to match")

    def cmd(rid: int, seq: int, v: float) -> bytes:
        return CommandMsg(rid, seq, 0.0, v, 0.1, 2.0, "ok", 1, -1).encode()

    pub0.put(cmd(0, 5, 0.7))
    pub0.put(cmd(0, 5, 0.1))  # same seq: stale
    pub0.put(cmd(0, 3, 0.2))  # older seq: stale
    pub0.put(cmd(4, 9, 0.3))  # robot 4's command on robot 0's key: rejected
    pub4.put(b"\xc1garbage")  # not msgpack: rejected
    pub4.put(ControlMsg("end", 0.0).encode())  # wrong message type: rejected
    pub4.put(cmd(4, 0, 9.0))  # accepted, clamped to v_max by the world
    counts = node.cycle.counts
    until(lambda: counts.commands + counts.stale + counts.rejected == 7,
          node.apply_commands, "seven commands")
    assert (counts.commands, counts.stale, counts.rejected) == (2, 2, 3)
    assert node.sim.command[node.sim.index_of(0)].tolist() == [0.7, 0.1]
    assert node.sim.command[node.sim.index_of(4)][0] == pytest.approx(1.1)  # default v_max
    reasons = [e["reason"] for e in rig.events("rejected")]
    assert len(reasons) == 3 and any("key of robot" in r for r in reasons)
    rig.recorder.flush()
    rows = (rig.options.out_dir / "commands.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[1].startswith("0.0000,0,5,")


def test_a_seq_jump_or_a_plan_from_the_future_is_refused_not_stored(rig: Rig) -> None:
    node = rig.node
    pub0 = rig.client.declare_publisher(rig.keys.cmd(0))
    until(lambda: pub0.matching_status.matching, lambda: None, "command publisher to match")

    def cmd(seq: int, v: float, stamp: float = 0.0) -> bytes:
        return CommandMsg(0, seq, stamp, v, 0.0, 2.0, "ok").encode()

    bound = max_seq(node.sim.t_s)
    pub0.put(cmd(2**63 - 1, 0.9))  # far beyond what the time allows
    pub0.put(cmd(1, 0.5))
    pub0.put(cmd(bound + 1, 0.9))  # one beyond
    pub0.put(cmd(2, 0.4, stamp=MAX_CMD_AHEAD_S + 5.0))  # planned on a pose of the future
    pub0.put(cmd(bound, 0.3))  # the largest allowed now
    until(lambda: node.cycle.counts.commands + node.cycle.counts.rejected == 5, node.apply_commands,
          "five commands")
    assert node.cycle.counts.seq_jumps == 2 and node.cycle.counts.future_cmds == 1
    assert node.cycle.counts.commands == 2 and node.cycle.last_seq[0] == bound
    assert node.sim.command[node.sim.index_of(0)][0] == pytest.approx(0.3)
    node.sim.step(0.5)  # half a second later, half a second more of seq
    pub0.put(cmd(bound + 500, 0.2))
    until(lambda: node.cycle.counts.commands == 3, node.apply_commands, "a later command")
    assert node.cycle.last_seq[0] == bound + 500
    reasons = node.cycle.rejected_by_reason
    assert reasons["cmd.seq"] == 2 and reasons["cmd.pose_stamp"] == 1


def _pose_publishers_match(rig: Rig, slot: int) -> list:
    """The world's publishers of every cell it publishes now, on `slot`, once each matches a
    subscriber (the world declares them on first use)."""
    pubs = [rig.node.poses_pub(slot, cell) for cell, _ in rig.node.cycle.pose_cells()]
    until(lambda: all(p.matching_status.matching for p in pubs), lambda: None,
          "pose subscriber")
    return pubs


def test_control_and_poses_carry_the_worlds_source_info(rig: Rig) -> None:
    node = rig.node
    control = rig.client.declare_subscriber(rig.keys.control)
    poses = rig.client.declare_subscriber(rig.keys.poses_all)
    until(lambda: node.control_pub.matching_status.matching, lambda: None, "control to match")
    _pose_publishers_match(rig, 0)
    node.put_control(ControlMsg("start", 0.0))
    node.publish_poses()
    for sub in (control, poses):
        sample = sub.recv()
        assert isinstance(sample, zenoh.Sample)
        assert sample.source_info is not None
        assert str(sample.source_info.source_id.zid) == str(rig.router.zid())


def test_tick_publishes_poses_one_message_per_cell(rig: Rig) -> None:
    """Every disc is within 5 m of the origin: it is all in cell (0, 0); the world also
    publishes the empty cells around it, within reach of a robot."""
    poses = rig.client.declare_subscriber(rig.keys.poses_all)
    assert rig.node.pose_slots == 5  # 50 Hz world, 10 Hz control
    pubs = _pose_publishers_match(rig, 1)
    assert len(pubs) == 9
    rig.node.tick()
    got: list = []
    until(lambda: len(got) == 9, lambda: got.extend(filter(None, [poses.try_recv()])), "poses")
    by_key = {str(s.key_expr): PosesMsg.decode(s.payload.to_bytes(), known_ids={0, 4, -1})
              for s in got}
    assert set(by_key) == {rig.keys.poses_cell(1, (i, j))  # tick 1 on slot 1 mod 5
                           for i in (-1, 0, 1) for j in (-1, 0, 1)}
    for key, msg in by_key.items():
        assert msg.tick == 1 and msg.t_s == pytest.approx(0.02)
        if key == rig.keys.poses_cell(1, (0, 0)):
            assert msg.robot_ids.tolist() == [0, 4] and msg.obstacle_ids.tolist() == [-1]
        else:
            assert msg.robot_ids.shape == (0,) and msg.obstacle_ids.shape == (0,)


def test_run_configs_encode_every_robot(tmp_path: Path) -> None:
    scenario = scenario_from_dict(SCENARIO, "test")
    options = WorldOptions(run_id="r", scenario_path=tmp_path / "x.yaml", control_rate_hz=20.0)
    configs = run_configs(scenario, options)
    assert set(configs) == {0, 4}
    assert RunConfigMsg.decode(configs[0]).control_rate_hz == 20.0


def test_parse_args_defaults_and_exclusive_endpoints(tmp_path: Path) -> None:
    opts = parse_args(["--run", "r1", "--scenario", "s.yaml"])
    assert opts.listen == "tcp/127.0.0.1:7447" and opts.connect is None
    assert opts.out_dir == Path("runs") / "r1"
    opts = parse_args(["--run", "r1", "--scenario", "s.yaml", "--connect", "tcp/h:1",
                       "--time-scale", "4"])
    assert opts.listen is None and opts.connect == "tcp/h:1" and opts.time_scale == 4.0
    for bad in (["--listen", "a", "--connect", "b"], ["--rate-hz", "-1"], ["--run", "x/y"]):
        with pytest.raises(SystemExit):
            parse_args(["--run", "r1", "--scenario", "s.yaml", *bad])


def test_parse_command_link_fault_options() -> None:
    from world.sim.link import LinkFaults

    opts = parse_args(["--run", "r1", "--scenario", "s.yaml", "--latency-ms", "50",
                       "--jitter-ms", "15", "--drop", "0.2", "--fault-seed", "3"])
    assert opts.link == LinkFaults(latency_ms=50.0, jitter_ms=15.0, drop=0.2)
    assert opts.fault_seed == 3
    assert not parse_args(["--run", "r1", "--scenario", "s.yaml"]).link.active
    for bad in (["--drop", "-0.1"], ["--reorder", "2"], ["--jitter-ms", "nan"]):
        with pytest.raises(SystemExit):
            parse_args(["--run", "r1", "--scenario", "s.yaml", *bad])


def test_relays_and_a_fixed_id_go_into_the_worlds_router_settings(tmp_path: Path) -> None:
    from agent.security import make_run_pki
    from world.node import world_settings

    make_run_pki(tmp_path / "tls", "r1", [0, 4])
    scenario = scenario_from_dict(SCENARIO, "test")
    opts = parse_args(["--run", "r1", "--scenario", "s.yaml", "--listen", "tls/0.0.0.0:7447",
                       "--tls", str(tmp_path / "tls"), "--relay", "b=4", "--zid", "e1f0a5"])
    assert opts.relays == (("b", (4,)),) and opts.zid == "e1f0a5"
    settings = world_settings(opts, scenario)
    acl = json.loads(settings["access_control"])
    assert {"id": "s-router-b",
            "cert_common_names": [scoped_cn("router-b", "r1")]} in acl["subjects"]
    assert json.loads(settings["id"]) == "e1f0a5"
    bad = [
        (["--relay", "b=7"], "robots of the run"),          # not in the scenario
        (["--connect", "tls/h:1"], "--tls with --connect"),  # the world's router enforces
    ]
    for extra, words in bad:
        argv = ["--run", "r1", "--scenario", "s.yaml", "--tls", str(tmp_path / "tls"), *extra]
        with pytest.raises(ValueError, match=words):
            world_settings(parse_args(argv), scenario)
    with pytest.raises(ValueError, match="--relay needs --tls"):
        world_settings(parse_args(["--run", "r1", "--scenario", "s.yaml", "--relay", "b=4"]),
                       scenario)


def test_a_pose_subscriber_puts_each_sample_on_the_robots_queue(rig: Rig) -> None:
    """The robot's pose handler (`agent.process.enqueue_on_receive`): Zenoh's receiving
    thread puts every sample on a queue the robot's loop blocks on; nothing else runs."""
    import queue

    from agent.process import enqueue_on_receive
    from eifp_wire import PoseDecoder

    handler = enqueue_on_receive(queue.SimpleQueue().put)
    if isinstance(handler, zenoh.handlers.Callback):
        assert handler.indirect is False  # on Zenoh's thread: no thread of its own
    samples: queue.SimpleQueue = queue.SimpleQueue()
    sub = rig.client.declare_subscriber(rig.keys.poses_cell(0, (0, 0)),
                                        enqueue_on_receive(samples.put))
    try:
        pub = rig.node.poses_pub(0, (0, 0))
        until(lambda: pub.matching_status.matching, lambda: None, "pose subscriber")
        rig.node.publish_poses()  # tick 0: slot 0
        sample = samples.get(timeout=DEADLINE_S)
        assert PoseDecoder().decode(sample.payload.to_bytes()).tick == 0
    finally:
        sub.undeclare()


def test_one_zenoh_thread_unless_the_environment_says_otherwise(monkeypatch) -> None:
    import os

    from agent.process import ONE_THREAD_RUNTIME, use_one_zenoh_thread

    monkeypatch.delenv("ZENOH_RUNTIME", raising=False)
    use_one_zenoh_thread()
    assert os.environ["ZENOH_RUNTIME"] == ONE_THREAD_RUNTIME
    monkeypatch.setenv("ZENOH_RUNTIME", "(rx: (worker_threads: 2))")
    use_one_zenoh_thread()
    assert os.environ["ZENOH_RUNTIME"] == "(rx: (worker_threads: 2))"
