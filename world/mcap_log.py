"""Foxglove views of a run: `run.mcap` and a live Foxglove WebSocket server (an I/O edge).

Topics (frame ``world``, z up, SI units; every log time is the sim time in ns):

- ``/world/scene``           foxglove.SceneUpdate, every `SCENE_EVERY_TICKS` world ticks: one
                             entity ``robot/<id>`` per robot (disc in the robot's colour,
                             heading arrow, goal as a faint flat disc, id label) and one
                             entity ``obstacles`` (grey cylinders at their current positions);
                             every `TRAIL_EVERY_S` also one entity ``trail/<id>`` per robot
                             (the last `TRAIL_POINTS` positions; it stays until replaced).
- ``/robot/<id>/command``    JSON ``eifp.Command``: each applied command (t, robot, seq, v,
                             omega, status, side, resolved).
- ``/robot/<id>/plan``       foxglove.SceneUpdate: entity ``robot/<id>/plan``: reference path,
                             MPC prediction, via-points, red lines to the threats, status label.
- ``/robot/<id>/plan/raw``   JSON ``eifp.PlanDebug``: the same numbers, raw.

Each sink has its own `foxglove.Context` (the recorder's MCAP writer and the live server never
see each other's channels, nor the SDK's global context). A message is built only if one of
its channels has a sink (a live server's channel has one only while a client subscribes to
it), and built once for every context that wants it.

The file is deterministic: log times are sim times, compression runs on the logging thread,
attachments carry time 0, and nothing wall-clock (planning times) is written, so a lockstep
run gives a byte-identical `run.mcap` for the same inputs.

The prototype and its measurements: docs/visualisation.md.
"""

from __future__ import annotations

import functools
import json
import math
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

import foxglove
import numpy as np
from foxglove import Channel, Context, Schema
from foxglove.channels import SceneUpdateChannel
from foxglove.mcap import MCAPCompression, MCAPWriteOptions
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from agent.core.scenario import Scenario
from agent.core.types import PlanDebug

WORLD_FRAME = "world"
SCENE_TOPIC = "/world/scene"
SCENE_EVERY_TICKS = 2
"""A scene every this many world ticks: 25 Hz at the world's 50 Hz."""
TRAIL_EVERY_S = 0.2
"""Sim time between two trail points."""
TRAIL_POINTS = 25
"""Trail length in points (5 s of sim time)."""
LIVE_BACKLOG = 256
"""Messages queued per live client before the oldest is dropped (the publisher never waits)."""

DISC_HEIGHT_M = 0.10
OBSTACLE_HEIGHT_M = 0.30
TRAIL_Z_M = 0.01
PLAN_Z_M = 0.12

_IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)  # Quaternion() is all zeros, not identity
_OBSTACLE_COLOUR = Color(r=0.55, g=0.55, b=0.55, a=0.8)
_THREAT_COLOUR = Color(r=0.9, g=0.1, b=0.1, a=1.0)
_VIA_COLOUR = Color(r=1.0, g=0.85, b=0.0, a=1.0)
_MPC_COLOUR = Color(r=0.1, g=0.1, b=0.1, a=1.0)
_TEXT_COLOUR = Color(r=1.0, g=1.0, b=1.0, a=1.0)


def command_topic(robot_id: int) -> str:
    return f"/robot/{int(robot_id)}/command"


def plan_topic(robot_id: int) -> str:
    return f"/robot/{int(robot_id)}/plan"


def plan_raw_topic(robot_id: int) -> str:
    return f"/robot/{int(robot_id)}/plan/raw"


