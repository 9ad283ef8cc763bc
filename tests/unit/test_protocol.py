"""Tests of the wire protocol: round trips, one rejection test per kind of malformation, and
fuzzing (arbitrary bytes / msgpack objects / mutated valid messages decode to a valid
message or raise ProtocolError, never anything else)."""

from __future__ import annotations

import copy
import dataclasses
import math
import re

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import protocol
from agent.core.config import SUB_CONFIGS, MpcConfig, PlannerConfig, RobotLimits
from agent.core.scenario import RobotSpec
from agent.core.types import PlanDebug, PlanResult, PlanStatus, PoseSnapshot, Side
from protocol import (
    MAX_DEBUG_POINTS,
    MAX_DEBUG_THREATS,
    MAX_MESSAGE_BYTES,
    MAX_ROBOTS,
    SCHEMA_VERSION,
    CommandMsg,
    ControlMsg,
    PlanDebugMsg,
    PosesMsg,
    ProtocolError,
    RunConfigMsg,
    RunKeys,
    plan_pose_slot,
    pose_slot_count,
    pose_slot_of_tick,
    session_settings,
    validate_run_id,
)

FUZZ = settings(max_examples=300, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow])


def make_poses(n: int = 3, m: int = 2, t_s: float = 1.25, tick: int = 62) -> PosesMsg:
    rng = np.random.default_rng(7)
    return PosesMsg(
        t_s=t_s,
        tick=tick,
        robot_ids=np.arange(n),
        robot_pose=rng.uniform(-5.0, 5.0, size=(n, 3)),
        robot_radius_m=np.full(n, 0.5),
        obstacle_ids=-1 - np.arange(m),
        obstacle_xy_m=rng.uniform(-5.0, 5.0, size=(m, 2)),
        obstacle_radius_m=np.full(m, 0.3),
    )


def make_command(**overrides: object) -> CommandMsg:
    fields = dict(robot_id=2, seq=17, pose_stamp_s=3.2, v_mps=0.9, omega_radps=-0.4,
                  plan_ms=4.5, status="ok", side=1, resolved_id=5, hold_s=0.15)
    fields.update(overrides)
    return CommandMsg(**fields)


def make_config() -> RunConfigMsg:
    spec = RobotSpec(id=2, start=(-4.0, 0.5, 0.1), goal=(4.0, -0.5), radius_m=0.4,
                     limits=RobotLimits(v_max_mps=0.8, omega_max_radps=1.2), planner="eifp")
    planner = PlannerConfig(mpc=MpcConfig(horizon_steps=15, clearance_margin_m=0.2),
                            profile="paper").with_settings(**{
                                "safety.d_safety_m": 0.25, "threats.max_neighbors": 7,
                                "cost.side_hysteresis": 0.3, "reference.corner_radius_m": 0.5,
                                "orca.time_horizon_s": 3.0})
    return RunConfigMsg(run_id="run-1", robot=spec, planner=planner, goal_tolerance_m=0.2,
                        control_rate_hz=10.0, world_rate_hz=50.0, time_scale=1.0, time_limit_s=60.0,
                        cmd_timeout_s=0.5, known_ids=(0, 1, 2, -1),
                        static_map=((-1, 0.0, 5.0, 1.0),))


def make_debug(**overrides: object) -> PlanDebugMsg:
    rng = np.random.default_rng(11)
    debug = PlanDebug(ego=np.array([1.0, -2.0, 0.3]), threat_ids=(0, 1, -1),
                      via_points_m=rng.uniform(-5, 5, (1, 2)),
                      reference_m=rng.uniform(-5, 5, (21, 2)),
                      predicted_m=rng.uniform(-5, 5, (21, 2)))
    fields = dict(robot_id=2, seq=17, t_s=3.2, v_mps=0.9, omega_radps=-0.4, status="ok",
                  debug=debug)
    fields.update(overrides)
    return PlanDebugMsg(**fields)


def raw(msg: object) -> dict:
    """The msgpack map of an encoded message, for hand mutation."""
    return msgpack.unpackb(msg.encode())


def discs(body: dict) -> np.ndarray:
    """A writable copy of a raw `PosesMsg` body's disc rows (k, 4): x, y, heading, radius."""
    return np.frombuffer(body["discs"], dtype="<f8").reshape(-1, 4).copy()


def poses_body(ids: list[int], rows: np.ndarray | None = None) -> dict:
    """A raw `PosesMsg` body with these ids (robots first) and disc rows (default: at the
    origin, heading 0, radius 1)."""
    if rows is None:
        rows = np.zeros((len(ids), 4))
        rows[:, 3] = 1.0
    body = raw(make_poses())
    body["ids"] = np.array(ids, dtype="<i4").tobytes()
    body["discs"] = np.asarray(rows, dtype="<f8").tobytes()
    return body


def pack(obj: object) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


DECODERS = (PosesMsg.decode, CommandMsg.decode, RunConfigMsg.decode, ControlMsg.decode,
            PlanDebugMsg.decode)


# --- Round trips ---------------------------------------------------------------------------


def test_poses_round_trip() -> None:
    msg = make_poses()
    back = PosesMsg.decode(msg.encode(), known_ids={0, 1, 2, -1, -2})
    assert back.t_s == msg.t_s and back.tick == msg.tick
    for name in ("robot_ids", "robot_pose", "robot_radius_m", "obstacle_ids", "obstacle_xy_m",
                 "obstacle_radius_m"):
        np.testing.assert_array_equal(getattr(back, name), getattr(msg, name))
    assert back.n_robots == 3


def test_poses_far_from_the_origin_round_trip() -> None:
    """Coordinates beyond the decoder's quick bound (1 km) are checked column by column and
    pass up to MAX_COORD_M."""
    msg = make_poses()
    far = PosesMsg(**{**{f.name: getattr(msg, f.name) for f in dataclasses.fields(msg)},
                      "robot_pose": msg.robot_pose + [5e5, -9e5, 0.0]})
    back = PosesMsg.decode(far.encode())
    np.testing.assert_array_equal(back.robot_pose, far.robot_pose)


def test_poses_empty_round_trip() -> None:
    msg = make_poses(n=0, m=0)
    back = PosesMsg.decode(msg.encode())
    assert back.robot_pose.shape == (0, 3) and back.obstacle_xy_m.shape == (0, 2)


