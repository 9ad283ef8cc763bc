"""Tests of `eifp_wire.keys`: run ids, the key expressions of a run, and ids parsed back."""

from __future__ import annotations

import pytest

from eifp_wire.keys import (
    MAX_CELL_INDEX,
    MAX_POSE_SLOTS,
    RunKeys,
    check_robot_id,
    validate_run_id,
)
from eifp_wire.limits import MAX_ROBOT_ID, ProtocolError


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


def test_robot_ids_are_ints_in_range() -> None:
    assert check_robot_id(0) == 0 and check_robot_id(MAX_ROBOT_ID) == MAX_ROBOT_ID
    for bad in (-1, MAX_ROBOT_ID + 1, True, 1.0, "1", None):
        with pytest.raises(ProtocolError, match="robot id"):
            check_robot_id(bad)


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
    assert k.poses_all == "eifp/r1/poses/*/*/*"
    for bad in (-1, MAX_POSE_SLOTS, 1.0, True, "1"):
        with pytest.raises(ProtocolError, match="pose slot"):
            k.poses_slot(bad)
        with pytest.raises(ProtocolError, match="pose slot"):
            k.poses_cell(bad, (0, 0))


def test_pose_cell_keys_encode_the_slot_and_the_cell() -> None:
    k = RunKeys("r1")
    assert k.poses_cell(3, (-1, 2)) == "eifp/r1/poses/3/-1/2"
    assert k.poses_cell(None, (0, 0)) == "eifp/r1/poses/*/0/0"
    assert k.poses_every_cell(2) == "eifp/r1/poses/2/*/*"
    assert k.poses_every_cell(None) == k.poses_all
    for slot, cell in ((0, (0, 0)), (4, (-7, 12)), (999, (MAX_CELL_INDEX, -MAX_CELL_INDEX))):
        assert k.cell_of_poses(k.poses_cell(slot, cell)) == (slot, cell)
    for bad_cell in ((0,), (0, 0, 0), (1.0, 0), (True, 0), (MAX_CELL_INDEX + 1, 0), [0, 0]):
        with pytest.raises(ProtocolError, match="pose cell"):
            k.poses_cell(0, bad_cell)  # type: ignore[arg-type]


@pytest.mark.parametrize("key", [
    "eifp/r1/poses/3", "eifp/r1/poses/3/1", "eifp/r1/poses/3/1/2/3", "eifp/r1/poses/03/1/2",
    "eifp/r1/poses/3/-0/2", "eifp/r1/poses/3/01/2", "eifp/r1/poses/3/+1/2",
    "eifp/r1/poses/*/1/2", "eifp/r1/poses/3/x/2", "eifp/r2/poses/3/1/2",
    "eifp/r1/poses/1000/1/2", "eifp/r1/poses/3/1000000000/2", "eifp/r1/cmd/3"])
def test_bad_pose_cell_keys_are_refused(key: str) -> None:
    with pytest.raises(ProtocolError):
        RunKeys("r1").cell_of_poses(key)


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
