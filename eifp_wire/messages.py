"""The messages other than the pose stream (`eifp_wire.poses`), each with its encode/decode.

- `CommandMsg` (robot -> world, with its `WallStamps`; `encode_command` packs one without
  building the objects, byte for byte the same),
- `PlanDebugMsg` (robot -> viewers: one plan's internals),
- `ControlMsg` (world -> all: the run started or ended),
- `RunConfigMsg` (world -> one robot, a query reply: everything it needs to plan).

Each checks its fields when constructed and when decoded; any malformation raises
`ProtocolError` naming the field.
"""

from __future__ import annotations

import sys
import typing
from collections.abc import Collection, Iterable
from dataclasses import dataclass
from typing import Literal

import msgpack
import numpy as np

from agent.core.config import PLANNER_NAMES, PlannerConfig
from agent.core.scenario import RobotSpec
from agent.core.types import PlanDebug, PlanResult, PlanStatus, Side
from eifp_wire.codec import (
    F8,
    SCHEMA_VERSION,
    check_float,
    check_int,
    check_str,
    check_values,
    dump_dataclass,
    known_set,
    load_dataclass,
    open_envelope,
    pack_message,
    read_column,
)
from eifp_wire.keys import check_robot_id, validate_run_id
from eifp_wire.limits import (
    MAX_CLOCK_ID,
    MAX_COORD_M,
    MAX_DEBUG_POINTS,
    MAX_DEBUG_THREATS,
    MAX_HOLD_S,
    MAX_OBSTACLES,
    MAX_RADIUS_M,
    MAX_ROBOT_ID,
    MAX_ROBOTS,
    MAX_RUN_ID_CHARS,
    MAX_SEQ,
    MAX_SPEED,
    MAX_TIME_S,
    MIN_OBSTACLE_ID,
    ProtocolError,
)

_STATUS_VALUES = frozenset(s.value for s in PlanStatus)
_SIDE_MIN, _SIDE_MAX = int(Side.RIGHT), int(Side.LEFT)

TIMING_COLUMNS = ("robot_clock", "world_clock", "pose_pub_ns", "pose_rx_ns", "plan_start_ns",
                  "plan_end_ns", "cmd_pub_ns", "cmd_rx_ns", "applied_ns")
"""Wall stamps per applied command: the robot's and the world's clock ids, then the pose
published (world), received (robot), planning started and ended, the command published
(robot), received and applied (world)."""


@dataclass(frozen=True)
class WallStamps:
    """Wall-clock stamps of one command's way from a pose to the world, in integer ns.

    Each stamp is `time.monotonic_ns()` of the host that took it. Monotonic clocks agree
    between the processes of one Linux host (one boot); `clock_id` (robot) and
    `pose_clock_id` (world) name the clocks, so stages that cross processes are measured
    only when both ends share a clock (`orchestrator.analysis.metrics`). 0: not stamped.

    Args:
        clock_id: the robot's clock.
        pose_clock_id: the world's clock (echoed from the pose's `PosesMsg.clock_id`).
        pose_pub_ns: the world published the pose the plan used (echoed, world's clock).
        pose_rx_ns: the robot received that pose.
        plan_start_ns, plan_end_ns: the robot's planning cycle.
        pub_ns: the robot published the command.
    """

    clock_id: int = 0
    pose_clock_id: int = 0
    pose_pub_ns: int = 0
    pose_rx_ns: int = 0
    plan_start_ns: int = 0
    plan_end_ns: int = 0
    pub_ns: int = 0

    FIELDS: typing.ClassVar[tuple[str, ...]] = (
        "clock_id", "pose_clock_id", "pose_pub_ns", "pose_rx_ns", "plan_start_ns",
        "plan_end_ns", "pub_ns")
    _CHECKS: typing.ClassVar[tuple[tuple[str, str, int], ...]] = tuple(
        (name, f"cmd.wall.{name}", MAX_CLOCK_ID if name.endswith("clock_id") else MAX_SEQ)
        for name in FIELDS)

    def __post_init__(self) -> None:
        values = self.__dict__
        for name, where, hi in self._CHECKS:
            values[name] = check_int(values[name], where, 0, hi)

    def as_list(self) -> list[int]:
        """The stamps in `FIELDS` order (the wire form)."""
        return [getattr(self, name) for name in self.FIELDS]

    @classmethod
    def from_list(cls, value: object) -> WallStamps:
        """Parse the wire form; `ProtocolError` unless a list of `len(FIELDS)` ints."""
        if not isinstance(value, list | tuple) or len(value) != len(cls.FIELDS):
            raise ProtocolError(f"cmd.wall: expected a list of {len(cls.FIELDS)} integers")
        return cls(*value)