_XY_LIST = {"type": "array", "items": {"type": "array", "items": {"type": "number"}}}
COMMAND_SCHEMA: dict[str, Any] = {
    "title": "eifp.Command",
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "sim time the world applied it [s]"},
        "robot": {"type": "integer"},
        "seq": {"type": "integer"},
        "v": {"type": "number", "description": "forward speed [m/s]"},
        "omega": {"type": "number", "description": "turn rate [rad/s]"},
        "status": {"type": "string"},
        "side": {"type": "integer", "description": "-1 right, 0 none, 1 left"},
        "resolved": {"type": ["integer", "null"]},
    },
}
PLAN_SCHEMA: dict[str, Any] = {
    "title": "eifp.PlanDebug",
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "sim time of the plan [s]"},
        "robot": {"type": "integer"},
        "ego": {"type": "array", "items": {"type": "number"},
                "description": "x, y, heading the robot planned from"},
        "threats": {"type": "array", "items": {"type": "integer"}},
        "via_points": _XY_LIST,
        "reference_path": _XY_LIST,
        "mpc_prediction": _XY_LIST,
        "v": {"type": "number"},
        "omega": {"type": "number"},
        "status": {"type": "string"},
    },
}

_TAB10 = ["1f77b4", "ff7f0e", "2ca02c", "d62728", "9467bd", "8c564b", "e377c2", "7f7f7f",
          "bcbd22", "17becf"]
_TAB20 = ["1f77b4", "aec7e8", "ff7f0e", "ffbb78", "2ca02c", "98df8a", "d62728", "ff9896",
          "9467bd", "c5b0d5", "8c564b", "c49c94", "e377c2", "f7b6d2", "7f7f7f", "c7c7c7",
          "bcbd22", "dbdb8d", "17becf", "9edae5"]


def robot_rgb(n: int) -> np.ndarray:
    """(n, 3) RGB in [0, 1], the colours of `orchestrator.analysis.plots.robot_colours`:
    tab10 up to 10 robots, tab20 up to 20 (tables here: no matplotlib import), else
    matplotlib's hsv wheel."""
    if n <= 20:
        table = _TAB10 if n <= 10 else _TAB20
        return np.array([[int(h[i:i + 2], 16) / 255.0 for i in (0, 2, 4)]
                         for h in table[:n]]).reshape(n, 3)
    from matplotlib import colormaps

    return np.asarray(colormaps["hsv"](np.linspace(0.0, 1.0, n, endpoint=False)))[:, :3]


def to_ns(t_s: float) -> int:
    """Sim time [s] to integer ns, rounded (0.02 k s gives exact ticks)."""
    return int(round(float(t_s) * 1e9))


def _stamp(ns: int) -> Timestamp:
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _colour(rgb: Sequence[float], a: float = 1.0) -> Color:
    return _rgba(float(rgb[0]), float(rgb[1]), float(rgb[2]), float(a))


@functools.lru_cache(maxsize=4096)
def _rgba(r: float, g: float, b: float, a: float) -> Color:
    """A colour, made once: a scene of 64 robots uses 128 of them 25 times a second (the
    messages are only read, so one object serves them all)."""
    return Color(r=r, g=g, b=b, a=a)


def _yaw(theta: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2.0), w=math.cos(theta / 2.0))


def _pose(x: float, y: float, z: float, q: Quaternion = _IDENTITY) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=q)


def _points(xy: np.ndarray, z: float) -> list[Point3]:
    return [Point3(x=x, y=y, z=z) for x, y in np.asarray(xy, dtype=float).reshape(-1, 2).tolist()]


def _disc(x: float, y: float, z: float, r: float, height: float, colour: Color
          ) -> CylinderPrimitive:
    return CylinderPrimitive(pose=_pose(x, y, z), size=Vector3(x=2.0 * r, y=2.0 * r, z=height),
                             bottom_scale=1.0, top_scale=1.0, color=colour)


@functools.lru_cache(maxsize=4096)
def _goal_disc(x: float, y: float, r: float, colour: Color) -> CylinderPrimitive:
    """A goal's faint flat disc, made once per goal (it is in every scene)."""
    return _disc(x, y, 0.005, r, 0.01, colour)


# ---------------------------------------------------------------------------------------------
# Pure conversion


