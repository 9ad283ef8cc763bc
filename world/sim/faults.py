"""A run's fault plan: link faults, per-robot timing and process faults (pure parsing).

One `FaultPlan` describes everything `orchestrator run` injects, in both modes:

- ``links``: the `world.sim.link.LinkFaults` of every robot's pose link and command link
  (each direction gets the full delay: a pose is ``latency`` old when it arrives, and its
  command reaches the world another ``latency`` later);
- ``timing``: per robot, its control rate and phase and an added planning delay (a
  CPU-starved robot: its command leaves that much later than it would);
- ``process``: robot processes killed (SIGKILL), stopped (SIGSTOP for a while, then
  SIGCONT) or restarted (SIGKILL, then a new process with the same id) at a sim time.

Flag syntax (`parse_*`): ``--slow-robot I:MS``, ``--robot-rate I:HZ[:PHASE_S]``,
``--kill-robot I@T``, ``--stop-robot I@T:DUR``, ``--restart-robot I@T`` (T, DUR in sim s).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Literal

from world.sim.link import LinkFaults

ProcessFaultKind = Literal["kill", "stop", "restart"]


class FaultSpecError(ValueError):
    """A fault flag that cannot be parsed or does not fit the scenario."""


@dataclass(frozen=True)
class ProcessFault:
    """One robot process fault at sim time `at_s`.

    Args:
        kind: ``kill`` (SIGKILL, never back), ``stop`` (SIGSTOP for `duration_s`, then
            SIGCONT) or ``restart`` (SIGKILL, then a new process with the same id).
        robot_id: the robot.
        at_s: sim time [s] of the fault.
        duration_s: how long a ``stop`` lasts [sim s]; 0 for the others.
    """

    kind: ProcessFaultKind
    robot_id: int
    at_s: float
    duration_s: float = 0.0

    def describe(self) -> str:
        """The flag that would make this fault."""
        tail = f":{self.duration_s:g}" if self.kind == "stop" else ""
        return f"--{self.kind}-robot {self.robot_id}@{self.at_s:g}{tail}"


@dataclass(frozen=True)
class RobotTiming:
    """One robot's timing faults.

    Args:
        control_rate_hz: its planning rate [1/sim s]; None: the run's.
        phase_s: offset of its planning slots [sim s] (first plan at stamp + phase).
        plan_delay_ms: added planning delay [ms of sim time] before each command leaves.
    """

    control_rate_hz: float | None = None
    phase_s: float = 0.0
    plan_delay_ms: float = 0.0


@dataclass(frozen=True)
class FaultPlan:
    """Everything injected into one run.

    Args:
        links: faults of every pose and command link.
        seed: seeds every link's generator (with the link kind and robot id).
        timing: robot id -> `RobotTiming` (robots not listed: no timing fault).
        process: process faults, in any order.
        compensate_latency: the robots forward-predict by the age of the poses.
        command_hold_periods: how many control periods the world may apply a robot's
            command before it brakes (None: the controller's own,
            `agent.planning.controller.COMMAND_HOLD_PERIODS`); a hold longer than the
            world's command time-out switches the hold off.
    """

    links: LinkFaults = field(default_factory=LinkFaults)
    seed: int = 0
    timing: Mapping[int, RobotTiming] = field(default_factory=dict)
    process: tuple[ProcessFault, ...] = ()
    compensate_latency: bool = True
    command_hold_periods: float | None = None

    def __post_init__(self) -> None:
        hold = self.command_hold_periods
        if hold is not None and not (math.isfinite(hold) and hold > 0.0):
            raise FaultSpecError(f"command_hold_periods: must be > 0, got {hold!r}")

    def timing_of(self, robot_id: int) -> RobotTiming:
        """The timing of `robot_id` (the default if it has none)."""
        return self.timing.get(int(robot_id), RobotTiming())

    @property
    def active(self) -> bool:
        """True if anything at all is injected (or compensation is off)."""
        return bool(self.links.active or self.timing or self.process
                    or not self.compensate_latency or self.command_hold_periods is not None)

    def check(self, robot_ids: Collection[int]) -> None:
        """Raise `FaultSpecError` if a fault names a robot the scenario does not have."""
        known = {int(r) for r in robot_ids}
        for rid in self.timing:
            if rid not in known:
                raise FaultSpecError(f"robot {rid}: no such robot (ids {sorted(known)})")
        for f in self.process:
            if f.robot_id not in known:
                raise FaultSpecError(f"{f.describe()}: no robot {f.robot_id} "
                                     f"(ids {sorted(known)})")

    def to_json(self) -> dict[str, Any]:
        """Plain data for run.json."""
        return {
            "links": self.links.as_dict(),
            "seed": self.seed,
            "timing": {str(k): vars(v) for k, v in sorted(self.timing.items())},
            "process": [vars(p) for p in self.process],
            "compensate_latency": self.compensate_latency,
            "command_hold_periods": self.command_hold_periods,
        }


def _number(text: str, what: str, *, positive: bool = False) -> float:
    try:
        value = float(text)
    except ValueError:
        raise FaultSpecError(f"{what}: not a number: {text!r}") from None
    if not math.isfinite(value) or value < 0.0 or (positive and value == 0.0):
        raise FaultSpecError(f"{what}: must be {'> 0' if positive else '>= 0'}, got {text!r}")
    return value


def _robot(text: str, flag: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise FaultSpecError(f"{flag}: robot id must be an int, got {text!r}") from None
    if value < 0:
        raise FaultSpecError(f"{flag}: robot id must be >= 0, got {value}")
    return value


def parse_slow_robot(text: str) -> tuple[int, float]:
    """``I:MS`` -> (robot id, added planning delay in ms)."""
    rid, sep, ms = text.partition(":")
    if not sep:
        raise FaultSpecError(f"--slow-robot: expected I:MS, got {text!r}")
    return _robot(rid, "--slow-robot"), _number(ms, "--slow-robot MS")


def parse_robot_rate(text: str) -> tuple[int, float, float]:
    """``I:HZ[:PHASE_S]`` -> (robot id, control rate, phase)."""
    parts = text.split(":")
    if len(parts) not in (2, 3):
        raise FaultSpecError(f"--robot-rate: expected I:HZ[:PHASE_S], got {text!r}")
    phase = _number(parts[2], "--robot-rate PHASE_S") if len(parts) == 3 else 0.0
    return (_robot(parts[0], "--robot-rate"), _number(parts[1], "--robot-rate HZ",
                                                      positive=True), phase)


def parse_process_fault(kind: ProcessFaultKind, text: str) -> ProcessFault:
    """``I@T`` (kill, restart) or ``I@T:DUR`` (stop) -> a `ProcessFault`."""
    flag = f"--{kind}-robot"
    rid, sep, rest = text.partition("@")
    if not sep:
        want = "I@T:DUR" if kind == "stop" else "I@T"
        raise FaultSpecError(f"{flag}: expected {want}, got {text!r}")
    if kind == "stop":
        at, sep, dur = rest.partition(":")
        if not sep:
            raise FaultSpecError(f"{flag}: expected I@T:DUR, got {text!r}")
        return ProcessFault("stop", _robot(rid, flag), _number(at, f"{flag} T"),
                            _number(dur, f"{flag} DUR", positive=True))
    return ProcessFault(kind, _robot(rid, flag), _number(rest, f"{flag} T"))


def build_plan(*, latency_ms: float = 0.0, jitter_ms: float = 0.0, drop: float = 0.0,
               dup: float = 0.0, reorder: float = 0.0, seed: int = 0,
               slow: Collection[str] = (), rates: Collection[str] = (),
               kill: Collection[str] = (), stop: Collection[str] = (),
               restart: Collection[str] = (), compensate_latency: bool = True) -> FaultPlan:
    """A `FaultPlan` from flag values (strings as typed); raises `FaultSpecError`."""
    try:
        links = LinkFaults(latency_ms=latency_ms, jitter_ms=jitter_ms, drop=drop, dup=dup,
                           reorder=reorder)
    except ValueError as exc:
        raise FaultSpecError(f"link faults: {exc}") from None
    timing: dict[int, RobotTiming] = {}
    for text in slow:
        rid, ms = parse_slow_robot(text)
        timing[rid] = replace(timing.get(rid, RobotTiming()), plan_delay_ms=ms)
    for text in rates:
        rid, hz, phase = parse_robot_rate(text)
        timing[rid] = replace(timing.get(rid, RobotTiming()), control_rate_hz=hz, phase_s=phase)
    process = tuple(
        [parse_process_fault("kill", t) for t in kill]
        + [parse_process_fault("stop", t) for t in stop]
        + [parse_process_fault("restart", t) for t in restart])
    return FaultPlan(links=links, seed=int(seed),
                     timing=timing,
                     process=tuple(sorted(process, key=lambda f: f.at_s)),
                     compensate_latency=compensate_latency)
