"""The robot process's pose subscribers (`agent.node.CellPoses`), with a session that records
what is declared and undeclared: new cells before old ones go."""

from __future__ import annotations

from typing import Any

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
