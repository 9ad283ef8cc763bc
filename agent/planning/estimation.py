"""Estimating the others' motion from observed poses only (pure).

A robot never receives another's velocity, plan or goal: it keeps a short history of the
poses it observed and estimates, per other disc,
- velocity: least-squares slope of position against time over the last
  `window_s` (a constant-velocity fit; robust to one noisy sample, exact for straight motion);
- linearity w_j of Eq. (15) (our choice, the paper leaves it open): the straightness index
  |p_last - p_first| / (path length over the window), in [0, 1]; 1 for a straight track,
  lower for a turning or dithering one, 0 for a disc that has not moved (< 1 cm);
- s_j, the ghost path's start: the oldest position inside the window;
- heading: the latest observed one (the pose carries it), used by the braking guard for
  the direction a robot can speed up in (`agent.planning.safety.unseen_speed_up_mps`);
- recent speed: distance over time between the disc's two newest samples, with that
  interval's length. The least-squares slope trails a speed change by about window / 2;
  this one by half an interval (a sixth of the window or less), so the braking guard
  reads from it how much of a speed change the slope does not show yet;
- recent turn rate: the heading change between the same two samples (wrapped to
  [-pi, pi)) over that interval. The slope's direction trails a turn as its magnitude
  trails a speed change; the braking guard reads from it how far a robot turning towards
  this one may have turned since (`agent.planning.safety.unseen_turn_closing_mps`). Samples are at
  most a third of the window apart, so a robot's heading moves by less than a half turn
  between them (omega_max window / 3 = 0.25 rad at 1.5 rad/s) and the wrap is unambiguous.
All neighbours are handled at once with arrays of shape (H samples, n discs).
"""

from __future__ import annotations

import math
from typing import final

import numpy as np

from agent.core.types import Others, PoseSnapshot

_MIN_TRAVEL_M = 0.01


ESTIMATION_WINDOW_S = 0.75
"""History the velocity and linearity estimates fit over [s]. The least-squares slope
trails a speed change by about half of it (the braking guard allows for that lag), and it
averages out the pose noise of about 7 samples 0.1 s apart; much longer windows smooth
over the others' own turns and lag their avoidance manoeuvres."""

ESTIMATION_MARGIN_M = 5.0
"""Only others within the sensing radius plus this are estimated (`RobotController`): farther
ones cannot come into range during the (<= 1 s, `MAX_COMPENSATED_AGE_S` of
`agent.planning.controller`) forward prediction below a closing speed of 5 m/s."""


