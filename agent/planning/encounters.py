"""Encounter rules for eIFP: who gives way to whom, decided by each robot alone.

Not in the paper. Its cost of Eqs. (15)-(17) is evaluated by every robot on its own view,
and two robots in mirror-symmetric positions (setup A, the crossings of D, F and G) see
mirrored costs: when one prefers its LEFT tangent the other prefers its RIGHT one, which
are the two choices that do *not* fit together (each passes in front of the other). They
then run side by side, each chasing a tangent point that moves away as fast as it does.
Mirror symmetry can only be broken by a rule that tells right from left, so every robot
follows the same chiral convention, the one ships have used for a century (COLREGs rules
13-15), with no communication:

- **head-on** (the other's course within `RECIPROCAL_RAD` of the reverse of ours): both
  give way and pass on the RIGHT tangent (port to port);
- **crossing, the other on our right** (bearing in (-pi, 0)): we give way on the RIGHT
  tangent, which for a crossing from the right is the one behind it;
- **crossing, the other on our left**: we *stand on*: the other is not resolved (it gives
  way to us) unless it becomes imminent (below);
- **overtaking** (courses within `SAME_COURSE_RAD`, the other ahead of us and we behind
  it, seen from its course; otherwise two such courses converge and it is a crossing): we
  resolve it with
  the ordinary eIFP cost if its DCPA is inside the inflated radius L, and otherwise leave
  it (robots moving together in a stream are not threats, however close D_thresh says
  they pass); **being overtaken** (the other behind us, we ahead of it): we stand on.
- Others that barely move (slower than `MOVING_MPS`), and scenario obstacles, are plain
  obstacles: resolved with the ordinary cost.

Safety net: a stand-on robot resolves the other after all, on the RIGHT tangent (which
fits whatever the other does on its RIGHT), once the encounter is imminent: TCPA below
`STAND_ON_EMERGENCY_S` with DCPA inside the inflated radius L. In eIFP-MPC the
tracker's half-plane constraints also keep every near neighbour out, stand-on or not.

Two robots can both find the other on their left only on nearly reciprocal courses (the
head-on rule takes those) or when already close and diverging; the safety net covers the
rest. Both-RIGHT is always consistent: each turns clockwise about the line of sight.

The role of each other is remembered from the first cycle it is a threat, while it stays
sensed and is still approaching (TCPA > 0), so the manoeuvre itself does not reclassify the
encounter (`update_role_memory`).
"""

from __future__ import annotations

import cmath
import enum
import math
from collections.abc import Mapping

import numpy as np

from agent.core.types import Others

RECIPROCAL_RAD = math.radians(45.0)
"""Courses within this of exactly opposite are head-on."""

SAME_COURSE_RAD = math.radians(67.5)
"""Courses within this of each other are an overtaking encounter."""

MOVING_MPS = 0.15
"""Others slower than this are treated as obstacles."""

STAND_ON_EMERGENCY_S = 2.0
"""A stand-on robot gives way after all once TCPA is below this with DCPA inside L: about
the time a robot at 1.1 m/s turning at 1.5 rad/s needs to move L = 1.3 m sideways, so the
encounter is still resolved when the other does not give way."""


class Role(enum.IntEnum):
    """What this robot does about one other."""

    RESOLVE = 0  # an obstacle, a slow robot, or one we overtake: the ordinary eIFP choice
    GIVE_WAY = 1  # resolve it, on the RIGHT tangent
    STAND_ON = 2  # leave it to the other (not a threat) unless imminent


