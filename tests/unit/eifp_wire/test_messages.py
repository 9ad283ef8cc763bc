"""Tests of `eifp_wire.messages`: round trips and rejections of `CommandMsg` (and
`encode_command`, byte for byte the same), `PlanDebugMsg`, `ControlMsg` and `RunConfigMsg`."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.core.config import SUB_CONFIGS, PlannerConfig, RobotLimits
from agent.core.scenario import RobotSpec
from agent.core.types import PlanDebug, PlanResult, PlanStatus, Side
from eifp_wire.limits import MAX_DEBUG_POINTS, MAX_DEBUG_THREATS, ProtocolError
from eifp_wire.messages import (
    CommandMsg,
    ControlMsg,
    PlanDebugMsg,
    RunConfigMsg,
    WallStamps,
    encode_command,
)
from tests.unit.eifp_wire.samples import FUZZ, make_command, make_config, make_debug, pack, raw

# --- CommandMsg (robot -> world) -------------------------------------------------------------


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


def test_wall_stamps_round_trip_and_bad_ones_are_rejected():
    wall = WallStamps(clock_id=5, pose_clock_id=5, pose_pub_ns=10, pose_rx_ns=11,
                      plan_start_ns=12, plan_end_ns=13, pub_ns=14)
    cmd = CommandMsg(robot_id=1, seq=2, pose_stamp_s=0.5, v_mps=0.1, omega_radps=0.0,
                              plan_ms=1.0, status="ok", wall=wall)
    assert CommandMsg.decode(cmd.encode()).wall == wall
    body = raw(cmd)
    for bad in ([1, 2, 3], [-1, 0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0, 2**63], "x", None):
        body["wall"] = bad
        with pytest.raises(ProtocolError, match="cmd.wall"):
            CommandMsg.decode(pack(body))


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


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_command_rejects_non_finite(bad) -> None:
    for key in ("v", "omega", "pose_stamp", "plan_ms"):
        body = raw(make_command())
        body[key] = bad
        with pytest.raises(ProtocolError, match="non-finite"):
            CommandMsg.decode(pack(body))


def test_command_rejects_unknown_and_wrong_sender() -> None:
    with pytest.raises(ProtocolError, match="unknown"):
        CommandMsg.decode(make_command(robot_id=9).encode(), known_ids={0, 1, 2})
    with pytest.raises(ProtocolError, match="key of robot"):
        CommandMsg.decode(make_command(robot_id=1).encode(), expected_robot_id=2)


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


# --- encode_command: a robot's command, packed without building a CommandMsg ----------------


def _command_fields(msg: CommandMsg) -> dict:
    return dict(robot_id=msg.robot_id, seq=msg.seq, pose_stamp_s=msg.pose_stamp_s,
                v_mps=msg.v_mps, omega_radps=msg.omega_radps, plan_ms=msg.plan_ms,
                status=msg.status, side=msg.side, resolved_id=msg.resolved_id,
                hold_s=msg.hold_s, wall=msg.wall.as_list())


@pytest.mark.parametrize("overrides", [
    {}, {"resolved_id": None, "hold_s": None}, {"status": PlanStatus.ESCAPE, "side": -1},
    {"wall": WallStamps(3, 4, 5, 6, 7, 8, 2**62)}, {"v_mps": -0.0, "seq": 0},
])
def test_encode_command_gives_the_bytes_of_command_msg(overrides: dict) -> None:
    msg = make_command(**overrides)
    assert encode_command(**_command_fields(msg)) == msg.encode()


def test_encode_command_takes_numpy_numbers_as_command_msg_does() -> None:
    msg = make_command()
    fields = {**_command_fields(msg), "v_mps": np.float64(0.9), "resolved_id": np.int64(5)}
    assert encode_command(**fields) == msg.encode()


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
        encode_command(**fields)


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
    ("ego", np.array([0, 0, 1e4]).tobytes()), ("ego", np.array([2e6, 0, 0]).tobytes()),
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


# --- ControlMsg (world -> all) ---------------------------------------------------------------


def test_control_round_trip() -> None:
    for msg in (ControlMsg("start", 0.0), ControlMsg("end", 12.5, "all_arrived")):
        assert ControlMsg.decode(msg.encode()) == msg


def test_control_rejects_unknown_kind() -> None:
    body = raw(ControlMsg("start", 0.0))
    body["kind"] = "pause"
    with pytest.raises(ProtocolError, match="kind"):
        ControlMsg.decode(pack(body))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_control_rejects_non_finite(bad) -> None:
    with pytest.raises(ProtocolError, match="non-finite"):
        ControlMsg.decode(pack({**raw(ControlMsg("end", 1.0)), "t": bad}))


# --- RunConfigMsg (world -> one robot) -------------------------------------------------------


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
    # an ablation reaches a distributed robot as the orchestrator set it
    ablated = dataclasses.replace(msg, planner=PlannerConfig(without="routing,liveness"))
    back = RunConfigMsg.decode(ablated.encode())
    assert back.planner.without_names == ("routing", "liveness")


def test_config_wire_covers_every_dataclass_field() -> None:
    body = raw(make_config())
    assert set(body["robot"]) == {f.name for f in dataclasses.fields(RobotSpec)}
    assert set(body["planner"]) == {f.name for f in dataclasses.fields(PlannerConfig)}
    for group in SUB_CONFIGS:
        sub = getattr(PlannerConfig(), group)
        assert set(body["planner"][group]) == {f.name for f in dataclasses.fields(sub)}
    assert set(body["robot"]["limits"]) == {f.name for f in dataclasses.fields(RobotLimits)}


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


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_config_rejects_non_finite(bad) -> None:
    body = raw(make_config())
    body["planner"]["mpc"]["dt_s"] = bad
    with pytest.raises(ProtocolError, match="non-finite"):
        RunConfigMsg.decode(pack(body))


def test_config_rejects_another_run_or_robot() -> None:
    with pytest.raises(ProtocolError, match="expected 3"):
        RunConfigMsg.decode(make_config().encode(), expected_robot_id=3)
    with pytest.raises(ProtocolError, match="expected 'other'"):
        RunConfigMsg.decode(make_config().encode(), expected_run_id="other")


@pytest.mark.parametrize(("path", "value", "message"), [
    (("planner", "threats", "t_max_s"), -1.0, "threats: t_max_s: must be > 0"),
    (("planner", "threats", "sensing_radius_m"), 0.0, "sensing_radius_m: must be > 0"),
    (("planner", "cost", "w_angle"), -0.3, "cost: w_angle: must be >= 0"),
    (("planner", "threats", "max_neighbors"), 0, "max_neighbors: must be > 0"),
    (("planner", "mpc", "horizon_steps"), 0, "mpc: horizon_steps: must be > 0"),
    (("planner", "safety", "braking_margin_m"), -1.0, "braking_margin_m: must be >= 0"),
    (("planner", "profile"), "fast", "profile: expected one of default, paper"),
    (("planner", "without"), "routing,bogus", "without: unknown mechanism 'bogus'"),
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
