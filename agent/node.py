"""The robot process: senses poses, plans with `RobotController`, publishes commands.

One OS process per robot, a Zenoh client of the run's router (multicast scouting off,
explicit endpoint). It knows nothing but what arrives on the wire (see `eifp_wire`):

1. Connect (retrying until ``--startup-timeout-s``), fetch this robot's `RunConfigMsg` from
   the world's queryable (retrying with the same deadline), build the controller.
2. Declare the pose subscriber (Zenoh's receiving thread puts each sample on a queue the
   loop blocks on; the loop keeps the newest `POSE_RING` of them: the robot always acts on
   the newest pose, never a backlog), the control subscriber, the world-liveliness subscriber, the
   command publisher (DROP, express), the debug publisher (its plans' internals for
   viewers, `PlanDebugMsg`, DROP, express) and, last, its own liveliness token.
3. Loop: drain control and liveliness (their callbacks fill an `Inbox` each), decode the
   ring (an `eifp_wire.poses.PoseDecoder`; the newest valid snapshot goes to
   `RobotController.observe`, which drops stale or out-of-order ones), and plan at the
   control rate in SIM time: when the newest pose's stamp reaches the next scheduled plan
   time, plan and publish one `CommandMsg` (`eifp_wire.messages.encode_command`); the schedule
   advances by one period (slots already passed are skipped and counted as overruns, never
   planned as a backlog).

Faults: a malformed pose or control message raises `ProtocolError`; it is counted, logged
to stderr (the first few, then every 100th) and the robot keeps running. The robot stops
commanding and exits with `ExitCode.WORLD_LOST` if the world's liveliness token disappears
before the end message and is not back within `WORLD_BLIP_GRACE_S` (0.5 s), or no pose
arrives for ``--pose-timeout-s`` while running. If the process itself was suspended
(SIGSTOP: more than `SUSPEND_GAP_S` of wall time between two loop iterations that neither
its CPU time nor its waits explain), its link has been closed by the
lease and the world's token vanishes from its view; it then sends nothing and waits up to
`REJOIN_GRACE_S` for the token to return (the client reconnects by itself) before giving up.

Injected faults (``--latency-ms``, ``--jitter-ms``, ``--drop``, ``--dup``, ``--reorder``,
``--fault-seed``): every valid pose passes through a seeded `world.sim.link.FaultyLink` in sim
time before the controller sees it; the controller drops what is stale or out of order.
The robot's sim clock is the newest pose's stamp *as it arrived from the world*, before the
injected fault, advanced by wall time x time_scale: it stands for the synchronised clock
of a real fleet, so the planner measures the true age of the poses it plans on and
forward-predicts by it (``--no-latency-compensation`` turns that off). A pose older than
`STALE_PLAN_S` when its slot comes gives a brake command instead of a plan. The robot plans
for when its command will leave (the sim clock plus `RobotNode.compute_s`, its recent plan
times), and sends a brake for a plan that took longer than that plus the command hold.
``--plan-delay-ms`` holds every command back that long (a CPU-starved robot),
``--control-phase-s`` shifts the planning slots. It
exits 0 on the ``end`` `ControlMsg` and on SIGTERM/SIGINT/SIGHUP. On exit it logs one line
``robot <id> exit: reason='...' code=N rejected=N stale=N skipped=N plans=N overruns=N
plan_errors=N stale_plans=N late_plans=N link_dropped=N suspended=N seq=N`` to stderr
(``rejected``: malformed messages; ``stale``: poses the controller dropped as old or out of order;
``skipped``: valid poses not observed because a newer one was waiting in the ring;
``overruns``: plan slots skipped; ``stale_plans``: brakes on too-old poses;
``late_plans``: plans sent as a brake because they took longer than allowed for plus the
command hold;
``link_dropped``: poses the injected link lost; ``suspended``: times it found it had not
run for more than `SUSPEND_GAP_S`, stopped or not scheduled: a machine so loaded that a
process waits that long for a core is counted too, since its link may have lapsed as
well). The launcher collects these lines into ``robots.json``.

Exit status (`agent.process.ExitCode`): OK (end of run, or a signal), TRANSPORT (cannot
connect before the startup deadline), BAD_INPUT (no valid configuration), WORLD_LOST (the
world is gone).

Planning slots are staggered over the world's ticks (`plan_phase_s`: robot k plans on the
ticks k mod 5 of each 0.1 s period), so only a fifth of the robots plan on any one pose.
The world publishes tick t on the pose slot ``poses/<t mod 5>``
(`world.sim.schedule.pose_slot_count`) and a robot subscribes to the one slot its plans fall
on (`world.sim.schedule.plan_pose_slot`): it receives and decodes 10 poses per second
instead of 50, and the router sends a fifth of the bytes. A robot whose plan slots are not
on one pose slot (``--control-phase-s`` between ticks, ``--control-rate-hz`` 20 ...)
subscribes to every slot (``poses/*``).
Between poses the loop blocks on the pose queue (woken by the pose itself: no polling while
the world runs late), at most `MAX_NAP_S`. Zenoh runs on one thread of the process
(`agent.process.use_one_zenoh_thread`). A robot's cost per cycle is in docs/scale.md
(`orchestrator bench --process`).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import queue
import sys
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
import zenoh

from agent import flags as argtypes
from agent.core.types import PlanStatus
from agent.process import (
    ExitCode,
    SessionError,
    StallWatch,
    StopFlag,
    check_tls_files,
    close_session,
    die_with_launcher,
    enqueue_on_receive,
    monotonic_clock_id,
    open_session,
    stop_on_signals,
    use_one_zenoh_thread,
)
from eifp_wire import (
    MAX_ROBOT_ID,
    ControlMsg,
    PlanDebugMsg,
    PoseDecoder,
    PosesMsg,
    ProtocolError,
    RunConfigMsg,
    RunKeys,
    TlsFiles,
    check_pose_time,
    encode_command,
    next_seq,
    plan_pose_slot,
    pose_slot_count,
    robot_cn,
    session_settings,
)
from world.sim.link import LINK_POSES, FaultyLink, LinkFaults, link_rng

if TYPE_CHECKING:
    from agent.planning.controller import RobotController

POSE_RING = 2
"""The world's newest pose samples a robot keeps after draining its queue (older ones are
dropped unread)."""
CONNECT_ATTEMPT_MS = 1000
QUERY_TIMEOUT_S = 1.0
STAMP_EPS_S = 1e-6
"""Tolerance on sim-time comparisons (stamps are sums of float ticks)."""
SUSPEND_GAP_S = 0.5
"""A loop stall this long (wall time between two iterations that the loop's CPU time and its
waits do not explain, `agent.process.StallWatch`) means the process was suspended (stopped,
or not scheduled for that long, as some robots are while a fork launcher starts many robots
on a small host)."""
REJOIN_GRACE_S = 5.0
"""After a suspension, how long the robot waits for the world's token to come back."""
WORLD_BLIP_GRACE_S = 0.5
"""Otherwise, how long it waits (sending nothing) before it takes a vanished world token
for a lost world. A stall of the whole host can let the transport lease close every robot's
link at once, also for a robot that did not see its own loop stall; taking that for a lost
world, it would exit and stand, an obstacle, in the others' way for the rest of the run."""
COMPUTE_DECAY = 0.9
"""Per plan, how much of the longest recent plan time the robot still expects (see
`RobotNode.compute_s`, at most `STALE_PLAN_S`): a spike is forgotten by half in about 7
plans. Chosen, not fitted: a tenth per control period forgets a start-up or crowd spike
within a few seconds while still covering the next few plans of a sustained overload."""
STALE_PLAN_S = 1.0
"""Poses older than this [sim s] when planning: brake instead (compensation is capped there)."""
MAX_NAP_S = 0.25
"""Longest wait for a pose: without poses, control and liveliness messages are read at least
this often. Longer than the control period, so a robot receiving its poses wakes for them
only (a wait as long as the period ran out just before every other pose)."""
CPU_TOKEN_WAIT_S = 0.05
"""Longest wait for a CPU token (`RobotNode.sense_and_plan`) before planning without one."""


