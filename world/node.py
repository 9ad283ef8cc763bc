"""The world process: ground truth of a distributed run (the I/O edge around `WorldCycle`).

One process simulates every robot's unicycle and publishes poses; robots are separate
processes that only sense poses and send velocity commands (see `eifp_wire.keys`).
What to do with each message, tick and liveliness change is decided by a
`world.world_cycle.WorldCycle`; this module owns the Zenoh session, the pacing, the run
directory and the logs.

Lifecycle:
1. Load the scenario, open the run directory (`RunRecorder`), open a Zenoh session (by
   default a router listening on one endpoint, which with ``--tls`` enforces the run's
   access control, relay routers of other hosts included (``--relay``); without TLS,
   ``--connect`` makes it a client of an existing router), declare the configuration
   queryable, the command subscriber, the robot liveliness subscriber (history on) and
   finally the world's own liveliness token.
2. Wait until every robot's liveliness token is present (deadline ``--wait-robots-s``),
   then publish a ``start`` `ControlMsg`.
3. Fixed-rate loop: each tick is ``1 / rate_hz`` of sim time, paced to
   ``dt / time_scale`` of wall time. Each tick drains liveliness changes, configuration
   queries and commands (all read from handler channels, never in callbacks), applies the
   newest command per robot (zero-order hold, `WorldSim.set_command`), steps the world,
   publishes one `PosesMsg` (DROP, batched: `poses_pub`) per cell of the pose grid within
   reach of a robot, on the tick's pose slot (``poses/<tick mod K>/<i>/<j>``,
   `world.sim.schedule.pose_slot_count`, `WorldCycle.pose_cells`), and records the tick. The robots'
   plan internals (``debug/<id>``, `PlanDebugMsg`, through a ring) are validated and
   recorded into ``run.mcap`` (`RunRecorder.record_plan`).
4. The run ends when every robot has arrived (``all_arrived``), when every robot has
   arrived or been lost for ``--lost-grace-s`` (``arrived_or_lost``: a lost robot does not
   hold the run to its limit), at the scenario's time limit (``time_limit``) or on
   SIGTERM/SIGINT (``signal``): publish an ``end`` `ControlMsg`, write
   the ``end`` event, give robots a moment (``--linger-s``) to leave, close everything.

Faults: a malformed command or plan-debug message is rejected (`ProtocolError`), counted and
logged as a ``rejected`` event (the first `world.world_cycle.MAX_REJECT_EVENTS`); the
``end`` event always has the exact total (``rejected``) and tallies per key
(``rejected_by_key``) and per reason (``rejected_by_reason``: the field or kind of error,
e.g. ``cmd.v``). Valid commands pass through their robot's command link
(`world.sim.link.FaultyLink`, ``--latency-ms`` ...: injected delay, loss, duplication,
reordering, in sim time); a command whose ``seq`` does not increase is dropped as stale and
counted. A robot whose liveliness token disappears (crash, or hang past the 1 s transport
lease) is logged as ``robot_lost`` and set offline (it brakes and stays as an obstacle); a
returning token logs ``robot_rejoined`` and brings it back (its sequence numbering
restarts).

Events (``events.jsonl``, sim time ``t``; ``wall`` is Unix time where detection latency
matters): world_ready, robot_joined, robot_lost, robot_rejoined, robot_left, unknown_robot,
start, arrived, contact, cmd_timeout, rejected, startup_timeout, end (with ``tick_ms``: the
loop's tick wall times, p50 / p99 / mean / max, and the ``overruns`` counter; a world that
refuses its flags ends at once with reason ``bad_input``, the message as ``error`` and the
flag at fault as ``flag``, `agent.flags.FlagError`).

Exit status (`agent.process.ExitCode.of_run`): OK every robot arrived with no contact,
CONTACT, ROBOT_LOST, INTERRUPTED or INCOMPLETE otherwise; BAD_INPUT for bad arguments or a
bad scenario, TRANSPORT when the session could not be opened.
"""

from __future__ import annotations