@dataclass(frozen=True)
class CommandMsg:
    """Robot -> world: one velocity command.

    Wire body: ``robot`` (int), ``seq`` (int), ``pose_stamp`` (float), ``v``, ``omega``,
    ``plan_ms`` (float), ``status`` (str), ``side`` (-1|0|1), ``resolved`` (int or nil),
    ``hold`` (float or nil), ``wall`` (`WallStamps` as a list of ints).

    Args:
        robot_id: sender (must match the key's id; checked by `decode(expected_robot_id=)`).
        seq: per-process sequence number, strictly increasing (the world drops stale ones).
        pose_stamp_s: sim time of the pose the plan was made from.
        v_mps, omega_radps: the command (the world clamps it to the robot's limits).
        plan_ms: wall time the plan took.
        status: a `agent.core.types.PlanStatus` value.
        side: a `agent.core.types.Side` value.
        resolved_id: id of the threat the chosen via-point resolves, or None.
        hold_s: how long (sim s, in (0, `MAX_HOLD_S`]) the world may apply this command
            if no newer one arrives; after that it brakes the robot (a command is good for
            the period it was planned for, not until a lost link's time-out). None: until
            the world's own command time-out.
        wall: wall-clock stamps of the command's way (`WallStamps`).
    """

    robot_id: int
    seq: int
    pose_stamp_s: float
    v_mps: float
    omega_radps: float
    plan_ms: float
    status: str
    side: int = 0
    resolved_id: int | None = None
    hold_s: float | None = None
    wall: WallStamps = WallStamps()

    TYPE: typing.ClassVar[str] = "cmd"

    def __post_init__(self) -> None:
        d = self.__dict__  # frozen: fields are written through the instance dict
        d["robot_id"] = check_int(d["robot_id"], "cmd.robot", 0, MAX_ROBOT_ID)
        d["seq"] = check_int(d["seq"], "cmd.seq", 0, MAX_SEQ)
        d["pose_stamp_s"] = check_float(d["pose_stamp_s"], "cmd.pose_stamp", 0.0, MAX_TIME_S)
        d["v_mps"] = check_float(d["v_mps"], "cmd.v", -MAX_SPEED, MAX_SPEED)
        d["omega_radps"] = check_float(d["omega_radps"], "cmd.omega", -MAX_SPEED, MAX_SPEED)
        d["plan_ms"] = check_float(d["plan_ms"], "cmd.plan_ms", 0.0)
        status = check_str(d["status"], "cmd.status", 32)
        if status not in _STATUS_VALUES:
            raise ProtocolError(f"cmd.status: unknown status {status!r}")
        d["status"] = str(status)
        d["side"] = check_int(d["side"], "cmd.side", _SIDE_MIN, _SIDE_MAX)
        if d["resolved_id"] is not None:
            d["resolved_id"] = check_int(d["resolved_id"], "cmd.resolved", MIN_OBSTACLE_ID,
                                         MAX_ROBOT_ID)
        if d["hold_s"] is not None:
            d["hold_s"] = check_float(d["hold_s"], "cmd.hold", 0.0, MAX_HOLD_S, lo_open=True)
        if not isinstance(self.wall, WallStamps):
            raise ProtocolError(f"cmd.wall: expected WallStamps, got {type(self.wall).__name__}")

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        return pack_message(self.TYPE, {
            "robot": self.robot_id,
            "seq": self.seq,
            "pose_stamp": self.pose_stamp_s,
            "v": self.v_mps,
            "omega": self.omega_radps,
            "plan_ms": self.plan_ms,
            "status": self.status,
            "side": self.side,
            "resolved": self.resolved_id,
            "hold": self.hold_s,
            "wall": self.wall.as_list(),
        })

    @classmethod
    def decode(cls, data: object, *, known_ids: Collection[int] | None = None,
               expected_robot_id: int | None = None) -> CommandMsg:
        """Parse and validate.

        Args:
            known_ids: if given, the robot id must be one of them.
            expected_robot_id: if given (the id in the key), the message must carry it.
        """
        body = open_envelope(data, cls.TYPE, (
            "robot", "seq", "pose_stamp", "v", "omega", "plan_ms", "status", "side", "resolved",
            "hold", "wall",
        ))
        msg = cls(
            robot_id=body["robot"],
            seq=body["seq"],
            pose_stamp_s=body["pose_stamp"],
            v_mps=body["v"],
            omega_radps=body["omega"],
            plan_ms=body["plan_ms"],
            status=body["status"],
            side=body["side"],
            resolved_id=body["resolved"],
            hold_s=body["hold"],
            wall=WallStamps.from_list(body["wall"]),
        )
        _check_sender("cmd.robot", msg.robot_id, known_ids, expected_robot_id)
        return msg