class CpuTokens(Protocol):
    """A counting semaphore shared by the robots of one host (e.g. multiprocessing's)."""

    def acquire(self, block: bool = True, timeout: float | None = None) -> bool: ...

    def release(self) -> None: ...


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
    parser = argtypes.Parser(prog="python -m agent", description=__doc__.split("\n")[0])
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


class _Exit(Exception):
    """Leave the robot's loop with this reason and exit status."""

    def __init__(self, reason: str, code: int) -> None:
        super().__init__(reason)
        self.reason = reason
        self.code = code


def connect(options: AgentOptions, stop: StopFlag, deadline: float) -> zenoh.Session:
    """Connect as a client, retrying until `deadline` (monotonic); raises `_Exit`.

    Each attempt waits `CONNECT_ATTEMPT_MS` at most: a refused certificate then ends in
    TRANSPORT at the deadline instead of an `open` that retries forever."""
    tls = None
    if options.tls_dir is not None:
        tls = TlsFiles.in_dir(options.tls_dir, robot_cn(options.robot_id))
        problem = check_tls_files(tls)
        if problem:
            raise _Exit(f"--tls {options.tls_dir}: {problem}", ExitCode.BAD_INPUT)
    try:
        settings = session_settings(mode="client", connect=[options.connect],
                                    connect_timeout_ms=CONNECT_ATTEMPT_MS, tls=tls)
    except ValueError as exc:
        raise _Exit(str(exc), ExitCode.BAD_INPUT) from exc
    try:
        session = open_session(settings, deadline=deadline, stop=stop)
    except SessionError as exc:
        raise _Exit(f"cannot connect to {options.connect}: {exc}", ExitCode.TRANSPORT) from exc
    if session is None:
        raise _Exit("signal", ExitCode.OK)
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
    if world_zid is None:
        return True
    return source is not None and str(source.zid) == world_zid


