"""ORCA baseline (RVO2 through `pyrvo`) driving a unicycle.

ORCA is holonomic: each cycle it picks the velocity closest to a preferred velocity
among those outside every neighbour's reciprocal velocity obstacle. Here, per cycle:

1. Build a fresh `pyrvo.RVOSimulator` in the robot's frame (robot at the origin: float32
   precision does not depend on where the arena is): the robot is agent 0, with its current
   velocity and the preferred velocity toward the goal; each sensed other (within
   `sensing_radius_m`, nearest `max_neighbors`, ties in input order) is an agent at its
   observed position with its estimated velocity. Every disc is inflated by
   d_safety / 2, so a pair's combined radius is r_i + r_j + d_safety, the clearance the
   other planners use. The others get `max_neighbors = 0`: their own ORCA solve is
   irrelevant and skipped. A fresh simulator costs less than resetting a reused one, and
   RVO2 cannot remove agents safely
   (`clear_agents` leaves dangling pointers in its k-d tree).
2. `do_step()` once and read agent 0's new velocity v_orca.
3. Turn it into a unicycle command with `unicycle.heading_law`: err = wrap(angle(v_orca) -
   theta), omega = clip(k err), v = |v_orca| max(0, cos(err)); then, if the last command
   is given, the rate limits (`unicycle.clamp_command`).

Preferred velocity: toward the goal at min(v_max, sqrt(2 accel_max d)), which slows the
robot so it could stop at the goal.

Caveats of the baseline, accepted: RVO2 assumes every neighbour runs ORCA and takes half
of the avoidance (the 0.5 u of the ORCA half-plane); scenario obstacles and robots running
other planners do not reciprocate. The unicycle only follows v_orca after turning, which
the d_safety margin partly absorbs. And ORCA deadlocks in symmetric crossings of three or
more robots that start at rest in view of each other (the 4-robot cross stops all four at
the centre, discs touching): the ORCA velocities stay symmetric and shrink to zero; plain
holonomic RVO2 with the same parameters does the same
(tests/unit/agent/planning/test_orca.py). No
perturbation is added: this is the plain method. Deterministic: no randomness, no clock,
the same inputs give the same command.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyrvo

from agent.core.config import PlannerConfig, RobotLimits
from agent.core.types import Others
from agent.planning.unicycle import HEADING_GAIN, clamp_command, heading_law


@dataclass(frozen=True)
class OrcaCommand:
    """One ORCA cycle.

    Args:
        v_mps, omega_radps: unicycle command within the bounds (and rate limits if the
            last command was given).
        velocity_orca_mps: (2,) ORCA's holonomic velocity for this robot (world frame).
        velocity_pref_mps: (2,) the preferred velocity it was asked for.
        n_neighbors: how many others entered the ORCA solve.
    """

    v_mps: float
    omega_radps: float
    velocity_orca_mps: np.ndarray
    velocity_pref_mps: np.ndarray
    n_neighbors: int


class OrcaController:
    """ORCA velocity selection plus a heading controller for a unicycle.

    Args:
        limits: actuation limits (v_max is ORCA's max speed).
        config: planner settings: `safety.d_safety_m`, `threats.sensing_radius_m`,
            `threats.max_neighbors`, `orca.time_horizon_s`.
        control_period_s: command period: RVO2's time step (used when discs already
            overlap) and the rate limits' dt.
    """

    def __init__(
        self, limits: RobotLimits, config: PlannerConfig, control_period_s: float = 0.1
    ) -> None:
        if control_period_s <= 0.0 or config.orca.time_horizon_s <= 0.0:
            raise ValueError("control_period_s and orca.time_horizon_s must be positive")
        self.limits = limits
        self.config = config
        self.control_period_s = control_period_s

    def preferred_velocity(self, position: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """(2,) toward the goal at min(v_max, sqrt(2 accel_max d)); zero at the goal."""
        to_goal = np.asarray(goal, dtype=float) - np.asarray(position, dtype=float)
        dist = float(np.hypot(to_goal[0], to_goal[1]))
        if dist < 1e-9:
            return np.zeros(2)
        speed = min(self.limits.v_max_mps, np.sqrt(2.0 * self.limits.accel_max_mps2 * dist))
        velocity: np.ndarray = to_goal * (speed / dist)
        return velocity

    def command(
        self,
        position: np.ndarray,
        heading_rad: float,
        velocity: np.ndarray,
        goal: np.ndarray,
        radius_m: float,
        others: Others,
        last_command: np.ndarray | None = None,
    ) -> OrcaCommand:
        """One ORCA cycle.

        Args:
            position: (2,) robot position [m].
            heading_rad: robot heading theta.
            velocity: (2,) robot's current velocity [m/s] (v (cos theta, sin theta)).
            goal: (2,) goal position [m].
            radius_m: robot radius (d_safety / 2 is added).
            others: sensed discs; `radius_m` gets d_safety / 2 added, `velocity_mps` is
                their estimated velocity.
            last_command: (2,) previously applied [v, omega]; if given, rates are limited.

        Returns:
            The command and ORCA's velocities.
        """
        cfg, lim = self.config, self.limits
        position = np.asarray(position, dtype=float)
        velocity = np.asarray(velocity, dtype=float)
        if position.shape != (2,) or velocity.shape != (2,) or np.shape(goal) != (2,):
            raise ValueError("position, velocity and goal must have shape (2,)")
        values = (*position, *velocity, *np.asarray(goal, dtype=float), heading_rad, radius_m)
        if not np.all(np.isfinite(values)):
            raise ValueError("non-finite input")
        pref = self.preferred_velocity(position, goal)
        margin = 0.5 * cfg.safety.d_safety_m
        horizon = cfg.orca.time_horizon_s
        sensing_m, max_neighbors = cfg.threats.sensing_radius_m, cfg.threats.max_neighbors

        rel = others.position_m - position  # (K, 2)
        dist = np.hypot(rel[:, 0], rel[:, 1])
        near = np.flatnonzero(dist <= sensing_m)
        near = near[np.argsort(dist[near], kind="stable")][:max_neighbors]

        sim = pyrvo.RVOSimulator(
            self.control_period_s,
            sensing_m,
            max_neighbors,
            horizon,
            horizon,
            radius_m + margin,
            lim.v_max_mps,
        )
        me = sim.add_agent(
            (0.0, 0.0),
            sensing_m,
            max_neighbors,
            horizon,
            horizon,
            radius_m + margin,
            lim.v_max_mps,
            velocity.tolist(),
        )
        sim.set_agent_pref_velocity(me, pref.tolist())
        radii = (others.radius_m[near] + margin).tolist()
        speeds = np.hypot(others.velocity_mps[near, 0], others.velocity_mps[near, 1]).tolist()
        for p, v, r, s in zip(
            rel[near].tolist(), others.velocity_mps[near].tolist(), radii, speeds, strict=True
        ):
            # A passive agent: no neighbours of its own, keeps its velocity.
            sim.add_agent(p, sensing_m, 0, horizon, horizon, r, max(s, 1e-3), v)
        sim.do_step()
        new_v = sim.get_agent_velocity(me)
        v_orca = np.array([new_v.x, new_v.y])
        speed = float(np.hypot(v_orca[0], v_orca[1]))
        if speed > lim.v_max_mps:
            # RVO2 solves its linear program in float32: its velocity can exceed maxSpeed by
            # float32 round-off (1.1000104 for 1.1 m/s; found by the random-input test).
            v_orca *= lim.v_max_mps / speed
            speed = lim.v_max_mps

        direction = float(np.arctan2(v_orca[1], v_orca[0])) if speed > 1e-6 else heading_rad
        v, omega = heading_law(heading_rad, direction, speed, lim, HEADING_GAIN)
        if last_command is not None:
            v, omega = clamp_command(
                v, omega, lim, last_command[0], last_command[1], self.control_period_s
            )
        return OrcaCommand(
            v_mps=v,
            omega_radps=omega,
            velocity_orca_mps=v_orca,
            velocity_pref_mps=pref,
            n_neighbors=int(near.shape[0]),
        )