def _check_sender(where: str, robot_id: int, known_ids: Collection[int] | None,
                  expected_robot_id: int | None) -> None:
    """Raise unless `robot_id` is one of `known_ids` and the id in the message's key
    (`expected_robot_id`), each if given."""
    if known_ids is not None and robot_id not in known_ids:
        raise ProtocolError(f"{where}: unknown robot id {robot_id}")
    if expected_robot_id is not None and robot_id != expected_robot_id:
        raise ProtocolError(f"{where}: id {robot_id} sent on the key of robot {expected_robot_id}")


def encode_command(robot_id: int, seq: int, pose_stamp_s: float, v_mps: float,
                   omega_radps: float, plan_ms: float, status: str, side: int,
                   resolved_id: int | None, hold_s: float | None, wall: list[int]) -> bytes:
    """``CommandMsg(...).encode()`` of these fields (`wall`: `WallStamps.as_list`), byte
    for byte, without building the message objects.

    A robot sends one command per control cycle. Values of the usual types in range are
    checked by one chain of comparisons and packed; anything else is built as a
    `CommandMsg`, whose checks raise `ProtocolError` naming the field.
    """
    if (type(robot_id) is int and 0 <= robot_id <= MAX_ROBOT_ID
            and type(seq) is int and 0 <= seq <= MAX_SEQ
            and type(pose_stamp_s) is float and 0.0 <= pose_stamp_s <= MAX_TIME_S
            and type(v_mps) is float and -MAX_SPEED <= v_mps <= MAX_SPEED
            and type(omega_radps) is float and -MAX_SPEED <= omega_radps <= MAX_SPEED
            and type(plan_ms) is float and 0.0 <= plan_ms <= _MAX_FLOAT
            and status in _STATUS_VALUES and type(side) is int and _SIDE_MIN <= side <= _SIDE_MAX
            and (resolved_id is None
                 or type(resolved_id) is int and MIN_OBSTACLE_ID <= resolved_id <= MAX_ROBOT_ID)
            and (hold_s is None or type(hold_s) is float and 0.0 < hold_s <= MAX_HOLD_S)
            and _packable_wall(wall)):
        return msgpack.packb({
            "schema": SCHEMA_VERSION, "type": CommandMsg.TYPE, "robot": robot_id, "seq": seq,
            "pose_stamp": pose_stamp_s, "v": v_mps, "omega": omega_radps, "plan_ms": plan_ms,
            "status": str(status), "side": side, "resolved": resolved_id, "hold": hold_s,
            "wall": wall}, use_bin_type=True)
    return CommandMsg(robot_id=robot_id, seq=seq, pose_stamp_s=pose_stamp_s, v_mps=v_mps,
                      omega_radps=omega_radps, plan_ms=plan_ms, status=status, side=side,
                      resolved_id=resolved_id, hold_s=hold_s,
                      wall=WallStamps.from_list(wall)).encode()


def _packable_wall(wall: list[int]) -> bool:
    """Whether `encode_command` may pack `wall` as it is: a list of `len(WallStamps.FIELDS)`
    ints, each stamp within `MAX_SEQ` and the two clock ids within `MAX_CLOCK_ID`."""
    return (type(wall) is list and len(wall) == len(WallStamps.FIELDS)
            and all(type(x) is int and 0 <= x <= MAX_SEQ for x in wall)
            and wall[0] <= MAX_CLOCK_ID and wall[1] <= MAX_CLOCK_ID)


_MAX_FLOAT = sys.float_info.max