def fetch_config(session: zenoh.Session, keys: RunKeys, robot_id: int, stop: StopFlag,
                 deadline: float, world_zid: str | None = None,
                 counts: dict[str, int] | None = None) -> RunConfigMsg:
    """Query the world for this robot's configuration until `deadline`; raises `_Exit`.

    Every reply is read (no consolidation: a forged reply must not hide the world's); one
    from a session other than `world_zid` is refused and counted in
    ``counts["refused_config"]``."""
    problem = "no reply"
    while not stop:
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            raise _Exit(f"no configuration for robot {robot_id}: {problem}", ExitCode.BAD_INPUT)
        replies = session.get(keys.config(robot_id), timeout=min(QUERY_TIMEOUT_S, remaining),
                              consolidation=zenoh.ConsolidationMode.NONE)
        for reply in replies:
            if not from_world(reply.replier_id, world_zid):
                if counts is not None:
                    counts["refused_config"] = counts.get("refused_config", 0) + 1
                log.warning("robot %d: refused a configuration reply from %s (not the world)",
                            robot_id, reply.replier_id)
                problem = (f"every reply came from {reply.replier_id.zid}, not the world "
                           f"({world_zid}); behind a relay router, give the world's id with "
                           "--world-zid")
                continue
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
    raise _Exit("signal", ExitCode.OK)


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


class Inbox:
    """Samples a subscriber's Zenoh thread puts here (`enqueue_on_receive`): the loop sees
    whether any came with `empty`, a C call, instead of calling into Zenoh every cycle."""

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[zenoh.Sample] = queue.SimpleQueue()
        self.put = self._queue.put
        self.empty = self._queue.empty

    def try_recv(self) -> zenoh.Sample | None:
        """The oldest sample not read yet, or None."""
        return None if self._queue.empty() else self._queue.get_nowait()


