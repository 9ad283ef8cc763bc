"""A robot process's lifecycle under injected process faults, as the lockstep loop emulates it.

`world.sim.faults.ProcessFault` kinds and what they do to a robot process:

- ``stop`` (SIGSTOP for ``duration_s``): the process freezes (`ProcessState.STOPPED`); the
  world notices only when the transport lease runs out (`Transition.LEASE_EXPIRED`), and
  the robot is back when it resumes (`Transition.RESUMED`).
- ``kill``: the process is gone for good (`ProcessState.DOWN`); the world sees it at once.
- ``restart``: a kill followed, ``restart_delay_s`` later, by a new process with the same id
  (`Transition.RESTARTED`).

Pure: time comes in as sim seconds; the caller (`world.sim.lockstep`) applies what the
transitions mean to the world, the links and the controller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

EPS_S = 1e-9
"""Tolerance on sim-time comparisons (fault times are sums of float ticks)."""


class ProcessState(Enum):
    """What a robot process is doing."""

    UP = "up"
    """Running: it senses, plans and commands."""
    STOPPED = "stopped"
    """Frozen (SIGSTOP): senses nothing, plans nothing, its link still open until the lease."""
    DOWN = "down"
    """Gone (killed), until a restart brings a new process."""


class Transition(Enum):
    """A change the world (or the robot) sees at a tick, in the order `RobotLifecycle.advance`
    reports them."""

    LEASE_EXPIRED = "lease_expired"
    """A stopped process's transport lease ran out: the world takes the robot offline."""
    RESUMED = "resumed"
    """A stopped process runs again (the world brings it back if it took it offline)."""
    RESTARTED = "restarted"
    """A killed process's replacement is up: a fresh controller, clear links."""


@dataclass
class RobotLifecycle:
    """One robot process's state and the sim times [s] its pending transitions fall due.

    Args:
        state: the process's state.
        resume_s: when a stopped process resumes (inf: not stopped).
        lease_s: when a stopped process's lease runs out (inf: not stopped).
        back_s: when a killed process's replacement is up (inf: not coming back).
    """

    state: ProcessState = ProcessState.UP
    resume_s: float = math.inf
    lease_s: float = math.inf
    back_s: float = math.inf

    @property
    def up(self) -> bool:
        """The process is running."""
        return self.state is ProcessState.UP

    @property
    def down(self) -> bool:
        """The process is gone (killed, and not back yet)."""
        return self.state is ProcessState.DOWN

    @property
    def gone_for_good(self) -> bool:
        """Killed with no restart to come: it no longer holds a run open."""
        return self.state is ProcessState.DOWN and self.back_s == math.inf

    def fault(self, kind: str, t_s: float, duration_s: float, *, lease_s: float,
              restart_delay_s: float) -> bool:
        """Apply a process fault at sim time `t_s`; returns True if the process died now.

        A ``stop`` only freezes a running process; a ``kill`` or ``restart`` ends any process
        that is not already down. Other faults, or faults that do not apply, change nothing.

        Args:
            kind: ``stop``, ``kill`` or ``restart``.
            t_s: the fault's sim time.
            duration_s: how long a stop lasts.
            lease_s: the transport lease (how long until the world notices a stop).
            restart_delay_s: how long a restarted robot is away.
        """
        if kind == "stop" and self.state is ProcessState.UP:
            self.state = ProcessState.STOPPED
            self.resume_s, self.lease_s = t_s + duration_s, t_s + lease_s
            return False
        if kind in ("kill", "restart") and self.state is not ProcessState.DOWN:
            self.state = ProcessState.DOWN
            self.resume_s = self.lease_s = math.inf
            self.back_s = t_s + restart_delay_s if kind == "restart" else math.inf
            return True
        return False

    def advance(self, t_s: float) -> tuple[Transition, ...]:
        """The transitions due by sim time `t_s`, in order, with the state moved on.

        `Transition.LEASE_EXPIRED` is reported at every tick from the lease's end until the
        stopped process resumes (the world takes it offline once).
        """
        out: list[Transition] = []
        if self.state is ProcessState.STOPPED and t_s + EPS_S >= self.lease_s:
            out.append(Transition.LEASE_EXPIRED)
        if self.state is ProcessState.STOPPED and t_s + EPS_S >= self.resume_s:
            self.state = ProcessState.UP
            out.append(Transition.RESUMED)
        if self.state is ProcessState.DOWN and t_s + EPS_S >= self.back_s:
            self.state, self.back_s = ProcessState.UP, math.inf
            out.append(Transition.RESTARTED)
        return tuple(out)