def _points(value: object, where: str, max_n: int) -> np.ndarray:
    """A packed polyline: ``bin`` of 2 k little-endian float64, returned read-only (k, 2)."""
    flat = read_column(value, where, F8, None, 2 * max_n)
    if flat.shape[0] % 2:
        raise ProtocolError(f"{where}: odd number of coordinates")
    check_values(flat, where, -MAX_COORD_M, MAX_COORD_M)
    return flat.reshape(-1, 2)


def _check_ego(ego: np.ndarray) -> None:
    """A plan's ego pose: x, y within the coordinate range, a finite heading."""
    check_values(ego[:2], "debug.ego.xy", -MAX_COORD_M, MAX_COORD_M)
    check_values(ego[2:], "debug.ego.theta", -1e3, 1e3)


def _pack_points(points: np.ndarray) -> bytes:
    return np.ascontiguousarray(points, dtype=F8).reshape(-1).tobytes()


@dataclass(frozen=True, eq=False)
class PlanDebugMsg:
    """Robot -> viewers: one plan's internals (`agent.core.types.PlanDebug`), for viewing.

    Sent once per plan on ``debug/<id>`` with congestion control DROP: nothing waits for it
    and nothing decides on it. The world records it in ``run.mcap``.

    Wire body: ``robot`` (int), ``seq`` (the seq of the command it belongs to), ``t`` (sim
    time of the plan), ``v``, ``omega`` (the command), ``status`` (str), ``ego`` (bin, 3
    <f8: x, y, heading), ``threats`` (list of ids), ``via``, ``ref``, ``pred`` (bin of
    <f8 x, y pairs: via-points, reference path samples, MPC prediction).

    Args:
        robot_id: sender (must match the key's id; checked by `decode(expected_robot_id=)`).
        seq: the sequence number of the command this plan produced.
        t_s: sim time at which the robot planned.
        v_mps, omega_radps: the command.
        status: a `agent.core.types.PlanStatus` value.
        debug: the internals; arrays read-only, at most `MAX_DEBUG_POINTS` points each
            and `MAX_DEBUG_THREATS` threats.
    """

    robot_id: int
    seq: int
    t_s: float
    v_mps: float
    omega_radps: float
    status: str
    debug: PlanDebug

    TYPE: typing.ClassVar[str] = "debug"

    def __post_init__(self) -> None:
        self._check_scalars()
        d = self.debug
        if not isinstance(d, PlanDebug):
            raise ProtocolError("debug: expected a PlanDebug")
        if len(d.threat_ids) > MAX_DEBUG_THREATS:
            raise ProtocolError(f"debug.threats: more than {MAX_DEBUG_THREATS}")
        for tid in d.threat_ids:
            check_int(tid, "debug.threats[]", MIN_OBSTACLE_ID, MAX_ROBOT_ID)
        _check_ego(d.ego)
        for name, where in (("via_points_m", "debug.via"), ("reference_m", "debug.ref"),
                            ("predicted_m", "debug.pred")):
            points = getattr(d, name)
            if points.shape[0] > MAX_DEBUG_POINTS:
                raise ProtocolError(f"{where}: {points.shape[0]} points exceed "
                                    f"{MAX_DEBUG_POINTS}")
            check_values(points, where, -MAX_COORD_M, MAX_COORD_M)

    def _check_scalars(self) -> None:
        """Check (and normalise) every field but `debug`."""
        set_ = object.__setattr__
        set_(self, "robot_id", check_int(self.robot_id, "debug.robot", 0, MAX_ROBOT_ID))
        set_(self, "seq", check_int(self.seq, "debug.seq", 0, MAX_SEQ))
        set_(self, "t_s", check_float(self.t_s, "debug.t", 0.0))
        set_(self, "v_mps", check_float(self.v_mps, "debug.v", -MAX_SPEED, MAX_SPEED))
        set_(self, "omega_radps",
             check_float(self.omega_radps, "debug.omega", -MAX_SPEED, MAX_SPEED))
        status = check_str(self.status, "debug.status", 32)
        if status not in _STATUS_VALUES:
            raise ProtocolError(f"debug.status: unknown status {status!r}")
        set_(self, "status", str(status))

    @classmethod
    def from_result(cls, robot_id: int, seq: int, t_s: float,
                    result: PlanResult) -> PlanDebugMsg | None:
        """The message of one plan, or None if the plan has no `PlanDebug` (a brake).

        Polylines longer than `MAX_DEBUG_POINTS` are cut to their first points.
        """
        d = result.debug
        if d is None:
            return None
        if (len(d.threat_ids) > MAX_DEBUG_THREATS
                or max(len(d.via_points_m), len(d.reference_m), len(d.predicted_m))
                > MAX_DEBUG_POINTS):
            d = PlanDebug(ego=d.ego, threat_ids=d.threat_ids[:MAX_DEBUG_THREATS],
                          via_points_m=d.via_points_m[:MAX_DEBUG_POINTS],
                          reference_m=d.reference_m[:MAX_DEBUG_POINTS],
                          predicted_m=d.predicted_m[:MAX_DEBUG_POINTS])
        return cls(robot_id=robot_id, seq=seq, t_s=t_s, v_mps=result.v_mps,
                   omega_radps=result.omega_radps, status=str(result.status.value), debug=d)

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        d = self.debug
        return pack_message(self.TYPE, {
            "robot": self.robot_id,
            "seq": self.seq,
            "t": self.t_s,
            "v": self.v_mps,
            "omega": self.omega_radps,
            "status": self.status,
            "ego": _pack_points(d.ego),
            "threats": list(d.threat_ids),
            "via": _pack_points(d.via_points_m),
            "ref": _pack_points(d.reference_m),
            "pred": _pack_points(d.predicted_m),
        })

    @classmethod
    def decode(cls, data: object, *, known_ids: Collection[int] | None = None,
               expected_robot_id: int | None = None) -> PlanDebugMsg:
        """Parse and validate.

        Args:
            known_ids: if given, the robot id and every threat id must be one of them.
            expected_robot_id: if given (the id in the key), the message must carry it.
        """
        body = open_envelope(data, cls.TYPE, (
            "robot", "seq", "t", "v", "omega", "status", "ego", "threats", "via", "ref", "pred",
        ))
        ego = read_column(body["ego"], "debug.ego", F8, 3, 3)
        threats = body["threats"]
        if not isinstance(threats, list) or len(threats) > MAX_DEBUG_THREATS:
            raise ProtocolError(f"debug.threats: expected a list of at most "
                                f"{MAX_DEBUG_THREATS} ids")
        threat_ids = tuple(check_int(i, "debug.threats[]", MIN_OBSTACLE_ID, MAX_ROBOT_ID)
                           for i in threats)
        _check_ego(ego)
        # Every array is checked here, once (the world decodes one message per plan of
        # every robot): the PlanDebug and the message are built without checking again.
        debug = PlanDebug.trusted(ego, threat_ids,
                                  _points(body["via"], "debug.via", MAX_DEBUG_POINTS),
                                  _points(body["ref"], "debug.ref", MAX_DEBUG_POINTS),
                                  _points(body["pred"], "debug.pred", MAX_DEBUG_POINTS))
        msg = object.__new__(cls)
        for name, value in (("robot_id", body["robot"]), ("seq", body["seq"]),
                            ("t_s", body["t"]), ("v_mps", body["v"]),
                            ("omega_radps", body["omega"]), ("status", body["status"]),
                            ("debug", debug)):
            object.__setattr__(msg, name, value)
        msg._check_scalars()
        known = known_set(known_ids)
        _check_sender("debug.robot", msg.robot_id, known, expected_robot_id)
        strangers = set() if known is None else set(threat_ids) - known
        if strangers:
            raise ProtocolError(f"debug.threats: unknown ids {sorted(strangers)[:8]}")
        return msg