class RobotNode:
    """One robot's Zenoh edge: declarations, the sense-plan-act loop and its counters.

    Args:
        session: an open client session (closed by the caller).
        options: command-line options.
        config: this robot's configuration from the world.
        stop: polled; set by the signal handlers.
    """

    def __init__(self, session: zenoh.Session, options: AgentOptions, config: RunConfigMsg,
                 stop: StopFlag, cpu_tokens: CpuTokens | None = None,
                 world_zid: str | None = None, refused_config: int = 0) -> None:
        self.keys = RunKeys(options.run_id)
        self.options = options
        self.cpu_tokens = cpu_tokens
        self.config = config
        self.robot_id = config.robot.id
        self.stop = stop
        period_s = 1.0 / (options.control_rate_hz or config.control_rate_hz)
        self.controller = make_controller(config, period_s,
                                          compensate_latency=options.compensate_latency)
        warm_up(config, period_s)
        # Slots: the injected phase if one is given, else spread over the world's ticks.
        phase_s = options.control_phase_s
        if not phase_s:
            phase_s = plan_phase_s(config.robot.id, period_s, 1.0 / config.world_rate_hz)
        self.schedule = PlanSchedule(period_s, phase_s)
        self.decoder = PoseDecoder(config.known_ids)
        self.counts = {"rejected": 0, "stale": 0, "skipped": 0, "plans": 0, "overruns": 0,
                       "plan_errors": 0, "stale_plans": 0, "late_plans": 0, "link_dropped": 0,
                       "suspended": 0,
                       "token_timeouts": 0, "refused_poses": 0, "refused_control": 0,
                       "refused_config": refused_config}
        self.world_zid = world_zid
        self.seq = -1  # the last command's seq (`eifp_wire.clock.next_seq`); none yet
        # How long [sim s] the robot expects its next plan to take, from sensing to sending:
        # the longest recent plan time, decaying by COMPUTE_DECAY per plan. The robot plans
        # for the time its command will leave (`plan_and_send`).
        self.compute_s = 0.0
        # CPU time of the loop by part (thread CPU clock of this, the main, thread) and the
        # process's CPU clock at the loop's start: see `cpu_summary`.
        self.cpu_s = {"sense": 0.0, "plan": 0.0, "send": 0.0}
        self.cpu_start: tuple[float, float] | None = None
        self.last_rx_wall: float | None = None
        self.newest: PosesMsg | None = None
        self.newest_rx_ns = 0
        self.clock_id = monotonic_clock_id()
        self.world_alive = False
        self.world_seen = False
        self.world_gone_wall: float | None = None
        self.world_grace_s = WORLD_BLIP_GRACE_S
        self.stalls = StallWatch()
        self.resumed_wall = -math.inf
        # The sim clock: the newest pose's stamp as it arrived from the world (before any
        # injected fault), advanced by wall time x time_scale. It stands for the clock
        # synchronisation a real fleet has (PTP/NTP): the injected delay is measured by it.
        self.clock_tick = -1
        self.clock_stamp_s = 0.0
        self.clock_wall = 0.0
        self.pose_link: FaultyLink[tuple[PosesMsg, int]] = FaultyLink(
            options.link, link_rng(options.fault_seed, LINK_POSES, self.robot_id))

        # Only the pose slot this robot plans on (a K-th of the stream, K = world ticks per
        # control period), or every slot if its plan slots are not all on one of them.
        self.pose_slot = plan_pose_slot(
            period_s, phase_s, 1.0 / config.world_rate_hz,
            pose_slot_count(config.world_rate_hz, config.control_rate_hz))
        pose_key = (self.keys.poses_all if self.pose_slot is None
                    else self.keys.poses_slot(self.pose_slot))
        # Zenoh's receiving thread puts each sample on a queue (a C call, no Python frame
        # and no thread of ours in between); the loop blocks on the queue, so it wakes when
        # a pose arrives, and then drains it into the ring (`wait_for_poses`).
        self.pose_queue: queue.SimpleQueue[zenoh.Sample] = queue.SimpleQueue()
        self.pose_ring: deque[zenoh.Sample] = deque(maxlen=POSE_RING)
        self.pose_rx_wall = 0.0  # when the loop took the ring's samples off the queue
        self.pose_sub = session.declare_subscriber(pose_key,
                                                   enqueue_on_receive(self.pose_queue.put))
        log.info("robot %d: poses from %s", self.robot_id, pose_key)
        # Control and the world's liveliness land in inboxes the loop checks with a C call.
        self.control_sub = Inbox()
        self.world_sub = Inbox()
        self._subscribers = (
            session.declare_subscriber(self.keys.control, enqueue_on_receive(self.control_sub.put)),
            session.liveliness().declare_subscriber(
                self.keys.alive_world, enqueue_on_receive(self.world_sub.put), history=True))
        self.cmd_pub = session.declare_publisher(
            self.keys.cmd(self.robot_id), congestion_control=zenoh.CongestionControl.DROP,
            express=True)
        # The planner's internals, for viewers only (the world records them in run.mcap):
        # DROP and express like the commands, so they never hold the robot up.
        self.debug_pub = session.declare_publisher(
            self.keys.debug(self.robot_id), congestion_control=zenoh.CongestionControl.DROP,
            express=True)
        # Declared last: once the world sees it, every subscription above is in place.
        self.token = session.liveliness().declare_token(self.keys.alive_robot(self.robot_id))

    def _reject(self, what: str, exc: ProtocolError) -> None:
        self.counts["rejected"] += 1
        n = self.counts["rejected"]
        if n <= 10 or n % 100 == 0:
            log.warning("robot %d: rejected %s #%d: %s", self.robot_id, what, n, exc)

    def _refuse(self, what: str, counter: str, why: str) -> None:
        """Count a well-formed message refused as not the world's (forged), log the first few."""
        self.counts[counter] += 1
        n = self.counts[counter]
        if n <= 10 or n % 100 == 0:
            log.warning("robot %d: refused %s #%d: %s", self.robot_id, what, n, why)

    def poll_control(self) -> None:
        """Start/end announcements; raises `_Exit` on the end.

        Only the world's session may end the run: a control message whose source is not
        the world (`from_world`) is refused and counted (``refused_control``)."""
        while (sample := self.control_sub.try_recv()) is not None:
            source = sample.source_info.source_id if sample.source_info else None
            if not from_world(source, self.world_zid):
                self._refuse("control message", "refused_control",
                             f"from {source.zid if source else 'an unnamed source'}")
                continue
            try:
                msg = ControlMsg.decode(sample.payload.to_bytes())
            except ProtocolError as exc:
                self._reject("control message", exc)
                continue
            if msg.kind == "end":  # "start" needs no action: planning begins with the poses
                raise _Exit(f"end ({msg.reason})", ExitCode.OK)

    def poll_world(self) -> None:
        """World liveliness; raises `_Exit` if the world is gone before the end.

        A vanished token is given `WORLD_BLIP_GRACE_S` to come back (a link the lease closed
        during a machine-wide stall reconnects by itself); right after this process was
        suspended (SIGSTOP), whose link the lease surely closed, `REJOIN_GRACE_S`. The robot
        sends nothing meanwhile.
        """
        now = time.monotonic()
        while (sample := self.world_sub.try_recv()) is not None:
            if sample.kind == zenoh.SampleKind.PUT:
                if self.world_gone_wall is not None:
                    log.warning("robot %d: world back after %.2f s", self.robot_id,
                                now - self.world_gone_wall)
                self.world_alive = self.world_seen = True
                self.world_gone_wall = None
            elif self.world_alive:
                self.world_alive = False
                self.poll_control()  # the end message may have been queued just before
                self.world_gone_wall = now
                if now - self.resumed_wall <= REJOIN_GRACE_S:
                    self.world_grace_s = REJOIN_GRACE_S
                    log.warning("robot %d: world token gone right after a suspension; "
                                "waiting %.1f s for it", self.robot_id, REJOIN_GRACE_S)
                else:
                    self.world_grace_s = WORLD_BLIP_GRACE_S
        gone = self.world_gone_wall
        if gone is not None and now - gone > self.world_grace_s:
            if self.world_grace_s == REJOIN_GRACE_S:
                raise _Exit(f"world lost (token not back within {REJOIN_GRACE_S:.0f} s)",
                            ExitCode.WORLD_LOST)
            raise _Exit("world lost (liveliness token gone)", ExitCode.WORLD_LOST)

    def sim_now(self) -> float:
        """The robot's sim clock (see `__init__`)."""
        return self.clock_stamp_s + (time.monotonic() - self.clock_wall) * self.config.time_scale

    def poll_poses(self) -> bool:
        """Decode the ring, pass the newest valid pose through the pose link, observe what
        the link releases.

        Every sample is decoded (a malformed one is rejected and counted wherever it sits
        in the ring), newest first; only the newest valid one enters the link: the older
        ones are older than it, so the controller would drop them as out of order anyway
        (they are counted as ``skipped``). Without injected faults the link is a no-op and
        is bypassed.

        Returns:
            True if a pose newer than any observed before was released.
        """
        ring = self.pose_ring
        newest: PosesMsg | None = None
        while ring:
            sample = ring.pop()  # newest first
            try:
                msg = self.decoder.decode(sample.payload.to_bytes())
            except ProtocolError as exc:
                self._reject("pose message", exc)
                continue
            if newest is not None:
                self.counts["skipped"] += 1
                continue
            # The clock moves only on a pose that passed every check: a forged far-future
            # pose would otherwise make every genuine one look out of date.
            why = check_pose_time(msg.tick, msg.t_s, world_rate_hz=self.config.world_rate_hz,
                                  time_limit_s=self.config.time_limit_s,
                                  clock_s=self.sim_now() if self.clock_tick >= 0 else None,
                                  time_scale=self.config.time_scale)
            if why is not None:
                self._refuse("pose message", "refused_poses",
                             f"{why}: tick {msg.tick}, t {msg.t_s:.3f} s")
                continue
            newest = msg
        released: list[tuple[PosesMsg, int]] = []
        if newest is not None:
            # When the loop took the pose off the queue: it waits on the queue, so normally
            # as the pose arrived.
            arrived = self.pose_rx_wall
            self.last_rx_wall = arrived
            if newest.tick > self.clock_tick:
                self.clock_tick, self.clock_stamp_s, self.clock_wall = (
                    newest.tick, newest.t_s, arrived)
            released.append((newest, round(arrived * 1e9)))
        link = self.pose_link
        if link.faults.active:
            for item in released:
                link.send(self.sim_now(), item)
            released = link.receive(self.sim_now())
            self.counts["link_dropped"] = link.counts.dropped
        fresh = False
        for msg, rx_ns in released:
            if not self.controller.observe(msg.to_snapshot()):
                self.counts["stale"] += 1
                continue
            self.newest, self.newest_rx_ns = msg, rx_ns
            fresh = True
        return fresh

    def plan_and_send(self, cpu_start_s: float | None = None) -> None:
        """Plan on the newest pose if its stamp reached the schedule; publish the command.

        The planner gets the sim clock's time, so it forward-predicts by the pose's real
        age (injected delay included); a pose older than `STALE_PLAN_S` gives a brake.
        `cpu_start_s`: this thread's CPU clock when the caller stopped counting (counted
        from here on as planning); None: read it now.
        """
        msg = self.newest
        if msg is None or not self.schedule.due(msg.t_s):
            return
        now_s = self.sim_now()
        cpu0 = time.thread_time() if cpu_start_s is None else cpu_start_s
        plan_start_ns = time.monotonic_ns()
        try:
            if not self.options.plan:
                result = self.controller.brake()
            elif now_s - msg.t_s > STALE_PLAN_S:
                self.counts["stale_plans"] += 1
                result = self.controller.brake()
            else:  # planned for when the command will leave, as far as the robot can tell
                result = self.controller.plan(now_s + self.compute_s)
        except Exception:  # a planner bug must not leave the robot driving blind
            self.counts["plan_errors"] += 1
            if self.counts["plan_errors"] <= 3:
                log.exception("robot %d: planner raised; braking", self.robot_id)
            result = self.controller.brake()
        plan_end_ns = time.monotonic_ns()
        cpu1 = time.thread_time()
        self.cpu_s["plan"] += cpu1 - cpu0
        if self.options.plan_delay_ms > 0.0:  # a CPU-starved robot: the command leaves late
            delay_s = self.options.plan_delay_ms * 1e-3 / self.config.time_scale
            slept = time.monotonic()
            time.sleep(delay_s)
            self.stalls.waited(time.monotonic() - slept, delay_s)
            cpu1 = time.thread_time()
        took_s = self.sim_now() - now_s
        if (result.status is not PlanStatus.STALE
                and took_s > self.compute_s + self.controller.command_hold_s):
            # Later than it allowed for by more than the hold: the world stopped holding the
            # previous command and braked the robot while this plan assumed it still applied.
            self.counts["late_plans"] += 1
            result = self.controller.brake()
        # Capped at STALE_PLAN_S: a plan a stop (SIGSTOP) stretched must not make the robot
        # plan seconds ahead for the rest of the run (the controller caps the age there too).
        self.compute_s = min(max(took_s, COMPUTE_DECAY * self.compute_s), STALE_PLAN_S)
        # The fields of a `CommandMsg`, its `WallStamps` in their wire order.
        # On the clock of the poses (`eifp_wire.clock.next_seq`): a robot whose seq a forger pushed
        # up catches up as time passes.
        self.seq = next_seq(self.seq, msg.t_s)
        self.cmd_pub.put(encode_command(
            self.robot_id, self.seq, msg.t_s, float(result.v_mps), float(result.omega_radps),
            max(0.0, float(result.times.total_ms)), result.status, int(result.side),
            None if result.resolved_id is None else int(result.resolved_id),
            self.controller.command_hold_s,
            [self.clock_id, msg.clock_id, msg.pub_ns, self.newest_rx_ns, plan_start_ns,
             plan_end_ns, time.monotonic_ns()]))
        debug = PlanDebugMsg.from_result(self.robot_id, self.seq, now_s, result)
        if debug is not None:
            self.debug_pub.put(debug.encode())
        self.cpu_s["send"] += time.thread_time() - cpu1
        self.counts["plans"] += 1
        self.counts["overruns"] += self.schedule.planned(msg.t_s)

    def sense_and_plan(self) -> bool:
        """`poll_poses`, then `plan_and_send` if a fresh pose came (and the world is seen),
        holding one of the host's CPU tokens meanwhile if the robot has them.

        With tokens (`agent.fleet` hands them out, one per core) at most that many robots
        of a host compute at once and each runs its cycle to the end instead of being time-
        sliced against every other runnable robot: when they want more CPU than there is,
        the first in line are on time and the queue's tail is late, instead of all of
        them late. A robot that gets no token within `CPU_TOKEN_WAIT_S` goes ahead
        without one (counted as ``token_timeouts``): a lost token costs throughput, never
        a stop.

        Returns:
            True if a pose newer than any observed before was released.
        """
        tokens = self.cpu_tokens
        held = False
        if tokens is not None and self.pose_ring:
            asked = time.monotonic()
            held = tokens.acquire(timeout=CPU_TOKEN_WAIT_S)
            self.stalls.waited(time.monotonic() - asked, CPU_TOKEN_WAIT_S)
            if not held:
                self.counts["token_timeouts"] += 1
        try:
            cpu0 = time.thread_time()
            fresh = self.poll_poses()
            cpu1 = time.thread_time()
            self.cpu_s["sense"] += cpu1 - cpu0
            if fresh and self.world_alive:  # never command a world we cannot see
                self.plan_and_send(cpu1)
            return fresh
        finally:
            if held and tokens is not None:
                tokens.release()

    def wait_for_poses(self) -> None:
        """Block until a pose arrives, the pose link releases one, or `MAX_NAP_S` passed;
        then move every queued sample from the world into the ring.

        The loop wakes once per pose and is asleep otherwise: no polling, and nothing
        runs between the pose's arrival and the loop but Zenoh's own thread. A sample that
        is not from the world's session never enters the ring (counted in
        ``refused_poses``): a flood of forged poses must not push the world's out of it.
        """
        wait_s = MAX_NAP_S
        link_due_s = self.pose_link.next_due_s
        if link_due_s is not None:
            wait_s = min(wait_s,
                         max(0.0, (link_due_s - self.sim_now()) / self.config.time_scale))
        pending = self.pose_queue
        napped = time.monotonic()
        try:
            sample = pending.get(timeout=wait_s)
        except queue.Empty:
            self.stalls.waited(time.monotonic() - napped, wait_s)
            return
        self.pose_rx_wall = time.monotonic()
        self.stalls.waited(self.pose_rx_wall - napped, wait_s)
        world_zid = self.world_zid
        while True:
            if world_zid is None:
                self.pose_ring.append(sample)
            else:
                info = sample.source_info
                if info is not None and str(info.source_id.zid) == world_zid:
                    self.pose_ring.append(sample)
                else:
                    self._refuse("pose message", "refused_poses",
                                 f"from {info.source_id.zid if info else 'an unnamed source'}")
            if pending.empty():
                return
            sample = pending.get_nowait()

    def run(self, startup_deadline: float) -> tuple[str, int]:
        """The robot's loop; returns (reason, exit status).

        Args:
            startup_deadline: monotonic time by which the world's token must have been seen
                (after that, the world owns the start: it ends the run if robots are missing).
        """
        self.cpu_start = (time.thread_time(), time.process_time())
        try:
            while not self.stop:
                stall_s = self.stalls.tick()
                if stall_s > SUSPEND_GAP_S:
                    self.resumed_wall = time.monotonic()
                    self.counts["suspended"] += 1
                    log.warning("robot %d: resumed after %.2f s without running (suspended?)",
                                self.robot_id, stall_s)
                if not self.control_sub.empty():
                    self.poll_control()
                if not self.world_sub.empty() or self.world_gone_wall is not None:
                    self.poll_world()
                if not self.world_seen and time.monotonic() > startup_deadline:
                    raise _Exit("world not seen before the startup deadline", ExitCode.WORLD_LOST)
                if (not self.sense_and_plan() and self.last_rx_wall is not None
                        and time.monotonic() - max(self.last_rx_wall, self.resumed_wall)
                        > self.options.pose_timeout_s):
                    raise _Exit(f"no poses for {self.options.pose_timeout_s:.1f} s",
                                ExitCode.WORLD_LOST)
                self.wait_for_poses()
            return "signal", ExitCode.OK
        except _Exit as stop:
            return stop.reason, stop.code
        finally:
            # Stop commanding before anything else.
            self.cmd_pub.undeclare()
            self.debug_pub.undeclare()

    def cpu_summary(self) -> dict[str, int]:
        """CPU time the loop took since it started, by part, in whole microseconds.

        ``cpu_sense_us``: draining the pose ring, decoding, the pose link, observing
        (`poll_poses`); ``cpu_plan_us``: `RobotController.plan` (estimates, planner, MPC);
        ``cpu_send_us``: encoding and publishing the command; ``cpu_loop_us``: the rest of
        the main thread (control and liveliness polls, waiting, taking samples off the
        queue); ``cpu_threads_us``: every other thread of the process (Zenoh's runtime:
        receiving, putting the pose samples on the queue, sending, the lease).
        Thread and process CPU clocks (`time.thread_time`, `time.process_time`); empty
        before the loop started. `orchestrator scale` divides them by the plans.
        """
        if self.cpu_start is None:
            return {}
        main_s = time.thread_time() - self.cpu_start[0]
        process_s = time.process_time() - self.cpu_start[1]
        parts = {**self.cpu_s, "loop": main_s - sum(self.cpu_s.values()),
                 "threads": process_s - main_s}
        return {f"cpu_{k}_us": max(0, round(v * 1e6)) for k, v in parts.items()}

    def summary(self) -> str:
        """Counters and `cpu_summary` as key=value pairs (integers)."""
        fields = {**self.counts, "seq": self.seq, **self.cpu_summary()}
        return " ".join(f"{k}={v}" for k, v in fields.items())


