"""Following a run from its files, as the launcher does: events.jsonl and trajectory.csv.

The world appends one JSON line per event and flushes it (`EventTail` reads the complete
ones), and writes trajectory.csv every few ticks (`last_trajectory_time` is the sim time of
its last complete row); `distributed_progress` sums them up for a progress line.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class DistributedProgress:
    """What `distributed.run_distributed` reports to `on_progress` about every
    `distributed.POLL_S` of wall time.

    Args:
        wall_s: wall time since the world was spawned.
        started: the world has published the start.
        sim_t_s: the newest sim time seen in the events or the trajectory file.
        n_robots: robots in the scenario.
        arrived: robot ids that have arrived.
        contacts: contacts so far.
        lost: robot ids whose processes the world has lost (and not seen rejoin).
        robots_running: robot processes still running.
        events: every event read so far, in order (parsed JSON lines).
    """

    wall_s: float
    started: bool
    sim_t_s: float
    n_robots: int
    arrived: frozenset[int]
    contacts: int
    lost: frozenset[int]
    robots_running: int
    events: tuple[dict[str, Any], ...] = field(repr=False, default=())


class EventTail:
    """Reads new complete lines of events.jsonl (the world appends and flushes per line)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.offset = 0
        self.events: list[dict[str, Any]] = []

    def poll(self) -> list[dict[str, Any]]:
        try:
            with open(self.path, "rb") as f:
                f.seek(self.offset)
                chunk = f.read()
        except FileNotFoundError:
            return []
        end = chunk.rfind(b"\n") + 1
        self.offset += end
        new = []
        for line in chunk[:end].splitlines():
            try:
                new.append(json.loads(line))
            except ValueError:
                continue
        self.events.extend(new)
        return new


def last_trajectory_time(path: Path) -> float:
    """Sim time of the last complete row of trajectory.csv (0 if none yet)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - 512))
            tail = f.read()
    except FileNotFoundError:
        return 0.0
    lines = tail.split(b"\n")
    for line in reversed(lines[:-1]):  # the last piece may be a partial row
        try:
            return float(line.split(b",", 1)[0])
        except ValueError:
            continue
    return 0.0


def distributed_progress(events: list[dict[str, Any]], out_dir: Path, t0: float, n_robots: int,
                         robots: Sequence[subprocess.Popen[bytes]]) -> DistributedProgress:
    """What `events` (a run's events.jsonl so far) and its trajectory.csv say of a run
    launched at monotonic `t0`, with `robots` its robot processes."""
    arrived: set[int] = set()
    lost: set[int] = set()
    contacts = 0
    started = False
    sim_t = 0.0
    for e in events:
        kind = e.get("kind")
        sim_t = max(sim_t, float(e.get("t", 0.0)))
        if kind == "start":
            started = True
        elif kind == "arrived":
            arrived.add(int(e["robot"]))
        elif kind == "contact":
            contacts += 1
        elif kind == "robot_lost":
            lost.add(int(e["robot"]))
        elif kind == "robot_rejoined":
            lost.discard(int(e["robot"]))
    sim_t = max(sim_t, last_trajectory_time(out_dir / "trajectory.csv"))
    return DistributedProgress(
        wall_s=time.monotonic() - t0,
        started=started,
        sim_t_s=sim_t if math.isfinite(sim_t) else 0.0,
        n_robots=n_robots,
        arrived=frozenset(arrived),
        contacts=contacts,
        lost=frozenset(lost),
        robots_running=sum(p.poll() is None for p in robots),
        events=tuple(events),
    )
