"""The pose stream cut into cells: the world's messages of a tick, a robot's snapshot of them.

**World** (`cell_payloads`): a tick's validated `PosesMsg` is cut into one payload per cell
the world publishes (`world.sim.cells.CellRule.published`: every cell within reach of a
robot, empty or not), each a `PosesMsg` of the discs whose centre is in that cell, sent on
``poses/<slot>/<i>/<j>`` (`eifp_wire.keys.RunKeys.poses_cell`).

**Robot** (`CellAssembler`): the messages of the cells a robot holds arrive one by one; the
assembler hands out one `PoseView` per tick, built from messages of that one tick only and
merged as the lockstep loop merges the same cells (`world.sim.cells.ViewMerger`). The rule:

- A cell the robot held from its start is *expected*; a cell added later is expected from
  its first message on (its subscription may take a moment to reach the world; it holds no
  disc the robot needs yet, `world.sim.cells`).
- Tick T is released as soon as every expected cell has delivered T; otherwise when a
  message of a newer tick arrives, or `wait_s` of wall time after T's first message
  (`ASSEMBLY_WAIT_TICKS` world ticks at the run's time scale). A robot that searches
  every cell (`CellAssembler.search`) knows no expected set and always waits.
- An expected cell whose message of T is lost or late is *held* (``held``): its newest
  message, at most `hold_s` of sim time older than T (`HOLD_PERIODS` planning periods), its
  discs moved on to T at the velocity between that message and the one before (dead
  reckoning; a disc seen once stays where it was). A disc that is also in a fresh message of
  T keeps the fresh pose. With nothing that recent the cell is ``missing`` (its discs are
  not in the view), and after `MAX_CELL_MISSES` releases in a row without it, it is expected
  again only once it delivers (the world may have stopped publishing it).
- A message of a tick already released is ``late``: it only updates what a hold would use.

So a lost cell message costs the robot a tenth of a second of dead reckoning for the discs
in that cell, not the whole tick; with every message on time the view is exactly the
lockstep one.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import asdict, dataclass, field

import numpy as np

from agent.core.types import PoseSnapshot
from eifp_wire.codec import known_set
from eifp_wire.poses import PoseDecoder, PosesMsg
from world.sim.cells import Cell, ViewMerger, cells_of

ASSEMBLY_WAIT_TICKS = 0.5
"""How long a robot waits for the rest of a tick's cells after its first one, in world
ticks (10 ms of wall time at 50 Hz, time scale 1). The world sends a tick's cells back to
back, so they normally all arrive within a millisecond; the wait only matters when one is
lost."""
MAX_CELL_MISSES = 3
"""Releases in a row a cell may miss before it is no longer waited for."""
HOLD_PERIODS = 3.0
"""How many planning periods old a cell's message may be to fill in for a lost one (0.3 s
at 10 Hz). Dead reckoned over that long from the velocity between its two newest messages
(0.1 s apart), a disc within the robots' limits (1.5 m/s^2; 1.5 rad/s at 1.1 m/s, 1.65 m/s^2
sideways) is off by at most a (0.05 t + t^2 / 2), about 0.1 m, a third of the default safety
margin; one moving straight at a constant speed, as obstacles do, not at all."""


def cell_payloads(msg: PosesMsg, cells: Iterable[Cell], size_m: float
                  ) -> list[tuple[Cell, bytes]]:
    """One payload per cell of `cells` (sorted): the `PosesMsg` of `msg`'s discs whose
    centre is in that cell (robots first, in `msg`'s order), empty if none is.

    Discs in cells not listed are not sent: no robot is near them."""
    ids, values = msg.discs()
    groups: dict[Cell, np.ndarray] = {}
    if ids.shape[0]:
        keys = cells_of(values[:, :2], size_m)
        unique, inverse = np.unique(keys, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        order = np.argsort(inverse, kind="stable")
        bounds = np.searchsorted(inverse[order], np.arange(unique.shape[0] + 1))
        for k, (i, j) in enumerate(unique.tolist()):
            groups[(int(i), int(j))] = order[bounds[k]:bounds[k + 1]]
    empty = np.zeros(0, dtype=np.int64)
    chosen = sorted(set(cells))
    return list(zip(chosen, msg.encode_parts([groups.get(cell, empty) for cell in chosen]),
                    strict=True))


@dataclass(frozen=True)
class PoseView:
    """One tick's poses as a robot assembled them from its cells.

    Args:
        t_s: sim time at which the poses were true.
        tick: the world tick of every message in it.
        snapshot: the discs of its cells (`world.sim.cells.canonical_order`).
        rx_wall_s: when the robot had it (monotonic wall seconds): the arrival of the
            message that completed it, or the end of the wait.
        pub_ns: the earliest `PosesMsg.pub_ns` of its messages (0: none stamped).
        clock_id: the publishing host's clock of `pub_ns`.
        parts: messages of tick `tick` in it.
        held: cells filled from an earlier message (dead reckoned).
        missing: expected cells with nothing recent enough.
    """

    t_s: float
    tick: int
    snapshot: PoseSnapshot = field(repr=False)
    rx_wall_s: float = 0.0
    pub_ns: int = 0
    clock_id: int = 0
    parts: int = 0
    held: int = 0
    missing: int = 0


@dataclass
class AssemblyCounts:
    """What a `CellAssembler` counted.

    Args:
        views: views released.
        partial: views released without every expected cell of their tick.
        held: cells filled from an earlier message.
        missing: expected cells left out (nothing recent enough).
        late: messages of a tick already released (or passed over).
    """

    views: int = 0
    partial: int = 0
    held: int = 0
    missing: int = 0
    late: int = 0

    def as_dict(self) -> dict[str, int]:
        """Name -> count, prefixed ``cells_`` (``cells_held``, ...)."""
        return {f"cells_{k}": v for k, v in asdict(self).items()}


@dataclass
class _CellState:
    decoder: PoseDecoder
    expected: bool
    last: PosesMsg | None = None
    before: PosesMsg | None = None
    misses: int = 0

    def keep(self, msg: PosesMsg) -> None:
        """Remember `msg` if it is one of the two newest of this cell."""
        if self.last is None or msg.tick > self.last.tick:
            self.before, self.last = self.last, msg
        elif msg.tick < self.last.tick and (self.before is None or msg.tick > self.before.tick):
            self.before = msg


def dead_reckoned(last: PosesMsg, before: PosesMsg | None, t_s: float) -> PoseSnapshot:
    """`last`'s discs moved on to `t_s` at their velocity from `before` to `last` (a disc
    not in `before`, or no `before`, stays where it was); headings turn likewise."""
    snap = last.to_snapshot()
    dt = t_s - last.t_s
    gap = 0.0 if before is None else last.t_s - before.t_s
    if before is None or dt <= 0.0 or gap <= 0.0:
        return snap
    prev = before.to_snapshot()
    _, now_rows, prev_rows = np.intersect1d(snap.ids, prev.ids, assume_unique=True,
                                            return_indices=True)
    step = snap.pose[now_rows] - prev.pose[prev_rows]
    step[:, 2] = np.remainder(step[:, 2] + np.pi, 2.0 * np.pi) - np.pi
    pose = snap.pose.copy()
    pose[now_rows] += step * (dt / gap)
    pose[:, 2] = np.remainder(pose[:, 2] + np.pi, 2.0 * np.pi) - np.pi
    return PoseSnapshot.trusted(stamp_s=t_s, tick=last.tick, ids=snap.ids, pose=pose,
                                radius_m=snap.radius_m)


class CellAssembler:
    """One robot's cell messages in, one `PoseView` per tick out (the module's rule).

    Args:
        known_ids: robot and obstacle ids of the run (every cell's decoder refuses others).
        wait_s: wall seconds to wait for a tick's missing cells after its first message.
        hold_s: sim seconds a cell's message may be older than the tick it fills in for.
    """

    def __init__(self, known_ids: Collection[int] | None, *, wait_s: float,
                 hold_s: float) -> None:
        self.known_ids = known_set(known_ids)
        self.wait_s = float(wait_s)
        self.hold_s = float(hold_s)
        self.cells: dict[Cell, _CellState] = {}
        self.every = False
        self.counts = AssemblyCounts()
        self.merger = ViewMerger()
        self.pending: dict[Cell, PosesMsg] = {}
        self.pending_tick = -1
        self.first_wall_s = 0.0
        self.last_wall_s = 0.0
        self.released_tick = -1

    # --- which cells -------------------------------------------------------------------------

    def hold(self, cells: Iterable[Cell], *, expected: bool) -> None:
        """Take messages of `cells` (`expected`: wait for them from now on)."""
        for cell in cells:
            if cell not in self.cells:
                self.cells[cell] = _CellState(PoseDecoder(self.known_ids), expected)

    def drop(self, cells: Iterable[Cell]) -> None:
        """Forget `cells`."""
        for cell in cells:
            self.cells.pop(cell, None)
            self.pending.pop(cell, None)

    def search(self) -> None:
        """Take every cell's messages and wait the full `wait_s` for each tick."""
        self.every = True

    def found(self, held: Iterable[Cell]) -> None:
        """Back to the cells `held` (added with `hold` already)."""
        self.every = False
        self.drop([c for c in self.cells if c not in set(held)])

    def accepts(self, cell: Cell) -> bool:
        """Whether messages of `cell` are taken."""
        return self.every or cell in self.cells

    # --- messages ------------------------------------------------------------------------------

    def decode(self, cell: Cell, payload: object) -> PosesMsg:
        """Decode a message of `cell` with that cell's own decoder (its id block repeats
        from tick to tick); raises `eifp_wire.limits.ProtocolError`."""
        state = self.cells.get(cell)
        if state is None:
            state = self.cells[cell] = _CellState(PoseDecoder(self.known_ids), False)
        return state.decoder.decode(payload)

    def add(self, cell: Cell, msg: PosesMsg, wall_s: float) -> PoseView | None:
        """A valid message of `cell` taken off the queue at `wall_s`; returns the view of an
        older tick it forces out, if any."""
        state = self.cells.get(cell)
        if state is None:
            return None
        state.keep(msg)
        if msg.tick <= self.released_tick or msg.tick < self.pending_tick:
            self.counts.late += 1
            return None
        out = None
        if msg.tick > self.pending_tick:
            if self.pending:
                out = self._release(wall_s)
            self.pending_tick, self.first_wall_s = msg.tick, wall_s
        self.pending[cell] = msg
        self.last_wall_s = wall_s
        if not self.every:
            state.expected = True
        return out

    @property
    def deadline_wall_s(self) -> float | None:
        """When the tick being assembled is released at the latest (None: none is)."""
        return self.first_wall_s + self.wait_s if self.pending else None

    def complete(self) -> bool:
        """Every expected cell has delivered the tick being assembled."""
        if not self.pending or self.every:
            return False
        expected = [c for c, s in self.cells.items() if s.expected]
        return bool(expected) and all(c in self.pending for c in expected)

    def ready(self, wall_s: float) -> PoseView | None:
        """The tick being assembled, if it is complete or its wait is over at `wall_s`."""
        if self.complete():
            return self._release(self.last_wall_s)
        deadline = self.deadline_wall_s
        if deadline is not None and wall_s >= deadline:
            return self._release(deadline)
        return None

    def _fill(self, t_s: float) -> tuple[list[PoseSnapshot], int, int]:
        """The held parts of the expected cells missing from the pending tick."""
        held: list[PoseSnapshot] = []
        missing = 0
        for cell in sorted(self.cells):
            state = self.cells[cell]
            if cell in self.pending:
                state.misses = 0
                continue
            if not state.expected:
                continue
            state.misses += 1
            if state.misses >= MAX_CELL_MISSES:
                state.expected = False
            last = state.last
            if last is None or t_s - last.t_s > self.hold_s + 1e-9:
                missing += 1
                continue
            held.append(dead_reckoned(last, state.before, t_s))
        return held, len(held), missing

    def _release(self, rx_wall_s: float) -> PoseView:
        msgs = [self.pending[c] for c in sorted(self.pending)]
        tick, t_s = self.pending_tick, msgs[0].t_s
        parts = [m.to_snapshot() for m in msgs]
        held, n_held, missing = self._fill(t_s)
        if held:
            fresh = np.concatenate([p.ids for p in parts])
            for part in held:
                keep = ~np.isin(part.ids, fresh)
                parts.append(part if keep.all() else PoseSnapshot.trusted(
                    stamp_s=t_s, tick=tick, ids=part.ids[keep], pose=part.pose[keep],
                    radius_m=part.radius_m[keep]))
                fresh = np.concatenate([fresh, part.ids[keep]])
        snapshot = self.merger.merge(parts, t_s, tick)
        stamped = [m.pub_ns for m in msgs if m.pub_ns]
        counts = self.counts
        counts.views += 1
        counts.held += n_held
        counts.missing += missing
        counts.partial += bool(n_held or missing)
        self.released_tick, self.pending = tick, {}
        return PoseView(t_s=t_s, tick=tick, snapshot=snapshot, rx_wall_s=rx_wall_s,
                        pub_ns=min(stamped) if stamped else 0, clock_id=msgs[0].clock_id,
                        parts=len(msgs), held=n_held, missing=missing)