def run_agent(options: AgentOptions, on_ready: Callable[[], None] | None = None,
              cpu_tokens: CpuTokens | None = None) -> int:
    """Run one robot process to its end; returns its exit status.

    `on_ready` is called once the robot's liveliness token is declared (`agent.fleet` uses
    it to start the next robot); `cpu_tokens`: see `RobotNode.sense_and_plan`.

    If the session cannot be closed in time (the router hangs), the process leaves with
    `os._exit` after logging: nothing is left to flush but stderr.
    """
    with stop_on_signals() as stop:
        return _run_agent(options, stop, on_ready, cpu_tokens)


def _run_agent(options: AgentOptions, stop: StopFlag, on_ready: Callable[[], None] | None,
               cpu_tokens: CpuTokens | None) -> int:
    keys = RunKeys(options.run_id)
    summary = ""
    session: zenoh.Session | None = None
    deadline = time.monotonic() + options.startup_timeout_s
    use_one_zenoh_thread()
    log.info("robot %d: run %s, connecting to %s", options.robot_id, options.run_id,
             options.connect)
    try:
        session = connect(options, stop, deadline)
        world_zid = world_zid_of(session, options)
        refused: dict[str, int] = {}
        config = fetch_config(session, keys, options.robot_id, stop, deadline, world_zid,
                              refused)
        node = RobotNode(session, options, config, stop, cpu_tokens, world_zid,
                         refused.get("refused_config", 0))
        if on_ready is not None:
            on_ready()
        reason, code = node.run(deadline)
        summary = node.summary()
    except _Exit as exc:
        reason, code = exc.reason, exc.code
    except BaseException:
        if session is not None:
            close_session(session)  # an unexpected error: still release the transport
        raise
    level = logging.INFO if code == ExitCode.OK else logging.ERROR
    log.log(level, "robot %d exit: reason=%r code=%d %s", options.robot_id, reason, code,
            summary)
    if session is not None and not close_session(session):
        log.error("robot %d: session close timed out; leaving without it", options.robot_id)
        logging.shutdown()
        os._exit(code)
    return code


def main(argv: list[str] | None = None, on_ready: Callable[[], None] | None = None,
         cpu_tokens: CpuTokens | None = None) -> int:
    """Entry point of ``python -m agent`` (`on_ready`, `cpu_tokens`: see `run_agent`)."""
    die_with_launcher()
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s agent %(levelname)s %(message)s")
    return run_agent(parse_args(argv), on_ready, cpu_tokens)
