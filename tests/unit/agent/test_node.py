"""The robot process's pose subscribers (`agent.node.CellPoses`), with a session that records
what is declared and undeclared: new cells before old ones go."""

from __future__ import annotations

from typing import Any

import pytest

from agent.node import CellPoses, PoseInbox
from eifp_wire import RunKeys
from world.sim.cells import CellChange

KEYS = RunKeys("r1")


class _Sub:
    def __init__(self, log: list[str], key: str) -> None:
        self.log, self.key = log, key

    def undeclare(self) -> None:
        self.log.append(f"-{self.key}")


class _Session:
    def __init__(self) -> None:
        self.log: list[str] = []

    def declare_subscriber(self, key: str, handler: Any) -> _Sub:
        self.log.append(f"+{key}")
        return _Sub(self.log, key)


def _poses(slot: int | None) -> tuple[CellPoses, _Session]:
    session = _Session()
    return CellPoses(session, KEYS, slot, PoseInbox(None)), session  # type: ignore[arg-type]


def test_cells_are_subscribed_on_the_robots_slot_before_any_is_dropped() -> None:
    poses, session = _poses(2)
    poses.hold([(0, 0), (1, 0)])
    poses.apply(CellChange(added=frozenset({(2, 0)}), dropped=frozenset({(0, 0)})))
    assert session.log == ["+eifp/r1/poses/2/0/0", "+eifp/r1/poses/2/1/0",
                           "+eifp/r1/poses/2/2/0", "-eifp/r1/poses/2/0/0"]
    assert sorted(poses.subs) == [(1, 0), (2, 0)]


def test_searching_subscribes_to_every_cell_until_the_robot_is_found() -> None:
    poses, session = _poses(None)
    poses.hold([(0, 0)])
    poses.apply(CellChange(dropped=frozenset({(0, 0)}), search=True))
    poses.apply(CellChange(added=frozenset({(5, 0)}), found=True))
    assert session.log == ["+eifp/r1/poses/*/0/0", "+eifp/r1/poses/*/*/*",
                           "-eifp/r1/poses/*/0/0", "+eifp/r1/poses/*/5/0",
                           "-eifp/r1/poses/*/*/*"]
    assert poses.every is None and list(poses.subs) == [(5, 0)]


class _Sample:
    def __init__(self, key: str, payload: bytes) -> None:
        import zenoh

        self.key_expr, self.payload, self.source_info = key, zenoh.ZBytes(payload), None


def test_the_inbox_takes_what_is_queued_without_waiting_and_counts_it() -> None:
    """`RobotNode.poll_poses` moves what came since the loop's wait into the ring with
    ``wait(0.0)``, so a tick's late cells waiting in the queue are assembled, not lost."""
    inbox = PoseInbox(None)
    assert inbox.wait(0.0) == (pytest.approx(0.0, abs=0.05), [])
    for k in range(3):
        inbox.queue.put(_Sample(KEYS.poses_cell(0, (k, 0)), b"x" * (k + 1)))  # type: ignore[arg-type]
    inbox.wait(0.0)
    assert inbox.take() == [(KEYS.poses_cell(0, (k, 0)), b"x" * (k + 1)) for k in range(3)]
    assert inbox.summary() == {"rx_pose_msgs": 3, "rx_pose_bytes": 6}
    assert inbox.take() == []
