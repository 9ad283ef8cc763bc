"""Scenario domain types: robots, obstacles and a whole resolved scenario (pure).

The world, the robots and the orchestrator share these; the YAML file format that maps onto
them, with its loader and validation, is `world.scenario_file`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from agent.core.config import PlannerConfig, RobotLimits


@dataclass(frozen=True)
class RobotSpec:
    """One robot of a scenario.

    Args:
        id: robot id (>= 0, unique).
        start: (x [m], y [m], heading [rad]).
        goal: (x [m], y [m]).
        radius_m: disc radius.
        limits: actuation limits.
        planner: one of `agent.core.config.PLANNER_NAMES`.
    """

    id: int
    start: tuple[float, float, float]
    goal: tuple[float, float]
    radius_m: float = 0.5
    limits: RobotLimits = field(default_factory=RobotLimits)
    planner: str = "eifp-mpc"


@dataclass(frozen=True)
class ObstacleSpec:
    """A disc obstacle, static or moving at constant velocity.

    Args:
        id: negative id (-1, -2, ...), assigned in file order.
        center: (x [m], y [m]) at t = 0.
        radius_m: disc radius.
        velocity: (vx [m/s], vy [m/s]).
    """

    id: int
    center: tuple[float, float]
    radius_m: float
    velocity: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class Scenario:
    """A whole scenario, resolved (every robot has its own limits and planner).

    Args:
        name: short name (`setup_d`, `circle_16`, ...).
        description: one line for humans.
        time_limit_s: the run fails if not every robot has arrived by then.
        goal_tolerance_m: a robot has arrived when its centre is this close to its goal.
        planner_config: parameters shared by the robots' planners.
        robots: the robots, ids unique.
        obstacles: disc obstacles.
    """

    name: str
    description: str
    time_limit_s: float
    goal_tolerance_m: float
    planner_config: PlannerConfig
    robots: tuple[RobotSpec, ...]
    obstacles: tuple[ObstacleSpec, ...] = ()

    def robot(self, robot_id: int) -> RobotSpec:
        """The robot with this id; KeyError if none."""
        for spec in self.robots:
            if spec.id == robot_id:
                return spec
        raise KeyError(robot_id)