def scene_update(t_s: float, robot_ids: Sequence[int], xy_m: np.ndarray, heading_rad: np.ndarray,
                 radius_m: np.ndarray, goal_m: np.ndarray, colours: np.ndarray,
                 obstacles: np.ndarray, trails: Sequence[np.ndarray] | None = None, *,
                 labels: bool = True) -> SceneUpdate:
    """One world instant as a SceneUpdate. Entities are replaced by id, so each message is
    self-contained (seeking in a recording shows the right scene).

    Args:
        t_s: sim time.
        robot_ids: (n,) ids; xy_m (n, 2), heading_rad (n,), radius_m (n,), goal_m (n, 2),
            colours (n, 3) RGB.
        obstacles: (m, 3) x, y, radius at `t_s`.
        trails: per robot a (k, 2) polyline, oldest first (entities ``trail/<id>``), or None
            for none in this message (Foxglove keeps the last ones: an entity stays until
            replaced, and trails are the costliest part of a scene to build).
    """
    stamp = _stamp(to_ns(t_s))
    xy = np.asarray(xy_m, dtype=float).reshape(-1, 2).tolist()
    heading = np.asarray(heading_rad, dtype=float).reshape(-1).tolist()
    radius = np.asarray(radius_m, dtype=float).reshape(-1).tolist()
    goal = np.asarray(goal_m, dtype=float).reshape(-1, 2).tolist()
    entities = []
    for k, rid in enumerate(robot_ids):
        (x, y), th, r, (gx, gy) = xy[k], heading[k], radius[k], goal[k]
        solid, faint = _colour(colours[k], 0.9), _colour(colours[k], 0.35)
        arrow_len = max(2.0 * r, 0.3)
        if trails is not None and len(trails[k]) >= 2:
            entities.append(SceneEntity(
                timestamp=stamp, frame_id=WORLD_FRAME, id=f"trail/{rid}",
                lines=[LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_pose(0, 0, 0),
                                     thickness=0.04, points=_points(trails[k], TRAIL_Z_M),
                                     color=faint)]))
        texts = [TextPrimitive(pose=_pose(x, y, DISC_HEIGHT_M + 0.2), billboard=True,
                               font_size=14.0, scale_invariant=True, color=_TEXT_COLOUR,
                               text=str(rid))] if labels else None
        entities.append(SceneEntity(
            timestamp=stamp, frame_id=WORLD_FRAME, id=f"robot/{rid}",
            cylinders=[_disc(x, y, DISC_HEIGHT_M / 2.0, r, DISC_HEIGHT_M, solid),
                       _goal_disc(gx, gy, r, faint)],
            arrows=[ArrowPrimitive(pose=_pose(x, y, DISC_HEIGHT_M + 0.01, _yaw(th)),
                                   shaft_length=0.7 * arrow_len, shaft_diameter=0.05,
                                   head_length=0.3 * arrow_len, head_diameter=0.12,
                                   color=solid)],
            texts=texts,
        ))
    entities.append(SceneEntity(
        timestamp=stamp, frame_id=WORLD_FRAME, id="obstacles",
        cylinders=[_disc(ox, oy, OBSTACLE_HEIGHT_M / 2.0, orad, OBSTACLE_HEIGHT_M,
                         _OBSTACLE_COLOUR)
                   for ox, oy, orad in np.asarray(obstacles, dtype=float).reshape(-1, 3).tolist()],
    ))
    return SceneUpdate(entities=entities)


