"""The robot process: the Zenoh edge around one `agent.robot_cycle.RobotCycle`.

One OS process per robot, a Zenoh client of the run's router (multicast scouting off,
explicit endpoint). It knows nothing but what arrives on the wire (see `eifp_wire`). Every
decision (what a pose does, when to plan, what to send, what to count, when the world is
lost) is the cycle's; this module reads the clocks and the wire, feeds them in, publishes
what comes out and logs.

1. Connect (retrying until ``--startup-timeout-s``), fetch this robot's `RunConfigMsg` from
   the world's queryable (retrying with the same deadline), build the cycle (`make_cycle`).
2. Declare one pose subscriber per cell the robot holds (`world.sim.cells`; Zenoh's
   receiving thread puts each sample on a queue the loop blocks on, `PoseInbox`; the loop
   keeps the newest `POSE_RING` of them: the robot acts on the newest tick, never a
   backlog), the control subscriber, the
   world-liveliness subscriber, the command publisher (DROP, express), the debug publisher
   (its plans' internals for viewers, `PlanDebugMsg`, DROP, express) and, last, its own
   liveliness token.
3. Loop: drain control and liveliness (their callbacks fill an `Inbox` each), hand the
   ring to `RobotCycle.sense` (which assembles one view per tick from the cells'
   messages), make the subscription changes it asks for (`CellPoses`: subscribe to new
   cells before dropping old ones), and when a planning slot is due plan, publish one
   `CommandMsg` and the plan's `PlanDebugMsg`. ``--plan-delay-ms`` holds every command back
   that long (a CPU-starved robot).

It exits 0 on the ``end`` `ControlMsg` and on SIGTERM/SIGINT/SIGHUP, and with
`ExitCode.WORLD_LOST` when the world's token stays away past its grace
(`agent.robot_cycle.WorldWatch`) or no pose arrives for ``--pose-timeout-s`` while running.
Once its signal handlers are in place it logs its start line, ``robot <id> start:
{"run": ..., "connect": ...}`` (JSON: the run and the endpoint it dials, before it connects).
On exit it logs one line ``robot <id> exit: reason='...' code=N rejected=N stale=N ...
seq=N cpu_sense_us=N ...`` to stderr: the counters of `agent.robot_cycle.RobotCounters`,
the last seq and `CpuMeter.summary`. The launcher collects both lines into ``robots.json``
(`orchestrator.experiments.distributed.collect_robot_exits`).

Exit status (`agent.process.ExitCode`): OK (end of run, or a signal), TRANSPORT (cannot
connect before the startup deadline), BAD_INPUT (no valid configuration), WORLD_LOST (the
world is gone).

Planning slots are staggered over the world's ticks (`world.sim.schedule.plan_phase_s`:
robot k plans on the ticks k mod 5 of each 0.1 s period), so only a fifth of the robots
plan on any one pose. The world publishes tick t on the pose slot ``poses/<t mod 5>/...``
(`world.sim.schedule.pose_slot_count`) and a robot subscribes to the one slot its plans fall
on (`world.sim.schedule.plan_pose_slot`): it receives and decodes 10 ticks per second
instead of 50, and the router sends a fifth of the bytes. A robot whose plan slots are not
on one pose slot (``--control-phase-s`` between ticks, ``--control-rate-hz`` 20 ...)
subscribes to its cells on every slot (``poses/*/<i>/<j>``). The exit line also has the
pose messages and bytes the robot received (``rx_pose_msgs``, ``rx_pose_bytes``) and the
assembler's counts (``cells_held``, ...). Between poses the loop blocks on the pose queue
(woken by the pose itself: no polling while the world runs late), at most `MAX_NAP_S`.
Zenoh runs on one thread of the process (`agent.process.use_one_zenoh_thread`). A robot's
cost per cycle is in docs/scale.md (`orchestrator bench --process`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import queue
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from typing import Protocol

import zenoh

from agent.process import (
    ExitCode,
    StallWatch,
    StopFlag,
    close_session,
    die_with_launcher,
    enqueue_on_receive,
    monotonic_clock_id,
    stop_on_signals,
    use_one_zenoh_thread,
)
from agent.robot_cycle import REJOIN_GRACE_S, RobotCycle, is_world
from agent.startup import (
    AgentOptions,
    RobotExit,
    connect,
    fetch_config,
    make_controller,
    parse_args,
    warm_up,
    world_zid_of,
)
from eifp_wire import RunConfigMsg, RunKeys, plan_pose_slot, pose_slot_count
from world.sim.cells import Cell, CellChange
from world.sim.link import LINK_POSES, FaultyLink, link_rng
from world.sim.schedule import PlanSchedule, plan_phase_s

POSE_RING = 32
"""The world's newest pose samples a robot keeps after draining its queue (older ones are
dropped unread): two ticks of the 3 x 3 cells a robot holds at most, and more."""
MAX_NAP_S = 0.25
"""Longest wait for a pose: without poses, control and liveliness messages are read at least
this often. Longer than the control period, so a robot receiving its poses wakes for them
only (a wait as long as the period ran out just before every other pose)."""
CPU_TOKEN_WAIT_S = 0.05
"""Longest wait for a CPU token (`cpu_token`) before planning without one."""


class CpuTokens(Protocol):
    """A counting semaphore shared by the robots of one host (e.g. multiprocessing's)."""

    def acquire(self, block: bool = True, timeout: float | None = None) -> bool: ...

    def release(self) -> None: ...


log = logging.getLogger("agent")


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


def source_zid(sample: zenoh.Sample) -> str | None:
    """The Zenoh id of the session that published `sample`, if it says."""
    info = sample.source_info
    return None if info is None else str(info.source_id.zid)


class PoseInbox:
    """The world's pose samples: Zenoh's receiving thread puts each on `queue` (a C call, no
    Python frame and no thread of ours in between); the loop blocks on the queue, so it wakes
    when a pose arrives, and moves what is queued into a ring of the newest `size`.

    A sample that is not from the world's session (`world_zid`; None: not checked) never
    enters the ring: a flood of forged poses must not push the world's out of it.
    """

    def __init__(self, world_zid: str | None, size: int = POSE_RING) -> None:
        self.world_zid = world_zid
        self.queue: queue.SimpleQueue[zenoh.Sample] = queue.SimpleQueue()
        self.ring: deque[zenoh.Sample] = deque(maxlen=size)
        self.rx_wall_s = 0.0
        """When the loop last took samples off the queue (monotonic): as they arrived."""
        self.rx_msgs = 0
        self.rx_bytes = 0
        """Pose samples (and their payload bytes) taken off the queue, refused ones too."""

    def wait(self, wait_s: float) -> tuple[float, list[str | None]]:
        """Block until a sample arrives or `wait_s` passed, then move every queued sample
        into the ring; returns (seconds waited, the sources of the samples refused)."""
        napped = time.monotonic()
        try:
            sample = self.queue.get(timeout=wait_s)
        except queue.Empty:
            return time.monotonic() - napped, []
        self.rx_wall_s = time.monotonic()
        refused: list[str | None] = []
        while True:
            self.rx_msgs += 1
            self.rx_bytes += len(sample.payload)
            zid = None if self.world_zid is None else source_zid(sample)
            if self.world_zid is None or is_world(zid, self.world_zid):
                self.ring.append(sample)
            else:
                refused.append(zid)
            if self.queue.empty():
                return self.rx_wall_s - napped, refused
            sample = self.queue.get_nowait()

    def take(self) -> list[tuple[str, bytes]]:
        """The ring's samples as (key expression, payload), oldest first; the ring is left
        empty."""
        samples = [(str(sample.key_expr), sample.payload.to_bytes()) for sample in self.ring]
        self.ring.clear()
        return samples

    def summary(self) -> dict[str, int]:
        """``rx_pose_msgs`` and ``rx_pose_bytes`` for the exit line."""
        return {"rx_pose_msgs": self.rx_msgs, "rx_pose_bytes": self.rx_bytes}


class CellPoses:
    """A robot's pose subscribers, one per cell it holds (and one on every cell while it
    searches for itself), all feeding one `PoseInbox`.

    Args:
        session: the robot's session.
        keys: the run's keys.
        slot: the pose slot the robot plans on (None: every slot).
        inbox: where every sample goes.
    """

    def __init__(self, session: zenoh.Session, keys: RunKeys, slot: int | None,
                 inbox: PoseInbox) -> None:
        self.session, self.keys, self.slot = session, keys, slot
        self.handler = enqueue_on_receive(inbox.queue.put)
        self.subs: dict[Cell, zenoh.Subscriber[None]] = {}
        self.every: zenoh.Subscriber[None] | None = None

    def _declare(self, key: str) -> zenoh.Subscriber[None]:
        return self.session.declare_subscriber(key, self.handler)

    def hold(self, cells: Iterable[Cell]) -> None:
        """Subscribe to `cells`."""
        for cell in sorted(cells):
            if cell not in self.subs:
                self.subs[cell] = self._declare(self.keys.poses_cell(self.slot, cell))

    def apply(self, change: CellChange) -> None:
        """Subscribe to what `change` adds (or to every cell), then drop what it drops."""
        self.hold(change.added)
        if change.search and self.every is None:
            self.every = self._declare(self.keys.poses_every_cell(self.slot))
        for cell in change.dropped:
            sub = self.subs.pop(cell, None)
            if sub is not None:
                sub.undeclare()
        if change.found and self.every is not None:
            self.every.undeclare()
            self.every = None


@contextlib.contextmanager
def cpu_token(tokens: CpuTokens | None, wanted: bool, stalls: StallWatch
              ) -> Iterator[bool | None]:
    """Hold one of the host's CPU tokens for the block, if there are tokens and `wanted`.

    With tokens (`agent.fleet` hands them out, one per core) at most that many robots of a
    host compute at once and each runs its cycle to the end instead of being time-sliced
    against every other runnable robot: when they want more CPU than there is, the first in
    line are on time and the queue's tail is late, instead of all of them late. A robot that
    gets no token within `CPU_TOKEN_WAIT_S` goes ahead without one: a lost token costs
    throughput, never a stop. The token is given back however the block ends.

    Yields:
        True if a token is held, False if none came in time, None if none was asked for.
    """
    if tokens is None or not wanted:
        yield None
        return
    asked = time.monotonic()
    held = tokens.acquire(timeout=CPU_TOKEN_WAIT_S)
    stalls.waited(time.monotonic() - asked, CPU_TOKEN_WAIT_S)
    try:
        yield held
    finally:
        if held:
            tokens.release()


class CpuMeter:
    """CPU time of the robot's loop by part: this (the main) thread's CPU clock spent
    sensing, planning and sending, and the process's CPU clock, from `start`."""

    PARTS = ("sense", "plan", "send")

    def __init__(self) -> None:
        self.spent_s = dict.fromkeys(self.PARTS, 0.0)
        self.started: tuple[float, float] | None = None

    def start(self) -> None:
        """The loop starts: every part is counted from now."""
        self.started = (time.thread_time(), time.process_time())

    def add(self, part: str, cpu_s: float) -> None:
        """Count `cpu_s` of this thread's CPU time to `part`."""
        self.spent_s[part] += cpu_s

    def summary(self) -> dict[str, int]:
        """CPU time since `start`, by part, in whole microseconds.

        ``cpu_sense_us``: draining the pose ring, decoding, the pose link, observing;
        ``cpu_plan_us``: `RobotController.plan` (estimates, planner, MPC); ``cpu_send_us``:
        encoding and publishing the command; ``cpu_loop_us``: the rest of the main thread
        (control and liveliness polls, waiting, taking samples off the queue);
        ``cpu_threads_us``: every other thread of the process (Zenoh's runtime: receiving,
        putting the pose samples on the queue, sending, the lease). Empty before `start`.
        `orchestrator scale` divides them by the plans.
        """
        if self.started is None:
            return {}
        main_s = time.thread_time() - self.started[0]
        process_s = time.process_time() - self.started[1]
        parts = {**self.spent_s, "loop": main_s - sum(self.spent_s.values()),
                 "threads": process_s - main_s}
        return {f"cpu_{k}_us": max(0, round(v * 1e6)) for k, v in parts.items()}


def make_cycle(options: AgentOptions, config: RunConfigMsg, world_zid: str | None,
               refused_config: int = 0) -> RobotCycle:
    """The robot's `RobotCycle`: its controller (warmed up), planning slots and pose link."""
    period_s = 1.0 / (options.control_rate_hz or config.control_rate_hz)
    controller = make_controller(config, period_s, compensate_latency=options.compensate_latency)
    warm_up(config, period_s)
    return RobotCycle(
        config, controller, PlanSchedule(period_s, _phase_s(options, config)),
        link=FaultyLink(options.link, link_rng(options.fault_seed, LINK_POSES, config.robot.id)),
        world_zid=world_zid, plan=options.plan, refused_config=refused_config)


def _phase_s(options: AgentOptions, config: RunConfigMsg) -> float:
    """The planning slots' phase: the injected one if given, else spread over the ticks."""
    if options.control_phase_s:
        return options.control_phase_s
    period_s = 1.0 / (options.control_rate_hz or config.control_rate_hz)
    return plan_phase_s(config.robot.id, period_s, 1.0 / config.world_rate_hz)


class RobotNode:
    """One robot's Zenoh edge around its `RobotCycle`: declarations, clocks, the loop, logs.

    Args:
        session: an open client session (closed by the caller).
        options: command-line options.
        config: this robot's configuration from the world.
        stop: polled; set by the signal handlers.
        cpu_tokens: the host's CPU tokens (`cpu_token`), or None.
        world_zid: the world's Zenoh id (`world_zid_of`), or None.
        refused_config: configuration replies refused while fetching `config`.
    """

    def __init__(self, session: zenoh.Session, options: AgentOptions, config: RunConfigMsg,
                 stop: StopFlag, cpu_tokens: CpuTokens | None = None,
                 world_zid: str | None = None, refused_config: int = 0) -> None:
        self.keys = RunKeys(options.run_id)
        self.options = options
        self.cpu_tokens = cpu_tokens
        self.robot_id = config.robot.id
        self.stop = stop
        self.cycle = make_cycle(options, config, world_zid, refused_config)
        self.cpu = CpuMeter()
        self.clock_id = monotonic_clock_id()
        self.stalls = StallWatch()
        # Only the pose slot this robot plans on (a K-th of the stream, K = world ticks per
        # control period), or every slot if its plan slots are not all on one of them.
        schedule = self.cycle.schedule
        self.pose_slot = plan_pose_slot(
            schedule.period_s, schedule.phase_s or 0.0, 1.0 / config.world_rate_hz,
            pose_slot_count(config.world_rate_hz, config.control_rate_hz))
        self.poses = PoseInbox(world_zid)
        self.pose_subs = CellPoses(session, self.keys, self.pose_slot, self.poses)
        self.pose_subs.hold(self.cycle.cells.cells or ())
        log.info("robot %d: poses of cells %s on slot %s", self.robot_id,
                 sorted(self.pose_subs.subs), "*" if self.pose_slot is None else self.pose_slot)
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

    def _log_notices(self) -> None:
        for text in self.cycle.take_notices():
            log.warning("%s", text)

    def poll_control(self) -> None:
        """Start/end announcements; raises `RobotExit` on the end (`RobotCycle.control`)."""
        while (sample := self.control_sub.try_recv()) is not None:
            reason = self.cycle.control(sample.payload.to_bytes(), source_zid(sample))
            self._log_notices()
            if reason is not None:
                raise RobotExit(reason, ExitCode.OK)

    def poll_world(self) -> None:
        """World liveliness; raises `RobotExit` if the world is gone before the end
        (`agent.robot_cycle.WorldWatch`). The robot sends nothing meanwhile."""
        now = time.monotonic()
        watch = self.cycle.world
        while (sample := self.world_sub.try_recv()) is not None:
            if sample.kind == zenoh.SampleKind.PUT:
                gone_s = watch.appeared(now)
                if gone_s is not None:
                    log.warning("robot %d: world back after %.2f s", self.robot_id, gone_s)
            elif watch.alive:
                self.poll_control()  # the end message may have been queued just before
                if watch.vanished(now) == REJOIN_GRACE_S:
                    log.warning("robot %d: world token gone right after a suspension; "
                                "waiting %.1f s for it", self.robot_id, REJOIN_GRACE_S)
        reason = watch.lost(now)
        if reason is not None:
            raise RobotExit(reason, ExitCode.WORLD_LOST)

    def poll_poses(self) -> bool:
        """Hand the ring to `RobotCycle.sense`; True if a fresh pose was observed.

        What was queued since the loop's wait goes in too: a robot that was not scheduled
        for a while must not take a tick's cells for lost while they wait in its queue."""
        if not self.poses.queue.empty():
            self._refuse(self.poses.wait(0.0)[1])
        fresh = self.cycle.sense(self.poses.take(), self.poses.rx_wall_s, time.monotonic())
        for change in self.cycle.take_cell_changes():
            self.pose_subs.apply(change)
        self._log_notices()
        return fresh

    def plan_and_send(self, cpu_start_s: float | None = None) -> None:
        """Plan on the newest pose if its stamp reached the schedule; publish the command.

        The planner gets the sim clock's time, so it forward-predicts by the pose's real
        age (injected delay included). `cpu_start_s`: this thread's CPU clock when the caller
        stopped counting (counted from here on as planning); None: read it now.
        """
        cycle = self.cycle
        if not cycle.due():
            return
        now_s = cycle.clock.now_s(time.monotonic())
        cpu0 = time.thread_time() if cpu_start_s is None else cpu_start_s
        plan_start_ns = time.monotonic_ns()
        planned = cycle.plan(now_s)
        plan_end_ns = time.monotonic_ns()
        if planned.error is not None and cycle.counts.plan_errors <= 3:
            log.error("robot %d: planner raised; braking", self.robot_id,
                      exc_info=planned.error)
        cpu1 = time.thread_time()
        self.cpu.add("plan", cpu1 - cpu0)
        if self.options.plan_delay_ms > 0.0:  # a CPU-starved robot: the command leaves late
            delay_s = self.options.plan_delay_ms * 1e-3 / cycle.config.time_scale
            slept = time.monotonic()
            time.sleep(delay_s)
            self.stalls.waited(time.monotonic() - slept, delay_s)
            cpu1 = time.thread_time()
        command = cycle.command(planned, cycle.clock.now_s(time.monotonic()) - now_s)
        self.cmd_pub.put(command.encode(self.clock_id, plan_start_ns, plan_end_ns,
                                        time.monotonic_ns()))
        if command.debug is not None:
            self.debug_pub.put(command.debug.encode())
        self.cpu.add("send", time.thread_time() - cpu1)

    def sense_and_plan(self) -> bool:
        """`poll_poses`, then `plan_and_send` if a fresh pose came (and the world is seen),
        holding one of the host's CPU tokens meanwhile if the robot has them (`cpu_token`).

        Returns:
            True if a pose newer than any observed before was released.
        """
        with cpu_token(self.cpu_tokens, bool(self.poses.ring), self.stalls) as held:
            if held is False:
                self.cycle.counts.token_timeouts += 1
            cpu0 = time.thread_time()
            fresh = self.poll_poses()
            cpu1 = time.thread_time()
            self.cpu.add("sense", cpu1 - cpu0)
            if fresh and self.cycle.world.alive:  # never command a world we cannot see
                self.plan_and_send(cpu1)
            return fresh

    def wait_for_poses(self) -> None:
        """Block until a pose arrives, the pose link releases one, or `MAX_NAP_S` passed;
        then move every queued sample from the world into the ring (`PoseInbox.wait`).

        The loop wakes once per pose and is asleep otherwise: no polling, and nothing runs
        between the pose's arrival and the loop but Zenoh's own thread. A sample refused as
        not the world's is counted in ``refused_poses``.
        """
        wait_s = self.cycle.nap_s(time.monotonic(), MAX_NAP_S)
        waited_s, refused = self.poses.wait(wait_s)
        self.stalls.waited(waited_s, wait_s)
        self._refuse(refused)
        self._log_notices()

    def _refuse(self, sources: list[str | None]) -> None:
        """Count the pose samples refused as not the world's."""
        for zid in sources:
            self.cycle.refuse_pose(f"from {zid or 'an unnamed source'}")

    def run(self, startup_deadline: float) -> tuple[str, int]:
        """The robot's loop; returns (reason, exit status).

        Args:
            startup_deadline: monotonic time by which the world's token must have been seen
                (after that, the world owns the start: it ends the run if robots are missing).
        """
        cycle = self.cycle
        self.cpu.start()
        try:
            while not self.stop:
                stall_s = self.stalls.tick()
                if cycle.loop_stalled(stall_s, time.monotonic()):
                    log.warning("robot %d: resumed after %.2f s without running (suspended?)",
                                self.robot_id, stall_s)
                if not self.control_sub.empty():
                    self.poll_control()
                if not self.world_sub.empty() or cycle.world.gone_wall_s is not None:
                    self.poll_world()
                if not cycle.world.seen and time.monotonic() > startup_deadline:
                    raise RobotExit("world not seen before the startup deadline",
                                    ExitCode.WORLD_LOST)
                if (not self.sense_and_plan()
                        and cycle.pose_timed_out(time.monotonic(), self.options.pose_timeout_s)):
                    raise RobotExit(f"no poses for {self.options.pose_timeout_s:.1f} s",
                                ExitCode.WORLD_LOST)
                self.wait_for_poses()
            return "signal", ExitCode.OK
        except RobotExit as stop:
            return stop.reason, stop.code
        finally:
            # Stop commanding before anything else.
            self.cmd_pub.undeclare()
            self.debug_pub.undeclare()

    def summary(self) -> str:
        """Counters, the last seq and `CpuMeter.summary` as key=value pairs (integers)."""
        fields = {**self.cycle.summary_fields(), **self.poses.summary(), **self.cpu.summary()}
        return " ".join(f"{k}={v}" for k, v in fields.items())


def run_agent(options: AgentOptions, on_ready: Callable[[], None] | None = None,
              cpu_tokens: CpuTokens | None = None) -> int:
    """Run one robot process to its end; returns its exit status.

    `on_ready` is called once the robot's liveliness token is declared (`agent.fleet` uses
    it to start the next robot); `cpu_tokens`: see `cpu_token`.

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
    # the start line: where the robot dials, for the launcher (robots.json) and tests
    log.info("robot %d start: %s", options.robot_id,
             json.dumps({"run": options.run_id, "connect": options.connect}))
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
    except RobotExit as exc:
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