def test_poses_size_is_linear_in_the_robot_count() -> None:
    """36 bytes per robot (int32 id, four float64) over a fixed envelope, up to MAX_ROBOTS."""
    envelope = len(make_poses(n=0, m=0).encode())
    for n in (1, 7, 8, 100, 128, 1000, 1820, 1821, protocol.MAX_ROBOTS):
        size = len(make_poses(n=n, m=0).encode())
        # msgpack's bin headers take 1, 2 or 4 bytes more per column as columns grow.
        assert 36 * n <= size - envelope <= 36 * n + 15, n
    assert len(make_poses(n=protocol.MAX_ROBOTS, m=0).encode()) <= protocol.MAX_MESSAGE_BYTES


def test_poses_arrays_are_read_only() -> None:
    msg = PosesMsg.decode(make_poses().encode())
    with pytest.raises(ValueError):
        msg.robot_pose[0, 0] = 1.0


def test_poses_snapshot_round_trip() -> None:
    snap = PoseSnapshot(stamp_s=2.0, tick=100, ids=np.array([0, 1, -1]),
                        pose=np.array([[0.0, 1.0, 0.5], [2.0, 3.0, -1.0], [5.0, 6.0, 0.0]]),
                        radius_m=np.array([0.5, 0.4, 1.0]))
    msg = PosesMsg.from_snapshot(snap)
    np.testing.assert_array_equal(msg.robot_ids, [0, 1])
    np.testing.assert_array_equal(msg.obstacle_ids, [-1])
    np.testing.assert_array_equal(msg.obstacle_xy_m, [[5.0, 6.0]])
    back = PosesMsg.decode(msg.encode()).to_snapshot()
    assert back.stamp_s == 2.0 and back.tick == 100
    np.testing.assert_array_equal(back.ids, snap.ids)
    np.testing.assert_array_equal(back.pose, snap.pose)
    np.testing.assert_array_equal(back.radius_m, snap.radius_m)
    np.testing.assert_array_equal(back.is_robot, [True, True, False])


def test_to_snapshot_gives_obstacles_zero_heading() -> None:
    snap = make_poses(n=1, m=2).to_snapshot()
    np.testing.assert_array_equal(snap.ids, [0, -1, -2])
    np.testing.assert_array_equal(snap.pose[1:, 2], [0.0, 0.0])


def test_command_round_trip() -> None:
    msg = make_command(status=PlanStatus.ESCAPE, side=Side.RIGHT, resolved_id=None)
    back = CommandMsg.decode(msg.encode(), known_ids={0, 1, 2}, expected_robot_id=2)
    assert back == msg
    assert back.status == "escape" and back.side == -1 and back.resolved_id is None
    assert back.hold_s == 0.15
    no_hold = make_command(hold_s=None)
    assert CommandMsg.decode(no_hold.encode()).hold_s is None


def test_command_round_trip_every_status_and_side() -> None:
    for status in PlanStatus:
        for side in Side:
            msg = make_command(status=status, side=side)
            assert CommandMsg.decode(msg.encode()) == msg


def test_config_round_trip_rebuilds_nested_dataclasses() -> None:
    msg = make_config()
    back = RunConfigMsg.decode(msg.encode(), expected_run_id="run-1", expected_robot_id=2)
    assert back == msg
    assert isinstance(back.robot, RobotSpec) and isinstance(back.robot.limits, RobotLimits)
    for group in SUB_CONFIGS:
        assert type(getattr(back.planner, group)) is type(getattr(msg.planner, group))
    assert back.planner.mpc.horizon_steps == 15 and back.planner.mpc.clearance_margin_m == 0.2
    assert back.planner.safety.d_safety_m == 0.25 and back.planner.threats.max_neighbors == 7
    assert back.planner.cost.side_hysteresis == 0.3
    assert back.planner.reference.corner_radius_m == 0.5
    assert back.planner.orca.time_horizon_s == 3.0
    # the profile reaches a distributed robot as set in the scenario
    assert back.planner.profile == "paper" and back.planner.is_paper
    assert back.robot.start == (-4.0, 0.5, 0.1) and back.robot.goal == (4.0, -0.5)
    # the static map every robot routes over
    assert back.static_map == ((-1, 0.0, 5.0, 1.0),)


def test_config_round_trip_with_defaults() -> None:
    msg = RunConfigMsg(run_id="r", robot=RobotSpec(id=0, start=(0, 0, 0), goal=(1, 1)),
                       planner=PlannerConfig(), goal_tolerance_m=0.25, control_rate_hz=10,
                       world_rate_hz=50, time_scale=2, time_limit_s=30, cmd_timeout_s=0.5,
                       known_ids=[0])
    back = RunConfigMsg.decode(msg.encode())
    assert back == msg and back.planner == PlannerConfig()
    assert isinstance(back.robot.start[0], float)


def test_config_wire_covers_every_dataclass_field() -> None:
    body = raw(make_config())
    assert set(body["robot"]) == {f.name for f in dataclasses.fields(RobotSpec)}
    assert set(body["planner"]) == {f.name for f in dataclasses.fields(PlannerConfig)}
    for group in SUB_CONFIGS:
        sub = getattr(PlannerConfig(), group)
        assert set(body["planner"][group]) == {f.name for f in dataclasses.fields(sub)}
    assert set(body["robot"]["limits"]) == {f.name for f in dataclasses.fields(RobotLimits)}


def test_control_round_trip() -> None:
    for msg in (ControlMsg("start", 0.0), ControlMsg("end", 12.5, "all_arrived")):
        assert ControlMsg.decode(msg.encode()) == msg


def test_every_message_carries_schema_and_type() -> None:
    for msg, kind in ((make_poses(), "poses"), (make_command(), "cmd"), (make_config(), "config"),
                      (ControlMsg("start", 0.0), "control"), (make_debug(), "debug")):
        body = raw(msg)
        assert body["schema"] == SCHEMA_VERSION and body["type"] == kind


# --- Rejections: one test per kind of malformation ------------------------------------------


@pytest.mark.parametrize("decode", DECODERS)
def test_rejects_random_bytes(decode) -> None:
    rng = np.random.default_rng(3)
    for _ in range(200):
        with pytest.raises(ProtocolError):
            decode(rng.bytes(int(rng.integers(0, 300))))


@pytest.mark.parametrize("msg", [make_poses(), make_command(), make_config(),
                                 ControlMsg("end", 1.0, "time_limit"), make_debug()])
def test_rejects_every_truncation(msg) -> None:
    data = msg.encode()
    for cut in range(len(data)):
        with pytest.raises(ProtocolError):
            type(msg).decode(data[:cut])


def test_rejects_trailing_bytes() -> None:
    with pytest.raises(ProtocolError, match="msgpack"):
        CommandMsg.decode(make_command().encode() + b"\x00")


