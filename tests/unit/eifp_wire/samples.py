"""Valid sample messages and raw-body helpers shared by the wire package's tests."""

from __future__ import annotations

import msgpack
import numpy as np
from hypothesis import HealthCheck, settings

from agent.core.config import MpcConfig, PlannerConfig, RobotLimits
from agent.core.scenario import RobotSpec
from agent.core.types import PlanDebug
from eifp_wire.limits import ProtocolError
from eifp_wire.messages import CommandMsg, ControlMsg, PlanDebugMsg, RunConfigMsg
from eifp_wire.poses import PosesMsg
from tests.examples import examples

FUZZ = settings(max_examples=examples(300), deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow])
"""Hypothesis settings of the fuzz tests: many examples, no deadline, no example database."""


def make_poses(n: int = 3, m: int = 2, t_s: float = 1.25, tick: int = 62) -> PosesMsg:
    """`n` robots (ids 0..n-1) and `m` obstacles (ids -1..-m) at seeded random places."""
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
    """Robot 2's command, with `overrides` of its fields."""
    fields = dict(robot_id=2, seq=17, pose_stamp_s=3.2, v_mps=0.9, omega_radps=-0.4,
                  plan_ms=4.5, status="ok", side=1, resolved_id=5, hold_s=0.15)
    fields.update(overrides)
    return CommandMsg(**fields)


def make_config() -> RunConfigMsg:
    """Robot 2's configuration, with non-default values in every planner group."""
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
    """Robot 2's plan internals (seeded random polylines), with `overrides` of its fields."""
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


def pack(obj: object) -> bytes:
    """`obj` as msgpack, as the encoders write it (bytes as ``bin``)."""
    return msgpack.packb(obj, use_bin_type=True)


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


DECODERS = (PosesMsg.decode, CommandMsg.decode, RunConfigMsg.decode, ControlMsg.decode,
            PlanDebugMsg.decode)
"""Every message type's decoder."""


def decode_or_protocol_error(decode, data: object) -> None:
    """Either a valid message or ProtocolError; any other exception fails the test."""
    try:
        msg = decode(data)
    except ProtocolError:
        return
    # A decoded message re-encodes and decodes to itself (it is a valid message).
    assert type(msg).decode(msg.encode()) is not None