import logging
import math
import os
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from agent import flags as argtypes
from agent.core.scenario import Scenario
from agent.files import UnsafePathError
from agent.planning.routing import StaticMap
from agent.process import (
    ExitCode,
    SessionError,
    StopFlag,
    check_tls_files,
    close_session,
    die_with_launcher,
    monotonic_clock_id,
    open_session,
    stop_on_signals,
)
from eifp_wire import (
    WORLD_CN,
    ControlMsg,
    RunConfigMsg,
    RunKeys,
    TlsFiles,
    access_control,
    pose_slot_count,
    pose_slot_of_tick,
    router_cn,
    session_settings,
)
from world.recorder import RunRecorder
from world.scenario_file import ScenarioError, load_scenario
from world.sim.cells import Cell
from world.sim.link import LinkFaults
from world.world_cycle import LOST_GRACE_S, WorldCycle

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
FLUSH_TICKS = 5
"""trajectory.csv and commands.csv are flushed every this many ticks (0.1 s at 50 Hz)."""
IDLE_POLL_S = 0.01
"""Wall period of the waiting and lingering loops."""

log = logging.getLogger("world")


@dataclass(frozen=True)
class WorldOptions:
    """Command-line options of the world process.

    Args:
        run_id: run id (safe characters, see `eifp_wire.keys.validate_run_id`).
        scenario_path: scenario YAML file.
        listen: endpoint to listen on as a router (None when `connect` is given).
        connect: endpoint of an existing router to join as a client.
        rate_hz: world tick rate in sim time.
        time_scale: sim seconds per wall second.
        out_dir: run directory.
        cmd_timeout_s: sim time after which a robot without a fresh command brakes.
        wait_robots_s: wall deadline for every robot to be alive before the start.
        control_rate_hz: planning rate served to the robots in their configuration.
        linger_s: wall time the world waits after the end for robots to leave.
        link: faults injected on every robot's command link (sim-time delays).
        fault_seed: seeds the command links (with the link kind and the robot id).
        tls_dir: directory with ``ca.pem``, ``world.pem``, ``world.key``: mutual TLS, and
            as a router the run's access control (`eifp_wire.access.access_control`); endpoints
            are then ``tls/...``. None: plain TCP, no authentication. Not with `connect`:
            the world's own router is what enforces the access control.
        relays: relay routers on other hosts (``python -m world.router``), as
            ``(name, robot ids behind it)``: router ``router-<name>`` may speak for those
            robots only (`eifp_wire.access.access_control`).
        zid: the session's Zenoh id (None: random). Robots behind a relay check the source
            of poses against it (``python -m agent --world-zid``).
        lost_grace_s: sim time a lost robot may still come back (a stopped process that
            resumes, a restarted one); a robot lost longer than this, like one that
            arrived, no longer holds the run open (`world.world_cycle.LOST_GRACE_S`).
    """

    run_id: str
    scenario_path: Path
    listen: str | None = DEFAULT_ENDPOINT
    connect: str | None = None
    rate_hz: float = 50.0
    time_scale: float = 1.0
    out_dir: Path = Path("runs")
    cmd_timeout_s: float = 0.5
    wait_robots_s: float = 30.0
    control_rate_hz: float = 10.0
    linger_s: float = 3.0
    link: LinkFaults = field(default_factory=LinkFaults)
    fault_seed: int = 0
    tls_dir: Path | None = None
    relays: tuple[tuple[str, tuple[int, ...]], ...] = ()
    zid: str | None = None
    lost_grace_s: float = LOST_GRACE_S