def plan_scene_update(t_s: float, robot_id: int, debug: PlanDebug,
                      threat_xy: Sequence[tuple[float, float]], colour: Sequence[float],
                      label: str) -> SceneUpdate:
    """A robot's planner internals as one entity ``robot/<id>/plan``: reference path (robot
    colour), MPC prediction (dark), via-points (yellow spheres), a red line from the robot
    to each threat in `threat_xy`, and a label."""
    stamp = _stamp(to_ns(t_s))
    x, y = float(debug.ego[0]), float(debug.ego[1])
    lines = []
    if len(debug.reference_m) >= 2:
        lines.append(LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_pose(0, 0, 0),
                                   thickness=0.03, points=_points(debug.reference_m, PLAN_Z_M),
                                   color=_colour(colour, 0.9)))
    if len(debug.predicted_m) >= 2:
        lines.append(LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_pose(0, 0, 0),
                                   thickness=0.05, points=_points(debug.predicted_m, PLAN_Z_M),
                                   color=_MPC_COLOUR))
    if threat_xy:
        seg = []
        for tx, ty in threat_xy:
            seg += [Point3(x=x, y=y, z=PLAN_Z_M), Point3(x=float(tx), y=float(ty), z=PLAN_Z_M)]
        lines.append(LinePrimitive(type=LinePrimitiveLineType.LineList, pose=_pose(0, 0, 0),
                                   thickness=0.03, points=seg, color=_THREAT_COLOUR))
    spheres = [SpherePrimitive(pose=_pose(vx, vy, PLAN_Z_M), size=Vector3(x=0.15, y=0.15, z=0.15),
                               color=_VIA_COLOUR)
               for vx, vy in debug.via_points_m.tolist()]
    return SceneUpdate(entities=[SceneEntity(
        timestamp=stamp, frame_id=WORLD_FRAME, id=f"robot/{int(robot_id)}/plan",
        lines=lines or None, spheres=spheres or None,
        texts=[TextPrimitive(pose=_pose(x, y, PLAN_Z_M + 0.45), billboard=True, font_size=12.0,
                             scale_invariant=True, color=_TEXT_COLOUR, text=label)],
    )])


