"""Key expressions of a run, and the run ids and robot ids they are built from.

Every key is prefixed by the run id, so two runs on one machine never cross:

- ``eifp/<run>/poses/<slot>``      world -> robots, `PosesMsg`, once per world tick, on the
                                   slot ``tick mod K`` (`pose_slot_count`); a robot that
                                   plans on one slot of every control period subscribes
                                   to that slot only, anything else to ``poses/*``.
- ``eifp/<run>/cmd/<id>``          robot <id> -> world, `CommandMsg`.
- ``eifp/<run>/config/<id>``       queryable served by the world, replies `RunConfigMsg`.
- ``eifp/<run>/control``           world -> all, `ControlMsg` (run started / ended).
- ``eifp/<run>/debug/<id>``        robot <id> -> world (and viewers), `PlanDebugMsg`: the
                                   planner's internals, for viewing only; no robot
                                   subscribes to it.
- ``eifp/<run>/alive/world``       liveliness token of the world process.
- ``eifp/<run>/alive/robot/<id>``  liveliness token of robot process <id>.

The pose-slot schedule (`world.sim.schedule`) decides which slot a tick goes on; it is part
of this contract, so its functions are re-exported here.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from eifp_wire.limits import MAX_ROBOT_ID, MAX_RUN_ID_CHARS, ProtocolError
from world.sim.schedule import MAX_POSE_SLOTS as MAX_POSE_SLOTS  # re-exported: the schedule
from world.sim.schedule import plan_pose_slot as plan_pose_slot  # is part of the wire
from world.sim.schedule import pose_slot_count as pose_slot_count  # contract
from world.sim.schedule import pose_slot_of_tick as pose_slot_of_tick

KEY_ROOT = "eifp"

_RUN_ID_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_ROBOT_ID_RE = re.compile(r"0|[1-9][0-9]{0,9}")


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
        """World -> robots pose stream of the ticks ``tick mod K == slot`` (`pose_slot_count`)."""
        if isinstance(slot, bool) or not isinstance(slot, int) or not 0 <= slot < MAX_POSE_SLOTS:
            raise ProtocolError(f"pose slot must be an int in [0, {MAX_POSE_SLOTS}), got {slot!r}")
        return f"{self.prefix}/poses/{slot}"

    @property
    def poses_all(self) -> str:
        """Wildcard over every pose slot: every world tick's poses."""
        return f"{self.prefix}/poses/*"

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
