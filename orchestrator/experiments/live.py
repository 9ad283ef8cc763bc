"""The live Foxglove view of a distributed run: a passive Zenoh client feeding a `LiveView`.

`orchestrator run --live` starts a Foxglove WebSocket server (`world.mcap_log.LiveView`) in
the launcher. In lockstep mode the recorder tees into it (`world.recorder.RunRecorder`). In
distributed mode the world and the robots are other processes, so `LiveBridge` joins the
run's router as a Zenoh client and only subscribes: poses (every slot and every cell of the
pose grid, gathered into one scene per tick by `TickGather`), commands and the robots' plan
internals (``debug/*``), each through a small ring (the newest samples win, nothing queues
up). It never publishes on the run's keys and declares no liveliness token,
so the world does not wait for it and no robot sees it.

Passive by construction: the world and the robots publish poses, commands and debug with
congestion control DROP (a slow subscriber loses samples, it never holds a publisher up),
the bridge does its decoding and message building on its own thread in the launcher, and it
builds a Foxglove message only for a topic some client subscribed to. What it costs the
world is measured in docs/visualisation.md.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np
import zenoh

from agent.core.scenario import Scenario
from agent.process import (
    SampleSubscriber,
    SessionError,
    StopFlag,
    close_session,
    open_session,
)
from eifp_wire import (
    CommandMsg,
    PlanDebugMsg,
    PosesMsg,
    ProtocolError,
    RunKeys,
    TlsFiles,
    session_settings,
)
from world.mcap_log import LiveView, RunViz

IDLE_S = 0.005
"""Wall time the bridge sleeps when nothing arrived."""
CONNECT_S = 60.0
"""Wall deadline for the bridge to reach the world's router."""

POSE_RING = 512
"""Pose messages the bridge's ring holds: every cell of a few ticks."""

log = logging.getLogger("live")


class TickGather:
    """The world's pose messages of one tick, one per cell of the pose grid, gathered into
    that tick's robots: a tick is handed out whole once a message of a newer tick arrives
    (a tick later than it happened, 20 ms at 50 Hz)."""

    def __init__(self) -> None:
        self.tick = -1
        self.t_s = 0.0
        self._ids: list[np.ndarray] = []
        self._poses: list[np.ndarray] = []

    def add(self, msg: PosesMsg) -> tuple[float, int, np.ndarray, np.ndarray] | None:
        """One cell's message; returns (t, tick, robot ids (n,), poses (n, 3)) of the tick
        it completes, or None. Messages of older ticks are dropped."""
        out = None
        if msg.tick > self.tick:
            if self._ids:
                ids = np.concatenate(self._ids)
                ids, first = np.unique(ids, return_index=True)  # a cell heard twice
                out = (self.t_s, self.tick, ids, np.concatenate(self._poses)[first])
            self.tick, self.t_s, self._ids, self._poses = msg.tick, msg.t_s, [], []
        elif msg.tick < self.tick:
            return None
        self._ids.append(msg.robot_ids)
        self._poses.append(msg.robot_pose)
        return out