@pytest.mark.parametrize("payload", [None, "text", 12, [1, 2], object()])
def test_rejects_non_bytes_payload(payload) -> None:
    with pytest.raises(ProtocolError, match="bytes"):
        CommandMsg.decode(payload)


def test_accepts_bytearray_and_memoryview() -> None:
    data = make_command().encode()
    assert CommandMsg.decode(bytearray(data)) == CommandMsg.decode(memoryview(data))


@pytest.mark.parametrize("key, value", [
    ("seq", "17"), ("seq", 1.5), ("seq", True), ("v", "fast"), ("v", None), ("status", 3),
    ("side", 2), ("side", 0.0), ("robot", -1), ("seq", -1), ("plan_ms", -1.0),
    ("status", "bogus"), ("resolved", "x"), ("pose_stamp", [1.0]), ("v", 1e9),
    ("hold", 0.0), ("hold", -0.1), ("hold", 61.0), ("hold", float("nan")), ("hold", True),
    ("hold", "0.1"),
])
def test_command_rejects_wrong_type_or_range(key, value) -> None:
    body = raw(make_command())
    body[key] = value
    with pytest.raises(ProtocolError):
        CommandMsg.decode(pack(body))


@pytest.mark.parametrize("msg", [make_poses(), make_command(), make_config(),
                                 ControlMsg("start", 0.0), make_debug()])
def test_rejects_each_missing_key(msg) -> None:
    body = raw(msg)
    for key in body:
        broken = dict(body)
        del broken[key]
        with pytest.raises(ProtocolError):
            type(msg).decode(pack(broken))


@pytest.mark.parametrize("msg", [make_poses(), make_command(), make_config(),
                                 ControlMsg("start", 0.0), make_debug()])
def test_rejects_extra_key(msg) -> None:
    body = raw(msg)
    body["extra"] = 1
    with pytest.raises(ProtocolError, match="unknown keys"):
        type(msg).decode(pack(body))


def test_rejects_missing_and_extra_nested_keys() -> None:
    for path in (("robot", "limits"), ("planner", "mpc"), ("planner",), ("robot",)):
        body = raw(make_config())
        node = body
        for p in path:
            node = node[p]
        node["surprise"] = 1.0
        with pytest.raises(ProtocolError, match="surprise"):
            RunConfigMsg.decode(pack(body))
        del node["surprise"]
        node.pop(next(iter(node)))
        with pytest.raises(ProtocolError, match="missing keys"):
            RunConfigMsg.decode(pack(body))


def test_rejects_duplicate_map_keys() -> None:
    # Hand-built map of 3 entries where "type" appears twice.
    data = b"\x83" + pack("schema") + pack(1) + pack("type") + pack("cmd") + pack("type") \
        + pack("cmd")
    with pytest.raises(ProtocolError, match="duplicate"):
        CommandMsg.decode(data)
    # A PosesMsg map (flat: its size is checked against its header) with "tick" twice.
    body = raw(make_poses())
    items = b"".join(pack(k) + pack(v) for k, v in body.items())
    for head in (bytes([0x80 | len(body) + 1]), b"\xde" + (len(body) + 1).to_bytes(2, "big"),
                 b"\xdf" + (len(body) + 1).to_bytes(4, "big")):
        with pytest.raises(ProtocolError, match="duplicate"):
            PosesMsg.decode(head + items + pack("tick") + pack(body["tick"]))
    assert PosesMsg.decode(bytes([0x80 | len(body)]) + items).tick == body["tick"]
    assert PosesMsg.decode(b"\xde" + len(body).to_bytes(2, "big") + items).tick == body["tick"]


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_rejects_non_finite(bad) -> None:
    for key in ("v", "omega", "pose_stamp", "plan_ms"):
        body = raw(make_command())
        body[key] = bad
        with pytest.raises(ProtocolError, match="non-finite"):
            CommandMsg.decode(pack(body))
    for column in range(4):
        for row in (1, 4):  # a robot, an obstacle
            body = raw(make_poses())
            values = discs(body)
            values[row, column] = bad
            body["discs"] = values.tobytes()
            with pytest.raises(ProtocolError, match="non-finite|heading"):
                PosesMsg.decode(pack(body))
    body = raw(make_poses())
    body["t"] = bad
    with pytest.raises(ProtocolError, match="non-finite"):
        PosesMsg.decode(pack(body))
    body = raw(make_config())
    body["planner"]["mpc"]["dt_s"] = bad
    with pytest.raises(ProtocolError, match="non-finite"):
        RunConfigMsg.decode(pack(body))
    with pytest.raises(ProtocolError):
        ControlMsg.decode(pack({**raw(ControlMsg("end", 1.0)), "t": bad}))


def test_poses_rejects_array_length_mismatch() -> None:
    for cut in (8, 32, 33):  # a value, a disc, and not a whole number of float64
        body = raw(make_poses())
        body["discs"] = body["discs"][:-cut]
        with pytest.raises(ProtocolError, match="expected"):
            PosesMsg.decode(pack(body))
    body = raw(make_poses())
    body["discs"] += bytes(32)  # a disc too many
    with pytest.raises(ProtocolError, match="expected"):
        PosesMsg.decode(pack(body))
    body = raw(make_poses())
    body["ids"] = body["ids"][:-3]  # not a whole number of int32
    with pytest.raises(ProtocolError, match="multiple"):
        PosesMsg.decode(pack(body))


def test_poses_rejects_columns_as_lists() -> None:
    for key, value in (("discs", [0.0, 1.0, 2.0]), ("ids", [0, 1, 2])):
        body = raw(make_poses())
        body[key] = value
        with pytest.raises(ProtocolError, match="bin"):
            PosesMsg.decode(pack(body))


def test_poses_rejects_robots_after_obstacles_and_obstacles_that_turn() -> None:
    body = raw(make_poses())  # ids 0, 1, 2, -1, -2
    body["ids"] = np.array([0, 1, -1, 2, -2], dtype="<i4").tobytes()
    with pytest.raises(ProtocolError, match="first"):
        PosesMsg.decode(pack(body))
    body = raw(make_poses())
    values = discs(body)
    values[3, 2] = 0.5  # an obstacle with a heading
    body["discs"] = values.tobytes()
    with pytest.raises(ProtocolError, match="heading"):
        PosesMsg.decode(pack(body))


def test_poses_rejects_huge_array() -> None:
    n = MAX_ROBOTS + 1
    with pytest.raises(ProtocolError, match="exceed"):
        PosesMsg.decode(pack(poses_body(list(range(n)))))
    with pytest.raises(ProtocolError, match="cap"):
        make_poses(n=MAX_ROBOTS + 1, m=0)


