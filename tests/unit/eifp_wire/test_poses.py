"""Tests of `eifp_wire.poses`: `PosesMsg` round trips and rejections, and a receiver's
`PoseDecoder`, which must accept exactly what a fresh decode accepts."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.types import PoseSnapshot
from eifp_wire.limits import MAX_MESSAGE_BYTES, MAX_ROBOTS, ProtocolError
from eifp_wire.poses import PoseDecoder, PosesMsg
from tests.unit.eifp_wire.samples import (
    FUZZ,
    decode_or_protocol_error,
    discs,
    make_poses,
    pack,
    poses_body,
    raw,
)

KNOWN = frozenset({0, 1, 2, -1, -2})


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
    for n in (1, 7, 8, 100, 128, 1000, 1820, 1821, MAX_ROBOTS):
        size = len(make_poses(n=n, m=0).encode())
        # msgpack's bin headers take 1, 2 or 4 bytes more per column as columns grow.
        assert 36 * n <= size - envelope <= 36 * n + 15, n
    assert len(make_poses(n=MAX_ROBOTS, m=0).encode()) <= MAX_MESSAGE_BYTES


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


def test_poses_carry_their_publish_stamp_and_clock():
    snap = PosesMsg(t_s=1.0, tick=50, robot_ids=np.array([0]),
                             robot_pose=np.zeros((1, 3)), robot_radius_m=np.array([0.5]),
                             obstacle_ids=np.zeros(0, dtype=np.int64),
                             obstacle_xy_m=np.zeros((0, 2)), obstacle_radius_m=np.zeros(0),
                             pub_ns=123456789, clock_id=42)
    back = PosesMsg.decode(snap.encode())
    assert back.pub_ns == 123456789 and back.clock_id == 42
    body = raw(snap)
    body["clock"] = 2**40
    with pytest.raises(ProtocolError, match="poses.clock"):
        PosesMsg.decode(pack(body))


# --- Rejections ------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_poses_rejects_non_finite(bad) -> None:
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


def test_poses_rejects_unknown_ids() -> None:
    with pytest.raises(ProtocolError, match="unknown"):
        PosesMsg.decode(make_poses().encode(), known_ids={0, 1, -1, -2})  # robot 2 unknown
    with pytest.raises(ProtocolError, match="unknown"):
        PosesMsg.decode(make_poses().encode(), known_ids={0, 1, 2, -1})  # obstacle -2 unknown


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


# --- Fuzzing with the receivers' options: unknown ids, hostile values, huge arrays ---------


@FUZZ
@given(ids=st.binary(max_size=48), values=st.binary(max_size=320))
def test_fuzz_pose_blocks(ids: bytes, values: bytes) -> None:
    body = raw(make_poses())
    body["ids"], body["discs"] = ids, values
    decode_or_protocol_error(PosesMsg.decode, pack(body))


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


# --- PoseDecoder: a receiver's stream, each id block checked once ----------------------------


def test_pose_decoder_hands_out_one_id_array_while_the_ids_repeat() -> None:
    decoder = PoseDecoder(KNOWN)
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
    decoder = PoseDecoder(KNOWN)
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
    decoder = PoseDecoder(KNOWN)
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
    decoder = PoseDecoder(KNOWN)
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
    decoder = PoseDecoder(KNOWN)
    data = make_poses().encode()
    decoder.decode(data)
    head = data[0]
    assert head == 0x88  # a fixmap of 8 entries; one more entry, a second "t"
    repeated = bytes([head + 1]) + data[1:] + pack("t") + pack(9.0)
    with pytest.raises(ProtocolError, match="duplicate map key"):
        decoder.decode(repeated)
