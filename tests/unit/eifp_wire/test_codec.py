"""Tests of `eifp_wire.codec`: the envelope every message shares, bounded parsing, the field
checks and the configuration serialiser; one rejection test per kind of malformation, run
over every message type, and fuzzing (arbitrary bytes / msgpack objects / mutated valid
messages decode to a valid message or raise ProtocolError, never anything else)."""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import math

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.core.types import PlanDebug
from eifp_wire.codec import (
    SCHEMA_VERSION,
    check_float,
    check_int,
    dump_dataclass,
    load_dataclass,
)
from eifp_wire.limits import MAX_MESSAGE_BYTES, ProtocolError
from eifp_wire.messages import (
    CommandMsg,
    ControlMsg,
    PlanDebugMsg,
    RunConfigMsg,
    WallStamps,
    encode_command,
)
from eifp_wire.poses import PosesMsg
from tests.unit.eifp_wire.samples import (
    DECODERS,
    FUZZ,
    decode_or_protocol_error,
    make_command,
    make_config,
    make_debug,
    make_poses,
    pack,
    raw,
)

# --- The bytes of schema 4 -------------------------------------------------------------------


def _pinned_messages() -> dict[str, bytes]:
    """One message of each type whose bytes depend only on the wire package (a `RunConfigMsg`
    carries every planner setting, so its bytes follow the planner's configuration)."""
    poses = PosesMsg(t_s=1.25, tick=62, robot_ids=np.array([0, 1]),
                     robot_pose=np.array([[1.0, -2.0, 0.5], [3.5, 4.25, -1.0]]),
                     robot_radius_m=np.array([0.5, 0.4]), obstacle_ids=np.array([-1]),
                     obstacle_xy_m=np.array([[0.0, 5.0]]), obstacle_radius_m=np.array([1.0]),
                     pub_ns=123456789, clock_id=42)
    wall = [3, 3, 10, 11, 12, 13, 14]
    cmd = CommandMsg(robot_id=2, seq=17, pose_stamp_s=3.2, v_mps=0.9, omega_radps=-0.4,
                     plan_ms=4.5, status="ok", side=1, resolved_id=5, hold_s=0.15,
                     wall=WallStamps(*wall))
    debug = PlanDebug(ego=np.array([1.0, -2.0, 0.3]), threat_ids=(0, 1, -1),
                      via_points_m=np.array([[1.0, 2.0]]),
                      reference_m=np.array([[0.0, 0.0], [0.5, 0.25]]),
                      predicted_m=np.array([[0.0, 0.0], [0.1, 0.0]]))
    return {
        "poses": poses.encode(),
        "cmd": cmd.encode(),
        "cmd_fast": encode_command(2, 17, 3.2, 0.9, -0.4, 4.5, "ok", 1, 5, 0.15, wall),
        "control": ControlMsg("end", 12.5, "all_arrived").encode(),
        "debug": PlanDebugMsg(robot_id=2, seq=17, t_s=3.2, v_mps=0.9, omega_radps=-0.4,
                              status="ok", debug=debug).encode(),
    }


PINNED = {  # (size in bytes, SHA-256) of schema 4
    "poses": (178, "3ab5e771bfdd52e3396217383c216904513454eeedab3620241703291672d37b"),
    "cmd": (146, "00f569ab9b7a2961d03bc44608736684fdeaa46336d17cacf2b94e38a25cff88"),
    "cmd_fast": (146, "00f569ab9b7a2961d03bc44608736684fdeaa46336d17cacf2b94e38a25cff88"),
    "control": (61, "4a72efaa12bbc33dd1bca78421228b1346e7c4279e0c74806279fc41989c6b32"),
    "debug": (220, "3a83b084944e3314807137d95e8e64c0c696bf988449cb3bda73eac72676bf10"),
}


def test_the_bytes_of_schema_4_are_pinned() -> None:
    """A change to these bytes is a change of the wire format: it needs a new
    `SCHEMA_VERSION` (and new pins)."""
    assert SCHEMA_VERSION == 4
    got = {k: (len(v), hashlib.sha256(v).hexdigest()) for k, v in _pinned_messages().items()}
    assert got == PINNED


# --- Field checks and the configuration serialiser -------------------------------------------


def test_number_checks_take_numpy_numbers_and_refuse_bools() -> None:
    assert check_float(np.float32(0.5), "f") == 0.5 and check_float(3, "f") == 3.0
    assert check_int(np.int64(7), "i", 0, 10) == 7
    for bad in (True, "1", None, [1.0]):
        with pytest.raises(ProtocolError, match="^f: expected a number"):
            check_float(bad, "f")
    with pytest.raises(ProtocolError, match="^i: expected an int"):
        check_int(1.0, "i", 0, 10)
    with pytest.raises(ProtocolError, match=r"^f: 0.0 outside \(0.0, 1.0\]"):
        check_float(0.0, "f", 0.0, 1.0, lo_open=True)
    with pytest.raises(ProtocolError, match="^i: 11 outside"):
        check_int(11, "i", 0, 10)
    with pytest.raises(ProtocolError, match="too large"):
        check_float(10**400, "f")


@dataclasses.dataclass(frozen=True)
class _Inner:
    gain: float
    name: str = "x"


@dataclasses.dataclass(frozen=True)
class _Outer:
    count: int
    pair: tuple[float, float]
    inner: _Inner
    limit: float | None = None
    on: bool = True


def test_the_configuration_serialiser_round_trips_and_checks_each_hint() -> None:
    obj = _Outer(count=3, pair=(1.0, 2.5), inner=_Inner(gain=0.5), limit=None)
    body = dump_dataclass(obj, "o")
    assert body == {"count": 3, "pair": [1.0, 2.5], "inner": {"gain": 0.5, "name": "x"},
                    "limit": None, "on": True}
    assert load_dataclass(msgpack.unpackb(pack(body)), _Outer, "o") == obj  # as received
    for path, value, where in ((("count",), 1.5, "o.count"), (("pair",), [1.0], "o.pair"),
                               (("inner", "gain"), "fast", "o.inner.gain"),
                               (("on",), 1, "o.on"), (("limit",), math.nan, "o.limit")):
        broken = copy.deepcopy(body)
        node = broken
        for p in path[:-1]:
            node = node[p]
        node[path[-1]] = value
        with pytest.raises(ProtocolError, match=f"^{where}"):
            load_dataclass(broken, _Outer, "o")


# --- Rejections: one test per kind of malformation ------------------------------------------


def test_every_message_carries_schema_and_type() -> None:
    for msg, kind in ((make_poses(), "poses"), (make_command(), "cmd"), (make_config(), "config"),
                      (ControlMsg("start", 0.0), "control"), (make_debug(), "debug")):
        body = raw(msg)
        assert body["schema"] == SCHEMA_VERSION and body["type"] == kind


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


def test_rejects_oversized_payload() -> None:
    body = raw(ControlMsg("end", 1.0))
    body["reason"] = "x" * (MAX_MESSAGE_BYTES + 10)
    with pytest.raises(ProtocolError, match="exceeds"):
        ControlMsg.decode(pack(body))
    with pytest.raises(ProtocolError):
        ControlMsg("end", 1.0, "x" * 10_000)


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


# --- Fuzzing ---------------------------------------------------------------------------------


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