def test_rejects_oversized_payload() -> None:
    body = raw(ControlMsg("end", 1.0))
    body["reason"] = "x" * (MAX_MESSAGE_BYTES + 10)
    with pytest.raises(ProtocolError, match="exceeds"):
        ControlMsg.decode(pack(body))
    with pytest.raises(ProtocolError):
        ControlMsg("end", 1.0, "x" * 10_000)


def test_rejects_unknown_robot_id() -> None:
    with pytest.raises(ProtocolError, match="unknown"):
        PosesMsg.decode(make_poses().encode(), known_ids={0, 1, -1, -2})  # robot 2 unknown
    with pytest.raises(ProtocolError, match="unknown"):
        PosesMsg.decode(make_poses().encode(), known_ids={0, 1, 2, -1})  # obstacle -2 unknown
    with pytest.raises(ProtocolError, match="unknown"):
        CommandMsg.decode(make_command(robot_id=9).encode(), known_ids={0, 1, 2})
    with pytest.raises(ProtocolError, match="key of robot"):
        CommandMsg.decode(make_command(robot_id=1).encode(), expected_robot_id=2)
    with pytest.raises(ProtocolError, match="expected 3"):
        RunConfigMsg.decode(make_config().encode(), expected_robot_id=3)
    with pytest.raises(ProtocolError, match="expected 'other'"):
        RunConfigMsg.decode(make_config().encode(), expected_run_id="other")


def test_poses_rejects_bad_ids_and_radii() -> None:
    base = make_poses()
    cases = {
        "duplicate": dict(robot_ids=[0, 0, 1]),
        "negative robot": dict(robot_ids=[0, -3, 1]),
        "positive obstacle": dict(obstacle_ids=[-1, 4]),
        "zero radius": dict(robot_radius_m=[0.5, 0.0, 0.5]),
        "negative radius": dict(obstacle_radius_m=[0.3, -0.3]),
        "float ids": dict(robot_ids=[0.0, 1.0, 2.5]),
        "far away": dict(obstacle_xy_m=[[0.0, 0.0], [1e9, 0.0]]),
        "bad shape": dict(robot_pose=np.zeros((3, 2))),
    }
    for name, change in cases.items():
        fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(base)}
        fields.update(change)
        with pytest.raises(ProtocolError):
            PosesMsg(**fields)
            pytest.fail(name)
    for row, column, value, name in ((1, 3, -1.0, "radius"), (4, 3, 0.0, "radius"),
                                     (0, 0, 2e6, "x"), (3, 1, -2e6, "y"),
                                     (2, 2, 1e4, "theta")):
        body = raw(base)
        values = discs(body)
        values[row, column] = value
        body["discs"] = values.tobytes()
        with pytest.raises(ProtocolError, match=f"discs.{name}"):
            PosesMsg.decode(pack(body))


@pytest.mark.parametrize("version", [0, SCHEMA_VERSION + 1, "1", 1.0, None, True])
def test_rejects_bad_schema_version(version) -> None:
    for msg in (make_poses(), make_command(), make_config(), ControlMsg("start", 0.0)):
        body = raw(msg)
        body["schema"] = version
        with pytest.raises(ProtocolError, match="schema"):
            type(msg).decode(pack(body))


def test_rejects_message_of_another_type() -> None:
    with pytest.raises(ProtocolError, match="type"):
        CommandMsg.decode(make_poses().encode())
    with pytest.raises(ProtocolError, match="type"):
        PosesMsg.decode(ControlMsg("end", 1.0).encode())


def test_rejects_non_map_top_level() -> None:
    for obj in ([1, 2], 5, "poses", None, b"bin"):
        with pytest.raises(ProtocolError, match="map"):
            PosesMsg.decode(pack(obj))


@pytest.mark.parametrize(("path", "value", "message"), [
    (("planner", "threats", "t_max_s"), -1.0, "threats: t_max_s: must be > 0"),
    (("planner", "threats", "sensing_radius_m"), 0.0, "sensing_radius_m: must be > 0"),
    (("planner", "cost", "w_angle"), -0.3, "cost: w_angle: must be >= 0"),
    (("planner", "threats", "max_neighbors"), 0, "max_neighbors: must be > 0"),
    (("planner", "mpc", "horizon_steps"), 0, "mpc: horizon_steps: must be > 0"),
    (("planner", "safety", "braking_margin_m"), -1.0, "braking_margin_m: must be >= 0"),
    (("planner", "profile"), "fast", "profile: expected one of default, paper"),
    (("robot", "limits", "accel_max_mps2"), 0.0, "accel_max_mps2: must be > 0"),
    (("robot", "limits", "v_min_mps"), 2.0, "v_min_mps: must be <= v_max_mps"),
])
def test_config_rejects_out_of_range_fields_by_name(path, value, message) -> None:
    # Typed right but out of range: the robot would fail later, inside its controller or
    # planner (e.g. a hold of -1 periods); the wire loader names the field instead.
    body = raw(make_config())
    node = body
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    with pytest.raises(ProtocolError, match=message) as caught:
        RunConfigMsg.decode(pack(body))
    assert str(caught.value).startswith("config." + path[0])


def test_control_rejects_unknown_kind() -> None:
    body = raw(ControlMsg("start", 0.0))
    body["kind"] = "pause"
    with pytest.raises(ProtocolError, match="kind"):
        ControlMsg.decode(pack(body))


def test_config_rejects_bad_values() -> None:
    mutations = [
        (("robot", "planner"), "rrt"),
        (("robot", "radius_m"), 0.0),
        (("robot", "id"), -1),
        (("robot", "start"), [0.0, 0.0]),
        (("robot", "goal"), "here"),
        (("planner", "reference", "max_depth"), 2.5),
        (("planner", "reference", "max_depth"), 0),
        (("planner", "cost", "w_angle"), "none"),
        (("planner", "cost", "w_angle"), -1.0),
        (("planner", "profile"), "fast"),
        (("planner", "profile"), None),
        (("planner", "safety"), {"d_safety_m": 0.3}),  # a field missing
        (("planner", "mpc", "horizon_steps"), None),
        (("control_rate",), 0.0),
        (("time_scale",), -1.0),
        (("goal_tolerance",), -0.1),
        (("known_ids",), [0, 1]),  # lacks the robot's own id
        (("known_ids",), [2, 2]),
        (("known_ids",), "abc"),
        (("run",), "bad run/id"),
        (("static_map",), "abc"),
        (("static_map",), [[-1, 0.0, 1.0]]),  # no radius
        (("static_map",), [[-1, 0.0, 1.0, 0.0]]),  # zero radius
        (("static_map",), [[-1, 0.0, float("nan"), 1.0]]),
        (("static_map",), [[-1, 1.0e9, 0.0, 1.0]]),
        (("static_map",), [[-2, 0.0, 1.0, 1.0]]),  # not a known id
        (("static_map",), [[1, 0.0, 1.0, 1.0]]),  # a robot's id
        (("static_map",), None),
    ]
    for path, value in mutations:
        body = raw(make_config())
        node = body
        for p in path[:-1]:
            node = node[p]
        node[path[-1]] = value
        with pytest.raises(ProtocolError):
            RunConfigMsg.decode(pack(body))
            pytest.fail(f"{path} = {value!r} accepted")