def classify(
    heading_rad: float, speed_mps: float, position_m: np.ndarray, others: Others
) -> tuple[np.ndarray, np.ndarray]:
    """The encounter role of each other, from geometry alone (no memory, no safety net).

    Args:
        heading_rad: own heading [rad].
        speed_mps: own speed [m/s]; a robot that barely moves stands on for no one.
        position_m: (2,) own position [m].
        others: the K others.

    Returns:
        roles: (K,) `Role` values (int).
        overtaken: (K,) bool, moving others on our course and ahead (we overtake them).
    """
    k = len(others)
    roles = np.full(k, int(Role.RESOLVE), dtype=np.int64)
    overtaken = np.zeros(k, dtype=bool)
    if k == 0 or speed_mps < MOVING_MPS:
        return roles, overtaken
    # Plain Python over complex numbers: K is at most the neighbour cap (10 by default),
    # where a loop costs a fraction of the ~40 small numpy calls of the array form.
    turn = complex(math.cos(-heading_rad), math.sin(-heading_rad))  # world -> own frame
    here = complex(position_m[0], position_m[1])
    give_way_role, stand_on_role = int(Role.GIVE_WAY), int(Role.STAND_ON)
    half_pi = 0.5 * math.pi
    rows = zip(others.position_m.tolist(), others.velocity_mps.tolist(),
               others.is_robot.tolist())
    for j, ((px, py), (vx, vy), is_robot) in enumerate(rows):
        velocity = complex(vx, vy)
        speed = abs(velocity)
        if not is_robot or speed < MOVING_MPS:
            continue  # an obstacle or a robot that barely moves: RESOLVE
        offset = complex(px, py) - here
        bearing = cmath.phase(offset * turn)  # where the other is, from our heading
        course = cmath.phase(velocity * turn)  # the other's course relative to ours
        # Where we are, seen from the other's course (its heading is its velocity).
        back_bearing = cmath.phase(-offset * (velocity / speed).conjugate())
        reciprocal = abs(cmath.phase(-cmath.exp(1j * course))) <= RECIPROCAL_RAD
        same = abs(course) <= SAME_COURSE_RAD
        ahead = abs(bearing) < half_pi
        behind_it = abs(back_bearing) > half_pi
        if same and ahead and behind_it:  # we come up from behind it
            overtaken[j] = True
        elif same and not ahead and not behind_it:  # it comes up from behind us
            roles[j] = stand_on_role
        elif reciprocal or bearing < 0.0:  # head-on, or crossing with it on our right
            roles[j] = give_way_role
        else:  # crossing with it on our left
            roles[j] = stand_on_role
    return roles, overtaken


def encounter_roles(
    heading_rad: float,
    speed_mps: float,
    position_m: np.ndarray,
    others: Others,
    tcpa_s: np.ndarray,
    dcpa_m: np.ndarray,
    inflated_m: np.ndarray,
    memory: Mapping[int, Role],
    emergency_s: float = STAND_ON_EMERGENCY_S,
) -> np.ndarray:
    """Roles for this cycle: remembered ones kept, new ones classified, the safety net applied.

    Args:
        heading_rad, speed_mps, position_m: own pose and speed.
        others: the K others the cycle plans against.
        tcpa_s, dcpa_m: (K,) TCPA and DCPA at the measured velocities (Eqs. 4-5).
        inflated_m: (K,) inflated radii L of each pair (Eq. 8).
        memory: id -> role from earlier cycles (see `update_role_memory`).
        emergency_s: a stand-on other with TCPA below this and DCPA < L is given way to.

    Returns:
        (K,) `Role` values (int).
    """
    roles, overtaken = classify(heading_rad, speed_mps, position_m, others)
    # Robots on our course that will not come inside L are neighbours in a stream, not
    # threats: D_thresh (a detection radius) would have us weave around them.
    roles[overtaken & (dcpa_m >= inflated_m)] = int(Role.STAND_ON)
    for k, rid in enumerate(others.ids.tolist()):
        kept = memory.get(rid)
        if kept is not None:
            roles[k] = int(kept)
    imminent = (tcpa_s > 0.0) & (tcpa_s < emergency_s) & (dcpa_m < inflated_m)
    roles[(roles == int(Role.STAND_ON)) & imminent] = int(Role.GIVE_WAY)
    return roles


def update_role_memory(others: Others, roles: np.ndarray, tcpa_s: np.ndarray,
                       threat: np.ndarray, memory: Mapping[int, Role]) -> dict[int, Role]:
    """The role memory after a cycle.

    An other's role is remembered from the first cycle it is a threat of Eq. (6), and kept
    while it is sensed and still approaching (TCPA > 0).

    Args:
        others: the K others of the cycle.
        roles: (K,) their roles this cycle.
        tcpa_s: (K,) their TCPA [s].
        threat: (K,) bool, which of them are threats of Eq. (6) this cycle (before any
            stand-on filtering).
        memory: the memory before the cycle.
    """
    ids = others.ids.tolist()
    remembered = np.array([rid in memory for rid in ids], dtype=bool)
    keep = (tcpa_s > 0.0) & (threat | remembered)
    role = roles.tolist()
    return {ids[k]: Role(role[k]) for k in keep.nonzero()[0].tolist()}
