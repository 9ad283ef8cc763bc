"""Pose cells: which cell a point is in, which cells a robot subscribes to, its view (pure).

The world publishes each tick's poses as one message per cell of a square grid
(`eifp_wire.keys.RunKeys.poses_cell`), every disc in the cell of its centre; a robot
subscribes to the cells near it and so receives what it can sense, not the whole fleet.
The lockstep loop (`world.sim.lockstep`) gives each robot the same view through the same
functions (`CellSubscription`, `merge_parts`), so lockstep and distributed runs see the
same neighbours.

Radii, from the planner's sensing radius (`ThreatConfig.sensing_radius_m`, 10 m by
default; `CellRule.of_config`):

- ``see_radius_m`` = sensing radius + `ESTIMATION_MARGIN_M` (15 m): the farthest disc a
  robot's controller estimates (`agent.planning.controller`).
- ``add_radius_m`` = see + `HISTORY_MARGIN_M` (18.75 m): a cell is subscribed as soon as
  any point of it is this close. A disc closing in at up to `MAX_CLOSING_SPEED_MPS` is
  then received for at least one estimation window (`ESTIMATION_WINDOW_S`) before it can
  come within ``see_radius_m``: its velocity is estimated from a full window of history.
- ``drop_radius_m`` = add + `HYSTERESIS_M` (20 m): a subscribed cell is dropped only once
  every point of it is farther than this, so a robot moving back and forth across a border
  does not subscribe and unsubscribe every cycle.
- the cell size is ``drop_radius_m`` (20 m): every cell a robot holds lies within 3 x 3
  cells around its own.

Cell (i, j) is the square ``[(i - 1/2) c, (i + 1/2) c) x [(j - 1/2) c, (j + 1/2) c)`` of
side c: the origin is the centre of cell (0, 0), so a small scenario around the origin is
one cell. Distances are centre to centre, as the planners' sensing radius is.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.config import PlannerConfig
from agent.core.types import PoseSnapshot
from agent.planning.estimation import ESTIMATION_MARGIN_M, ESTIMATION_WINDOW_S

Cell = tuple[int, int]
"""A cell's integer coordinates (i, j)."""

MAX_CLOSING_SPEED_MPS = 5.0
"""Closing speed of two discs the margins allow for: the controller's `ESTIMATION_MARGIN_M`
makes the same assumption over its longest forward prediction (5 m in 1 s)."""
HISTORY_MARGIN_M = ESTIMATION_WINDOW_S * MAX_CLOSING_SPEED_MPS
"""Distance a disc may close in over one estimation window (0.75 s x 5 m/s = 3.75 m)."""
HYSTERESIS_M = 1.25
"""How much farther than ``add_radius_m`` a subscribed cell must be before it is dropped.
Chosen: ten control periods at the default top speed (1.1 m/s), far more than the jitter
of a robot waiting or turning at a border, and it rounds the cell size to sensing + 10 m."""
PUBLISH_SLACK_M = 5.0
"""The world publishes every cell within ``drop_radius_m`` plus this of a robot, empty or
not: a robot's view of its own position lags the world's by a few cycles at most, so every
cell it holds is published and it can tell a lost message from an empty cell."""
SELF_MISSES = 3
"""Views in a row without the robot itself after which it looks for itself in every cell
(`CellSubscription.missed_self`)."""
_EPS_M = 1e-6
"""Cells are tested against a disc this much larger: rounding never leaves a border cell
out (a cell more is harmless, a cell less is a missing neighbour)."""


def cells_of(xy: np.ndarray, size_m: float) -> np.ndarray:
    """(n, 2) int64 cells of (n, 2) points [m] (``floor(x / c + 1/2)``)."""
    return np.floor(np.asarray(xy, dtype=float) / size_m + 0.5).astype(np.int64)


def cell_of(x_m: float, y_m: float, size_m: float) -> Cell:
    """The cell of one point."""
    return (math.floor(x_m / size_m + 0.5), math.floor(y_m / size_m + 0.5))


def _index_range(lo_m: float, hi_m: float, size_m: float) -> range:
    return range(math.floor(lo_m / size_m + 0.5), math.floor(hi_m / size_m + 0.5) + 1)


def cell_gaps(x_m: float, y_m: float, radius_m: float, size_m: float
              ) -> list[tuple[Cell, float]]:
    """Every cell with a point within `radius_m` of (x, y), and the squared distance from
    (x, y) to its nearest point (0 for the cell of (x, y))."""
    r = radius_m + _EPS_M
    out = []
    for i in _index_range(x_m - r, x_m + r, size_m):
        # The gap from x to the cell's x-interval (0 inside it).
        dx = max((i - 0.5) * size_m - x_m, 0.0, x_m - (i + 0.5) * size_m)
        for j in _index_range(y_m - r, y_m + r, size_m):
            dy = max((j - 0.5) * size_m - y_m, 0.0, y_m - (j + 0.5) * size_m)
            gap2 = dx * dx + dy * dy
            if gap2 <= r * r:
                out.append(((i, j), gap2))
    return out


