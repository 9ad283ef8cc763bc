"""The robot process: senses poses, plans with `RobotController`, publishes commands.

One OS process per robot, a Zenoh client of the run's router (multicast scouting off,
explicit endpoint). It knows nothing but what arrives on the wire (see `protocol`):

1. Connect (retrying until ``--startup-timeout-s``), fetch this robot's `RunConfigMsg` from
   the world's queryable (retrying with the same deadline), build the controller.
2. Declare the pose subscriber (a `RingChannel` of 2: the robot always acts on the newest
   pose, never a backlog), the control subscriber, the world-liveliness subscriber, the
   command publisher (DROP, express) and, last, its own liveliness token.
3. Loop: drain control and liveliness, drain the pose ring (the newest valid snapshot goes
   to `RobotController.observe`, which drops stale or out-of-order ones), and plan at the
   control rate in SIM time: when the newest pose's stamp reaches the next scheduled plan
   time, plan and publish one `CommandMsg`; the schedule advances by one period (slots
   already passed are skipped and counted as overruns, never planned as a backlog).

Faults: a malformed pose or control message raises `ProtocolError`; it is counted, logged
to stderr (the first few, then every 100th) and the robot keeps running. The robot stops
commanding and exits with `EXIT_WORLD_LOST` if the world's liveliness token disappears
before the end message, or no pose arrives for ``--pose-timeout-s`` while running. It
exits 0 on the ``end`` `ControlMsg` and on SIGTERM/SIGINT. On exit it logs one line
``robot <id> exit: reason='...' code=N rejected=N stale=N skipped=N plans=N overruns=N
plan_errors=N seq=N`` to stderr (``rejected``: malformed messages; ``stale``: poses the
controller dropped as old or out of order; ``skipped``: valid poses not observed because a
newer one was waiting; ``overruns``: plan slots skipped).

Exit status: 0 (end of run, or a signal), 2 (setup: cannot connect or get the
configuration before the startup deadline), 3 (the world is gone).

Planning slots are staggered over the world's ticks (`plan_phase_s`: robot k plans on the
ticks k mod 5 of each 0.1 s period), so only a fifth of the robots plan on any one pose.
Between slots the loop sleeps until just before the slot's pose is due; the poses of the
ticks in between wait in the ring and are observed on waking. An idle robot costs little
CPU and 128 robot processes share 2 cores (see README, "Scale").
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass
from types import FrameType
from typing import TYPE_CHECKING

import numpy as np
import zenoh

from protocol import (
    CommandMsg,
    ControlMsg,
    PosesMsg,
    ProtocolError,
    RunConfigMsg,
    RunKeys,
    session_settings,
    validate_run_id,
)

if TYPE_CHECKING:
    from agent.controller import RobotController

EXIT_OK = 0
EXIT_SETUP = 2
EXIT_WORLD_LOST = 3

POSE_RING = 2
"""Capacity of the pose channel: older poses are overwritten, never queued."""
CONNECT_ATTEMPT_MS = 1000
QUERY_TIMEOUT_S = 1.0
STAMP_EPS_S = 1e-6
"""Tolerance on sim-time comparisons (stamps are sums of float ticks)."""
CLOSE_TIMEOUT_S = 2.0
"""Wall time allowed for closing the session before the process leaves without it."""
IDLE_SLEEP_S = 0.01
MIN_SLEEP_S = 0.0005
WAKE_MARGIN_S = 0.001
"""Wall time before the next plan slot's pose is due at which the robot wakes to wait for it."""
MAX_NAP_S = 0.1
"""Longest single sleep: control and liveliness messages are read at least this often."""

log = logging.getLogger("agent")


@dataclass(frozen=True)
class AgentOptions:
    """Command-line options of a robot process.

    Args:
        run_id: run id.
        robot_id: this robot's id (>= 0).
        connect: router endpoint, e.g. ``tcp/127.0.0.1:7447``.
        control_rate_hz: planning rate in sim time; None: the rate the world serves.
        startup_timeout_s: wall deadline to connect and fetch the configuration.
        pose_timeout_s: wall time without poses, once running, after which the world
            is considered gone.
    """

    run_id: str
    robot_id: int
    connect: str
    control_rate_hz: float | None = None
    startup_timeout_s: float = 30.0
    pose_timeout_s: float = 5.0


