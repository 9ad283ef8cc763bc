"""The wire layer shared by the world, the robots and the orchestrator.

Every Zenoh key expression and every message schema lives in this package and nowhere else:
nothing else builds key strings or serialises messages (`tests/unit/test_architecture.py`).
It never imports zenoh. One concern per module:

- `eifp_wire.keys`: key expressions of a run (`RunKeys`), run and robot ids;
- `eifp_wire.limits`: the bounds on every value and the one error, `ProtocolError`;
- `eifp_wire.codec`: the msgpack envelope (`SCHEMA_VERSION`), bounded parsing, the checks
  of each field, the strict serialiser of the configuration dataclasses;
- `eifp_wire.poses`: the pose stream, `PosesMsg` and a receiver's `PoseDecoder`;
- `eifp_wire.messages`: `CommandMsg` (and `encode_command`), `PlanDebugMsg`, `ControlMsg`,
  `RunConfigMsg`;
- `eifp_wire.clock`: a command's sequence number and a pose's stamp against the
  receiver's sim clock;
- `eifp_wire.transport`: Zenoh session settings and their TLS part;
- `eifp_wire.access`: certificate common names and the routers' access-control lists.

The names below are the package's public interface: ``from eifp_wire import RunKeys``.
"""

from __future__ import annotations

from eifp_wire.access import (
    ACL_MESSAGES,
    OBSERVER_CN,
    ORCHESTRATOR_CN,
    ROUTER_CN_PREFIX,
    RUN_TAG_HEX,
    WORLD_CN,
    access_control,
    relay_access_control,
    robot_cn,
    router_cn,
    run_tag,
    scoped_cn,
)
from eifp_wire.clock import (
    MAX_CMD_AHEAD_S,
    MAX_POSE_AHEAD_S,
    SEQ_PER_S,
    TICK_TIME_TOLERANCE_S,
    check_pose_time,
    check_seq,
    max_seq,
    next_seq,
)
from eifp_wire.codec import SCHEMA_VERSION
from eifp_wire.keys import (
    KEY_ROOT,
    MAX_POSE_SLOTS,
    RunKeys,
    plan_pose_slot,
    pose_slot_count,
    pose_slot_of_tick,
    validate_run_id,
)
from eifp_wire.limits import (
    MAX_CLOCK_ID,
    MAX_COORD_M,
    MAX_DEBUG_POINTS,
    MAX_DEBUG_THREATS,
    MAX_HOLD_S,
    MAX_MESSAGE_BYTES,
    MAX_OBSTACLES,
    MAX_RADIUS_M,
    MAX_REASON_CHARS,
    MAX_ROBOT_ID,
    MAX_ROBOTS,
    MAX_RUN_ID_CHARS,
    MAX_SEQ,
    MAX_SPEED,
    MAX_TIME_S,
    MIN_OBSTACLE_ID,
    ProtocolError,
)
from eifp_wire.messages import (
    TIMING_COLUMNS,
    CommandMsg,
    ControlKind,
    ControlMsg,
    PlanDebugMsg,
    RunConfigMsg,
    WallStamps,
    encode_command,
)
from eifp_wire.poses import PoseDecoder, PosesMsg
from eifp_wire.transport import (
    TlsFiles,
    session_settings,
    tls_endpoint,
    tls_settings,
    validate_zid,
)

__all__ = [
    "ACL_MESSAGES", "KEY_ROOT", "MAX_CLOCK_ID", "MAX_CMD_AHEAD_S", "MAX_COORD_M",
    "MAX_DEBUG_POINTS", "MAX_DEBUG_THREATS", "MAX_HOLD_S", "MAX_MESSAGE_BYTES",
    "MAX_OBSTACLES", "MAX_POSE_AHEAD_S", "MAX_POSE_SLOTS", "MAX_RADIUS_M", "MAX_REASON_CHARS",
    "MAX_ROBOTS", "MAX_ROBOT_ID", "MAX_RUN_ID_CHARS", "MAX_SEQ", "MAX_SPEED", "MAX_TIME_S",
    "MIN_OBSTACLE_ID", "OBSERVER_CN", "ORCHESTRATOR_CN", "ROUTER_CN_PREFIX", "RUN_TAG_HEX",
    "SCHEMA_VERSION", "SEQ_PER_S", "TICK_TIME_TOLERANCE_S", "TIMING_COLUMNS", "WORLD_CN",
    "CommandMsg", "ControlKind", "ControlMsg", "PlanDebugMsg", "PoseDecoder", "PosesMsg",
    "ProtocolError", "RunConfigMsg", "RunKeys", "TlsFiles", "WallStamps",
    "access_control", "check_pose_time", "check_seq", "encode_command", "max_seq",
    "next_seq", "plan_pose_slot", "pose_slot_count", "pose_slot_of_tick",
    "relay_access_control", "robot_cn", "router_cn", "run_tag", "scoped_cn",
    "session_settings", "tls_endpoint", "tls_settings", "validate_run_id", "validate_zid",
]
