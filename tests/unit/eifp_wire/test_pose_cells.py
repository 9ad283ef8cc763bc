"""The pose stream in cells (`eifp_wire.pose_cells`): the world's per-cell payloads and a
robot's assembly of one view per tick, with lost, late and duplicated cell messages."""

from __future__ import annotations

import numpy as np
import pytest

from eifp_wire.pose_cells import (
    MAX_CELL_MISSES,
    CellAssembler,
    PoseView,
    cell_payloads,
    dead_reckoned,
)
from eifp_wire.poses import PosesMsg
from world.sim.cells import Cell

SIZE_M = 20.0
KNOWN = (0, 1, 2, 3, -1)
CELLS: tuple[Cell, ...] = ((0, 0), (1, 0), (0, 1))


def _msg(tick: int, robots: dict[int, tuple[float, float, float]],
         obstacles: dict[int, tuple[float, float]] | None = None,
         pub_ns: int = 0) -> PosesMsg:
    obstacles = obstacles or {}
    rid, oid = sorted(robots), sorted(obstacles, reverse=True)
    return PosesMsg(t_s=tick * 0.02, tick=tick, robot_ids=rid,
                    robot_pose=np.array([robots[i] for i in rid]).reshape(-1, 3),
                    robot_radius_m=[0.5] * len(rid), obstacle_ids=oid,
                    obstacle_xy_m=np.array([obstacles[i] for i in oid]).reshape(-1, 2),
                    obstacle_radius_m=[1.0] * len(oid), pub_ns=pub_ns, clock_id=7)


def _tick(tick: int, x1: float = 20.0, pub_ns: int = 0) -> dict[Cell, bytes]:
    """One tick cut into CELLS: robot 0 at the origin, 1 at (x1, 0), 2 at (0, 20), the
    obstacle at (3, 0); cell (0, 1) holds robot 2, (1, 0) robot 1."""
    msg = _msg(tick, {0: (0.0, 0.0, 0.0), 1: (x1, 0.0, 3.0), 2: (0.0, 20.0, 1.0)},
               {-1: (3.0, 0.0)}, pub_ns=pub_ns)
    return dict(cell_payloads(msg, CELLS, SIZE_M))


def _assembler() -> CellAssembler:
    asm = CellAssembler(KNOWN, wait_s=0.01, hold_s=0.1)
    asm.hold(CELLS, expected=True)
    return asm


def _feed(asm: CellAssembler, msgs: dict[Cell, bytes], wall_s: float,
          skip: tuple[Cell, ...] = ()) -> list[PoseView]:
    """Decode and add every message but those of `skip`; the views released."""
    out = []
    for cell, payload in sorted(msgs.items()):
        if cell not in skip:
            forced = asm.add(cell, asm.decode(cell, payload), wall_s)
            if forced is not None:
                out.append(forced)
    view = asm.ready(wall_s)
    return out + ([view] if view is not None else [])


# --- the world's payloads --------------------------------------------------------------------

def test_each_cell_payload_is_the_message_of_the_discs_in_that_cell() -> None:
    msg = _msg(5, {0: (0.0, 0.0, 0.0), 3: (25.0, 1.0, 0.5), 1: (-3.0, 2.0, 1.0)},
               {-1: (4.0, 4.0), -2: (29.0, -9.0)}, pub_ns=123)
    out = dict(cell_payloads(msg, [(1, 0), (0, 0), (5, 5), (0, 0)], SIZE_M))
    assert sorted(out) == [(0, 0), (1, 0), (5, 5)]  # sorted, once each, empty ones too
    zero, one, empty = (PosesMsg.decode(out[c]) for c in ((0, 0), (1, 0), (5, 5)))
    assert zero.robot_ids.tolist() == [0, 1] and zero.obstacle_ids.tolist() == [-1]
    assert one.robot_ids.tolist() == [3] and one.obstacle_ids.tolist() == [-2]
    assert empty.robot_ids.shape == (0,) and empty.obstacle_ids.shape == (0,)
    for part in (zero, one, empty):
        assert (part.tick, part.t_s, part.pub_ns, part.clock_id) == (5, 0.1, 123, 7)
    # The bytes of a message built of those discs.
    assert out[(1, 0)] == PosesMsg(
        t_s=0.1, tick=5, robot_ids=[3], robot_pose=[[25.0, 1.0, 0.5]], robot_radius_m=[0.5],
        obstacle_ids=[-2], obstacle_xy_m=[[29.0, -9.0]], obstacle_radius_m=[1.0],
        pub_ns=123, clock_id=7).encode()