# --- Key expressions and run ids -------------------------------------------------------------


@pytest.mark.parametrize("run_id", ["a", "run-1", "2024_05_01.exp.3", "X" * 64])
def test_valid_run_ids(run_id) -> None:
    assert validate_run_id(run_id) == run_id


@pytest.mark.parametrize("run_id", ["", "a/b", "*", "a*", "**", "$x", "a?b", "a#b", "a b",
                                    "-lead", ".hidden", "X" * 65, "é", "a\n", None, 5])
def test_rejects_bad_run_ids(run_id) -> None:
    with pytest.raises(ProtocolError, match="run id"):
        validate_run_id(run_id)
    with pytest.raises(ProtocolError):
        RunKeys(run_id)


def test_key_expressions_are_prefixed_by_run() -> None:
    a, b = RunKeys("run-a"), RunKeys("run-b")
    keys_a = {a.poses_slot(0), a.control, a.cmd(3), a.config(3), a.alive_world, a.alive_robot(3)}
    keys_b = {b.poses_slot(0), b.control, b.cmd(3), b.config(3), b.alive_world, b.alive_robot(3)}
    assert all(k.startswith("eifp/run-a/") for k in keys_a)
    assert not keys_a & keys_b
    assert a.cmd(3) == "eifp/run-a/cmd/3" and a.alive_robot(0) == "eifp/run-a/alive/robot/0"
    assert a.config_all == "eifp/run-a/config/*" and a.cmd_all == "eifp/run-a/cmd/*"


def test_debug_keys() -> None:
    k = RunKeys("r1")
    assert k.debug(3) == "eifp/r1/debug/3" and k.debug_all == "eifp/r1/debug/*"
    assert k.robot_id_of_debug("eifp/r1/debug/3") == 3
    for bad in ("eifp/r1/debug/x", "eifp/r1/debug/-1", "eifp/r1/cmd/3", "eifp/r2/debug/3",
                "eifp/r1/debug/03", "eifp/r1/debug/3/4"):
        with pytest.raises(ProtocolError):
            k.robot_id_of_debug(bad)


def test_pose_slot_keys() -> None:
    k = RunKeys("r1")
    assert k.poses_slot(0) == "eifp/r1/poses/0" and k.poses_slot(4) == "eifp/r1/poses/4"
    assert k.poses_all == "eifp/r1/poses/*"
    for bad in (-1, protocol.MAX_POSE_SLOTS, 1.0, True, "1"):
        with pytest.raises(ProtocolError, match="pose slot"):
            k.poses_slot(bad)


@pytest.mark.parametrize(("world_hz", "control_hz", "slots"), [
    (50.0, 10.0, 5), (50.0, 5.0, 10), (50.0, 50.0, 1), (50.0, 20.0, 1), (50.0, 100.0, 1),
    (60.0, 10.0, 6), (50.0, 10.000000001, 5), (50.0, 3.0, 1)])
def test_pose_slot_count_is_whole_ticks_per_period(world_hz, control_hz, slots) -> None:
    assert pose_slot_count(world_hz, control_hz) == slots


def test_pose_slot_count_rejects_bad_rates() -> None:
    for rates in ((0.0, 10.0), (50.0, -1.0), (math.inf, 10.0), (50.0, math.nan)):
        with pytest.raises(ValueError):
            pose_slot_count(*rates)


def test_plan_pose_slot_matches_the_ticks_a_robot_plans_on() -> None:
    tick_s, slots = 0.02, 5
    for phase_ticks in range(12):
        phase_s = phase_ticks * tick_s
        slot = plan_pose_slot(0.1, phase_s, tick_s, slots)
        assert slot == phase_ticks % 5
        # Every plan time over many periods is a tick published on that slot.
        for k in range(200):
            tick = round((phase_s + k * 0.1) / tick_s)
            assert pose_slot_of_tick(tick, slots) == slot
    assert plan_pose_slot(0.2, 0.04, tick_s, slots) == 2      # 5 Hz: every other period
    assert plan_pose_slot(0.05, 0.0, tick_s, slots) is None   # 20 Hz: 2.5 ticks apart
    assert plan_pose_slot(0.04, 0.0, tick_s, slots) is None   # 25 Hz: cycles the slots
    assert plan_pose_slot(0.1, 0.03, tick_s, slots) is None   # phase between ticks
    assert plan_pose_slot(0.1, 0.0, tick_s, 1) == 0           # one slot: everything on 0


def test_robot_id_parsed_from_keys() -> None:
    k = RunKeys("r1")
    assert k.robot_id_of_cmd(k.cmd(12)) == 12
    assert k.robot_id_of_alive(k.alive_robot(0)) == 0
    assert k.robot_id_of_config(k.config(4095)) == 4095
    for bad in ("eifp/r1/cmd/", "eifp/r1/cmd/-1", "eifp/r1/cmd/01", "eifp/r1/cmd/1/2",
                "eifp/r2/cmd/1", "eifp/r1/cmd/x", "eifp/r1/cmd/99999999999"):
        with pytest.raises(ProtocolError):
            k.robot_id_of_cmd(bad)
    with pytest.raises(ProtocolError):
        k.cmd(-1)


def test_session_settings() -> None:
    router = session_settings(mode="router", listen=["tcp/127.0.0.1:7447"])
    assert router["mode"] == '"router"' and router["scouting/multicast/enabled"] == "false"
    assert router["transport/link/tx/lease"] == str(protocol.LINK_LEASE_MS)
    assert router["transport/shared_memory/enabled"] == "false"
    assert "connect/endpoints" not in router
    client = session_settings(mode="client", connect=["tcp/127.0.0.1:1"], connect_timeout_ms=500)
    assert client["connect/endpoints"] == '["tcp/127.0.0.1:1"]'
    assert client["connect/timeout_ms"] == "500"
    with pytest.raises(ValueError):
        session_settings(mode="peer")  # type: ignore[arg-type]


# --- Fuzzing ---------------------------------------------------------------------------------


