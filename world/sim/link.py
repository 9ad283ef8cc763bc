"""Seeded network-fault model of one link (pure: no transport, no clock, no global RNG).

This kernel has no ``netem``, so latency, jitter, loss, duplication and reordering are
injected by the project itself, at the receive side of its own publish/subscribe layer:
the robot process passes every pose it receives through one `FaultyLink`, the world every
command of one robot through another, and the lockstep runner does the same in-process.

Time is SIM time. Every message is stamped in sim time and the world paces sim time at
``time_scale`` sim seconds per wall second, so a delay of 100 ms means 100 ms of sim time
(50 ms of wall time at ``--time-scale 2``): a fault level means the same thing to the
planner in every mode and at every speed.

The model, per message offered at `now_s` (one draw sequence per message, so a link's
behaviour depends only on its seed and the order of the messages offered):

1. dropped with probability `LinkFaults.drop`;
2. otherwise delayed by ``latency_ms + U(-jitter_ms, +jitter_ms)`` (never below 0);
3. with probability `LinkFaults.reorder`, held back a further ``reorder_delay_ms``
   so that later messages overtake it;
4. with probability `LinkFaults.dup`, a second copy is released after its own delay
   (drawn as in 2).

`FaultyLink.receive` releases every copy whose due time has come, in due-time order
(ties in the order offered). The receiver's own checks then drop what is stale: the
controller ignores poses whose tick is not newer (`RobotController.observe`), the world
commands whose ``seq`` is not newer.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field, fields
from typing import Generic, TypeVar

import numpy as np

T = TypeVar("T")

LINK_POSES = 0
"""Link kind of the pose stream a robot receives (seeded with (seed, LINK_POSES, robot))."""
LINK_COMMANDS = 1
"""Link kind of the command stream the world receives from one robot."""


@dataclass(frozen=True)
class LinkFaults:
    """Faults applied to every message of one link direction.

    Args:
        latency_ms: fixed delay [ms of sim time], >= 0.
        jitter_ms: half-width of the uniform delay jitter [ms], >= 0 (``100 ± 30``).
        drop: probability that a message is lost, in [0, 1].
        dup: probability that a message is delivered twice, in [0, 1].
        reorder: probability that a message is held back `reorder_delay_ms` extra, in [0, 1].
        reorder_delay_ms: the extra delay of a reordered message [ms], >= 0.
    """

    latency_ms: float = 0.0
    jitter_ms: float = 0.0
    drop: float = 0.0
    dup: float = 0.0
    reorder: float = 0.0
    reorder_delay_ms: float = 50.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{f.name}: expected a number, got {value!r}")
            value = float(value)
            if not math.isfinite(value) or value < 0.0:
                raise ValueError(f"{f.name}: must be finite and >= 0, got {value!r}")
            if f.name in ("drop", "dup", "reorder") and value > 1.0:
                raise ValueError(f"{f.name}: a probability in [0, 1], got {value!r}")
            object.__setattr__(self, f.name, value)

    @property
    def active(self) -> bool:
        """False if the link is perfect (every message delivered at once, once, in order)."""
        return bool(self.latency_ms or self.jitter_ms or self.drop or self.dup or self.reorder)

    def as_dict(self) -> dict[str, float]:
        """Field name -> value (for run.json and the stress tables)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def link_rng(seed: int, kind: int, robot_id: int) -> np.random.Generator:
    """The generator of one link: seeded from (run seed, link kind, robot id) only."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, int(kind), int(robot_id)])


@dataclass
class LinkCounts:
    """What a link did so far (offered = dropped + delivered - duplicated + in flight)."""

    offered: int = 0
    dropped: int = 0
    duplicated: int = 0
    reordered: int = 0
    delivered: int = 0


@dataclass
class FaultyLink(Generic[T]):
    """One direction of one link: messages in at `send`, out at their due time at `receive`.

    Args:
        faults: what to inject.
        rng: this link's generator (see `link_rng`).
    """

    faults: LinkFaults
    rng: np.random.Generator
    counts: LinkCounts = field(default_factory=LinkCounts)
    _queue: list[tuple[float, int, T]] = field(default_factory=list, repr=False)
    _order: int = 0

    def _delay_s(self) -> float:
        f = self.faults
        jitter = self.rng.uniform(-f.jitter_ms, f.jitter_ms) if f.jitter_ms else 0.0
        return max(0.0, f.latency_ms + jitter) * 1e-3

    def _push(self, due_s: float, message: T) -> None:
        heapq.heappush(self._queue, (due_s, self._order, message))
        self._order += 1

    def send(self, now_s: float, message: T) -> None:
        """Offer `message` at sim time `now_s` (it may be dropped, delayed, doubled)."""
        f = self.faults
        self.counts.offered += 1
        if not f.active:
            self._push(now_s, message)
            return
        # Fixed draw order per message keeps a link's behaviour a function of its seed.
        u_drop, u_reorder, u_dup = self.rng.random(3)
        if u_drop < f.drop:
            self.counts.dropped += 1
            return
        due_s = now_s + self._delay_s()
        if u_reorder < f.reorder:
            due_s += f.reorder_delay_ms * 1e-3
            self.counts.reordered += 1
        self._push(due_s, message)
        if u_dup < f.dup:
            self.counts.duplicated += 1
            self._push(now_s + self._delay_s(), message)

    def receive(self, now_s: float) -> list[T]:
        """Every message due by sim time `now_s`, in due-time order."""
        out = []
        while self._queue and self._queue[0][0] <= now_s + 1e-9:
            out.append(heapq.heappop(self._queue)[2])
        self.counts.delivered += len(out)
        return out

    @property
    def next_due_s(self) -> float | None:
        """Due time of the next message in flight, or None."""
        return self._queue[0][0] if self._queue else None

    @property
    def in_flight(self) -> int:
        """Messages (copies) not yet released."""
        return len(self._queue)

    def clear(self) -> None:
        """Forget everything in flight (the receiving process restarted)."""
        self._queue.clear()