def _positive(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _run_id(text: str) -> str:
    try:
        return validate_run_id(text)
    except ProtocolError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def _robot_id(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"robot id must be >= 0, got {value}")
    return value


def parse_args(argv: list[str] | None = None) -> AgentOptions:
    """Parse ``python -m agent`` arguments."""
    parser = argparse.ArgumentParser(prog="python -m agent", description=__doc__.split("\n")[0])
    parser.add_argument("--run", required=True, type=_run_id, help="run id")
    parser.add_argument("--id", required=True, type=_robot_id, help="robot id")
    parser.add_argument("--connect", required=True, help="router endpoint (tcp/HOST:PORT)")
    parser.add_argument("--control-rate-hz", type=_positive, default=None,
                        help="planning rate [1/sim s] (default: as served by the world, 10)")
    parser.add_argument("--startup-timeout-s", type=_positive, default=30.0,
                        help="wall deadline to connect and get the configuration")
    parser.add_argument("--pose-timeout-s", type=_positive, default=5.0,
                        help="wall time without poses after which the world is gone")
    args = parser.parse_args(argv)
    return AgentOptions(run_id=args.run, robot_id=args.id, connect=args.connect,
                        control_rate_hz=args.control_rate_hz,
                        startup_timeout_s=args.startup_timeout_s,
                        pose_timeout_s=args.pose_timeout_s)


class _StopFlag:
    """Set by SIGTERM/SIGINT; the loops poll it and leave (so the session is closed)."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        self.signum = signum

    def __bool__(self) -> bool:
        return self.signum is not None


class _Exit(Exception):
    """Leave the robot's loop with this reason and exit status."""

    def __init__(self, reason: str, code: int) -> None:
        super().__init__(reason)
        self.reason = reason
        self.code = code


def open_session(options: AgentOptions, stop: _StopFlag, deadline: float) -> zenoh.Session:
    """Connect as a client, retrying until `deadline` (monotonic); raises `_Exit`."""
    conf = zenoh.Config()
    for key, value in session_settings(mode="client", connect=[options.connect],
                                       connect_timeout_ms=CONNECT_ATTEMPT_MS).items():
        conf.insert_json5(key, value)
    last_error = "no attempt"
    while not stop:
        try:
            return zenoh.open(conf)
        except zenoh.ZError as exc:
            last_error = str(exc)
        if time.monotonic() > deadline:
            raise _Exit(f"cannot connect to {options.connect}: {last_error}", EXIT_SETUP)
        time.sleep(0.1)
    raise _Exit("signal", EXIT_OK)


def fetch_config(session: zenoh.Session, keys: RunKeys, robot_id: int, stop: _StopFlag,
                 deadline: float) -> RunConfigMsg:
    """Query the world for this robot's configuration until `deadline`; raises `_Exit`."""
    problem = "no reply"
    while not stop:
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            raise _Exit(f"no configuration for robot {robot_id}: {problem}", EXIT_SETUP)
        replies = session.get(keys.config(robot_id), timeout=min(QUERY_TIMEOUT_S, remaining))
        for reply in replies:
            if reply.ok is None:
                problem = f"world replied an error: {reply.err.payload.to_string()}"
                continue
            try:
                return RunConfigMsg.decode(reply.ok.payload.to_bytes(),
                                           expected_run_id=keys.run_id,
                                           expected_robot_id=robot_id)
            except ProtocolError as exc:
                problem = f"malformed configuration: {exc}"
                log.warning("robot %d: %s", robot_id, problem)
        time.sleep(0.1)
    raise _Exit("signal", EXIT_OK)


class PlanSchedule:
    """When to plan, in sim time: every `period_s`, from the first pose's stamp or on a phase.

    A plan is due when the newest pose's stamp reaches the next scheduled time. After a
    plan the schedule advances by one period; slots that have already passed (the robot was
    slow, or poses were lost) are skipped and counted, never planned as a backlog.

    Args:
        period_s: planning period in sim time (> 0).
        phase_s: None: the first slot is the first stamp seen. Else the slots are
            ``phase_s + k * period_s`` (k integer): the first one at or after the first
            stamp seen. Robots on different phases spread their planning over the world's
            ticks instead of all planning on the same pose.
    """

    def __init__(self, period_s: float, phase_s: float | None = None) -> None:
        if not period_s > 0.0:
            raise ValueError("period_s must be positive")
        if phase_s is not None and not math.isfinite(phase_s):
            raise ValueError("phase_s must be finite")
        self.period_s = float(period_s)
        self.phase_s = None if phase_s is None else float(phase_s)
        self.next_s: float | None = None
        self.skipped = 0

    def _first(self, stamp_s: float) -> float:
        if self.phase_s is None:
            return stamp_s
        k = math.ceil((stamp_s - self.phase_s) / self.period_s - STAMP_EPS_S)
        return self.phase_s + k * self.period_s

    def due(self, stamp_s: float) -> bool:
        """True if a pose stamped `stamp_s` should be planned on now."""
        if self.next_s is None:
            self.next_s = self._first(stamp_s)
        return stamp_s + STAMP_EPS_S >= self.next_s

    def planned(self, stamp_s: float) -> int:
        """Record a plan made on the pose stamped `stamp_s`; returns the slots skipped."""
        if self.next_s is None:
            self.next_s = self._first(stamp_s)
        self.next_s += self.period_s
        missed = 0
        if self.next_s + STAMP_EPS_S <= stamp_s:
            missed = math.floor((stamp_s - self.next_s) / self.period_s + STAMP_EPS_S) + 1
            self.next_s += missed * self.period_s
        self.skipped += missed
        return missed


def plan_phase_s(robot_id: int, period_s: float, tick_s: float) -> float:
    """This robot's planning phase: robots spread evenly over the world ticks of a period.

    With a 0.1 s period and 0.02 s ticks, robot k plans on the ticks ``k mod 5`` of every
    period, so at any tick only a fifth of the robots plan (and compete for the CPU).
    """
    slots = max(1, round(period_s / tick_s))
    return (robot_id % slots) * period_s / slots


def make_controller(config: RunConfigMsg, period_s: float) -> RobotController:
    """The robot's `RobotController`, its planner set up for this control period."""
    from agent.controller import RobotController

    return RobotController(config.robot, config.planner, config.goal_tolerance_m,
                           control_period_s=period_s)


def warm_up(config: RunConfigMsg, period_s: float) -> None:
    """Plan once with a throwaway controller so lazy imports and caches are ready in time.

    The first plan of a process costs ~0.3 s (imports, solver set-up); doing it before the
    liveliness token is declared keeps it out of the run. The scene is this robot at its
    start with a phantom disc ahead, so the threat and via-point paths are exercised too.
    """
    from agent.types import PoseSnapshot

    spec = config.robot
    x, y, heading = spec.start
    ahead_m = 4.0 * spec.radius_m + 1.0
    phantom = (x + ahead_m * math.cos(heading), y + ahead_m * math.sin(heading), heading + math.pi)
    try:
        controller = make_controller(config, period_s)
        for k in range(2):
            controller.observe(PoseSnapshot(
                stamp_s=0.1 * k, tick=k, ids=np.array([spec.id, spec.id + 1]),
                pose=np.array([spec.start, phantom]),
                radius_m=np.array([spec.radius_m, spec.radius_m])))
            controller.plan(0.1 * k)
    except Exception:  # warming up is an optimisation: report, never fail on it
        log.exception("robot %d: warm-up plan failed", spec.id)


class RobotNode:
    """One robot's Zenoh edge: declarations, the sense-plan-act loop and its counters.

    Args:
        session: an open client session (closed by the caller).
        options: command-line options.
        config: this robot's configuration from the world.
        stop: polled; set by the signal handlers.
    """

    def __init__(self, session: zenoh.Session, options: AgentOptions, config: RunConfigMsg,
                 stop: _StopFlag) -> None:
        self.keys = RunKeys(options.run_id)
        self.options = options
        self.config = config
        self.robot_id = config.robot.id
        self.stop = stop
        period_s = 1.0 / (options.control_rate_hz or config.control_rate_hz)
        self.controller = make_controller(config, period_s)
        warm_up(config, period_s)
        self.schedule = PlanSchedule(period_s, plan_phase_s(
            config.robot.id, period_s, 1.0 / config.world_rate_hz))
        self.tick_wall_s = 1.0 / (config.world_rate_hz * config.time_scale)
        self.known_ids = frozenset(config.known_ids)
        self.counts = {"rejected": 0, "stale": 0, "skipped": 0, "plans": 0, "overruns": 0,
                       "plan_errors": 0}
        self.seq = 0
        self.last_rx_wall: float | None = None
        self.newest: PosesMsg | None = None
        self.world_alive = False

        self.pose_sub = session.declare_subscriber(self.keys.poses,
                                                   zenoh.handlers.RingChannel(POSE_RING))
        self.control_sub = session.declare_subscriber(self.keys.control)
        self.world_sub = session.liveliness().declare_subscriber(self.keys.alive_world,
                                                                 history=True)
        self.cmd_pub = session.declare_publisher(
            self.keys.cmd(self.robot_id), congestion_control=zenoh.CongestionControl.DROP,
            express=True)
        # Declared last: once the world sees it, every subscription above is in place.
        self.token = session.liveliness().declare_token(self.keys.alive_robot(self.robot_id))

    def _reject(self, what: str, exc: ProtocolError) -> None:
        self.counts["rejected"] += 1
        n = self.counts["rejected"]
        if n <= 10 or n % 100 == 0:
            log.warning("robot %d: rejected %s #%d: %s", self.robot_id, what, n, exc)

    def poll_control(self) -> None:
        """Start/end announcements; raises `_Exit` on the end."""
        while (sample := self.control_sub.try_recv()) is not None:
            try:
                msg = ControlMsg.decode(sample.payload.to_bytes())
            except ProtocolError as exc:
                self._reject("control message", exc)
                continue
            if msg.kind == "end":  # "start" needs no action: planning begins with the poses
                raise _Exit(f"end ({msg.reason})", EXIT_OK)

    def poll_world(self) -> None:
        """World liveliness; raises `_Exit` if the world is gone before the end."""
        while (sample := self.world_sub.try_recv()) is not None:
            if sample.kind == zenoh.SampleKind.PUT:
                self.world_alive = True
            elif self.world_alive:
                self.world_alive = False
                self.poll_control()  # the end message may have been queued just before
                raise _Exit("world lost (liveliness token gone)", EXIT_WORLD_LOST)

    def poll_poses(self) -> bool:
        """Observe the newest valid pose waiting in the ring; True if it was new.

        Every sample is decoded (a malformed one is rejected and counted wherever it sits
        in the ring), newest first; only the newest valid one is observed: the older ones
        are older than it, so the controller would drop them as out of order anyway (they
        are counted as ``skipped``).
        """
        samples = []
        while (sample := self.pose_sub.try_recv()) is not None:
            samples.append(sample)
        newest: PosesMsg | None = None
        for sample in reversed(samples):
            try:
                msg = PosesMsg.decode(sample.payload.to_bytes(), known_ids=self.known_ids)
            except ProtocolError as exc:
                self._reject("pose message", exc)
                continue
            if newest is None:
                newest = msg
            else:
                self.counts["skipped"] += 1
        if newest is None:
            return False
        if not self.controller.observe(newest.to_snapshot()):
            self.counts["stale"] += 1
            return False
        self.newest = newest
        self.last_rx_wall = time.monotonic()
        return True

    def plan_and_send(self) -> None:
        """Plan on the newest pose if its stamp reached the schedule; publish the command."""
        msg = self.newest
        if msg is None or not self.schedule.due(msg.t_s):
            return
        # Sim time now: the stamp plus the wall time since the pose arrived, scaled.
        now_s = msg.t_s + (time.monotonic() - self.last_rx_wall) * self.config.time_scale
        try:
            result = self.controller.plan(now_s)
        except Exception:  # a planner bug must not leave the robot driving blind
            self.counts["plan_errors"] += 1
            if self.counts["plan_errors"] <= 3:
                log.exception("robot %d: planner raised; braking", self.robot_id)
            result = self.controller.brake()
        self.cmd_pub.put(CommandMsg(
            robot_id=self.robot_id, seq=self.seq, pose_stamp_s=msg.t_s, v_mps=result.v_mps,
            omega_radps=result.omega_radps, plan_ms=max(0.0, result.times.total_ms),
            status=result.status, side=int(result.side), resolved_id=result.resolved_id,
        ).encode())
        self.seq += 1
        self.counts["plans"] += 1
        self.counts["overruns"] += self.schedule.planned(msg.t_s)

    def _sleep(self) -> None:
        """Sleep until just before the pose of the next plan slot is due, then poll for it.

        The world publishes a pose every tick, but a robot needs one per plan slot: it
        sleeps through the ticks in between (their poses wait in the ring) and wakes
        `WAKE_MARGIN_S` before the slot's pose, predicted from the newest pose's stamp and
        arrival time at the world's pace.
        """
        now = time.monotonic()
        msg = self.newest
        if self.last_rx_wall is None or msg is None:
            time.sleep(IDLE_SLEEP_S)
            return
        ahead_s = max(0.0, (self.schedule.next_s or msg.t_s) - msg.t_s)
        expected = self.last_rx_wall + max(ahead_s / self.config.time_scale, self.tick_wall_s)
        due = expected - WAKE_MARGIN_S
        if now < due:
            time.sleep(min(due - now, MAX_NAP_S))
        elif now - expected > 3.0 * self.tick_wall_s:
            time.sleep(min(IDLE_SLEEP_S, self.tick_wall_s))  # poses late: back off
        else:
            time.sleep(MIN_SLEEP_S)

    def run(self, startup_deadline: float) -> tuple[str, int]:
        """The robot's loop; returns (reason, exit status).

        Args:
            startup_deadline: monotonic time by which the world's token must have been seen
                (after that, the world owns the start: it ends the run if robots are missing).
        """
        try:
            while not self.stop:
                self.poll_control()
                self.poll_world()
                if not self.world_alive and time.monotonic() > startup_deadline:
                    raise _Exit("world not seen before the startup deadline", EXIT_WORLD_LOST)
                if self.poll_poses():
                    self.plan_and_send()
                elif (self.last_rx_wall is not None
                      and time.monotonic() - self.last_rx_wall > self.options.pose_timeout_s):
                    raise _Exit(f"no poses for {self.options.pose_timeout_s:.1f} s",
                                EXIT_WORLD_LOST)
                self._sleep()
            return "signal", EXIT_OK
        except _Exit as stop:
            return stop.reason, stop.code
        finally:
            # Stop commanding before anything else.
            self.cmd_pub.undeclare()

    def summary(self) -> str:
        """Counters as key=value pairs."""
        return " ".join(f"{k}={v}" for k, v in {**self.counts, "seq": self.seq}.items())


def close_session(session: zenoh.Session, timeout_s: float = CLOSE_TIMEOUT_S) -> bool:
    """Close `session`, waiting at most `timeout_s`; False if the close is still stuck.

    Closing waits for the peer to acknowledge (up to 10 s inside zenoh): with a hung
    (SIGSTOPped) router that would keep a robot that has already stopped commanding alive.
    """
    done = threading.Event()

    def _close() -> None:
        try:
            session.close()
        except zenoh.ZError as exc:
            log.warning("closing the session: %s", exc)
        finally:
            done.set()

    threading.Thread(target=_close, name="zenoh-close", daemon=True).start()
    return done.wait(timeout_s)


def run_agent(options: AgentOptions) -> int:
    """Run one robot process to its end; returns its exit status.

    If the session cannot be closed in time (the router hangs), the process leaves with
    `os._exit` after logging: nothing is left to flush but stderr.
    """
    stop = _StopFlag()
    previous = {s: signal.signal(s, stop) for s in (signal.SIGTERM, signal.SIGINT)}
    keys = RunKeys(options.run_id)
    summary = ""
    session: zenoh.Session | None = None
    try:
        deadline = time.monotonic() + options.startup_timeout_s
        log.info("robot %d: run %s, connecting to %s", options.robot_id, options.run_id,
                 options.connect)
        try:
            session = open_session(options, stop, deadline)
            config = fetch_config(session, keys, options.robot_id, stop, deadline)
            node = RobotNode(session, options, config, stop)
            reason, code = node.run(deadline)
            summary = node.summary()
        except _Exit as exc:
            reason, code = exc.reason, exc.code
        except BaseException:
            if session is not None:
                close_session(session)  # an unexpected error: still release the transport
            raise
        level = logging.INFO if code == EXIT_OK else logging.ERROR
        log.log(level, "robot %d exit: reason=%r code=%d %s", options.robot_id, reason, code,
                summary)
        if session is not None and not close_session(session):
            log.error("robot %d: session close timed out; leaving without it", options.robot_id)
            logging.shutdown()
            os._exit(code)
        return code
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m agent``."""
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s agent %(levelname)s %(message)s")
    return run_agent(parse_args(argv))
