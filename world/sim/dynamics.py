"""Ground-truth world dynamics: unicycles, moving discs, contacts and arrival (pure).

The world integrates every robot's unicycle (Eq. 1) with the latest command held constant
over a tick (zero-order hold). It integrates the arc exactly rather than with the Euler
step of Eq. (1): the ground truth should not share the robots' model error. Commands are
clamped to the robot's limits; a robot whose command is older than its hold (the
`hold_s` the robot sent with it: the period it was planned for) brakes at its maximum
deceleration along the commanded arc; one whose command is older than `cmd_timeout_s`, or
whose process is offline, brakes at its maximum deceleration with zero turn rate. The
hold is what keeps a lost command from acting longer than its sender assumed (the braking
guard, `agent.planning.safety`, assumes a command acts for about one period); the time-out is the
world's own bound, for a robot that stopped sending.
No I/O, no clock: time advances only through `step(dt_s)`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.core.scenario import Scenario
from agent.core.types import PoseSnapshot

CONTACT_OVERLAP_M = 1.0e-3
"""Two discs are in contact when they overlap by more than this (1 mm)."""
GAP_REACH_M = 2.0
"""The world checks pairs whose gap is at most this: contacts, and `min_gap_m` below it."""
ALL_PAIRS_MAX_N = 48
"""Up to this many discs every pair is checked (cheaper than the grid for small scenes)."""
_HALF_NEIGHBOURHOOD = ((0, 0), (1, -1), (1, 0), (1, 1), (0, 1))
"""Grid cell offsets that visit every pair of neighbouring cells exactly once."""


@dataclass(frozen=True)
class TickEvents:
    """What changed during one tick.

    Args:
        arrivals: robot ids that reached their goal this tick.
        new_contacts: (id_a, id_b, overlap_m) for pairs that came into contact this tick;
            obstacle ids are negative.
        timeouts: robot ids whose command went stale this tick (they brake).
    """

    arrivals: tuple[int, ...] = ()
    new_contacts: tuple[tuple[int, int, float], ...] = ()
    timeouts: tuple[int, ...] = ()


def integrate_unicycle(pose: np.ndarray, v_mps: np.ndarray, omega_radps: np.ndarray,
                       dt_s: float) -> np.ndarray:
    """Exact constant-(v, omega) arc integration of Eq. (1)'s continuous model.

    Args:
        pose: (n, 3) x [m], y [m], heading [rad].
        v_mps: (n,) forward speeds.
        omega_radps: (n,) turn rates.
        dt_s: step length.

    Returns:
        (n, 3) poses after dt_s; headings wrapped to (-pi, pi].
    """
    theta = pose[:, 2]
    dtheta = omega_radps * dt_s
    # sin(x)/x with the straight-line limit where the turn is negligible.
    small = np.abs(dtheta) < 1e-9
    safe = np.where(small, 1.0, dtheta)
    sinc = np.where(small, 1.0 - dtheta**2 / 6.0, np.sin(safe) / safe)
    cosc = np.where(small, dtheta / 2.0, (1.0 - np.cos(safe)) / safe)
    ds = v_mps * dt_s
    out = np.empty_like(pose)
    c, s = np.cos(theta), np.sin(theta)
    out[:, 0] = pose[:, 0] + ds * (c * sinc - s * cosc)
    out[:, 1] = pose[:, 1] + ds * (s * sinc + c * cosc)
    out[:, 2] = np.angle(np.exp(1j * (theta + dtheta)))
    return out


def pair_gaps(centers_m: np.ndarray, radius_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gap (distance minus both radii) for every unordered pair.

    Args:
        centers_m: (n, 2) disc centres.
        radius_m: (n,) disc radii.

    Returns:
        (pairs (P, 2) int indices i < j, gaps_m (P,)).
    """
    n = centers_m.shape[0]
    i, j = np.triu_indices(n, k=1)
    d = np.hypot(centers_m[i, 0] - centers_m[j, 0], centers_m[i, 1] - centers_m[j, 1])
    return np.stack([i, j], axis=1), d - radius_m[i] - radius_m[j]