def _xy_json(points: np.ndarray) -> str:
    """(k, 2) finite points as a JSON list of [x, y], to 0.1 mm (one %-format of a template
    cached per k: 40 points in 16 µs against 30 µs point by point and 38 µs with
    `json.dumps`, measured under load)."""
    flat = np.asarray(points, dtype=float).reshape(-1).tolist()
    return _xy_template(len(flat) // 2) % tuple(flat)


@functools.lru_cache(maxsize=256)
def _xy_template(k: int) -> str:
    return "[" + ",".join(["[%.4f,%.4f]"] * k) + "]"


def plan_json(t_s: float, robot_id: int, debug: PlanDebug, v_mps: float, omega_radps: float,
              status: str) -> bytes:
    """The raw numbers of one plan as JSON (schema `PLAN_SCHEMA`): lengths to 0.1 mm,
    angles, speeds and times to 1e-6."""
    x, y, th = debug.ego.tolist()
    return (
        f'{{"t":{float(t_s):.6f},"robot":{int(robot_id)},'
        f'"ego":[{x:.4f},{y:.4f},{th:.6f}],"threats":{json.dumps(list(debug.threat_ids))},'
        f'"via_points":{_xy_json(debug.via_points_m)},'
        f'"reference_path":{_xy_json(debug.reference_m)},'
        f'"mpc_prediction":{_xy_json(debug.predicted_m)},'
        f'"v":{float(v_mps):.6f},"omega":{float(omega_radps):.6f},'
        f'"status":{json.dumps(str(status))}}}'
    ).encode()


# ---------------------------------------------------------------------------------------------
# Channels


def _json_channel(topic: str, schema: dict[str, Any], ctx: Context) -> Channel:
    return Channel(topic, schema=Schema(name=schema["title"], encoding="jsonschema",
                                        data=json.dumps(schema).encode()),
                   message_encoding="json", context=ctx)


_Chan = TypeVar("_Chan", Channel, SceneUpdateChannel)


def _with_sinks(channels: Sequence[_Chan]) -> list[_Chan]:
    return [c for c in channels if c.has_sinks()]


class RunViz:
    """Builds the messages of one run and logs them to the channels of one or more contexts.

    Fed by the world's recorder (`tick` every world tick, `command` per applied command,
    `plan` per plan) or by the live bridge from the wire. It keeps the trails and the newest
    position of every disc (threat lines are drawn to where the threat is now).

    Args:
        scenario: the run's scenario (goals, radii, obstacles and their motion).
        contexts: one or more foxglove Contexts (a recorder's, a live server's).
        scene_every: a scene every this many ticks.
        labels: draw id and status labels.
    """

    def __init__(self, scenario: Scenario, *contexts: Context,
                 scene_every: int = SCENE_EVERY_TICKS, labels: bool = True) -> None:
        if not contexts:
            raise ValueError("RunViz needs at least one Context")
        self._contexts = contexts
        self.scene_every = max(1, int(scene_every))
        self._labels = labels
        robots = scenario.robots
        self._index = {spec.id: k for k, spec in enumerate(robots)}
        self._goal = np.array([spec.goal for spec in robots], dtype=float).reshape(-1, 2)
        self._radius = np.array([spec.radius_m for spec in robots], dtype=float)
        self._colours = robot_rgb(len(robots))
        obstacles = scenario.obstacles
        self._obstacle_ids = [o.id for o in obstacles]
        self._obstacle_c0 = np.array([o.center for o in obstacles], dtype=float).reshape(-1, 2)
        self._obstacle_v = np.array([o.velocity for o in obstacles], dtype=float).reshape(-1, 2)
        self._obstacle_r = np.array([o.radius_m for o in obstacles], dtype=float)
        self._trails: list[deque[tuple[float, float]]] = [
            deque(maxlen=TRAIL_POINTS) for _ in robots]
        self._next_trail_s = -math.inf
        self._ticks = 0
        self._last_t_s = 0.0
        self._xy_ids: list[int] = []
        self._xy_now = np.zeros((0, 2))
        self._xy: dict[int, tuple[float, float]] | None = None
        self._scene = [SceneUpdateChannel(SCENE_TOPIC, context=c) for c in contexts]
        self._robot: dict[int, tuple[list[SceneUpdateChannel], list[Channel],
                                     list[Channel]]] = {}
        self.counts = {"scenes": 0, "commands": 0, "plans": 0}

    def _channels(self, rid: int
                  ) -> tuple[list[SceneUpdateChannel], list[Channel], list[Channel]]:
        """(plan scene, plan raw, command) channels of one robot, made on first use."""
        chans = self._robot.get(rid)
        if chans is None:
            chans = ([SceneUpdateChannel(plan_topic(rid), context=c) for c in self._contexts],
                     [_json_channel(plan_raw_topic(rid), PLAN_SCHEMA, c) for c in self._contexts],
                     [_json_channel(command_topic(rid), COMMAND_SCHEMA, c)
                      for c in self._contexts])
            self._robot[rid] = chans
        return chans

    def obstacles_at(self, t_s: float) -> np.ndarray:
        """(m, 3) x, y, radius of every obstacle at `t_s` (they move at constant velocity)."""
        xy = self._obstacle_c0 + self._obstacle_v * float(t_s)
        return np.column_stack((xy, self._obstacle_r))

    def tick(self, t_s: float, robot_ids: np.ndarray, pose: np.ndarray,
             tick: int | None = None) -> bool:
        """One world tick: ground-truth poses (n, 3) of the robots `robot_ids`.

        Logs a scene on every `scene_every`-th tick (`tick`, else the count of calls).
        Returns whether it did.
        """
        ids = np.asarray(robot_ids).reshape(-1).tolist()
        xy = np.asarray(pose, dtype=float)[:, :2]
        self._last_t_s = float(t_s)
        self._xy_ids, self._xy_now = ids, xy
        self._xy = None
        n = self._ticks if tick is None else int(tick)
        self._ticks += 1
        if n % self.scene_every:
            return False
        live = _with_sinks(self._scene)
        if not live:
            return False
        rows = [self._index.get(rid, -1) for rid in ids]
        known = [i for i, k in enumerate(rows) if k >= 0]
        rows = [rows[i] for i in known]
        trails = None
        if t_s >= self._next_trail_s - 1e-9:  # trails at their own, lower rate
            self._next_trail_s = float(t_s) + TRAIL_EVERY_S
            for i, k in zip(known, rows):
                self._trails[k].append(tuple(xy[i].tolist()))
            trails = [np.asarray(self._trails[k]) for k in rows]
        msg = scene_update(
            t_s, [ids[i] for i in known], xy[known], np.asarray(pose, dtype=float)[known, 2],
            self._radius[rows], self._goal[rows], self._colours[rows], self.obstacles_at(t_s),
            trails, labels=self._labels)
        log_time = to_ns(t_s)
        for c in live:
            c.log(msg, log_time=log_time)
        self.counts["scenes"] += 1
        return True

    def command(self, t_s: float, robot_id: int, seq: int, v_mps: float, omega_radps: float,
                status: str, side: int = 0, resolved: int | None = None) -> None:
        """One command the world applied (no planning time: the file stays deterministic)."""
        live = _with_sinks(self._channels(int(robot_id))[2])
        if not live:
            return
        payload = json.dumps({
            "t": round(float(t_s), 6), "robot": int(robot_id), "seq": int(seq),
            "v": round(float(v_mps), 6), "omega": round(float(omega_radps), 6),
            "status": str(status), "side": int(side),
            "resolved": None if resolved is None else int(resolved)}).encode()
        log_time = to_ns(t_s)
        for c in live:
            c.log(payload, log_time=log_time)
        self.counts["commands"] += 1

    def plan(self, t_s: float, robot_id: int, debug: PlanDebug, v_mps: float = 0.0,
             omega_radps: float = 0.0, status: str = "ok") -> None:
        """One plan's internals (logged at the plan's sim time)."""
        rid = int(robot_id)
        scene, raw, _ = self._channels(rid)
        log_time = to_ns(t_s)
        live = _with_sinks(scene)
        if live:
            k = self._index.get(rid)
            colour = self._colours[k] if k is not None else (0.2, 0.4, 0.8)
            threat_xy = [p for p in (self._threat_xy(tid) for tid in debug.threat_ids)
                         if p is not None]
            msg = plan_scene_update(t_s, rid, debug, threat_xy, colour,
                                    f"{status} v={v_mps:.2f} w={omega_radps:.2f}")
            for c in live:
                c.log(msg, log_time=log_time)
        live_raw = _with_sinks(raw)
        if live_raw:
            payload = plan_json(t_s, rid, debug, v_mps, omega_radps, status)
            for c_raw in live_raw:
                c_raw.log(payload, log_time=log_time)
        self.counts["plans"] += 1

    def _threat_xy(self, other_id: int) -> tuple[float, float] | None:
        if other_id >= 0:
            if self._xy is None:  # built once per tick, when a plan needs it
                self._xy = {i: (x, y) for i, (x, y) in zip(self._xy_ids, self._xy_now.tolist())}
            return self._xy.get(other_id)
        try:
            j = self._obstacle_ids.index(other_id)
        except ValueError:
            return None
        x, y = self._obstacle_c0[j] + self._obstacle_v[j] * self._last_t_s
        return float(x), float(y)


# ---------------------------------------------------------------------------------------------
# Sinks


class LiveView:
    """A Foxglove WebSocket server on its own Context (subprotocol ``foxglove.sdk.v1``).

    Passive: publishing never waits for a client (each client has a bounded queue of
    `LIVE_BACKLOG` messages; the oldest is dropped when it fills), and a message is built
    only for topics some client subscribed to. The app's clock follows sim time
    (``broadcast_time``).

    Args:
        host: address to bind (127.0.0.1 by default: serving other hosts is an opt-in).
        port: TCP port; 0 picks a free one (read it back from `port`).
        robot_ids: the run's robots: their channels (and the scene's) are made before the
            server accepts a client. The SDK gives a `RunViz` made later the same channels
            (same topic and schema on one context), and a client that connects at the very
            instant a channel is made can be refused its subscription ("unknown channel",
            seen once in a test), so making them first closes that window.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, *,
                 name: str = "eifp-swarm", robot_ids: Sequence[int] = ()) -> None:
        from foxglove.websocket import Capability

        self.host = host
        self.context = Context()
        ctx = self.context
        self._channels: list[SceneUpdateChannel | Channel] = [
            SceneUpdateChannel(SCENE_TOPIC, context=ctx)]
        for rid in robot_ids:
            self._channels += [SceneUpdateChannel(plan_topic(rid), context=ctx),
                               _json_channel(plan_raw_topic(rid), PLAN_SCHEMA, ctx),
                               _json_channel(command_topic(rid), COMMAND_SCHEMA, ctx)]
        self.server = foxglove.start_server(
            name=name, host=host, port=port, context=self.context,
            capabilities=[Capability.Time], message_backlog_size=LIVE_BACKLOG)

    @property
    def port(self) -> int:
        return int(self.server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def app_url(self) -> str | None:
        """A Foxglove app link that opens this server, or None once stopped."""
        return self.server.app_url()

    def time(self, t_s: float) -> None:
        """Move the app's clock to sim time `t_s`."""
        self.server.broadcast_time(to_ns(t_s))

    def stop(self) -> None:
        self.server.stop()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class McapLog:
    """Writes ``run.mcap`` for one run, optionally teeing every message to a `LiveView`.

    Args:
        path: the file; created new (an existing file or symlink there is an error).
        scenario: the run's scenario.
        live: a live server to publish the same channels to, or None.
        metadata: written as the MCAP metadata record ``run``.
        attachments: name -> bytes stored in the file (e.g. ``scenario.yaml``).
    """

    def __init__(self, path: Path, scenario: Scenario, *, live: LiveView | None = None,
                 metadata: dict[str, str] | None = None,
                 attachments: dict[str, bytes] | None = None) -> None:
        self.path = Path(path)
        self.context = Context()
        # compression_threads=0: zstd on the logging thread, no pool racing the planners
        # on a small machine, and output that does not depend on timing.
        options = MCAPWriteOptions(compression=MCAPCompression.Zstd, profile="",
                                   compression_threads=0)
        self._writer = foxglove.open_mcap(self.path, allow_overwrite=False,
                                          context=self.context, writer_options=options)
        self._writer.write_metadata("run", {"scenario": scenario.name,
                                            "robots": str(len(scenario.robots)),
                                            **(metadata or {})})
        for name, data in (attachments or {}).items():
            self._writer.attach(log_time=0, create_time=0, name=name, media_type="text/plain",
                                data=data)
        self.live = live
        contexts = (self.context,) if live is None else (self.context, live.context)
        self.viz = RunViz(scenario, *contexts)
        self._closed = False

    def tick(self, t_s: float, robot_ids: np.ndarray, pose: np.ndarray) -> None:
        if self.viz.tick(t_s, robot_ids, pose) and self.live is not None:
            self.live.time(t_s)

    def command(self, t_s: float, robot_id: int, seq: int, v_mps: float, omega_radps: float,
                status: str, side: int = 0, resolved: int | None = None) -> None:
        self.viz.command(t_s, robot_id, seq, v_mps, omega_radps, status, side, resolved)

    def plan(self, t_s: float, robot_id: int, debug: PlanDebug, v_mps: float,
             omega_radps: float, status: str) -> None:
        self.viz.plan(t_s, robot_id, debug, v_mps, omega_radps, status)

    def close(self) -> None:
        """Finish the file (summary and index); idempotent."""
        if not self._closed:
            self._closed = True
            self._writer.close()
