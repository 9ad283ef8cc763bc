"""The bounds every value on the wire is checked against, and the one error a broken one raises.

A receiver treats anything beyond these as garbage (or as an attack) and refuses the whole
message with `ProtocolError`; the encoders check the same bounds, so nothing valid is
refused on arrival.
"""

from __future__ import annotations

MAX_MESSAGE_BYTES = 1 << 20
"""Largest payload accepted (1 MiB)."""
MAX_ROBOTS = 4096
MAX_OBSTACLES = 4096
MAX_ROBOT_ID = 2**31 - 1
MIN_OBSTACLE_ID = -(2**31)
MAX_COORD_M = 1.0e6
"""|x|, |y| larger than this (1000 km) is treated as garbage."""
MAX_RADIUS_M = 1.0e3
MAX_SPEED = 1.0e3
"""|v| [m/s] and |omega| [rad/s] larger than this are treated as garbage."""
MAX_HOLD_S = 60.0
"""Longest a command may ask to be held [s]."""
MAX_TIME_S = 1.0e7
"""Largest sim time on the wire [s] (about 116 days): stamps, ticks' times, time limits."""
MAX_REASON_CHARS = 256
MAX_SEQ = 2**63 - 1
MAX_RUN_ID_CHARS = 64
MAX_CLOCK_ID = 2**31 - 1
MAX_DEBUG_THREATS = 256
"""Most threat ids a `PlanDebugMsg` carries."""
MAX_DEBUG_POINTS = 512
"""Most points in each polyline of a `PlanDebugMsg` (via-points, reference, prediction)."""


class ProtocolError(ValueError):
    """A message, key expression or run id that does not follow the wire protocol."""