def parse_args(argv: list[str] | None = None) -> WorldOptions:
    """Parse ``python -m world`` arguments."""
    parser = argtypes.Parser(prog="python -m world", description=__doc__.split("\n")[0])
    parser.add_argument("--run", required=True, type=argtypes.run_id, help="run id")
    parser.add_argument("--scenario", required=True, type=Path, help="scenario YAML file")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--listen", type=argtypes.endpoint,
                       help=f"router endpoint to listen on (default {DEFAULT_ENDPOINT})")
    where.add_argument("--connect", type=argtypes.endpoint,
                       help="join an existing router at this endpoint, as a client")
    parser.add_argument("--rate-hz", type=argtypes.positive, default=50.0,
                        help="tick rate [1/sim s]")
    parser.add_argument("--time-scale", type=argtypes.positive, default=1.0,
                        help="sim seconds per wall second")
    parser.add_argument("--out", type=Path, default=None, help="run directory (runs/<run>)")
    parser.add_argument("--cmd-timeout-s", type=argtypes.positive, default=0.5,
                        help="a robot without a command for this long (sim) brakes")
    parser.add_argument("--wait-robots-s", type=argtypes.positive, default=30.0,
                        help="wall deadline for every robot to be alive")
    parser.add_argument("--control-rate-hz", type=argtypes.positive, default=10.0,
                        help="planning rate served to the robots [1/sim s]")
    parser.add_argument("--linger-s", type=float, default=3.0,
                        help="wall time to wait for robots to leave after the end")
    faults = argtypes.add_link_fault_flags(parser, "the command links")
    faults.add_argument("--fault-seed", type=argtypes.non_negative_int, default=0,
                        help="seeds the command links")
    parser.add_argument("--tls", type=Path, default=None, metavar="DIR",
                        help="mutual TLS with DIR/ca.pem, DIR/world.pem, DIR/world.key, and "
                             "the run's access control (endpoints tls/HOST:PORT)")
    parser.add_argument("--relay", type=argtypes.relay, action="append", default=[],
                        metavar="NAME=IDS",
                        help="robots IDS (e.g. 2,3 or 8-15) reach the world through the relay "
                             "router NAME on another host (python -m world.router; its "
                             "certificate is router-NAME); repeatable")
    parser.add_argument("--zid", type=argtypes.zid, default=None, metavar="HEX",
                        help="the session's Zenoh id (robots behind a relay are given it "
                             "with --world-zid); default: random")
    parser.add_argument("--lost-grace-s", type=argtypes.positive, default=LOST_GRACE_S,
                        help="sim seconds a lost robot may still come back; once every robot "
                             "has arrived or been lost this long the run ends "
                             f"(default {LOST_GRACE_S:g})")
    args = parser.parse_args(argv)
    listen = None if args.connect else (args.listen or DEFAULT_ENDPOINT)
    return WorldOptions(
        run_id=args.run,
        scenario_path=args.scenario,
        listen=listen,
        connect=args.connect,
        rate_hz=args.rate_hz,
        time_scale=args.time_scale,
        out_dir=args.out if args.out is not None else Path("runs") / args.run,
        cmd_timeout_s=args.cmd_timeout_s,
        wait_robots_s=args.wait_robots_s,
        control_rate_hz=args.control_rate_hz,
        linger_s=max(0.0, args.linger_s),
        link=argtypes.link_faults(args),
        fault_seed=args.fault_seed,
        tls_dir=args.tls,
        relays=tuple(args.relay),
        zid=args.zid,
        lost_grace_s=args.lost_grace_s,
    )


def run_configs(scenario: Scenario, options: WorldOptions) -> dict[int, bytes]:
    """The encoded `RunConfigMsg` of every robot, served on the configuration queryable."""
    known = tuple(r.id for r in scenario.robots) + tuple(o.id for o in scenario.obstacles)
    static = StaticMap.of_obstacles(scenario.obstacles).rows()
    return {
        spec.id: RunConfigMsg(
            run_id=options.run_id,
            robot=spec,
            planner=scenario.planner_config,
            goal_tolerance_m=scenario.goal_tolerance_m,
            control_rate_hz=options.control_rate_hz,
            world_rate_hz=options.rate_hz,
            time_scale=options.time_scale,
            time_limit_s=scenario.time_limit_s,
            cmd_timeout_s=options.cmd_timeout_s,
            known_ids=known,
            static_map=static,
        ).encode()
        for spec in scenario.robots
    }