def covering(x_m: float, y_m: float, radius_m: float, size_m: float) -> frozenset[Cell]:
    """Every cell with a point within `radius_m` of (x, y): the cells that cover the disc.

    Exact up to `_EPS_M`: a cell is in the set when its nearest point is at most
    ``radius_m + _EPS_M`` away.
    """
    return frozenset(cell for cell, _ in cell_gaps(x_m, y_m, radius_m, size_m))


def cells_near(xy: np.ndarray, radius_m: float, size_m: float) -> frozenset[Cell]:
    """The cells of the squares of half-side `radius_m` around each of (n, 2) points: a
    superset of the cells covering each disc of that radius (`covering`), in one pass."""
    pts = np.asarray(xy, dtype=float).reshape(-1, 2)
    r = radius_m + _EPS_M
    ranges = np.hstack([cells_of(pts - r, size_m), cells_of(pts + r, size_m)])
    out: set[Cell] = set()
    for i0, j0, i1, j1 in set(map(tuple, ranges.tolist())):  # points in one cell share one
        out.update((i, j) for i in range(i0, i1 + 1) for j in range(j0, j1 + 1))
    return frozenset(out)


@dataclass(frozen=True)
class CellRule:
    """The grid and the radii of the subscription rule (see the module docstring).

    Args:
        see_radius_m: the farthest disc the robot's controller looks at.
        add_radius_m: a cell with a point this close is subscribed (>= see_radius_m).
        drop_radius_m: a subscribed cell is dropped once wholly farther (>= add_radius_m).
        size_m: the cell size.
    """

    see_radius_m: float
    add_radius_m: float
    drop_radius_m: float
    size_m: float

    def __post_init__(self) -> None:
        if not (0.0 < self.see_radius_m <= self.add_radius_m <= self.drop_radius_m
                and math.isfinite(self.drop_radius_m) and self.size_m > 0.0
                and math.isfinite(self.size_m)):
            raise ValueError(f"cell rule needs 0 < see <= add <= drop and a finite size > 0: "
                             f"{self}")

    @classmethod
    def of_config(cls, config: PlannerConfig) -> CellRule:
        """The rule for a run's planner settings (the cell size is the drop radius)."""
        see = config.threats.sensing_radius_m + ESTIMATION_MARGIN_M
        add = see + HISTORY_MARGIN_M
        drop = add + HYSTERESIS_M
        return cls(see_radius_m=see, add_radius_m=add, drop_radius_m=drop, size_m=drop)

    def cell_of(self, x_m: float, y_m: float) -> Cell:
        """The cell of a point."""
        return cell_of(x_m, y_m, self.size_m)

    def needed(self, x_m: float, y_m: float) -> frozenset[Cell]:
        """The cells a robot at (x, y) subscribes to at least (``add_radius_m``)."""
        return covering(x_m, y_m, self.add_radius_m, self.size_m)

    def update(self, held: Iterable[Cell], x_m: float, y_m: float) -> frozenset[Cell]:
        """The cells to hold for a robot at (x, y) that holds `held`: every cell within
        ``add_radius_m`` and those of `held` still within ``drop_radius_m``."""
        held = held if isinstance(held, frozenset | set) else frozenset(held)
        add2 = (self.add_radius_m + _EPS_M) ** 2
        return frozenset(cell for cell, gap2 in cell_gaps(x_m, y_m, self.drop_radius_m,
                                                          self.size_m)
                         if gap2 <= add2 or cell in held)

    def published(self, robot_xy: np.ndarray) -> frozenset[Cell]:
        """The cells the world publishes, empty or not: every cell within ``drop_radius_m``
        plus `PUBLISH_SLACK_M` of a robot ((n, 2) positions), a superset of what any robot
        holds."""
        return cells_near(robot_xy, self.drop_radius_m + PUBLISH_SLACK_M, self.size_m)


@dataclass(frozen=True)
class CellChange:
    """What a robot's subscriptions do after a view: subscribe `added` first, then drop
    `dropped`. `search` True: subscribe to every cell (the robot lost itself) and drop the
    cells; `found` True: the every-cell subscription is dropped after `added`."""

    added: frozenset[Cell] = frozenset()
    dropped: frozenset[Cell] = frozenset()
    search: bool = False
    found: bool = False

    @property
    def empty(self) -> bool:
        """Nothing to declare or undeclare."""
        return not (self.added or self.dropped or self.search or self.found)