def decode_or_protocol_error(decode, data: object) -> None:
    """Either a valid message or ProtocolError; any other exception fails the test."""
    try:
        msg = decode(data)
    except ProtocolError:
        return
    # A decoded message re-encodes and decodes to itself (it is a valid message).
    assert type(msg).decode(msg.encode()) is not None


msgpack_objects = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(2**63), max_value=2**64 - 1)
    | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=20)
    | st.binary(max_size=64),
    lambda children: st.lists(children, max_size=6)
    | st.dictionaries(st.text(max_size=12), children, max_size=6),
    max_leaves=30,
)


@FUZZ
@given(data=st.binary(max_size=1024))
def test_fuzz_arbitrary_bytes(data: bytes) -> None:
    for decode in DECODERS:
        decode_or_protocol_error(decode, data)


@FUZZ
@given(obj=msgpack_objects)
def test_fuzz_arbitrary_msgpack_objects(obj: object) -> None:
    data = pack(obj)
    for decode in DECODERS:
        decode_or_protocol_error(decode, data)


VALID_BODIES = {
    "poses": (PosesMsg.decode, raw(make_poses())),
    "cmd": (CommandMsg.decode, raw(make_command())),
    "config": (RunConfigMsg.decode, raw(make_config())),
    "control": (ControlMsg.decode, raw(ControlMsg("end", 2.0, "signal"))),
    "debug": (PlanDebugMsg.decode, raw(make_debug())),
}