class WorldNode:
    """The world's Zenoh edge around its `WorldCycle`: declarations, the loops, the recorder.

    Args:
        session: an open Zenoh session (closed by the caller).
        scenario: the loaded scenario.
        options: command-line options.
        recorder: the run directory writer.
        stop: polled; set by the signal handlers.
    """

    def __init__(self, session: zenoh.Session, scenario: Scenario, options: WorldOptions,
                 recorder: RunRecorder, stop: StopFlag) -> None:
        self.keys = RunKeys(options.run_id)
        self.session_zid = session.zid()
        self.options = options
        self.recorder = recorder
        self.stop = stop
        self.cycle = WorldCycle(scenario, options.run_id, cmd_timeout_s=options.cmd_timeout_s,
                                link=options.link, fault_seed=options.fault_seed,
                                lost_grace_s=options.lost_grace_s,
                                configs=run_configs(scenario, options))
        self.sim = self.cycle.sim
        self.dt_s = 1.0 / options.rate_hz
        self.tick_s: list[float] = []
        """Wall time of every tick of the loop (`tick`: drain, step, publish, record)."""

        n = len(scenario.robots)
        # Handler channels, read from the loop: callbacks never run project code.
        self.queryable = session.declare_queryable(self.keys.config_all)
        # Commands are stamped on arrival (the callback only stamps and enqueues; the loop
        # decodes): the wall stage "command received by the world" is the arrival, not the
        # next tick that drains it.
        self.cmd_queue: deque[tuple[int, zenoh.Sample]] = deque(maxlen=max(1024, 32 * n))
        self.cmd_sub = session.declare_subscriber(self.keys.cmd_all, self._on_command)
        self.clock_id = monotonic_clock_id()
        # Plans' internals for run.mcap: a ring (a flood drops the oldest, never blocks).
        self.debug_sub = session.declare_subscriber(
            self.keys.debug_all, zenoh.handlers.RingChannel(max(256, 8 * n)))
        self.alive_sub = session.liveliness().declare_subscriber(
            self.keys.alive_robot_all, history=True)
        # One publisher per pose slot and cell, declared when first used: tick t goes out
        # on poses/<t mod K>/<i>/<j>, so a robot that plans once a control period on a fixed
        # tick receives only its slot's poses, and only of the cells near it.
        self.session = session
        self.pose_slots = pose_slot_count(options.rate_hz, options.control_rate_hz)
        self.poses_pubs: dict[tuple[int, Cell], zenoh.Publisher] = {}
        for cell in self.cycle.published_cells():  # the start's, ready before the robots come
            for slot in range(self.pose_slots):
                self.poses_pub(slot, cell)
        # Start/end are rare and must arrive: reliable and blocking (a hung robot can hold
        # it up at most one transport lease, 1 s, before its link is closed).
        self.control_pub = session.declare_publisher(
            self.keys.control, congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE)
        self.control_sn = 0
        # Declared last: a robot that sees it knows the world is ready to serve.
        self.token = session.liveliness().declare_token(self.keys.alive_world)

    def put_control(self, msg: ControlMsg) -> None:
        """Publish `msg` with the world's source info: robots accept control only from the
        session of the router they are connected to (the world)."""
        self.control_sn += 1
        self.control_pub.put(msg.encode(),
                             source_info=zenoh.SourceInfo(self.control_pub.id, self.control_sn))

    # --- draining the channels -------------------------------------------------------------

    def _event(self, kind: str, **fields: object) -> None:
        self.recorder.event(kind, self.sim.t_s, **fields)

    def write_events(self) -> None:
        """Write the cycle's events (with the wall time where it asks) and log its notices."""
        for e in self.cycle.take_events():
            extra = {"wall": time.time()} if e.wall else {}
            self.recorder.event(e.kind, e.t_s, **e.fields, **extra)
        for text in self.cycle.take_notices():
            log.warning("%s", text)

    def poll_liveliness(self) -> None:
        """Track which robot processes are alive (`WorldCycle.liveliness`)."""
        while (sample := self.alive_sub.try_recv()) is not None:
            self.cycle.liveliness(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
        self.write_events()

    def serve_queries(self) -> None:
        """Answer configuration queries: ``config/<id>`` -> that robot's `RunConfigMsg`."""
        while (query := self.queryable.try_recv()) is not None:
            with query:
                key = str(query.key_expr)
                reply = self.cycle.config_reply(key)
                if reply is None:
                    query.reply_err(f"no robot configuration at {key}".encode())
                else:
                    query.reply(*reply)

    def apply_commands(self) -> None:
        """Hand each queued command to `WorldCycle.admit_command`, apply what the command
        links release and record it."""
        while self.cmd_queue:
            rx_ns, sample = self.cmd_queue.popleft()
            self.cycle.admit_command(str(sample.key_expr), sample.payload.to_bytes(), rx_ns)
        for applied in self.cycle.release_commands():
            applied_ns = time.monotonic_ns()
            rid, msg = applied.robot_id, applied.msg
            self.recorder.record_command(
                self.sim.t_s, rid, msg.seq, msg.pose_stamp_s, msg.v_mps, msg.omega_radps,
                msg.plan_ms, msg.status, msg.side, msg.resolved_id)
            w = msg.wall
            self.recorder.record_timing(rid, msg.seq, (
                w.clock_id, w.pose_clock_id, w.pose_pub_ns, w.pose_rx_ns, w.plan_start_ns,
                w.plan_end_ns, w.pub_ns, applied.rx_ns, applied_ns))
        self.write_events()

    def record_plans(self) -> None:
        """Record each robot's valid plan internals (run.mcap only)."""
        while (sample := self.debug_sub.try_recv()) is not None:
            got = self.cycle.plan_debug(str(sample.key_expr), sample.payload.to_bytes())
            if got is not None:
                rid, msg = got
                self.recorder.record_plan(msg.t_s, rid, msg.debug, v_mps=msg.v_mps,
                                          omega_radps=msg.omega_radps, status=msg.status)
        self.write_events()

    def _on_command(self, sample: zenoh.Sample) -> None:
        """Zenoh's thread: stamp the arrival and enqueue (the deque drops the oldest)."""
        self.cmd_queue.append((time.monotonic_ns(), sample))

    # --- phases ------------------------------------------------------------------------------

    def wait_for_robots(self) -> bool:
        """Until every robot is alive (True) or the deadline / a signal (False)."""
        deadline = time.monotonic() + self.options.wait_robots_s
        robot_ids = self.cycle.robot_ids
        while not self.stop:
            self.poll_liveliness()
            self.serve_queries()
            self.apply_commands()
            if self.cycle.alive >= robot_ids:
                return True
            if time.monotonic() > deadline:
                missing = sorted(robot_ids - self.cycle.alive)
                self._event("startup_timeout", missing=missing)
                log.error("robots %s not alive after %.1f s", missing, self.options.wait_robots_s)
                return False
            time.sleep(IDLE_POLL_S)
        return False

    def poses_pub(self, slot: int, cell: Cell) -> zenoh.Publisher:
        """The publisher of one pose slot and cell (declared on first use).

        DROP, so a slow robot never holds the world up, but not express: a tick's cells go
        out as a burst, and an express message takes a transmission batch of its own, of
        which Zenoh's data queue holds a few per link; a burst larger than that, while the
        link's thread was not scheduled within `wait_before_drop` (1 ms), lost cells on a
        loaded machine. Batched, a tick's cells share a frame, sent as soon as the link's
        thread runs (Zenoh holds a batch back only under back-pressure)."""
        pub = self.poses_pubs.get((slot, cell))
        if pub is None:
            pub = self.poses_pubs[(slot, cell)] = self.session.declare_publisher(
                self.keys.poses_cell(slot, cell),
                congestion_control=zenoh.CongestionControl.DROP, express=False)
        return pub

    def publish_poses(self) -> None:
        """The current ground truth, one `PosesMsg` per published cell (dropped, never
        blocking, if slow), on the pose slot of the current tick."""
        tick = self.sim.tick
        slot = pose_slot_of_tick(tick, self.pose_slots)
        for cell, payload in self.cycle.pose_cells(time.monotonic_ns(), self.clock_id):
            pub = self.poses_pub(slot, cell)
            pub.put(payload, source_info=zenoh.SourceInfo(pub.id, tick))

    def tick(self) -> None:
        """Apply commands, step the world by dt, publish and record."""
        self.poll_liveliness()
        self.serve_queries()
        self.apply_commands()
        self.record_plans()
        self.cycle.step(self.dt_s)
        self.publish_poses()
        self.recorder.record_tick(self.sim.t_s, self.sim.robot_ids, self.sim.pose,
                                  self.sim.applied)
        if self.sim.tick % FLUSH_TICKS == 0:  # watchers (the launcher's fault schedule)
            self.recorder.flush()             # follow sim time in trajectory.csv
        self.write_events()

    def run_loop(self) -> str:
        """The fixed-rate loop; returns the end reason."""
        period_wall = self.dt_s / self.options.time_scale
        self.publish_poses()  # tick 0: robots plan from the start poses at once
        self.recorder.record_tick(self.sim.t_s, self.sim.robot_ids, self.sim.pose,
                                  self.sim.applied)
        next_wall = time.monotonic() + period_wall
        while True:
            delay = next_wall - time.monotonic()
            if delay > 0.0:
                time.sleep(delay)
            elif delay < -period_wall:
                self.cycle.counts.overruns += 1
                next_wall = time.monotonic()  # resynchronise rather than burst to catch up
            next_wall += period_wall
            if self.stop:
                return "signal"
            t0 = time.perf_counter()
            self.tick()
            self.tick_s.append(time.perf_counter() - t0)
            reason = self.cycle.end_reason()
            if reason is not None:
                return reason

    def finish(self, reason: str) -> int:
        """Announce the end, record the summary, let robots leave; return the exit status."""
        cycle, sim = self.cycle, self.sim
        end = cycle.end(reason, tick_ms=_tick_summary(self.tick_s))
        self.put_control(ControlMsg("end", sim.t_s, reason))
        self.recorder.event(end.kind, end.t_s, **end.fields)
        log.info("end: %s at t=%.2f s, %d/%d arrived, %d contacts, %d rejected, %d stale",
                 reason, sim.t_s, len(end.fields["arrived"]), len(cycle.robot_ids),
                 sim.contact_count, cycle.counts.rejected, cycle.counts.stale)
        # Robots leave on the end message; a further signal cuts the wait short.
        deadline = time.monotonic() + self.options.linger_s
        signals = self.stop.count
        while cycle.alive and time.monotonic() < deadline and self.stop.count == signals:
            self.poll_liveliness()
            time.sleep(IDLE_POLL_S)
        return ExitCode.of_run(contacts=sim.contact_count, all_arrived=sim.all_arrived(),
                               robots_lost=bool(cycle.lost), interrupted=reason == "signal")

    def run(self) -> int:
        """Wait for the robots, run, finish."""
        n_robots = len(self.cycle.robot_ids)
        self._event("world_ready", run=self.options.run_id, n_robots=n_robots,
                    endpoint=self.options.listen or self.options.connect,
                    tls=self.options.tls_dir is not None, zid=str(self.session_zid),
                    relays={router_cn(name): list(ids) for name, ids in self.options.relays},
                    wall=time.time())
        log.info("run %s: waiting for %d robots", self.options.run_id, n_robots)
        if not self.wait_for_robots():
            self.finish("signal" if self.stop else "startup_timeout")
            return ExitCode.INTERRUPTED if self.stop else ExitCode.ROBOT_LOST
        self.put_control(ControlMsg("start", self.sim.t_s))
        self._event("start", mode="distributed", n_robots=n_robots,
                    cmd_link=self.options.link.as_dict(), fault_seed=self.options.fault_seed,
                    world_rate_hz=self.options.rate_hz,
                    control_rate_hz=self.options.control_rate_hz,
                    time_scale=self.options.time_scale, wall=time.time())
        log.info("start")
        return self.finish(self.run_loop())


def _tick_summary(tick_s: list[float]) -> dict[str, float] | None:
    """Median, 99th percentile, mean and largest tick wall time [ms], or None."""
    if not tick_s:
        return None
    ordered = sorted(tick_s)
    n = len(ordered)
    return {"p50": round(ordered[n // 2] * 1e3, 4),
            "p99": round(ordered[min(n - 1, math.ceil(0.99 * n) - 1)] * 1e3, 4),
            "mean": round(sum(ordered) / n * 1e3, 4), "max": round(ordered[-1] * 1e3, 4)}


def world_settings(options: WorldOptions, scenario: Scenario) -> dict[str, str]:
    """The world's Zenoh settings: a router on `options.listen` (with TLS: mutual TLS and the
    run's access control, relays included), or, without TLS only, a client of
    `options.connect`.

    Raises:
        agent.flags.FlagError: TLS with `connect` (the access control is enforced by the
            world's own router), a TLS file that is missing or unreadable, relays without
            TLS, or plain TCP on every interface.
        ValueError: a plain endpoint with TLS, or relays naming robots that are not in the
            scenario.
    """
    tls = None
    if options.tls_dir is not None:
        if options.connect:
            raise argtypes.FlagError(
                "--tls", "--tls with --connect: the world's own router enforces the run's "
                "access control; robots on other hosts reach it through a relay router "
                "(python -m world.router), so the world listens")
        tls = TlsFiles.in_dir(options.tls_dir, WORLD_CN)
        problem = check_tls_files(tls)
        if problem:
            raise argtypes.FlagError("--tls", f"--tls {options.tls_dir}: {problem}")
    if options.relays and tls is None:
        raise argtypes.FlagError("--relay", "--relay needs --tls: relays are told apart by "
                                 "their certificates")
    if options.connect:
        return session_settings(mode="client", connect=[options.connect],
                                connect_timeout_ms=int(options.wait_robots_s * 1e3),
                                zid=options.zid)
    listen = options.listen or DEFAULT_ENDPOINT
    if tls is None and argtypes.every_interface(listen):
        raise argtypes.FlagError("--listen", f"--listen {listen}: every interface only with "
                                 "--tls (mutual TLS and access control); plain TCP listens "
                                 "on one address")
    acl = None
    if tls is not None:
        acl = access_control(options.run_id, [r.id for r in scenario.robots],
                             relays=dict(options.relays))
    return session_settings(mode="router", listen=[listen], tls=tls, acl=acl, zid=options.zid)


def run_world(options: WorldOptions) -> int:
    """Run the world process to the end; returns its exit status.

    If the session cannot be closed in time, the process leaves with `os._exit` once the
    run directory is closed.
    """
    try:
        scenario = load_scenario(options.scenario_path)
    except ScenarioError as exc:
        log.error("%s", exc)
        return ExitCode.BAD_INPUT
    with stop_on_signals() as stop:
        try:
            recorder = RunRecorder(options.out_dir, scenario)
        except UnsafePathError as exc:
            log.error("%s", exc)
            return ExitCode.BAD_INPUT
        except OSError as exc:  # a file of the run there already (or a symlink), unwritable
            log.error("--out %s: cannot write %s: %s", options.out_dir,
                      Path(exc.filename or "").name or "the run", exc.strerror or exc)
            return ExitCode.BAD_INPUT
        try:
            try:
                settings = world_settings(options, scenario)
            except ValueError as exc:
                log.error("%s", exc)
                flag = exc.flag if isinstance(exc, argtypes.FlagError) else None
                recorder.event("end", 0.0, reason="bad_input", success=False, error=str(exc),
                               flag=flag)
                return ExitCode.BAD_INPUT
            try:
                session = open_session(settings)
            except SessionError as exc:
                log.error("cannot open the Zenoh session (%s): %s",
                          options.listen or options.connect, exc)
                recorder.event("end", 0.0, reason="transport_error", success=False,
                               error=str(exc))
                return ExitCode.TRANSPORT
            try:
                code = WorldNode(session, scenario, options, recorder, stop).run()
            except BaseException:
                close_session(session)
                raise
            recorder.close()  # the run directory is complete before the transport closes
            if not close_session(session):
                log.error("session close timed out; leaving without it")
                logging.shutdown()
                os._exit(code)
            return code
        finally:
            recorder.close()


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m world``."""
    die_with_launcher()
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s world %(levelname)s %(message)s")
    return run_world(parse_args(argv))