def test_discs_in_cells_not_published_are_left_out() -> None:
    msg = _msg(1, {0: (0.0, 0.0, 0.0), 1: (500.0, 0.0, 0.0)})
    payloads = cell_payloads(msg, [(0, 0)], SIZE_M)
    assert [PosesMsg.decode(p).robot_ids.tolist() for _, p in payloads] == [[0]]


# --- assembling a tick -----------------------------------------------------------------------

def test_a_tick_is_released_when_every_expected_cell_is_in() -> None:
    asm = _assembler()
    msgs = _tick(10, pub_ns=50)
    assert _feed(asm, msgs, 1.0, skip=((1, 0),)) == []
    assert asm.deadline_wall_s == pytest.approx(1.01)
    assert asm.add((1, 0), asm.decode((1, 0), msgs[(1, 0)]), 1.002) is None
    view = asm.ready(1.003)
    assert view is not None and (view.tick, view.parts, view.held, view.missing) == (10, 3, 0, 0)
    assert view.snapshot.ids.tolist() == [0, 1, 2, -1]
    assert view.rx_wall_s == 1.002 and view.pub_ns == 50 and view.clock_id == 7
    assert asm.deadline_wall_s is None and asm.ready(2.0) is None


def test_repeated_ids_give_the_same_merged_id_array() -> None:
    asm = _assembler()
    first = _feed(asm, _tick(10), 1.0)[0].snapshot
    second = _feed(asm, _tick(15), 1.1)[0].snapshot
    assert second.ids is first.ids  # each cell's decoder kept its id block


def test_a_lost_cell_is_dead_reckoned_from_its_last_two_messages() -> None:
    asm = _assembler()
    for tick, x1 in ((10, 20.0), (15, 20.5)):
        _feed(asm, _tick(tick, x1), tick * 0.02)
    assert _feed(asm, _tick(20, 21.0), 0.4, skip=((1, 0),)) == []
    (view,) = _feed(asm, {}, 0.4 + 0.011)
    assert (view.tick, view.parts, view.held, view.missing, view.rx_wall_s) == (
        20, 2, 1, 0, pytest.approx(0.41))
    row = view.snapshot.ids.tolist().index(1)
    assert view.snapshot.pose[row].tolist() == pytest.approx([21.0, 0.0, 3.0])
    assert asm.counts.as_dict()["cells_held"] == 1 and asm.counts.partial == 1


def test_dead_reckoning_wraps_the_heading_and_keeps_a_disc_seen_once() -> None:
    before = _msg(10, {1: (0.0, 0.0, 3.1)})
    last = _msg(15, {1: (1.0, 0.0, -3.1), 2: (5.0, 5.0, 0.0)})
    snap = dead_reckoned(last, before, 0.4)  # one more interval of 0.1 s
    assert snap.stamp_s == 0.4
    assert snap.pose[0].tolist() == pytest.approx([2.0, 0.0, -3.1 + (2 * np.pi - 6.2)])
    assert snap.pose[1].tolist() == [5.0, 5.0, 0.0]
    assert dead_reckoned(last, None, 0.4).pose.tolist() == last.to_snapshot().pose.tolist()


def test_a_disc_that_moved_into_a_fresh_cell_keeps_the_fresh_pose() -> None:
    """Robot 1 moves from cell (1, 0) into (0, 0); (1, 0)'s message is lost: its held copy
    still shows robot 1, which the view takes from the fresh message of (0, 0)."""
    asm = _assembler()
    _feed(asm, _tick(10, 10.5), 0.2)
    msgs = _tick(15, 9.5)
    assert 1 in PosesMsg.decode(msgs[(0, 0)]).robot_ids.tolist()
    _feed(asm, msgs, 0.3, skip=((1, 0),))
    (view,) = _feed(asm, {}, 0.32)
    assert view.held == 1 and view.snapshot.ids.tolist() == [0, 1, 2, -1]
    row = view.snapshot.ids.tolist().index(1)
    assert view.snapshot.pose[row, 0] == 9.5


