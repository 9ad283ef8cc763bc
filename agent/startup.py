"""How a robot process starts: its options, its connection, its configuration, its controller.

`agent.node.run_agent` calls these in order: `parse_args`, `connect` (retrying until the
start-up deadline), `world_zid_of`, `fetch_config` (the world's `RunConfigMsg`, replies from
other sessions refused), then `agent.node.make_cycle` builds the robot's controller with
`make_controller` and warms it up (`warm_up`) before the robot declares its liveliness
token. Each of them raises `RobotExit` with the exit status the process should leave with.
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import zenoh

from agent import flags as argtypes
from agent.process import ExitCode, SessionError, StopFlag, check_tls_files, open_session
from agent.robot_cycle import is_world
from eifp_wire import (
    MAX_ROBOT_ID,
    ProtocolError,
    RunConfigMsg,
    RunKeys,
    TlsFiles,
    robot_cn,
    session_settings,
)
from world.sim.link import LinkFaults

if TYPE_CHECKING:
    from agent.planning.controller import RobotController

CONNECT_ATTEMPT_MS = 1000
QUERY_TIMEOUT_S = 1.0

DESCRIPTION = "The robot process: senses poses, plans with `RobotController`, publishes commands."
"""``python -m agent --help``'s summary."""

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
        link: faults injected on this robot's pose link (sim-time delays).
        fault_seed: seeds the pose link (with the link kind and the robot id).
        control_phase_s: offset of the planning slots [sim s].
        plan_delay_ms: added planning delay [sim ms] before each command is published.
        compensate_latency: forward-predict by the poses' age before planning.
        tls_dir: directory with ``ca.pem``, ``robot-<id>.pem``, ``robot-<id>.key``: mutual
            TLS (the endpoint is then ``tls/...``). None: plain TCP.
        world_zid: the world's Zenoh id; poses, control and configuration replies from any
            other session are refused. None: the router this robot is connected to (the
            world is the run's router); a robot behind a relay router (`world.router`)
            needs it.
        plan: False: command a stop every cycle without planning (``--no-plan``: measures
            the process's own cost per cycle, `orchestrator bench --process`).
    """

    run_id: str
    robot_id: int
    connect: str
    control_rate_hz: float | None = None
    startup_timeout_s: float = 30.0
    pose_timeout_s: float = 5.0
    link: LinkFaults = field(default_factory=LinkFaults)
    fault_seed: int = 0
    control_phase_s: float = 0.0
    plan_delay_ms: float = 0.0
    compensate_latency: bool = True
    plan: bool = True
    tls_dir: Path | None = None
    world_zid: str | None = None


def _robot_id(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_ROBOT_ID:
        raise argparse.ArgumentTypeError(f"robot id must be in 0..{MAX_ROBOT_ID}, got {text!r}")
    return value


def parse_args(argv: list[str] | None = None) -> AgentOptions:
    """Parse ``python -m agent`` arguments."""
    parser = argtypes.Parser(prog="python -m agent", description=DESCRIPTION)
    parser.add_argument("--run", required=True, type=argtypes.run_id, help="run id")
    parser.add_argument("--id", required=True, type=_robot_id, help="robot id")
    parser.add_argument("--connect", required=True, type=argtypes.endpoint,
                        help="router endpoint (tcp/HOST:PORT or tls/HOST:PORT)")
    parser.add_argument("--control-rate-hz", type=argtypes.positive, default=None,
                        help="planning rate [1/sim s] (default: as served by the world, 10)")
    parser.add_argument("--startup-timeout-s", type=argtypes.positive, default=30.0,
                        help="wall deadline to connect and get the configuration")
    parser.add_argument("--pose-timeout-s", type=argtypes.positive, default=5.0,
                        help="wall time without poses after which the world is gone")
    faults = argtypes.add_link_fault_flags(parser, "the pose link")
    faults.add_argument("--fault-seed", type=argtypes.non_negative_int, default=0,
                        help="seeds the pose link")
    faults.add_argument("--control-phase-s", type=argtypes.non_negative, default=0.0,
                        help="offset of the planning slots [sim s]")
    faults.add_argument("--plan-delay-ms", type=argtypes.non_negative, default=0.0,
                        help="added planning delay [sim ms] (a CPU-starved robot)")
    faults.add_argument("--no-latency-compensation", action="store_true",
                        help="plan on the poses as stamped (no forward prediction by age)")
    parser.add_argument("--tls", type=Path, default=None, metavar="DIR",
                        help="mutual TLS with DIR/ca.pem, DIR/robot-<id>.pem, DIR/robot-<id>.key")
    parser.add_argument("--world-zid", type=argtypes.zid, default=None, metavar="HEX",
                        help="the world's Zenoh id (default: the router connected to; behind "
                             "a relay router, the world's --zid)")
    parser.add_argument("--no-plan", action="store_true",
                        help="sense and command a stop every cycle without planning (to "
                             "measure the process's own cost)")
    args = parser.parse_args(argv)
    return AgentOptions(run_id=args.run, robot_id=args.id, connect=args.connect,
                        control_rate_hz=args.control_rate_hz,
                        startup_timeout_s=args.startup_timeout_s,
                        pose_timeout_s=args.pose_timeout_s,
                        link=argtypes.link_faults(args),
                        fault_seed=args.fault_seed, control_phase_s=args.control_phase_s,
                        plan_delay_ms=args.plan_delay_ms,
                        compensate_latency=not args.no_latency_compensation,
                        plan=not args.no_plan, tls_dir=args.tls, world_zid=args.world_zid)


class RobotExit(Exception):
    """Leave the robot's loop with this reason and exit status."""

    def __init__(self, reason: str, code: int) -> None:
        super().__init__(reason)
        self.reason = reason
        self.code = code


def connect(options: AgentOptions, stop: StopFlag, deadline: float) -> zenoh.Session:
    """Connect as a client, retrying until `deadline` (monotonic); raises `RobotExit`.

    Each attempt waits `CONNECT_ATTEMPT_MS` at most: a refused certificate then ends in
    TRANSPORT at the deadline instead of an `open` that retries forever."""
    tls = None
    if options.tls_dir is not None:
        tls = TlsFiles.in_dir(options.tls_dir, robot_cn(options.robot_id))
        problem = check_tls_files(tls)
        if problem:
            raise RobotExit(f"--tls {options.tls_dir}: {problem}", ExitCode.BAD_INPUT)
    try:
        settings = session_settings(mode="client", connect=[options.connect],
                                    connect_timeout_ms=CONNECT_ATTEMPT_MS, tls=tls)
    except ValueError as exc:
        raise RobotExit(str(exc), ExitCode.BAD_INPUT) from exc
    try:
        session = open_session(settings, deadline=deadline, stop=stop)
    except SessionError as exc:
        raise RobotExit(f"cannot connect to {options.connect}: {exc}", ExitCode.TRANSPORT) from exc
    if session is None:
        raise RobotExit("signal", ExitCode.OK)
    return session


def world_zid_of(session: zenoh.Session, options: AgentOptions) -> str | None:
    """The world's Zenoh id: `AgentOptions.world_zid`, else the one router this client is
    connected to (None if there is not exactly one: then nothing is checked)."""
    if options.world_zid:
        return options.world_zid
    routers = [str(z) for z in session.info.routers_zid()]
    if len(routers) != 1:
        log.warning("robot %d: connected to %d routers: the source of the world's messages "
                    "is not checked", options.robot_id, len(routers))
        return None
    return routers[0]


def from_world(source: zenoh.EntityGlobalId | None, world_zid: str | None) -> bool:
    """True if a sample's source (`Sample.source_info.source_id`, `Reply.replier_id`) is the
    world's session (always, when the world's id is unknown)."""
    return is_world(None if source is None else str(source.zid), world_zid)


def fetch_config(session: zenoh.Session, keys: RunKeys, robot_id: int, stop: StopFlag,
                 deadline: float, world_zid: str | None = None,
                 counts: dict[str, int] | None = None) -> RunConfigMsg:
    """Query the world for this robot's configuration until `deadline`; raises `RobotExit`.

    Every reply is read (no consolidation: a forged reply must not hide the world's); one
    from a session other than `world_zid` is refused and counted in
    ``counts["refused_config"]``."""
    problem = "no reply"
    while not stop:
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            raise RobotExit(f"no configuration for robot {robot_id}: {problem}", ExitCode.BAD_INPUT)
        replies = session.get(keys.config(robot_id), timeout=min(QUERY_TIMEOUT_S, remaining),
                              consolidation=zenoh.ConsolidationMode.NONE)
        for reply in replies:
            if not from_world(reply.replier_id, world_zid):
                if counts is not None:
                    counts["refused_config"] = counts.get("refused_config", 0) + 1
                source = "no named session" if reply.replier_id is None else reply.replier_id.zid
                log.warning("robot %d: refused a configuration reply from %s (not the world)",
                            robot_id, source)
                problem = (f"every reply came from {source}, not the world "
                           f"({world_zid}); behind a relay router, give the world's id with "
                           "--world-zid")
                continue
            if reply.ok is None:
                error = "" if reply.err is None else reply.err.payload.to_string()
                problem = f"world replied an error: {error}"
                continue
            try:
                return RunConfigMsg.decode(reply.ok.payload.to_bytes(),
                                           expected_run_id=keys.run_id,
                                           expected_robot_id=robot_id)
            except ProtocolError as exc:
                problem = f"malformed configuration: {exc}"
                log.warning("robot %d: %s", robot_id, problem)
        time.sleep(0.1)
    raise RobotExit("signal", ExitCode.OK)


def make_controller(config: RunConfigMsg, period_s: float, *,
                    compensate_latency: bool = True) -> RobotController:
    """The robot's `RobotController`, its planner set up for this control period."""
    from agent.planning.controller import RobotController
    from agent.planning.routing import StaticMap

    static = StaticMap.from_rows(config.static_map)
    return RobotController(config.robot, config.planner, config.goal_tolerance_m,
                           control_period_s=period_s, compensate_latency=compensate_latency,
                           static_map=static)


def warm_up(config: RunConfigMsg, period_s: float) -> None:
    """Plan once with a throwaway controller so lazy imports and caches are ready in time.

    The first plan of a process costs ~0.3 s (imports, solver set-up); doing it before the
    liveliness token is declared keeps it out of the run. The scene is this robot at its
    start with a phantom disc ahead, so the threat and via-point paths are exercised too.
    """
    from agent.core.types import PoseSnapshot

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