@final  # `reset` re-runs __init__
class NeighborTracker:
    """Short pose history of every other disc and the estimates built from it.

    Args:
        own_id: this robot's id (excluded from the estimates).
        window_s: history length used for the estimates.
        max_samples: ring size H. Samples are kept at least window_s / (H - 2) apart (a
            newer snapshot closer than that to the one before the newest replaces the
            newest), so the window holds the same history whether poses arrive at the
            world's rate (50 Hz in a distributed run) or once per control period (lockstep).
    """

    def __init__(self, own_id: int, window_s: float = ESTIMATION_WINDOW_S,
                 max_samples: int = 8) -> None:
        if not window_s > 0.0:
            raise ValueError("window_s must be positive")
        if max_samples < 2:
            raise ValueError("max_samples must be >= 2")
        self.own_id = int(own_id)
        self.window_s = float(window_s)
        self.max_samples = int(max_samples)
        self.spacing_s = self.window_s / max(self.max_samples - 2, 1) - 1e-9
        self._col: dict[int, int] = {}
        self._ids = np.zeros(0, dtype=np.int64)
        self._radius = np.zeros(0)
        self._hdg = np.zeros((self.max_samples, 0))  # observed headings per sample
        self._t = np.full(self.max_samples, -np.inf)
        # Ring order, oldest first, when row r is the newest: rows fill in time order
        # because `update` is only given snapshots no older than the last one (the
        # controller drops stale and out-of-order ones before it calls `update`).
        ring = np.arange(self.max_samples)
        self._ring_order = [np.roll(ring, -(r + 1)) for r in range(self.max_samples)]
        self._pos = np.zeros((self.max_samples, 0, 2))
        self._seen = np.zeros((self.max_samples, 0), dtype=bool)
        self._latest = np.zeros(0, dtype=bool)
        self._row = -1
        self._last_ids: np.ndarray | None = None  # the previous snapshot's ids, and
        self._last_cols = np.zeros(0, dtype=np.int64)  # their columns (most ticks repeat them)
        # The previous snapshot's read-only id array (a robot's `eifp_wire.poses.PoseDecoder` hands
        # out the same one while the ids repeat), its other discs' rows, and where they go.
        self._same_ids: np.ndarray | None = None
        self._same_rows = np.zeros(0, dtype=np.int64)
        self._same_dest: slice | np.ndarray = self._last_cols

    def reset(self) -> None:
        """Forget all history."""
        self.__init__(self.own_id, self.window_s, self.max_samples)

    def _grow(self, new_ids: list[int]) -> None:
        for rid in new_ids:
            self._col[rid] = len(self._col)
        extra = len(new_ids)
        self._ids = np.concatenate([self._ids, np.array(new_ids, dtype=np.int64)])
        self._radius = np.concatenate([self._radius, np.zeros(extra)])
        self._pos = np.concatenate([self._pos, np.zeros((self.max_samples, extra, 2))], axis=1)
        self._hdg = np.concatenate([self._hdg, np.zeros((self.max_samples, extra))], axis=1)
        self._seen = np.concatenate(
            [self._seen, np.zeros((self.max_samples, extra), dtype=bool)], axis=1
        )
        self._latest = np.concatenate([self._latest, np.zeros(extra, dtype=bool)])

    def update(self, snapshot: PoseSnapshot) -> None:
        """Add one observed snapshot (the caller drops stale or out-of-order ones)."""
        all_ids = snapshot.ids
        same = all_ids is self._same_ids
        if not same:
            self._match(all_ids)
        rows, dest = self._same_rows, self._same_dest
        before = self._t[(self._row - 1) % self.max_samples] if self._row >= 0 else -np.inf
        if self._row < 0 or snapshot.stamp_s - before >= self.spacing_s:
            self._row = (self._row + 1) % self.max_samples  # else: replace the newest
        r = self._row
        self._t[r] = snapshot.stamp_s
        if same:  # the same discs as the snapshot before: the same pattern as `_latest`
            self._seen[r] = self._latest
        else:
            self._seen[r] = False
            self._seen[r, dest] = True
            self._latest = self._seen[r].copy()  # read-only from here on (never mutated)
        pose = snapshot.pose[rows]
        self._pos[r, dest] = pose[:, :2]
        self._radius[dest] = snapshot.radius_m[rows]
        self._hdg[r, dest] = pose[:, 2]

    def _match(self, all_ids: np.ndarray) -> None:
        """Find the other discs' rows in a snapshot with ids `all_ids` and their columns.

        Remembered for the next snapshot: a read-only id array that comes again (the same
        object) cannot have changed. Columns that are 0, 1, ..., k - 1 are written as a
        slice (the usual case: the discs come in the order they were first seen)."""
        mask = all_ids != self.own_id
        ids = all_ids[mask]
        if self._last_ids is not None and np.array_equal(ids, self._last_ids):
            cols = self._last_cols  # the same discs in the same order as last time
        else:
            new = [int(i) for i in ids.tolist() if int(i) not in self._col]
            if new:
                self._grow(new)
            cols = np.fromiter((self._col[int(i)] for i in ids.tolist()), dtype=np.int64,
                               count=ids.shape[0])
            self._last_ids, self._last_cols = ids.copy(), cols
        k = cols.shape[0]
        in_order = k == 0 or (int(cols[0]) == 0 and int(cols[-1]) == k - 1
                              and bool((np.diff(cols) == 1).all()))
        self._same_ids = None if all_ids.flags.writeable else all_ids
        self._same_rows = np.flatnonzero(mask)
        self._same_dest = slice(0, k) if in_order else cols

    def others(self, near_m: np.ndarray | None = None, within_m: float = np.inf) -> Others:
        """Estimates for the discs seen in the latest snapshot (ids in first-seen order).

        Args:
            near_m: (2,) a point; with `within_m`, only discs whose latest position is at
                most `within_m` from it are estimated (bounds the work in a crowd).
            within_m: see `near_m`.
        """
        if self._row < 0 or not self._latest.any():
            return Others.empty()
        r = self._row
        sel = self._latest
        if near_m is not None and math.isfinite(within_m):
            gap = self._pos[r] - np.asarray(near_m, dtype=float)
            sel = sel & (np.hypot(gap[:, 0], gap[:, 1]) <= within_m)
            if not sel.any():
                return Others.empty()
        t_now = self._t[r]
        order = self._ring_order[r]  # oldest first; unused rows have -inf
        t = self._t[order]
        in_window = t_now - t <= self.window_s + 1e-9  # a suffix of `order` (t is sorted)
        cols = sel.nonzero()[0]
        rows = order[in_window]
        window = (rows[:, None], cols)  # `numpy.ix_(rows, cols)`, without its set-up
        seen = self._seen[window]  # (h, k)
        tt = t[in_window] - t_now
        pos = self._pos[window]  # (h, k, 2)
        if seen.all():
            # Every disc in every sample of the window (the usual case: the world publishes
            # all discs each tick): one set of least-squares weights serves all columns.
            velocity, start, linearity = self._estimate_dense(pos, tt)
        else:
            velocity, start, linearity = self._estimate_sparse(pos, seen, tt)
        recent_speed, recent_turn, recent_interval = _recent_motion(
            pos, self._hdg[window], seen, tt)
        latest = pos[-1]
        ids = self._ids[cols]
        # Built from a validated snapshot (finite poses, radii) by finite arithmetic.
        return Others.trusted(
            ids=ids,
            position_m=latest,
            velocity_mps=velocity,
            radius_m=self._radius[cols],
            linearity=np.minimum(linearity, 1.0),  # >= 0 already
            track_start_m=start,
            is_robot=ids >= 0,
            heading_rad=self._hdg[r][cols],  # the latest sample: every column in it
            recent_speed_mps=recent_speed,
            recent_interval_s=recent_interval,
            recent_turn_rate_radps=recent_turn,
        )

    @staticmethod
    def _estimate_dense(pos: np.ndarray, tt: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Velocity, track start and straightness when every disc is in every sample.

        Args:
            pos: (h, k, 2) positions in the window, oldest first; the last row is the newest.
            tt: (h,) sample times relative to the newest (<= 0).
        """
        k = pos.shape[1]
        dtt = tt - tt.sum() / tt.shape[0]
        var_t = float(dtt @ dtt)
        if tt.shape[0] >= 2 and var_t > 1e-12:
            # Slope = sum (t_i - t_mean)(p_i - p_mean) / var = sum (t_i - t_mean) p_i / var,
            # summed sample by sample (not BLAS) so a disc's estimate never depends on
            # which other discs are estimated with it.
            velocity = ((dtt / var_t)[:, None, None] * pos).sum(axis=0)
        else:
            velocity = np.zeros((k, 2))
        start = pos[0]
        steps = pos[1:] - pos[:-1]
        path = np.sqrt((steps * steps).sum(axis=2)).sum(axis=0)
        chord_v = pos[-1] - start
        chord = np.sqrt((chord_v * chord_v).sum(axis=1))
        linearity = np.where(path > _MIN_TRAVEL_M, chord / np.maximum(path, 1e-12), 0.0)
        return velocity, start, linearity

    @staticmethod
    def _estimate_sparse(pos: np.ndarray, use: np.ndarray, tt: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As `_estimate_dense`, for discs missing from some samples (weighted by `use`).

        Args:
            pos: (h, k, 2) positions in the window (stale where not seen).
            use: (h, k) whether disc j was seen in sample i; the last row is all True.
            tt: (h,) sample times relative to the newest (<= 0).
        """
        w = use.astype(float)
        tt = tt[:, None]
        safe_count = np.maximum(w.sum(axis=0), 1.0)  # (k,)
        t_mean = (w * tt).sum(axis=0) / safe_count
        p_mean = (w[..., None] * pos).sum(axis=0) / safe_count[:, None]
        dt = (tt - t_mean) * w
        var_t = (dt * (tt - t_mean)).sum(axis=0)
        cov = (dt[..., None] * (pos - p_mean)).sum(axis=0)
        ok = (w.sum(axis=0) >= 2) & (var_t > 1e-12)
        velocity = np.where(ok[:, None], cov / np.where(ok, var_t, 1.0)[:, None], 0.0)
        # Oldest used sample per disc (ghost path start s_j) and straightness of the track.
        first = np.argmax(use, axis=0)
        start = pos[first, np.arange(pos.shape[1])]
        steps = np.linalg.norm(np.diff(pos, axis=0), axis=2)  # (h-1, k)
        path = (steps * (use[1:] & use[:-1])).sum(axis=0)
        chord = np.linalg.norm(pos[-1] - start, axis=1)
        linearity = np.where(path > _MIN_TRAVEL_M, chord / np.maximum(path, 1e-12), 0.0)
        return velocity, start, linearity


def _recent_motion(pos: np.ndarray, heading: np.ndarray, use: np.ndarray, tt: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed and turn rate between each disc's two newest samples in the window, and the
    interval.

    Args:
        pos: (h, k, 2) positions in the window, oldest first.
        heading: (h, k) observed headings in the same samples.
        use: (h, k) whether disc j was seen in sample i; the last row is all True.
        tt: (h,) sample times relative to the newest (<= 0).

    Returns:
        (k,) speed [m/s], (k,) signed turn rate [rad/s] and (k,) interval [s], all NaN for
        a disc seen once only.
    """
    k = pos.shape[1]
    if pos.shape[0] < 2:
        return np.full(k, np.nan), np.full(k, np.nan), np.full(k, np.nan)
    if use[-2].all():
        # the usual case, every disc in the sample before the newest too: one interval
        dt = float(tt[-1] - tt[-2])
        if dt <= 1e-9:
            return np.full(k, np.nan), np.full(k, np.nan), np.full(k, np.nan)
        step = pos[-1] - pos[-2]
        turn = _wrap(heading[-1] - heading[-2])
        return np.hypot(step[:, 0], step[:, 1]) / dt, turn / dt, np.full(k, dt)
    # some disc missing from the sample before the newest: its own newest earlier sample
    prev = np.where(use[:-1], np.arange(pos.shape[0] - 1)[:, None], -1).max(axis=0)
    known = prev >= 0
    cols = np.arange(k)
    prev_row = np.maximum(prev, 0)
    step = np.where(known[:, None], pos[-1] - pos[prev_row, cols], np.nan)
    turn = np.where(known, _wrap(heading[-1] - heading[prev_row, cols]), np.nan)
    interval = np.where(known, tt[-1] - tt[prev_row], np.nan)
    ok = interval > 1e-9  # NaN compares False
    safe = np.where(ok, interval, 1.0)
    speed = np.where(ok, np.hypot(step[:, 0], step[:, 1]) / safe, np.nan)
    return speed, np.where(ok, turn / safe, np.nan), np.where(ok, interval, np.nan)


def _wrap(angle_rad: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return np.remainder(angle_rad + np.pi, 2.0 * np.pi) - np.pi
