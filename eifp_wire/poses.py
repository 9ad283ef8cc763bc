"""The pose stream, world -> robots: `PosesMsg` and the receiver's `PoseDecoder`.

A `PosesMsg` travels as one block of ids and one block of disc rows (x, y, heading,
radius), so a robot reads each with one `numpy.frombuffer`. It is the one message every
robot decodes every control cycle, so its receiver has a decoder of its own that checks an
id block once while it repeats byte for byte (`PoseDecoder`).
"""

from __future__ import annotations

import typing
from collections.abc import Collection, Sequence
from dataclasses import dataclass

import msgpack
import numpy as np

from agent.core.types import PoseSnapshot
from eifp_wire.codec import (
    F8,
    I4,
    SCHEMA_VERSION,
    UNPACK_FLAT,
    check_float,
    check_ids,
    check_int,
    check_values,
    frozen_array,
    known_set,
    open_envelope,
    pack_message,
    read_column,
)
from eifp_wire.limits import (
    MAX_CLOCK_ID,
    MAX_COORD_M,
    MAX_MESSAGE_BYTES,
    MAX_OBSTACLES,
    MAX_RADIUS_M,
    MAX_ROBOT_ID,
    MAX_ROBOTS,
    MAX_SEQ,
    MAX_TIME_S,
    MIN_OBSTACLE_ID,
    ProtocolError,
)

_DISC_FIELDS = 4
"""Values per disc in a `PosesMsg`'s ``discs`` block: x, y, heading, radius."""
_DISC_LO = (-MAX_COORD_M, -MAX_COORD_M, -1e3, 0.0)
_DISC_HI = (MAX_COORD_M, MAX_COORD_M, 1e3, MAX_RADIUS_M)
_DISC_NEAR = min(_DISC_HI)
"""Discs whose every value is within +-this (and radius > 0) pass every range at once."""
_DISC_NAMES = ("x", "y", "theta", "radius")
_POSES_KEYS = ("t", "tick", "pub_ns", "clock", "ids", "discs")
_POSES_MAP_KEYS = frozenset(("schema", "type", *_POSES_KEYS))
_POSES_MAP_HEAD = bytes([0x80 | len(_POSES_MAP_KEYS)])
"""A `PosesMsg` payload starts with this fixmap header (its count of entries)."""
_POSES_VIEWS = frozenset(("robot_ids", "robot_pose", "robot_radius_m", "obstacle_ids",
                          "obstacle_xy_m", "obstacle_radius_m"))