def _paths(node: object, prefix: tuple = ()) -> list[tuple]:
    """Every key path into nested maps and lists."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append((*prefix, k))
            out.extend(_paths(v, (*prefix, k)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append((*prefix, i))
            out.extend(_paths(v, (*prefix, i)))
    return out


@FUZZ
@given(kind=st.sampled_from(sorted(VALID_BODIES)), pick=st.integers(min_value=0),
       action=st.sampled_from(["replace", "delete", "add"]), value=msgpack_objects)
def test_fuzz_mutated_valid_messages(kind: str, pick: int, action: str, value: object) -> None:
    decode, body = VALID_BODIES[kind]
    body = copy.deepcopy(body)
    paths = _paths(body)
    path = paths[pick % len(paths)]
    parent = body
    for p in path[:-1]:
        parent = parent[p]
    last = path[-1]
    if action == "replace":
        parent[last] = value
    elif action == "delete":
        del parent[last]
    elif isinstance(parent, dict):
        parent[f"x{last}"] = value
    else:
        parent.append(value)
    decode_or_protocol_error(decode, pack(body))


@FUZZ
@given(ids=st.binary(max_size=48), values=st.binary(max_size=320))
def test_fuzz_pose_blocks(ids: bytes, values: bytes) -> None:
    body = raw(make_poses())
    body["ids"], body["discs"] = ids, values
    decode_or_protocol_error(PosesMsg.decode, pack(body))


# --- Fuzzing with the receivers' options: unknown ids, hostile values, huge arrays ---------

KNOWN = frozenset({0, 1, 2, -1, -2})


@FUZZ
@given(robot_ids=st.lists(st.integers(-(2**31), 2**31 - 1), max_size=6),
       obstacle_ids=st.lists(st.integers(-(2**31), 2**31 - 1), max_size=4))
def test_fuzz_pose_ids_against_known_ids(robot_ids: list[int], obstacle_ids: list[int]) -> None:
    n, m = len(robot_ids), len(obstacle_ids)
    body = poses_body(robot_ids + obstacle_ids)
    try:
        msg = PosesMsg.decode(pack(body), known_ids=KNOWN)
    except ProtocolError:
        return
    ids = set(msg.robot_ids.tolist()) | set(msg.obstacle_ids.tolist())
    assert ids <= KNOWN and len(ids) == n + m
    assert (msg.robot_ids >= 0).all() and (msg.obstacle_ids < 0).all()


hostile = (st.floats(allow_nan=True, allow_infinity=True) | st.integers(-(2**63), 2**64 - 1)
           | st.text(max_size=40) | st.none() | st.booleans() | st.binary(max_size=16)
           | st.lists(st.integers(-(2**63), 2**64 - 1), max_size=3))


@FUZZ
@given(field=st.sampled_from(["robot", "seq", "pose_stamp", "v", "omega", "plan_ms", "status",
                              "side", "resolved", "hold"]), value=hostile,
       key_id=st.integers(0, 5))
def test_fuzz_command_fields_with_hostile_values(field: str, value: object,
                                                 key_id: int) -> None:
    body = raw(make_command())
    body[field] = value
    try:
        msg = CommandMsg.decode(pack(body), known_ids={0, 1, 2}, expected_robot_id=key_id)
    except ProtocolError:
        return
    assert msg.robot_id == key_id and msg.robot_id in {0, 1, 2}
    assert all(math.isfinite(x) for x in (msg.pose_stamp_s, msg.v_mps, msg.omega_radps,
                                          msg.plan_ms))
    assert msg.hold_s is None or 0.0 < msg.hold_s <= 60.0
    assert msg.seq >= 0 and msg.status in {s.value for s in PlanStatus}


@settings(max_examples=25, deadline=None, database=None)
@given(n=st.integers(MAX_ROBOTS - 2, MAX_ROBOTS + 40), short=st.integers(0, 2))
def test_fuzz_huge_pose_arrays(n: int, short: int) -> None:
    body = poses_body(list(range(n)))
    body["discs"] = body["discs"][:len(body["discs"]) - 8 * short]
    try:
        msg = PosesMsg.decode(pack(body))
    except ProtocolError:
        assert n > MAX_ROBOTS or short
        return
    assert msg.n_robots == n <= MAX_ROBOTS and not short


# --- wall-clock stamps ----------------------------------------------------------------------


def test_wall_stamps_round_trip_and_bad_ones_are_rejected():
    from protocol import WallStamps

    wall = WallStamps(clock_id=5, pose_clock_id=5, pose_pub_ns=10, pose_rx_ns=11,
                      plan_start_ns=12, plan_end_ns=13, pub_ns=14)
    cmd = protocol.CommandMsg(robot_id=1, seq=2, pose_stamp_s=0.5, v_mps=0.1, omega_radps=0.0,
                              plan_ms=1.0, status="ok", wall=wall)
    assert protocol.CommandMsg.decode(cmd.encode()).wall == wall
    body = msgpack.unpackb(cmd.encode())
    for bad in ([1, 2, 3], [-1, 0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0, 2**63], "x", None):
        body["wall"] = bad
        with pytest.raises(protocol.ProtocolError, match="cmd.wall"):
            protocol.CommandMsg.decode(msgpack.packb(body))


def test_poses_carry_their_publish_stamp_and_clock():
    snap = protocol.PosesMsg(t_s=1.0, tick=50, robot_ids=np.array([0]),
                             robot_pose=np.zeros((1, 3)), robot_radius_m=np.array([0.5]),
                             obstacle_ids=np.zeros(0, dtype=np.int64),
                             obstacle_xy_m=np.zeros((0, 2)), obstacle_radius_m=np.zeros(0),
                             pub_ns=123456789, clock_id=42)
    back = protocol.PosesMsg.decode(snap.encode())
    assert back.pub_ns == 123456789 and back.clock_id == 42
    body = msgpack.unpackb(snap.encode())
    body["clock"] = 2**40
    with pytest.raises(protocol.ProtocolError, match="poses.clock"):
        protocol.PosesMsg.decode(msgpack.packb(body))


# --- PoseDecoder: a receiver's stream, each id block checked once ----------------------------


def test_pose_decoder_hands_out_one_id_array_while_the_ids_repeat() -> None:
    decoder = protocol.PoseDecoder(KNOWN)
    first = decoder.decode(make_poses(tick=62).encode())
    second = decoder.decode(make_poses(tick=67).encode())
    ids, _ = first.discs()
    assert second.discs()[0] is ids and not ids.flags.writeable
    assert second.tick == 67
    snap = second.to_snapshot()
    assert snap.ids is ids
    np.testing.assert_array_equal(snap.pose, PosesMsg.decode(make_poses().encode()).to_snapshot()
                                  .pose)


def test_pose_decoder_checks_every_message_after_a_good_one() -> None:
    """The id cache only skips re-checking an id block that passed; every other check runs on
    every message, and a rejected block is never remembered as good."""
    decoder = protocol.PoseDecoder(KNOWN)
    good = make_poses()
    decoder.decode(good.encode())
    body = raw(good)
    values = discs(body)
    values[0, 0] = math.nan
    bad_values = {**body, "discs": values.tobytes()}
    duplicate = {**body, "ids": np.array([0, 1, 1, -1, -2], dtype="<i4").tobytes()}
    stranger = {**body, "ids": np.array([0, 1, 7, -1, -2], dtype="<i4").tobytes()}
    for bad in (bad_values, duplicate, stranger, duplicate, {**body, "t": -1.0},
                {**body, "discs": body["discs"][:-32]}):
        with pytest.raises(ProtocolError):
            decoder.decode(pack(bad))
    assert decoder.decode(good.encode()).n_robots == 3
    with pytest.raises(ProtocolError, match="unknown"):
        decoder.decode(pack(stranger))


@FUZZ
@given(steps=st.lists(st.tuples(st.sampled_from(["good", "ids", "discs", "both"]),
                                 st.integers(0, 4), st.sampled_from([-3, 0, 1, 9, 2**31 - 1]),
                                 st.sampled_from([0.0, -0.5, math.nan, 3e6, 0.7])),
                       min_size=1, max_size=12))
def test_fuzz_pose_decoder_agrees_with_a_fresh_decode(steps: list) -> None:
    """A long-lived decoder accepts exactly what `PosesMsg.decode` accepts, message by
    message, with the same arrays."""
    decoder = protocol.PoseDecoder(KNOWN)
    base = raw(make_poses())
    for kind, index, new_id, new_value in steps:
        body = dict(base)
        if kind in ("ids", "both"):
            ids = np.frombuffer(base["ids"], dtype="<i4").copy()
            ids[index] = new_id
            body["ids"] = ids.tobytes()
        if kind in ("discs", "both"):
            values = discs(base)
            values[index, index % 4] = new_value
            body["discs"] = values.tobytes()
        data = pack(body)
        try:
            expected = PosesMsg.decode(data, known_ids=KNOWN)
        except ProtocolError:
            with pytest.raises(ProtocolError):
                decoder.decode(data)
            continue
        got = decoder.decode(data)
        for name in ("robot_ids", "robot_pose", "robot_radius_m", "obstacle_ids",
                     "obstacle_xy_m", "obstacle_radius_m"):
            np.testing.assert_array_equal(getattr(got, name), getattr(expected, name))


@FUZZ
@given(field=st.sampled_from(["schema", "type", "t", "tick", "pub_ns", "clock", "extra"]),
       value=st.one_of(st.sampled_from([True, 4, 4.0, "poses", "cmd", -1, 2**63, 2**31,
                                        math.inf, 1.5, None, b"x"]),
                       st.integers(-5, 10**8), st.floats(allow_nan=True)))
def test_fuzz_pose_decoder_checks_the_envelope_of_every_message(field: str,
                                                                value: object) -> None:
    """After a good message (the id block remembered), a message with one envelope or time
    field changed is accepted exactly when `PosesMsg.decode` accepts it, and alike."""
    decoder = protocol.PoseDecoder(KNOWN)
    decoder.decode(make_poses().encode())
    body = raw(make_poses(tick=63, t_s=1.26))
    body[field] = value
    data = pack(body)
    try:
        expected = PosesMsg.decode(data, known_ids=KNOWN)
    except ProtocolError as exc:
        with pytest.raises(ProtocolError, match=re.escape(str(exc))):
            decoder.decode(data)
        return
    got = decoder.decode(data)
    assert (got.t_s, got.tick, got.pub_ns, got.clock_id) == (
        expected.t_s, expected.tick, expected.pub_ns, expected.clock_id)
    np.testing.assert_array_equal(got.to_snapshot().pose, expected.to_snapshot().pose)


def test_pose_decoder_refuses_a_repeated_key_after_a_good_message() -> None:
    decoder = protocol.PoseDecoder(KNOWN)
    data = make_poses().encode()
    decoder.decode(data)
    head = data[0]
    assert head == 0x88  # a fixmap of 8 entries; one more entry, a second "t"
    repeated = bytes([head + 1]) + data[1:] + pack("t") + pack(9.0)
    with pytest.raises(ProtocolError, match="duplicate map key"):
        decoder.decode(repeated)


# --- encode_command: a robot's command, packed without building a CommandMsg ----------------


def _command_fields(msg: CommandMsg) -> dict:
    return dict(robot_id=msg.robot_id, seq=msg.seq, pose_stamp_s=msg.pose_stamp_s,
                v_mps=msg.v_mps, omega_radps=msg.omega_radps, plan_ms=msg.plan_ms,
                status=msg.status, side=msg.side, resolved_id=msg.resolved_id,
                hold_s=msg.hold_s, wall=msg.wall.as_list())


@pytest.mark.parametrize("overrides", [
    {}, {"resolved_id": None, "hold_s": None}, {"status": PlanStatus.ESCAPE, "side": -1},
    {"wall": protocol.WallStamps(3, 4, 5, 6, 7, 8, 2**62)}, {"v_mps": -0.0, "seq": 0},
])
def test_encode_command_gives_the_bytes_of_command_msg(overrides: dict) -> None:
    msg = make_command(**overrides)
    assert protocol.encode_command(**_command_fields(msg)) == msg.encode()


def test_encode_command_takes_numpy_numbers_as_command_msg_does() -> None:
    msg = make_command()
    fields = {**_command_fields(msg), "v_mps": np.float64(0.9), "resolved_id": np.int64(5)}
    assert protocol.encode_command(**fields) == msg.encode()


@pytest.mark.parametrize(("field", "value", "where"), [
    ("v_mps", math.nan, "cmd.v"), ("omega_radps", 2e3, "cmd.omega"),
    ("plan_ms", math.inf, "cmd.plan_ms"), ("status", "bogus", "cmd.status"),
    ("side", 2, "cmd.side"), ("seq", -1, "cmd.seq"), ("hold_s", 0.0, "cmd.hold"),
    ("seq", True, "cmd.seq"), ("wall", [1, 2, 3], "cmd.wall"),
    ("wall", [2**31, 0, 0, 0, 0, 0, 0], "cmd.wall.clock_id"),
    ("wall", [0, 0, 0, 0, 0, 0, 1.5], "cmd.wall.pub_ns"),
])
def test_encode_command_refuses_what_command_msg_refuses(field: str, value: object,
                                                          where: str) -> None:
    fields = {**_command_fields(make_command()), field: value}
    with pytest.raises(ProtocolError, match=re.escape(where)):
        protocol.encode_command(**fields)


# --- PlanDebugMsg (robot -> viewers) ---------------------------------------------------------


def test_debug_round_trip() -> None:
    msg = make_debug()
    got = PlanDebugMsg.decode(msg.encode(), known_ids={0, 1, 2, -1}, expected_robot_id=2)
    assert (got.robot_id, got.seq, got.t_s, got.v_mps, got.omega_radps, got.status) == (
        2, 17, 3.2, 0.9, -0.4, "ok")
    assert got.debug.threat_ids == (0, 1, -1)
    for name in ("ego", "via_points_m", "reference_m", "predicted_m"):
        assert np.array_equal(getattr(got.debug, name), getattr(msg.debug, name)), name
    assert not got.debug.reference_m.flags.writeable  # views of the received bytes


def test_debug_empty_polylines_round_trip() -> None:
    msg = make_debug(debug=PlanDebug(ego=np.zeros(3)))
    got = PlanDebugMsg.decode(msg.encode())
    assert got.debug.threat_ids == () and got.debug.reference_m.shape == (0, 2)


def test_debug_from_result_and_brake() -> None:
    debug = make_debug().debug
    res = PlanResult(v_mps=0.5, omega_radps=0.1, status=PlanStatus.NO_FEASIBLE,
                     waypoints_m=np.zeros((2, 2)), debug=debug)
    msg = PlanDebugMsg.from_result(4, 9, 1.5, res)
    assert msg is not None and (msg.robot_id, msg.seq, msg.status) == (4, 9, "no_feasible")
    brake = PlanResult(v_mps=0.0, omega_radps=0.0, status=PlanStatus.STALE,
                       waypoints_m=np.zeros((2, 2)))
    assert PlanDebugMsg.from_result(4, 9, 1.5, brake) is None


def test_debug_from_result_cuts_long_polylines() -> None:
    long = np.zeros((MAX_DEBUG_POINTS + 5, 2))
    res = PlanResult(v_mps=0.5, omega_radps=0.1, status=PlanStatus.OK,
                     waypoints_m=np.zeros((2, 2)),
                     debug=PlanDebug(ego=np.zeros(3), threat_ids=tuple(range(300)),
                                     reference_m=long))
    msg = PlanDebugMsg.from_result(4, 9, 1.5, res)
    assert msg.debug.reference_m.shape == (MAX_DEBUG_POINTS, 2)
    assert len(msg.debug.threat_ids) == MAX_DEBUG_THREATS
    assert len(msg.encode()) < 64 * 1024


@pytest.mark.parametrize("key, value", [
    ("robot", -1), ("robot", "2"), ("seq", -1), ("seq", 1.5), ("t", -0.1), ("t", math.nan),
    ("v", 1e9), ("omega", math.inf), ("status", "bogus"), ("status", 3),
    ("threats", [0.5]), ("threats", "0"), ("threats", [True]), ("threats", [2**40]),
    ("threats", list(range(MAX_DEBUG_THREATS + 1))),
    ("ego", b"\x00" * 16), ("ego", [1.0, 2.0, 3.0]), ("ego", np.array([0, 0, np.nan]).tobytes()),
    ("via", b"\x00" * 12), ("via", b"\x00" * 8), ("ref", [[0.0, 0.0]]),
    ("ref", np.array([0.0, np.inf]).tobytes()), ("pred", np.array([0.0, 1e7]).tobytes()),
    ("pred", np.zeros(2 * MAX_DEBUG_POINTS + 2).tobytes()),
])
def test_debug_rejects_wrong_type_or_range(key, value) -> None:
    body = raw(make_debug())
    body[key] = value
    with pytest.raises(ProtocolError):
        PlanDebugMsg.decode(pack(body))


def test_debug_rejects_wrong_sender_and_strangers() -> None:
    data = make_debug().encode()
    with pytest.raises(ProtocolError, match="key of robot"):
        PlanDebugMsg.decode(data, expected_robot_id=3)
    with pytest.raises(ProtocolError, match="unknown robot"):
        PlanDebugMsg.decode(data, known_ids={0, 1, -1})
    with pytest.raises(ProtocolError, match="threats"):
        PlanDebugMsg.decode(data, known_ids={0, 2, -1})


def test_debug_rejects_a_command_on_its_key() -> None:
    with pytest.raises(ProtocolError, match="type"):
        PlanDebugMsg.decode(make_command().encode())
    with pytest.raises(ProtocolError, match="type"):
        CommandMsg.decode(make_debug().encode())


def test_debug_constructor_validates() -> None:
    with pytest.raises(ProtocolError):
        make_debug(status="nope")
    with pytest.raises(ProtocolError):
        make_debug(debug="not a PlanDebug")
    with pytest.raises(ProtocolError):
        make_debug(debug=PlanDebug(ego=np.zeros(3), reference_m=np.full((2, 2), 2e6)))