class CellSubscription:
    """The cells one robot holds, and how they follow it (`CellRule.update`).

    Starts with the cells needed at the robot's start pose. After each view it observed,
    the robot calls `follow` with its own position in it; a view without the robot itself
    (it restarted away from its start, or its own cell's message was lost) is reported with
    `missed_self`: before it was ever located, or `SELF_MISSES` times in a row, the robot
    searches every cell (``cells`` None) until a view shows it again.

    Args:
        rule: the run's `CellRule`.
        start_xy: the robot's start position [m].
    """

    def __init__(self, rule: CellRule, start_xy: Sequence[float]) -> None:
        self.rule = rule
        self.cells: frozenset[Cell] | None = rule.needed(float(start_xy[0]), float(start_xy[1]))
        """Cells held; None: every cell (searching)."""
        self.located = False
        self.self_misses = 0
        self.changes = 0
        """Subscriptions added or dropped so far (searching counts one)."""

    def follow(self, x_m: float, y_m: float) -> CellChange:
        """The robot is at (x, y) in the view it just observed: the change to make."""
        self.located, self.self_misses = True, 0
        held = self.cells
        new = self.rule.update(held or (), x_m, y_m)
        if held is None:
            self.cells = new
            self.changes += len(new)
            return CellChange(added=new, found=True)
        if new == held:
            return CellChange()
        self.cells = new
        change = CellChange(added=new - held, dropped=held - new)
        self.changes += len(change.added) + len(change.dropped)
        return change

    def missed_self(self) -> CellChange:
        """A view without the robot: search every cell if it is lost (see the class)."""
        self.self_misses += 1
        if self.cells is None or (self.located and self.self_misses < SELF_MISSES):
            return CellChange()
        dropped, self.cells = self.cells, None
        self.changes += 1
        return CellChange(dropped=dropped, search=True)

    def holds(self, cell: Cell) -> bool:
        """Whether messages of `cell` are for this robot."""
        return self.cells is None or cell in self.cells


def split_cells(snapshot: PoseSnapshot, size_m: float) -> dict[Cell, PoseSnapshot]:
    """The world's snapshot cut into one part per cell that holds a disc centre; each part
    keeps the discs in the snapshot's order."""
    keys = cells_of(snapshot.pose[:, :2], size_m)
    out: dict[Cell, PoseSnapshot] = {}
    if keys.shape[0] == 0:
        return out
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    order = np.argsort(inverse.reshape(-1), kind="stable")
    bounds = np.searchsorted(inverse.reshape(-1)[order], np.arange(unique.shape[0] + 1))
    for k, (i, j) in enumerate(unique.tolist()):
        rows = order[bounds[k]:bounds[k + 1]]
        out[(int(i), int(j))] = PoseSnapshot.trusted(
            stamp_s=snapshot.stamp_s, tick=snapshot.tick, ids=snapshot.ids[rows],
            pose=snapshot.pose[rows], radius_m=snapshot.radius_m[rows])
    return out


def canonical_order(ids: np.ndarray) -> np.ndarray:
    """Row order of a view: robots by ascending id, then obstacles -1, -2, ... (the world's
    own order for a scenario that lists its robots by id)."""
    key = np.where(ids >= 0, ids, np.int64(1 << 40) - ids)
    return np.argsort(key, kind="stable")


class ViewMerger:
    """Merges the parts of a view into one snapshot in `canonical_order`.

    While every part's id array is the very same read-only object as in the previous merge
    (a robot's per-cell `eifp_wire.poses.PoseDecoder` hands out the same one while a cell's
    discs do not change), the order and the merged id array are reused, so the controller's
    and the estimator's fast paths (`RobotController.observe`, `NeighborTracker.update`)
    recognise the snapshot's ids.
    """

    def __init__(self) -> None:
        self._key: tuple[int, ...] | None = None
        self._parts_ids: list[np.ndarray] = []  # keeps the keyed arrays alive
        self._order = np.zeros(0, dtype=np.int64)
        self._ids = np.zeros(0, dtype=np.int64)

    def merge(self, parts: Sequence[PoseSnapshot], stamp_s: float, tick: int) -> PoseSnapshot:
        """One snapshot of every disc in `parts`, stamped (`stamp_s`, `tick`).

        The parts hold different discs (one part per cell)."""
        if not parts:
            return PoseSnapshot.trusted(stamp_s=stamp_s, tick=tick,
                                        ids=np.zeros(0, dtype=np.int64), pose=np.zeros((0, 3)),
                                        radius_m=np.zeros(0))
        pose = np.concatenate([p.pose for p in parts])
        radius = np.concatenate([p.radius_m for p in parts])
        key = tuple(id(p.ids) for p in parts)
        if key != self._key or any(p.ids.flags.writeable for p in parts):
            all_ids = np.concatenate([p.ids for p in parts])
            order = canonical_order(all_ids)
            ids = all_ids[order]
            ids.flags.writeable = False
            self._key, self._parts_ids = key, [p.ids for p in parts]
            self._order, self._ids = order, ids
        return PoseSnapshot.trusted(stamp_s=stamp_s, tick=tick, ids=self._ids,
                                    pose=pose[self._order], radius_m=radius[self._order])


def merge_parts(parts: Mapping[Cell, PoseSnapshot], cells: Iterable[Cell] | None,
                stamp_s: float, tick: int, merger: ViewMerger | None = None) -> PoseSnapshot:
    """The view of the cells `cells` (None: every cell) of a tick cut by `split_cells`:
    their parts merged in `canonical_order` (cells without a part hold no disc)."""
    chosen = sorted(parts) if cells is None else sorted(c for c in cells if c in parts)
    return (merger or ViewMerger()).merge([parts[c] for c in chosen], stamp_s, tick)
