"""eIFP-MPC (or IFP, eIFP, ORCA) as an IR-SIM behaviour: a robot of an IR-SIM world file plans
with this project's planner, without Zenoh, processes or this project's world.

Import this module before `irsim.make` (the import registers the behaviour), then give
each differential-drive robot of the world file the behaviour ``eifp``:

.. code-block:: yaml

    robot:
      - number: 4
        distribution: {name: 'circle', radius: 6.0, center: [0, 0]}
        kinematics: {name: 'diff'}
        shape: {name: 'circle', radius: 0.3}
        vel_max: [1.1, 1.5]
        behavior: {name: 'eifp', planner: 'eifp-mpc'}   # planner and profile optional

Behaviour keys: ``planner`` (`agent.core.config.PLANNER_NAMES`, default ``eifp-mpc``),
``profile`` (``default`` or ``paper``, default ``default``) and ``goal_tolerance`` [m]
(default twice the robot's ``goal_threshold``: the planners stop within half the
tolerance, so inside IR-SIM's arrival distance).

Each IR-SIM step, the behaviour of a robot sees every other object as a disc (its id, its
pose, its ``radius``: polygons and lines count as the disc IR-SIM gives them), feeds them
to its `agent.planning.controller.RobotController` as a `PoseSnapshot` stamped with the
robot's own step count times the step time, plans once and returns ``[v, omega]``. The
robot's speed and turn-rate limits are its ``vel_max``. Robots keep their IR-SIM ids;
other objects get negative ids (``-1 - id``), as obstacles do in this project.

An edge adapter, like the robot process: the planning core never imports IR-SIM
(`tests/unit/test_architecture.py`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from irsim.lib import register_behavior_class

from agent.core.config import PLANNER_NAMES, PROFILES, RobotLimits, profile_config
from agent.core.scenario import RobotSpec
from agent.core.types import PoseSnapshot
from agent.planning.controller import RobotController

BEHAVIOR_NAME = "eifp"
"""The ``behavior: {name: ...}`` of an IR-SIM world file that selects this planner."""
KINEMATICS = "diff"
"""IR-SIM's differential drive: the unicycle the planners are built for (Eq. 1)."""


def obstacle_id(irsim_id: int) -> int:
    """The project id of a non-robot IR-SIM object: negative, unique per object."""
    return -1 - int(irsim_id)


def snapshot_of(ego: Any, others: list[Any], stamp_s: float, tick: int) -> PoseSnapshot:
    """What the ego robot senses: every object of the world as a disc, the ego first.

    Args:
        ego: the IR-SIM robot (``state`` (>= 3, 1): x [m], y [m], heading [rad]; ``radius``).
        others: the other IR-SIM objects (robots keep their ids, the rest are obstacles).
        stamp_s: sim time of the poses.
        tick: increasing step number.
    """
    objects = [ego, *others]
    ids = [int(o.id) if o.role == "robot" else obstacle_id(o.id) for o in objects]
    pose = np.zeros((len(objects), 3))
    for k, o in enumerate(objects):
        state = np.asarray(o.state, dtype=float).reshape(-1)
        pose[k, :2] = state[:2]
        if o.role == "robot" and state.size >= 3:
            pose[k, 2] = state[2]
    radius = np.array([float(o.radius) for o in objects])
    return PoseSnapshot(stamp_s=stamp_s, tick=tick, ids=np.array(ids), pose=pose,
                        radius_m=radius)


@register_behavior_class(KINEMATICS, BEHAVIOR_NAME)
class EifpBehavior:
    """One robot's planner inside IR-SIM; IR-SIM makes one per robot and calls it each step.

    Args:
        object_info: IR-SIM's description of the robot (unused: the robot is read each step).
        planner: one of `PLANNER_NAMES`.
        profile: one of `PROFILES`.
        goal_tolerance: arrival distance [m] the planner stops at half of; default twice
            the robot's ``goal_threshold``.

    Raises:
        ValueError: an unknown planner or profile (IR-SIM logs it and leaves the robot
            without a behaviour).
    """

    def __init__(self, object_info: Any = None, *, planner: str = "eifp-mpc",
                 profile: str = "default", goal_tolerance: float | None = None,
                 **_: Any) -> None:
        if planner not in PLANNER_NAMES:
            raise ValueError(f"behavior {BEHAVIOR_NAME}: planner must be one of "
                             f"{', '.join(PLANNER_NAMES)}, got {planner!r}")
        if profile not in PROFILES:
            raise ValueError(f"behavior {BEHAVIOR_NAME}: profile must be one of "
                             f"{', '.join(PROFILES)}, got {profile!r}")
        self.planner = planner
        self.config = profile_config(profile)
        self.goal_tolerance_m = goal_tolerance
        self.controller: RobotController | None = None
        self.goal: tuple[float, float] | None = None
        self.tick = 0

    def _controller(self, ego: Any, goal: tuple[float, float]) -> RobotController:
        """The robot's controller, made again when its goal changes."""
        if self.controller is None or goal != self.goal:
            vel_max = np.asarray(ego.vel_max, dtype=float).reshape(-1)
            state = np.asarray(ego.state, dtype=float).reshape(-1)
            spec = RobotSpec(id=int(ego.id), start=(state[0], state[1], state[2]), goal=goal,
                             radius_m=float(ego.radius), planner=self.planner,
                             limits=RobotLimits(v_max_mps=float(vel_max[0]),
                                                omega_max_radps=float(vel_max[1])))
            tolerance_m = (self.goal_tolerance_m if self.goal_tolerance_m is not None
                           else 2.0 * float(ego.goal_threshold))
            self.controller = RobotController(spec, self.config, tolerance_m,
                                              control_period_s=self.step_s(ego))
            self.goal = goal
        return self.controller

    @staticmethod
    def step_s(ego: Any) -> float:
        """IR-SIM's step time [s] (the world file's ``step_time``, default 0.1 s)."""
        return float(ego._world_param.step_time)

    def __call__(self, ego_object: Any, external_objects: list[Any],
                 **_: Any) -> np.ndarray:
        """One planning cycle: (2, 1) [v (m/s), omega (rad/s)]; zero without a goal."""
        if ego_object.goal is None:
            return np.zeros((2, 1))
        goal_m = np.asarray(ego_object.goal, dtype=float).reshape(-1)
        ctrl = self._controller(ego_object, (float(goal_m[0]), float(goal_m[1])))
        now_s = self.tick * self.step_s(ego_object)
        ctrl.observe(snapshot_of(ego_object, list(external_objects), now_s, self.tick))
        self.tick += 1
        result = ctrl.plan(now_s)
        return np.array([[result.v_mps], [result.omega_radps]])