@dataclass(frozen=True, eq=False)
class PosesMsg:
    """World -> robots: every disc's pose at one world tick (the robots' only sensor).

    Wire body: ``t`` (float), ``tick``, ``pub_ns``, ``clock`` (ints), ``ids`` (bin: one
    ``<i4`` per disc, the robots' ids >= 0 first, then the obstacles' < 0), ``discs`` (bin:
    four ``<f8`` per disc in the order of ``ids``: x, y, heading, radius; an obstacle's
    heading is 0). One row per disc, so a receiver reads each block with one
    `numpy.frombuffer` (`PoseDecoder`).

    Args:
        t_s: sim time at which the poses were true (>= 0).
        tick: world tick that produced them (>= 0).
        robot_ids: (n,) ids >= 0, unique, n <= `MAX_ROBOTS`.
        robot_pose: (n, 3) x [m], y [m], heading [rad].
        robot_radius_m: (n,) radii > 0.
        obstacle_ids: (m,) ids < 0, unique, m <= `MAX_OBSTACLES`.
        obstacle_xy_m: (m, 2) obstacle centres.
        obstacle_radius_m: (m,) radii > 0.
        pub_ns: wall time the world published it, `time.monotonic_ns()` on its host (0:
            not stamped); `clock_id` names that clock.
        clock_id: the publishing host's monotonic clock (`WallStamps`); 0: unknown.

    Arrays are read-only (copies when constructed, views of the payload when decoded); an
    invalid message raises `ProtocolError`.
    """

    t_s: float
    tick: int
    robot_ids: np.ndarray
    robot_pose: np.ndarray
    robot_radius_m: np.ndarray
    obstacle_ids: np.ndarray
    obstacle_xy_m: np.ndarray
    obstacle_radius_m: np.ndarray
    pub_ns: int = 0
    clock_id: int = 0

    TYPE: typing.ClassVar[str] = "poses"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "t_s", check_float(self.t_s, "poses.t", 0.0, MAX_TIME_S))
        set_(self, "tick", check_int(self.tick, "poses.tick", 0, MAX_SEQ))
        set_(self, "pub_ns", check_int(self.pub_ns, "poses.pub_ns", 0, MAX_SEQ))
        set_(self, "clock_id", check_int(self.clock_id, "poses.clock", 0, MAX_CLOCK_ID))
        try:
            rid = np.asarray(self.robot_ids)
            oid = np.asarray(self.obstacle_ids)
            if rid.ndim != 1 or oid.ndim != 1:
                raise ProtocolError("poses: ids must be 1-d")
            n, m = rid.shape[0], oid.shape[0]
            if n > MAX_ROBOTS or m > MAX_OBSTACLES:
                raise ProtocolError(f"poses: {n} robots / {m} obstacles exceed the caps")
            if rid.size and not np.issubdtype(rid.dtype, np.integer):
                raise ProtocolError("poses.robots.id: ids must be integers")
            if oid.size and not np.issubdtype(oid.dtype, np.integer):
                raise ProtocolError("poses.obstacles.id: ids must be integers")
            fields = {
                "robot_ids": frozen_array(rid, np.int64, (n,), "poses.robot_ids"),
                "robot_pose": frozen_array(self.robot_pose, np.float64, (n, 3), "poses.robot_pose"),
                "robot_radius_m": frozen_array(self.robot_radius_m, np.float64, (n,),
                                               "poses.robot_radius_m"),
                "obstacle_ids": frozen_array(oid, np.int64, (m,), "poses.obstacle_ids"),
                "obstacle_xy_m": frozen_array(self.obstacle_xy_m, np.float64, (m, 2),
                                              "poses.obstacle_xy_m"),
                "obstacle_radius_m": frozen_array(self.obstacle_radius_m, np.float64, (m,),
                                                  "poses.obstacle_radius_m"),
            }
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ProtocolError):
                raise
            raise ProtocolError(f"poses: bad array: {exc}") from exc
        check_ids(fields["robot_ids"], "poses.robots.id", 0, MAX_ROBOT_ID, None)
        check_ids(fields["obstacle_ids"], "poses.obstacles.id", MIN_OBSTACLE_ID, -1, None)
        check_values(fields["robot_pose"][:, :2], "poses.robots.xy", -MAX_COORD_M, MAX_COORD_M)
        check_values(fields["robot_pose"][:, 2], "poses.robots.theta", -1e3, 1e3)
        check_values(fields["robot_radius_m"], "poses.robots.radius", 0.0, MAX_RADIUS_M,
                     lo_open=True)
        check_values(fields["obstacle_xy_m"], "poses.obstacles.xy", -MAX_COORD_M, MAX_COORD_M)
        check_values(fields["obstacle_radius_m"], "poses.obstacles.radius", 0.0, MAX_RADIUS_M,
                     lo_open=True)
        for name, value in fields.items():
            set_(self, name, value)

    def __getattr__(self, name: str) -> np.ndarray:
        """The per-kind arrays of a decoded message, as views of its disc blocks, made on
        first use (a robot reads the blocks whole, `to_snapshot`)."""
        both: tuple[np.ndarray, np.ndarray] | None = self.__dict__.get("_discs")
        if both is None or name not in _POSES_VIEWS:
            raise AttributeError(name)
        ids, values = both
        n = self.__dict__["_n_robots"]
        views = {"robot_ids": ids[:n], "robot_pose": values[:n, :3],
                 "robot_radius_m": values[:n, 3], "obstacle_ids": ids[n:],
                 "obstacle_xy_m": values[n:, :2], "obstacle_radius_m": values[n:, 3]}
        self.__dict__.update(views)
        return views[name]

    @property
    def n_robots(self) -> int:
        """Number of robots in the message."""
        n = self.__dict__.get("_n_robots")
        return int(self.robot_ids.shape[0]) if n is None else n

    def discs(self) -> tuple[np.ndarray, np.ndarray]:
        """Every disc, robots then obstacles: ids (k,) int64 and (k, 4) x, y, heading, radius
        (heading 0 for obstacles), as on the wire."""
        both: tuple[np.ndarray, np.ndarray] | None = self.__dict__.get("_discs")
        if both is not None:  # decoded: the payload's own arrays
            return both
        n, m = self.robot_ids.shape[0], self.obstacle_ids.shape[0]
        values = np.zeros((n + m, _DISC_FIELDS))
        values[:n, :3] = self.robot_pose
        values[:n, 3] = self.robot_radius_m
        values[n:, :2] = self.obstacle_xy_m
        values[n:, 3] = self.obstacle_radius_m
        return np.concatenate([self.robot_ids, self.obstacle_ids]), values

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        ids, values = self.discs()
        return pack_message(self.TYPE, {
            "t": self.t_s,
            "tick": self.tick,
            "pub_ns": self.pub_ns,
            "clock": self.clock_id,
            "ids": ids.astype(I4).tobytes(),
            "discs": values.astype(F8).tobytes(),
        })

    def encode_parts(self, parts: Sequence[np.ndarray]) -> list[bytes]:
        """One payload per part: the message that holds only the discs of that part (row
        indices into `discs`, ascending), as `encode` gives it for such a message, without
        checking again what this one's construction checked (the world's per-cell
        messages, `eifp_wire.pose_cells.cell_payloads`)."""
        ids, values = self.discs()
        ids4, values8 = ids.astype(I4), values.astype(F8)
        head = {"t": self.t_s, "tick": self.tick, "pub_ns": self.pub_ns, "clock": self.clock_id}
        return [pack_message(self.TYPE, {**head, "ids": ids4[rows].tobytes(),
                                         "discs": values8[rows].tobytes()})
                for rows in parts]

    @classmethod
    def decode(cls, data: object, *, known_ids: Collection[int] | None = None) -> PosesMsg:
        """Parse and validate; `known_ids` (robot and obstacle ids) rejects strangers.

        A receiver of a stream decodes with its own `PoseDecoder` (the same checks, each
        id block checked once)."""
        return PoseDecoder(known_ids).decode(data)

    @classmethod
    def from_snapshot(cls, snapshot: PoseSnapshot, *, pub_ns: int = 0,
                      clock_id: int = 0) -> PosesMsg:
        """Split a world snapshot into robots (ids >= 0) and obstacles (ids < 0)."""
        robots = snapshot.ids >= 0
        return cls(
            t_s=snapshot.stamp_s,
            tick=snapshot.tick,
            robot_ids=snapshot.ids[robots],
            robot_pose=snapshot.pose[robots],
            robot_radius_m=snapshot.radius_m[robots],
            obstacle_ids=snapshot.ids[~robots],
            obstacle_xy_m=snapshot.pose[~robots, :2],
            obstacle_radius_m=snapshot.radius_m[~robots],
            pub_ns=pub_ns,
            clock_id=clock_id,
        )

    def to_snapshot(self) -> PoseSnapshot:
        """Robots then obstacles in one `PoseSnapshot`; obstacles get heading 0.

        Of a decoded message, the snapshot's arrays are views of the payload (nothing is
        copied or checked again)."""
        ids, values = self.discs()
        return PoseSnapshot.trusted(stamp_s=self.t_s, tick=self.tick, ids=ids,
                                    pose=values[:, :3], radius_m=values[:, 3])