def near_pairs(centers_m: np.ndarray, reach_m: float) -> np.ndarray:
    """Index pairs (i < j) whose centres are at most `reach_m` apart, sorted.

    A uniform grid of `reach_m` cells: each disc is compared with the discs in its own and
    the neighbouring cells only, so the work grows with n times the local density, not
    n^2 (sorting the cell keys is n log n with a small constant).

    Args:
        centers_m: (n, 2) disc centres.
        reach_m: largest centre distance of a pair (> 0).

    Returns:
        (P, 2) int64 indices, rows sorted lexicographically.
    """
    n = centers_m.shape[0]
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64)
    if n <= ALL_PAIRS_MAX_N:
        i, j = np.triu_indices(n, k=1)
    else:
        cell = np.floor(centers_m / reach_m).astype(np.int64)
        cell -= cell.min(axis=0)
        width = int(cell[:, 1].max()) + 3  # a row offset of +-1 never reaches the next column
        key = cell[:, 0] * width + cell[:, 1]
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        found_i, found_j = [], []
        for dx, dy in _HALF_NEIGHBOURHOOD:
            target = key + dx * width + dy
            lo = np.searchsorted(sorted_key, target, side="left")
            count = np.searchsorted(sorted_key, target, side="right") - lo
            total = int(count.sum())
            if total == 0:
                continue
            first = np.cumsum(count) - count
            a = np.repeat(np.arange(n), count)
            b = order[np.repeat(lo, count) + np.arange(total) - np.repeat(first, count)]
            if (dx, dy) == (0, 0):
                keep = a < b  # the same cell: each pair once, never a disc with itself
                a, b = a[keep], b[keep]
            found_i.append(np.minimum(a, b))
            found_j.append(np.maximum(a, b))
        if not found_i:
            return np.zeros((0, 2), dtype=np.int64)
        i, j = np.concatenate(found_i), np.concatenate(found_j)
    close = np.hypot(centers_m[i, 0] - centers_m[j, 0], centers_m[i, 1] - centers_m[j, 1])
    keep = close <= reach_m
    i, j = i[keep], j[keep]
    rank = np.lexsort((j, i))
    return np.stack([i[rank], j[rank]], axis=1).astype(np.int64)


