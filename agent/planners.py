"""One interface for the four planners: `ifp`, `eifp`, `eifp-mpc` and `orca`.

`make_planner(name, config)` returns an object with `plan(observation, now_s) -> PlanResult`.
Planners keep only the memory the method needs (the side chosen last time per threat, the
MPC warm start); for the same sequence of inputs they return the same decisions.
"""

from __future__ import annotations

from typing import Protocol

from agent.types import Observation, PlanResult


class Planner(Protocol):
    """A collision-avoidance planner for one robot."""

    name: str

    def plan(self, observation: Observation, now_s: float) -> PlanResult:
        """Decide the command for this cycle from what the robot observed at `now_s`."""
        ...

    def reset(self) -> None:
        """Forget all memory (side choices, warm starts)."""
        ...