class LiveBridge:
    """Subscribes to one run's poses, commands and plan internals; republishes them live.

    Args:
        run_id: the run's id (its key prefix).
        endpoint: the world's router endpoint, e.g. ``tcp/127.0.0.1:7447``.
        scenario: the run's scenario (goals, radii, obstacles).
        live: the live server to publish to.
        tls: a read-only identity of the run (``observer``, or ``orchestrator`` in compose)
            when the run uses TLS.
    """

    def __init__(self, run_id: str, endpoint: str, scenario: Scenario, live: LiveView,
                 tls: TlsFiles | None = None) -> None:
        self.keys = RunKeys(run_id)
        self.endpoint = endpoint
        self.tls = tls
        self.live = live
        self.viz = RunViz(scenario, live.context)
        self.known_ids = frozenset([r.id for r in scenario.robots]
                                   + [o.id for o in scenario.obstacles])
        self.counts = {"poses": 0, "commands": 0, "plans": 0, "rejected": 0}
        self.error: str | None = None
        self._stop = StopFlag()
        self._thread = threading.Thread(target=self._run, name="live-bridge", daemon=True)
        self._t_s = 0.0
        self._ticks = TickGather()

    def start(self) -> LiveBridge:
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        """Leave the loop and close the session (bounded)."""
        self._stop(0)
        self._thread.join(timeout_s)

    def _run(self) -> None:
        settings = session_settings(mode="client", connect=[self.endpoint],
                                    connect_timeout_ms=1000, tls=self.tls)
        try:
            session = open_session(settings, deadline=time.monotonic() + CONNECT_S,
                                   stop=self._stop)
        except SessionError as exc:
            self.error = f"cannot reach {self.endpoint}: {exc}"
            log.warning("live view: %s", self.error)
            return
        if session is None:
            return
        try:
            poses = session.declare_subscriber(self.keys.poses_all,
                                               zenoh.handlers.RingChannel(POSE_RING))
            cmds = session.declare_subscriber(self.keys.cmd_all, zenoh.handlers.RingChannel(256))
            debug = session.declare_subscriber(self.keys.debug_all,
                                               zenoh.handlers.RingChannel(256))
            while not self._stop:
                busy = self._drain_poses(poses)
                busy |= self._drain_commands(cmds)
                busy |= self._drain_plans(debug)
                if not busy:
                    time.sleep(IDLE_S)
        except Exception as exc:  # the view must never take the launcher down
            self.error = f"{type(exc).__name__}: {exc}"
            log.warning("live view stopped: %s", self.error)
        finally:
            close_session(session)

    def _drain_poses(self, sub: SampleSubscriber) -> bool:
        busy = False
        while (sample := sub.try_recv()) is not None:
            busy = True
            try:
                msg = PosesMsg.decode(sample.payload.to_bytes(), known_ids=self.known_ids)
            except ProtocolError:
                self.counts["rejected"] += 1
                continue
            self.counts["poses"] += 1
            self._t_s = max(self._t_s, msg.t_s)
            whole = self._ticks.add(msg)
            if whole is not None:
                t_s, tick, ids, pose = whole
                if self.viz.tick(t_s, ids, pose, tick=tick):
                    self.live.time(t_s)
        return busy

    def _drain_commands(self, sub: SampleSubscriber) -> bool:
        busy = False
        while (sample := sub.try_recv()) is not None:
            busy = True
            try:
                rid = self.keys.robot_id_of_cmd(str(sample.key_expr))
                msg = CommandMsg.decode(sample.payload.to_bytes(), known_ids=self.known_ids,
                                        expected_robot_id=rid)
            except ProtocolError:
                self.counts["rejected"] += 1
                continue
            self.counts["commands"] += 1
            # The world's apply time is not on the wire: the newest pose time stands for it.
            self.viz.command(self._t_s, rid, msg.seq, msg.v_mps, msg.omega_radps, msg.status,
                             msg.side, msg.resolved_id)
        return busy

    def _drain_plans(self, sub: SampleSubscriber) -> bool:
        busy = False
        while (sample := sub.try_recv()) is not None:
            busy = True
            try:
                rid = self.keys.robot_id_of_debug(str(sample.key_expr))
                msg = PlanDebugMsg.decode(sample.payload.to_bytes(), known_ids=self.known_ids,
                                          expected_robot_id=rid)
            except ProtocolError:
                self.counts["rejected"] += 1
                continue
            self.counts["plans"] += 1
            self.viz.plan(msg.t_s, rid, msg.debug, msg.v_mps, msg.omega_radps, msg.status)
        return busy


def start_live_view(host: str, port: int, scenario: Scenario) -> LiveView:
    """Start the live server for `scenario`'s run and print where to connect (stdout)."""
    live = LiveView(host, port, robot_ids=[r.id for r in scenario.robots])
    print(f"live view: ws://{host}:{live.port} (Foxglove: Open connection -> Foxglove "
          f"WebSocket; layout docs/foxglove-layout.json)", flush=True)
    url = live.app_url()
    if url:
        print(f"live view: {url}", flush=True)
    return live