ControlKind = Literal["start", "end"]


@dataclass(frozen=True)
class ControlMsg:
    """World -> all: the run started or ended.

    Wire body: ``kind`` ("start"|"end"), ``t`` (float), ``reason`` (str).

    Args:
        kind: ``"start"`` or ``"end"``.
        t_s: sim time of the announcement.
        reason: why the run ended (``all_arrived``, ``time_limit``, ``signal``, ...), or "".
    """

    kind: ControlKind
    t_s: float
    reason: str = ""

    TYPE: typing.ClassVar[str] = "control"

    def __post_init__(self) -> None:
        if self.kind not in ("start", "end"):
            raise ProtocolError(f"control.kind: {self.kind!r} is not 'start' or 'end'")
        object.__setattr__(self, "t_s", check_float(self.t_s, "control.t", 0.0, MAX_TIME_S))
        object.__setattr__(self, "reason", check_str(self.reason, "control.reason"))

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        return pack_message(self.TYPE, {"kind": self.kind, "t": self.t_s, "reason": self.reason})

    @classmethod
    def decode(cls, data: object) -> ControlMsg:
        """Parse and validate."""
        body = open_envelope(data, cls.TYPE, ("kind", "t", "reason"))
        if not isinstance(body["kind"], str):
            raise ProtocolError("control.kind: expected a string")
        # __post_init__ refuses any other kind than "start" or "end"
        kind = typing.cast(ControlKind, body["kind"])
        return cls(kind=kind, t_s=body["t"], reason=body["reason"])