class PoseDecoder:
    """Decodes the `PosesMsg` stream of one receiver, every message checked in full.

    The world sends the same discs in the same order every tick, so a message's ``ids``
    block is nearly always the previous one's, byte for byte. Its checks (robots first, ids
    unique, in range, all in `known_ids`) then passed already: the decoder does not repeat
    them and hands out the same read-only int64 id array again (`NeighborTracker.update`
    recognises it). Everything else (the envelope, every key, the time fields, the size,
    finiteness and range of every value) is checked on every message.

    Args:
        known_ids: robot and obstacle ids of the run; None: any.
    """

    def __init__(self, known_ids: Collection[int] | None = None) -> None:
        self.known_ids = known_set(known_ids)
        self._ids_bin: bytes | None = None
        self._ids = np.zeros(0, dtype=np.int64)
        self._n_robots = 0
        self._discs_bytes = 0
        self._discs_shape = (0, _DISC_FIELDS)

    def decode(self, data: object) -> PosesMsg:
        """Parse and validate one payload (`PosesMsg.decode`); raises `ProtocolError`.

        A message like the previous one (the same id block, every field of the usual type
        and in range) is accepted by one chain of comparisons (`_decode_usual`); anything
        else goes through the field-by-field checks, which name what is wrong."""
        if type(data) is bytes and self._ids_bin is not None:
            msg = self._decode_usual(data)
            if msg is not None:
                return msg
        return self._decode_checked(data)

    def _decode_usual(self, data: bytes) -> PosesMsg | None:
        """The message if it passes every check of `_decode_checked` with the previous id
        block, else None (then `_decode_checked` finds what is wrong)."""
        if len(data) > MAX_MESSAGE_BYTES or data[:1] != _POSES_MAP_HEAD:
            return None
        try:
            obj = msgpack.unpackb(data, **UNPACK_FLAT)
        except Exception:  # noqa: BLE001 - the checked path reports it
            return None
        # A fixmap of 8 entries with these 8 keys has no duplicate key.
        if type(obj) is not dict or obj.keys() != _POSES_MAP_KEYS:
            return None
        schema, t_s, tick, pub_ns, clock_id = (obj["schema"], obj["t"], obj["tick"],
                                               obj["pub_ns"], obj["clock"])
        discs_bin = obj["discs"]
        if not (type(schema) is int and schema == SCHEMA_VERSION and obj["type"] == "poses"
                and type(t_s) is float and 0.0 <= t_s <= MAX_TIME_S
                and type(tick) is int and 0 <= tick <= MAX_SEQ
                and type(pub_ns) is int and 0 <= pub_ns <= MAX_SEQ
                and type(clock_id) is int and 0 <= clock_id <= MAX_CLOCK_ID
                and obj["ids"] == self._ids_bin
                and type(discs_bin) is bytes and len(discs_bin) == self._discs_bytes):
            return None
        ids, n = self._ids, self._n_robots
        values = np.ndarray(self._discs_shape, F8, discs_bin)  # read-only view of the bytes
        if ids.shape[0] and not (float(np.abs(values).max()) <= _DISC_NEAR
                                 and float(values[:, 3].min()) > _DISC_LO[3]
                                 and (n == ids.shape[0] or not values[n:, 2].any())):
            return None
        msg = object.__new__(PosesMsg)  # the per-kind views come on first use (__getattr__)
        msg.__dict__.update(t_s=t_s, tick=tick, pub_ns=pub_ns, clock_id=clock_id,
                            _discs=(ids, values), _n_robots=n)
        return msg

    def _decode_checked(self, data: object) -> PosesMsg:
        body = open_envelope(data, PosesMsg.TYPE, _POSES_KEYS, flat=True)
        t_s = check_float(body["t"], "poses.t", 0.0, MAX_TIME_S)
        tick = check_int(body["tick"], "poses.tick", 0, MAX_SEQ)
        pub_ns = check_int(body["pub_ns"], "poses.pub_ns", 0, MAX_SEQ)
        clock_id = check_int(body["clock"], "poses.clock", 0, MAX_CLOCK_ID)
        ids_bin, discs_bin = body["ids"], body["discs"]
        if type(ids_bin) is not bytes or ids_bin != self._ids_bin:
            self._ids, self._n_robots = self._read_ids(ids_bin)
            self._ids_bin = ids_bin
            k = self._ids.shape[0]
            self._discs_bytes, self._discs_shape = 8 * _DISC_FIELDS * k, (k, _DISC_FIELDS)
        ids, n = self._ids, self._n_robots
        k = ids.shape[0]
        if type(discs_bin) is not bytes:
            raise ProtocolError(f"poses.discs: expected bin, got {type(discs_bin).__name__}")
        if len(discs_bin) != 8 * _DISC_FIELDS * k:
            raise ProtocolError(f"poses.discs: {len(discs_bin)} bytes, expected "
                                f"{8 * _DISC_FIELDS * k} for {k} discs")
        values = np.frombuffer(discs_bin, dtype=F8).reshape(k, _DISC_FIELDS)
        if k:
            # Every value within +-`_DISC_NEAR` and every radius > 0 passes every range
            # (max and min propagate NaN, which fails the comparison); else each column is
            # checked against its own range (`_check_discs`: far coordinates, or an error).
            if not (float(np.abs(values).max()) <= _DISC_NEAR
                    and float(values[:, 3].min()) > _DISC_LO[3]):
                _check_discs(values)
            if n < k and values[n:, 2].any():
                raise ProtocolError("poses.discs: an obstacle's heading is not 0")
        msg = object.__new__(PosesMsg)  # the per-kind views come on first use (__getattr__)
        msg.__dict__.update(t_s=t_s, tick=tick, pub_ns=pub_ns, clock_id=clock_id,
                            _discs=(ids, values), _n_robots=n)
        return msg

    def _read_ids(self, ids_bin: object) -> tuple[np.ndarray, int]:
        """The id block as a read-only int64 array and the number of robots; raises."""
        ids = read_column(ids_bin, "poses.ids", I4, None, MAX_ROBOTS + MAX_OBSTACLES)
        n = int(np.count_nonzero(ids >= 0))
        if n and ids[:n].min() < 0:
            raise ProtocolError("poses.ids: the robots' ids (>= 0) must come first")
        if n > MAX_ROBOTS or ids.shape[0] - n > MAX_OBSTACLES:
            raise ProtocolError(f"poses.ids: {n} robots / {ids.shape[0] - n} obstacles exceed "
                                "the caps")
        check_ids(ids, "poses.ids", MIN_OBSTACLE_ID, MAX_ROBOT_ID, self.known_ids)
        out = ids.astype(np.int64)
        out.flags.writeable = False
        return out, n


def _check_discs(values: np.ndarray) -> None:
    """Check each column of a ``discs`` block against its range; the error names it."""
    for j, name in enumerate(_DISC_NAMES):
        check_values(values[:, j], f"poses.discs.{name}", _DISC_LO[j], _DISC_HI[j],
                     lo_open=name == "radius")