def near_pair_gaps(centers_m: np.ndarray, radius_m: np.ndarray, reach_gap_m: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """`pair_gaps` restricted to the pairs whose gap is at most `reach_gap_m` (>= 0).

    Returns:
        (pairs (P, 2) int indices i < j sorted, gaps_m (P,)).
    """
    if centers_m.shape[0] < 2:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    reach = 2.0 * float(radius_m.max()) + reach_gap_m
    pairs = near_pairs(centers_m, reach)
    i, j = pairs[:, 0], pairs[:, 1]
    d = np.hypot(centers_m[i, 0] - centers_m[j, 0], centers_m[i, 1] - centers_m[j, 1])
    gaps = d - radius_m[i] - radius_m[j]
    keep = gaps <= reach_gap_m
    return pairs[keep], gaps[keep]


class WorldSim:
    """The simulated world of one scenario (pure state machine).

    Attributes:
        t_s: sim time.
        tick: number of completed steps.
        robot_ids: (n,) robot ids in scenario order.
        pose: (n, 3) ground-truth poses.
        applied: (n, 2) (v, omega) applied during the last tick.
        arrived: (n,) bool, latched on first arrival.
        arrival_time_s: (n,) sim time of arrival, NaN before.
        offline: (n,) bool, robots whose process is gone (they brake and stay as obstacles).
        min_gap_m: smallest gap seen between any two discs so far, among gaps of at most
            `GAP_REACH_M` (inf while no two discs came that close; the run's metrics
            compute the exact minimum from the trajectory).
        timeout_count: number of command time-outs so far.
        hold_expiry_count: number of commands that outlived their hold (the robot braked
            until a newer one came).
    """

    def __init__(self, scenario: Scenario, *, cmd_timeout_s: float = 0.5) -> None:
        if not cmd_timeout_s > 0.0:
            raise ValueError("cmd_timeout_s must be positive")
        self.scenario = scenario
        self.cmd_timeout_s = float(cmd_timeout_s)
        robots = scenario.robots
        self.robot_ids = np.array([r.id for r in robots], dtype=np.int64)
        self._index = {int(rid): k for k, rid in enumerate(self.robot_ids)}
        self.pose = np.array([r.start for r in robots], dtype=float).reshape(-1, 3)
        self.goal_m = np.array([r.goal for r in robots], dtype=float).reshape(-1, 2)
        self.radius_m = np.array([r.radius_m for r in robots], dtype=float)
        self.v_min_mps = np.array([r.limits.v_min_mps for r in robots], dtype=float)
        self.v_max_mps = np.array([r.limits.v_max_mps for r in robots], dtype=float)
        self.omega_max_radps = np.array([r.limits.omega_max_radps for r in robots], dtype=float)
        self.decel_mps2 = np.array([r.limits.accel_max_mps2 for r in robots], dtype=float)
        obstacles = scenario.obstacles
        self.obstacle_ids = np.array([o.id for o in obstacles], dtype=np.int64)
        self._obstacle_c0 = np.array([o.center for o in obstacles], dtype=float).reshape(-1, 2)
        self._obstacle_v = np.array([o.velocity for o in obstacles], dtype=float).reshape(-1, 2)
        self.obstacle_radius_m = np.array([o.radius_m for o in obstacles], dtype=float)
        self.goal_tolerance_m = scenario.goal_tolerance_m
        n = len(robots)
        self.t_s = 0.0
        self.tick = 0
        self.command = np.zeros((n, 2))
        self.command_time_s = np.full(n, -np.inf)
        self.command_hold_s = np.full(n, np.inf)
        self._expired = np.zeros(n, dtype=bool)
        self.applied = np.zeros((n, 2))
        self.arrived = np.zeros(n, dtype=bool)
        self.arrival_time_s = np.full(n, np.nan)
        self.offline = np.zeros(n, dtype=bool)
        self._stale = np.ones(n, dtype=bool)
        self._had_command = np.zeros(n, dtype=bool)
        self._in_contact: set[tuple[int, int]] = set()
        self.contact_count = 0
        self.timeout_count = 0
        self.hold_expiry_count = 0
        self.min_gap_m = np.inf
        self._all_ids = np.concatenate([self.robot_ids, self.obstacle_ids])
        self._all_radius = np.concatenate([self.radius_m, self.obstacle_radius_m])
        self._check_arrivals()

    def index_of(self, robot_id: int) -> int:
        """Row of `robot_id` in the state arrays; KeyError for an unknown id."""
        return self._index[int(robot_id)]

    def set_command(self, robot_id: int, v_mps: float, omega_radps: float,
                    hold_s: float | None = None) -> None:
        """Hold (v, omega), clamped to the robot's limits, from now until the next command,
        for at most `hold_s` (None: until the time-out); then the robot brakes."""
        k = self.index_of(robot_id)
        v = float(np.clip(v_mps, self.v_min_mps[k], self.v_max_mps[k]))
        w = float(np.clip(omega_radps, -self.omega_max_radps[k], self.omega_max_radps[k]))
        if not (np.isfinite(v) and np.isfinite(w)):
            raise ValueError(f"robot {robot_id}: non-finite command")
        if hold_s is not None and not hold_s > 0.0:  # NaN fails this too
            raise ValueError(f"robot {robot_id}: hold_s must be positive, got {hold_s!r}")
        self.command[k] = (v, w)
        self.command_time_s[k] = self.t_s
        self.command_hold_s[k] = np.inf if hold_s is None else float(hold_s)
        self._expired[k] = False
        self._had_command[k] = True

    def set_offline(self, robot_id: int, offline: bool) -> None:
        """Mark a robot's process as gone (it brakes and stays put) or back."""
        k = self.index_of(robot_id)
        self.offline[k] = bool(offline)
        if offline:
            self.command[k] = 0.0

    def obstacle_positions_m(self, t_s: float | None = None) -> np.ndarray:
        """(m, 2) obstacle centres at `t_s` (default: now); obstacles move at constant velocity."""
        t = self.t_s if t_s is None else t_s
        return self._obstacle_c0 + self._obstacle_v * t

    def step(self, dt_s: float) -> TickEvents:
        """Advance by dt_s with the held commands; report arrivals, contacts and time-outs."""
        if not dt_s > 0.0:
            raise ValueError("dt_s must be positive")
        stale = (self.t_s - self.command_time_s) > self.cmd_timeout_s
        went_stale = stale & ~self._stale & self._had_command & ~self.offline
        self._stale = stale
        timeouts = tuple(int(i) for i in self.robot_ids[went_stale])
        self.timeout_count += len(timeouts)
        # held for the ticks that start less than hold_s after the command (1e-9: rounding)
        expired = (self.t_s - self.command_time_s) >= self.command_hold_s - 1e-9
        self.hold_expiry_count += int(np.count_nonzero(expired & ~self._expired & ~stale
                                                       & ~self.offline))
        self._expired = expired

        v_cmd = self.command[:, 0].copy()
        w_cmd = self.command[:, 1].copy()
        stopping = stale | self.offline
        braking = stopping | expired
        # Braking: decelerate at the robot's limit towards v = 0. A command past its hold
        # brakes along its own arc (constant curvature omega / v: the robot stays on the
        # path it was steering, the turn of an avoidance manoeuvre is not cut short); a
        # timed-out or offline robot stops turning.
        if braking.any():  # most ticks nobody brakes: then the commands apply as they are
            v_brake = np.maximum(self.applied[:, 0] - self.decel_mps2 * dt_s, 0.0)
            scale = np.divide(v_brake, v_cmd, out=np.zeros_like(v_cmd), where=v_cmd > 0.0)
            w_brake = np.where(stopping, 0.0, w_cmd * np.clip(scale, 0.0, 1.0))
            v = np.where(braking, v_brake, v_cmd)
            w = np.where(braking, w_brake, w_cmd)
        else:
            v, w = v_cmd, w_cmd
        self.applied = np.stack([v, w], axis=1)
        self.pose = integrate_unicycle(self.pose, v, w, dt_s)
        self.t_s += dt_s
        self.tick += 1
        arrivals = self._check_arrivals()
        contacts = self._check_contacts()
        return TickEvents(arrivals=arrivals, new_contacts=contacts, timeouts=timeouts)

    def _check_arrivals(self) -> tuple[int, ...]:
        dist = np.hypot(*(self.pose[:, :2] - self.goal_m).T)
        new = (dist <= self.goal_tolerance_m) & ~self.arrived
        self.arrived |= new
        self.arrival_time_s[new] = self.t_s
        return tuple(int(i) for i in self.robot_ids[new])

    def _check_contacts(self) -> tuple[tuple[int, int, float], ...]:
        centers = np.concatenate([self.pose[:, :2], self.obstacle_positions_m()])
        pairs, gaps = near_pair_gaps(centers, self._all_radius, GAP_REACH_M)
        # Obstacle-obstacle pairs are scenery, not contacts.
        n = self.robot_ids.shape[0]
        robot_pair = pairs[:, 0] < n
        if np.any(robot_pair):
            self.min_gap_m = min(self.min_gap_m, float(gaps[robot_pair].min()))
        touching = robot_pair & (gaps < -CONTACT_OVERLAP_M)
        now = {
            (int(self._all_ids[a]), int(self._all_ids[b])): float(-g)
            for (a, b), g in zip(pairs[touching], gaps[touching])
        }
        new = tuple((a, b, ov) for (a, b), ov in now.items() if (a, b) not in self._in_contact)
        self._in_contact = set(now)
        self.contact_count += len(new)
        return new

    def all_arrived(self) -> bool:
        """True when every robot has reached its goal at least once."""
        return bool(np.all(self.arrived))

    def snapshot(self) -> PoseSnapshot:
        """What a sensor sees now: every robot's and obstacle's pose and radius."""
        m = self.obstacle_ids.shape[0]
        obstacle_pose = np.zeros((m, 3))
        obstacle_pose[:, :2] = self.obstacle_positions_m()
        return PoseSnapshot(
            stamp_s=self.t_s,
            tick=self.tick,
            ids=self._all_ids,
            pose=np.concatenate([self.pose, obstacle_pose]),
            radius_m=self._all_radius,
        )