def _static_map(rows: object, known: frozenset[int]
                ) -> tuple[tuple[int, float, float, float], ...]:
    """`RunConfigMsg.static_map` checked: [id, x, y, radius] rows, ids known obstacles."""
    what = "config.static_map"
    if isinstance(rows, str | bytes) or not isinstance(rows, Iterable):
        raise ProtocolError(f"{what}: expected a sequence of [id, x, y, radius]")
    out = []
    for row in rows:
        if isinstance(row, str | bytes) or not isinstance(row, Iterable):
            raise ProtocolError(f"{what}[]: expected [id, x, y, radius]")
        values = tuple(row)
        if len(values) != 4:
            raise ProtocolError(f"{what}[]: expected [id, x, y, radius]")
        disc_id = check_int(values[0], f"{what}[].id", MIN_OBSTACLE_ID, -1)
        if disc_id not in known:
            raise ProtocolError(f"{what}[].id: {disc_id} is not one of known_ids")
        out.append((disc_id,
                    check_float(values[1], f"{what}[].x", -MAX_COORD_M, MAX_COORD_M),
                    check_float(values[2], f"{what}[].y", -MAX_COORD_M, MAX_COORD_M),
                    check_float(values[3], f"{what}[].radius", 0.0, MAX_RADIUS_M, lo_open=True)))
        if len(out) > MAX_OBSTACLES:
            raise ProtocolError(f"{what}: more than {MAX_OBSTACLES} discs")
    return tuple(out)