def test_a_cell_with_nothing_recent_is_missing_and_after_a_few_not_waited_for() -> None:
    asm = _assembler()
    _feed(asm, _tick(10), 0.2)
    wall = 0.2
    for k in range(MAX_CELL_MISSES):
        wall += 0.1
        tick = 15 + 5 * k
        assert _feed(asm, _tick(tick), wall, skip=((1, 0),)) == []
        (view,) = _feed(asm, {}, wall + 0.011)
        assert view.held == (1 if k == 0 else 0) and view.missing == (0 if k == 0 else 1)
        assert 1 not in view.snapshot.ids.tolist() or k == 0
    # No longer expected: the next tick is complete without it, at once.
    (view,) = _feed(asm, _tick(35), wall + 0.1, skip=((1, 0),))
    assert view.tick == 35 and view.missing == 0
    # It delivers again: expected again.
    _feed(asm, _tick(40), wall + 0.2)
    assert _feed(asm, _tick(45), wall + 0.3, skip=((1, 0),)) == []


def test_a_newer_tick_forces_the_waiting_one_out() -> None:
    asm = _assembler()
    assert _feed(asm, _tick(10), 0.2, skip=((0, 1),)) == []
    views = _feed(asm, _tick(15), 0.205)
    assert [v.tick for v in views] == [10, 15]
    assert views[0].held == 0 and views[0].missing == 1  # (0, 1) never delivered
    assert 2 not in views[0].snapshot.ids.tolist()


def test_late_and_duplicated_messages() -> None:
    asm = _assembler()
    old = _tick(10)
    _feed(asm, _tick(15), 0.3)
    assert _feed(asm, old, 0.31) == [] and asm.counts.late == 3
    msgs = _tick(20)
    zero = asm.decode((0, 0), msgs[(0, 0)])
    assert asm.add((0, 0), zero, 0.4) is None
    assert asm.add((0, 0), zero, 0.4) is None  # a duplicate changes nothing
    assert asm.ready(0.4) is None
    (view,) = _feed(asm, msgs, 0.401)
    assert view.parts == 3 and view.snapshot.ids.tolist() == [0, 1, 2, -1]


def test_a_cell_added_later_is_waited_for_once_it_has_delivered() -> None:
    asm = CellAssembler(KNOWN, wait_s=0.01, hold_s=0.1)
    asm.hold([(0, 0)], expected=True)
    asm.hold([(1, 0)], expected=False)
    msgs = _tick(10)
    (view,) = _feed(asm, {(0, 0): msgs[(0, 0)]}, 0.2)  # (1, 0) not waited for yet
    assert view.parts == 1 and view.missing == 0
    again = _tick(12)
    _feed(asm, {c: again[c] for c in ((0, 0), (1, 0))}, 0.3)  # it delivered: expected now
    assert _feed(asm, {(0, 0): _tick(15)[(0, 0)]}, 0.4) == []
    assert asm.accepts((1, 0)) and not asm.accepts((0, 1))
    asm.drop([(1, 0)])
    assert not asm.accepts((1, 0))


def test_searching_takes_every_cell_and_waits_the_whole_wait() -> None:
    asm = CellAssembler(KNOWN, wait_s=0.01, hold_s=0.1)
    asm.search()
    msgs = _tick(10)
    for cell, payload in msgs.items():
        assert asm.accepts(cell)
        assert asm.add(cell, asm.decode(cell, payload), 0.2) is None
    assert asm.ready(0.205) is None
    view = asm.ready(0.211)
    assert view is not None and view.parts == 3 and view.snapshot.ids.tolist() == [0, 1, 2, -1]
    asm.hold([(0, 0)], expected=False)
    asm.found([(0, 0)])
    assert sorted(asm.cells) == [(0, 0)] and not asm.accepts((1, 0))
