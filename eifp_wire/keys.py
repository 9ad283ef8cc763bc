"""Key expressions of a run, and the run ids and robot ids they are built from.

Every key is prefixed by the run id, so two runs on one machine never cross:

- ``eifp/<run>/poses/<slot>/<i>/<j>``  world -> robots, `PosesMsg`: every disc whose centre
                                   is in cell (i, j) of the pose grid, once per world tick,
                                   on the slot ``tick mod K`` (`pose_slot_count`). i and j
                                   are signed decimal integers (``-1``); the grid, its cell
                                   size and the cells a robot holds are `world.sim.cells`
                                   (cell size = sensing radius + 10 m, 20 m by default). A
                                   robot subscribes to each cell it holds on the one slot
                                   its plans fall on (``poses/<slot>/<i>/<j>``), or on every
                                   slot (``poses/*/<i>/<j>``) if its plans are not all on
                                   one; a robot that lost itself subscribes to
                                   ``poses/<slot>/*/*`` until it sees itself again. The
                                   world publishes every cell within reach of a robot, empty
                                   or not (`world.sim.cells.CellRule.published`), so a
                                   robot can tell a lost message from an empty cell.
- ``eifp/<run>/cmd/<id>``          robot <id> -> world, `CommandMsg`.
- ``eifp/<run>/config/<id>``       queryable served by the world, replies `RunConfigMsg`.
- ``eifp/<run>/control``           world -> all, `ControlMsg` (run started / ended).
- ``eifp/<run>/debug/<id>``        robot <id> -> world (and viewers), `PlanDebugMsg`: the
                                   planner's internals, for viewing only; no robot
                                   subscribes to it.
- ``eifp/<run>/alive/world``       liveliness token of the world process.
- ``eifp/<run>/alive/robot/<id>``  liveliness token of robot process <id>.

The pose-slot schedule (`world.sim.schedule`) decides which slot a tick goes on, and the
pose grid (`world.sim.cells`) which cell a disc goes in; both are part of this contract, so
their functions are re-exported here. ``poses/<slot>`` (`RunKeys.poses_slot`, one message of
every disc per tick) is what the world published before the grid; only the transport
benchmarks (`orchestrator bench --floor`) still use it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from eifp_wire.limits import MAX_ROBOT_ID, MAX_RUN_ID_CHARS, ProtocolError
from world.sim.cells import Cell as Cell  # re-exported: the grid is part of the wire contract
from world.sim.cells import CellRule as CellRule
from world.sim.schedule import MAX_POSE_SLOTS as MAX_POSE_SLOTS  # re-exported: the schedule
from world.sim.schedule import plan_pose_slot as plan_pose_slot  # is part of the wire
from world.sim.schedule import pose_slot_count as pose_slot_count  # contract
from world.sim.schedule import pose_slot_of_tick as pose_slot_of_tick

KEY_ROOT = "eifp"

_RUN_ID_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_ROBOT_ID_RE = re.compile(r"0|[1-9][0-9]{0,9}")
_CELL_INDEX = r"(0|-?[1-9][0-9]{0,8})"
_CELL_KEY_RE = re.compile(rf"(0|[1-9][0-9]{{0,2}})/{_CELL_INDEX}/{_CELL_INDEX}")
MAX_CELL_INDEX = 10**9 - 1
"""Largest |i|, |j| of a pose cell in a key (coordinates are bounded by `MAX_COORD_M`)."""


def _check_cell(cell: object) -> Cell:
    if (not isinstance(cell, tuple) or len(cell) != 2
            or not all(isinstance(c, int | np.integer) and not isinstance(c, bool)
                       and abs(int(c)) <= MAX_CELL_INDEX for c in cell)):
        raise ProtocolError(f"pose cell must be two ints within +-{MAX_CELL_INDEX}, "
                            f"got {cell!r}")
    return (int(cell[0]), int(cell[1]))


def validate_run_id(run_id: object) -> str:
    """Return `run_id` if it is safe inside a key expression and a directory name.

    Allowed: 1..64 characters of ``[A-Za-z0-9_.-]``, starting with a letter or digit (no
    ``/``, wildcards, ``$``, ``?``, ``#`` or whitespace).
    """
    if not isinstance(run_id, str):
        raise ProtocolError(f"run id must be a string, got {type(run_id).__name__}")
    if not 0 < len(run_id) <= MAX_RUN_ID_CHARS or _RUN_ID_RE.fullmatch(run_id) is None:
        raise ProtocolError(
            f"bad run id {run_id!r}: 1..{MAX_RUN_ID_CHARS} chars of [A-Za-z0-9_.-], "
            "starting with a letter or digit"
        )
    return run_id


def check_robot_id(robot_id: object) -> int:
    """Return `robot_id` as an int if it is one in [0, `MAX_ROBOT_ID`] (bools are not)."""
    if isinstance(robot_id, bool) or not isinstance(robot_id, int | np.integer):
        raise ProtocolError(f"robot id must be an int, got {type(robot_id).__name__}")
    rid = int(robot_id)
    if not 0 <= rid <= MAX_ROBOT_ID:
        raise ProtocolError(f"robot id {rid} out of range [0, {MAX_ROBOT_ID}]")
    return rid


def _check_slot(slot: object) -> int:
    if isinstance(slot, bool) or not isinstance(slot, int) or not 0 <= slot < MAX_POSE_SLOTS:
        raise ProtocolError(f"pose slot must be an int in [0, {MAX_POSE_SLOTS}), got {slot!r}")
    return slot


@dataclass(frozen=True)
class RunKeys:
    """Every key expression of one run.

    Args:
        run_id: validated with `validate_run_id`.
    """

    run_id: str

    def __post_init__(self) -> None:
        validate_run_id(self.run_id)

    @property
    def prefix(self) -> str:
        """``eifp/<run>``."""
        return f"{KEY_ROOT}/{self.run_id}"

    def poses_slot(self, slot: int) -> str:
        """The whole-tick pose key of the ticks ``tick mod K == slot`` (before the grid; the
        transport benchmarks only)."""
        return f"{self.prefix}/poses/{_check_slot(slot)}"

    def poses_cell(self, slot: int | None, cell: Cell) -> str:
        """World -> robots poses of one cell on one slot (None: wildcard over the slots)."""
        i, j = _check_cell(cell)
        head = "*" if slot is None else str(_check_slot(slot))
        return f"{self.prefix}/poses/{head}/{i}/{j}"

    def poses_every_cell(self, slot: int | None) -> str:
        """Wildcard over every cell of one slot (None: of every slot)."""
        head = "*" if slot is None else str(_check_slot(slot))
        return f"{self.prefix}/poses/{head}/*/*"

    @property
    def poses_all(self) -> str:
        """Wildcard over every pose message: every cell of every world tick."""
        return self.poses_every_cell(None)

    def cell_of_poses(self, key: object) -> tuple[int, Cell]:
        """(slot, cell) of a ``poses/<slot>/<i>/<j>`` key (str or zenoh.KeyExpr)."""
        key = str(key)
        head = f"{self.prefix}/poses/"
        match = _CELL_KEY_RE.fullmatch(key[len(head):]) if key.startswith(head) else None
        if match is None:
            raise ProtocolError(f"key {key!r} is not a pose cell key under {head!r}")
        slot, i, j = (int(g) for g in match.groups())
        return _check_slot(slot), _check_cell((i, j))

    @property
    def control(self) -> str:
        """World -> all run start/end announcements."""
        return f"{self.prefix}/control"

    def cmd(self, robot_id: int) -> str:
        """Robot -> world command stream of one robot."""
        return f"{self.prefix}/cmd/{check_robot_id(robot_id)}"

    @property
    def cmd_all(self) -> str:
        """Wildcard over every robot's command stream (the world subscribes to it)."""
        return f"{self.prefix}/cmd/*"

    def config(self, robot_id: int) -> str:
        """Selector a robot queries for its `RunConfigMsg`."""
        return f"{self.prefix}/config/{check_robot_id(robot_id)}"

    @property
    def config_all(self) -> str:
        """Key expression of the world's configuration queryable."""
        return f"{self.prefix}/config/*"

    def debug(self, robot_id: int) -> str:
        """Robot -> viewers: one robot's planner internals (`PlanDebugMsg`)."""
        return f"{self.prefix}/debug/{check_robot_id(robot_id)}"

    @property
    def debug_all(self) -> str:
        """Wildcard over every robot's debug stream (the world and live viewers)."""
        return f"{self.prefix}/debug/*"

    @property
    def alive_world(self) -> str:
        """Liveliness token of the world."""
        return f"{self.prefix}/alive/world"

    def alive_robot(self, robot_id: int) -> str:
        """Liveliness token of one robot process."""
        return f"{self.prefix}/alive/robot/{check_robot_id(robot_id)}"

    @property
    def alive_robot_all(self) -> str:
        """Wildcard over every robot's liveliness token."""
        return f"{self.prefix}/alive/robot/*"

    def _id_after(self, key: object, middle: str) -> int:
        key = str(key)
        head = f"{self.prefix}/{middle}/"
        if not key.startswith(head):
            raise ProtocolError(f"key {key!r} is not under {head!r}")
        tail = key[len(head):]
        if _ROBOT_ID_RE.fullmatch(tail) is None:
            raise ProtocolError(f"key {key!r}: bad robot id {tail!r}")
        return check_robot_id(int(tail))

    def robot_id_of_cmd(self, key: object) -> int:
        """Robot id in a ``cmd/<id>`` key (str or zenoh.KeyExpr)."""
        return self._id_after(key, "cmd")

    def robot_id_of_debug(self, key: object) -> int:
        """Robot id in a ``debug/<id>`` key."""
        return self._id_after(key, "debug")

    def robot_id_of_config(self, key: object) -> int:
        """Robot id in a ``config/<id>`` key."""
        return self._id_after(key, "config")

    def robot_id_of_alive(self, key: object) -> int:
        """Robot id in an ``alive/robot/<id>`` key."""
        return self._id_after(key, "alive/robot")