@dataclass(frozen=True)
class RunConfigMsg:
    """World -> one robot (query reply): everything the robot needs to plan in this run.

    Wire body: ``run`` (str), ``robot`` (map of every `RobotSpec` field, ``limits`` nested),
    ``planner`` (map of every `PlannerConfig` field, ``mpc`` nested), ``goal_tolerance``,
    ``control_rate``, ``world_rate``, ``time_scale``, ``time_limit``, ``cmd_timeout`` (floats),
    ``known_ids`` (list of every robot and obstacle id of the run), ``static_map`` (list of
    [id, x, y, radius] of the static obstacles, which every robot knows in advance).

    Args:
        run_id: the run this configuration belongs to.
        robot: the robot's spec (its id, start, goal, radius, limits, planner name).
        planner: the shared planner parameters.
        goal_tolerance_m: a robot has arrived when its centre is this close to its goal.
        control_rate_hz: planning rate in sim time.
        world_rate_hz: world tick rate in sim time (poses arrive at this rate).
        time_scale: sim seconds per wall second the world runs at.
        time_limit_s: sim time at which the world gives up.
        cmd_timeout_s: a command older than this (sim time) makes the world brake the robot.
        known_ids: every robot (>= 0) and obstacle (< 0) id of the run.
        static_map: (id, x [m], y [m], radius [m]) of every static obstacle (the robots
            route round them, `agent.planning.routing`); each id is one of `known_ids`.
    """

    run_id: str
    robot: RobotSpec
    planner: PlannerConfig
    goal_tolerance_m: float
    control_rate_hz: float
    world_rate_hz: float
    time_scale: float
    time_limit_s: float
    cmd_timeout_s: float
    known_ids: tuple[int, ...]
    static_map: tuple[tuple[int, float, float, float], ...] = ()

    TYPE: typing.ClassVar[str] = "config"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        validate_run_id(self.run_id)
        if not isinstance(self.robot, RobotSpec) or not isinstance(self.planner, PlannerConfig):
            raise ProtocolError("config: robot must be a RobotSpec, planner a PlannerConfig")
        # Round-trip the nested dataclasses through the strict loader: one set of checks.
        try:
            robot = dump_dataclass(self.robot, "config.robot")
            planner = dump_dataclass(self.planner, "config.planner")
        except (TypeError, ValueError, OverflowError) as exc:
            raise ProtocolError(f"config: {exc}") from exc
        set_(self, "robot", load_dataclass(robot, RobotSpec, "config.robot"))
        set_(self, "planner", load_dataclass(planner, PlannerConfig, "config.planner"))
        check_robot_id(self.robot.id)
        if self.robot.planner not in PLANNER_NAMES:
            raise ProtocolError(f"config.robot.planner: unknown planner {self.robot.planner!r}")
        check_float(self.robot.radius_m, "config.robot.radius_m", 0.0, MAX_RADIUS_M, lo_open=True)
        for i, c in enumerate((*self.robot.start[:2], *self.robot.goal)):
            check_float(c, f"config.robot.coordinate[{i}]", -MAX_COORD_M, MAX_COORD_M)
        for name in ("goal_tolerance_m", "control_rate_hz", "world_rate_hz", "time_scale",
                     "time_limit_s", "cmd_timeout_s"):
            set_(self, name, check_float(getattr(self, name), f"config.{name}", 0.0, lo_open=True))
        if isinstance(self.known_ids, str | bytes) or not isinstance(
                self.known_ids, Iterable):
            raise ProtocolError("config.known_ids: expected a sequence of ints")
        ids = tuple(check_int(i, "config.known_ids[]", MIN_OBSTACLE_ID, MAX_ROBOT_ID)
                    for i in self.known_ids)
        if len(ids) > MAX_ROBOTS + MAX_OBSTACLES or len(set(ids)) != len(ids):
            raise ProtocolError("config.known_ids: too many or duplicate ids")
        if self.robot.id not in ids:
            raise ProtocolError("config.known_ids: does not contain the robot's own id")
        set_(self, "known_ids", ids)
        set_(self, "static_map", _static_map(self.static_map, frozenset(ids)))

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        return pack_message(self.TYPE, {
            "run": self.run_id,
            "robot": dump_dataclass(self.robot, "robot"),
            "planner": dump_dataclass(self.planner, "planner"),
            "goal_tolerance": self.goal_tolerance_m,
            "control_rate": self.control_rate_hz,
            "world_rate": self.world_rate_hz,
            "time_scale": self.time_scale,
            "time_limit": self.time_limit_s,
            "cmd_timeout": self.cmd_timeout_s,
            "known_ids": list(self.known_ids),
            "static_map": [list(d) for d in self.static_map],
        })

    @classmethod
    def decode(cls, data: object, *, expected_run_id: str | None = None,
               expected_robot_id: int | None = None) -> RunConfigMsg:
        """Parse and validate; optionally insist on this run and this robot."""
        body = open_envelope(data, cls.TYPE, (
            "run", "robot", "planner", "goal_tolerance", "control_rate", "world_rate",
            "time_scale", "time_limit", "cmd_timeout", "known_ids", "static_map",
        ))
        if not isinstance(body["known_ids"], list):
            raise ProtocolError("config.known_ids: expected a list")
        if not isinstance(body["static_map"], list):
            raise ProtocolError("config.static_map: expected a list")
        msg = cls(
            run_id=check_str(body["run"], "config.run", MAX_RUN_ID_CHARS),
            robot=load_dataclass(body["robot"], RobotSpec, "config.robot"),
            planner=load_dataclass(body["planner"], PlannerConfig, "config.planner"),
            goal_tolerance_m=body["goal_tolerance"],
            control_rate_hz=body["control_rate"],
            world_rate_hz=body["world_rate"],
            time_scale=body["time_scale"],
            time_limit_s=body["time_limit"],
            cmd_timeout_s=body["cmd_timeout"],
            known_ids=tuple(body["known_ids"]),
            static_map=tuple(body["static_map"]),
        )
        if expected_run_id is not None and msg.run_id != expected_run_id:
            raise ProtocolError(f"config.run: {msg.run_id!r}, expected {expected_run_id!r}")
        if expected_robot_id is not None and msg.robot.id != expected_robot_id:
            raise ProtocolError(f"config.robot.id: {msg.robot.id}, expected {expected_robot_id}")
        return msg
