"""A robot's per-cycle decisions (pure): what a pose does, when to plan, what to send.

The robot process (`agent.node.RobotNode`) is the Zenoh edge around one `RobotCycle`: it reads
the clocks and the wire, hands the cycle the payloads and the times (wall time as monotonic
seconds, `wall_s`), sends what the cycle returns and logs its notices. Nothing here reads a
clock, touches Zenoh or logs, so every decision is tested by calling it
(`tests/unit/agent/test_robot_cycle.py`).

- **Sensing** (`RobotCycle.sense`): the world sends each tick's poses as one message per
  cell of a grid, and the robot holds the cells near it (`world.sim.cells`). Every message
  of the pose ring is decoded with its cell's decoder (a malformed one is rejected and
  counted); one whose tick and time do not fit the robot's clock
  (`eifp_wire.clock.check_pose_time`) is refused (``refused_poses``). Each valid one sets the
  sim clock (`SimClock`) and goes to the `eifp_wire.pose_cells.CellAssembler`, which hands
  out one view per tick once that tick's cells are in (or lost: see there). The newest view
  (older ones are ``skipped``) passes through the injected pose link
  (`world.sim.link.FaultyLink`: injected faults act on a robot's whole tick, as in lockstep
  runs), and what the link releases is observed by the controller, which drops stale or
  out-of-order snapshots (``stale``). The robot's own position in a view it observed moves
  its cells (`world.sim.cells.CellSubscription.follow`); the changes wait in
  `RobotCycle.cell_changes` for the node to subscribe and unsubscribe.
- **Planning** (`RobotCycle.due`, `plan`, `command`): when the newest pose's stamp reaches the
  next planning slot (`world.sim.schedule.PlanSchedule`), plan for when the command will
  leave (the sim clock plus `RobotCycle.compute_s`); a pose older than `STALE_PLAN_S` gives a
  brake (``stale_plans``), a planner that raises gives a brake (``plan_errors``), and a plan
  that took longer than allowed for plus the command hold is sent as a brake
  (``late_plans``). Slots already passed are skipped (``overruns``).
- **The world's presence** (`WorldWatch`): a vanished liveliness token is given
  `WORLD_BLIP_GRACE_S` to come back, `REJOIN_GRACE_S` right after the robot's own suspension
  (a loop stall longer than `SUSPEND_GAP_S`, ``suspended``); then the robot leaves.

The sim clock is the newest pose's stamp *as it arrived from the world*, before any injected
fault, advanced by wall time x time_scale: it stands for the synchronised clock of a real
fleet, so the planner measures the true age of the poses it plans on.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Protocol

import numpy as np

from agent.core.types import PlanResult, PlanStatus, PoseSnapshot
from eifp_wire import (
    ControlMsg,
    PlanDebugMsg,
    PosesMsg,
    ProtocolError,
    RunConfigMsg,
    RunKeys,
    check_pose_time,
    encode_command,
    next_seq,
)
from eifp_wire.pose_cells import ASSEMBLY_WAIT_TICKS, HOLD_PERIODS, CellAssembler, PoseView
from world.sim.cells import Cell, CellChange, CellRule, CellSubscription
from world.sim.link import LINK_POSES, FaultyLink, LinkFaults, link_rng
from world.sim.schedule import PlanSchedule

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
`RobotCycle.compute_s`, at most `STALE_PLAN_S`): a spike is forgotten by half in about 7
plans. Chosen, not fitted: a tenth per control period forgets a start-up or crowd spike
within a few seconds while still covering the next few plans of a sustained overload."""
STALE_PLAN_S = 1.0
"""Poses older than this [sim s] when planning: brake instead (compensation is capped there)."""
MAX_KEYS_REMEMBERED = 256
"""Pose keys whose cell a robot remembers (`RobotCycle._cell_of`); more start it afresh."""


class Controls(Protocol):
    """What the cycle needs of a controller (`agent.planning.controller.RobotController`)."""

    command_hold_s: float

    def observe(self, snapshot: PoseSnapshot) -> bool: ...

    def plan(self, now_s: float) -> PlanResult: ...

    def brake(self) -> PlanResult: ...


@dataclass
class RobotCounters:
    """What a robot process counts; its exit line lists them in this order.

    Args:
        rejected: malformed pose or control messages.
        stale: poses the controller dropped as old or out of order.
        skipped: valid poses not observed because a newer one was in the ring.
        plans: commands sent.
        overruns: planning slots skipped.
        plan_errors: plans the planner raised on (sent as a brake).
        stale_plans: brakes sent because the newest pose was older than `STALE_PLAN_S`.
        late_plans: plans sent as a brake because they took longer than allowed for plus
            the command hold.
        link_dropped: poses the injected pose link lost.
        suspended: loop stalls longer than `SUSPEND_GAP_S`.
        token_timeouts: cycles run without a CPU token (none came in time).
        refused_poses: well-formed poses refused (not from the world's session, or a
            tick and time that do not fit the clock).
        refused_control: control messages not from the world's session.
        refused_config: configuration replies not from the world's session.
        unheld_poses: pose messages of a cell the robot no longer holds (in flight when it
            let the cell go).
    """

    rejected: int = 0
    stale: int = 0
    skipped: int = 0
    plans: int = 0
    overruns: int = 0
    plan_errors: int = 0
    stale_plans: int = 0
    late_plans: int = 0
    link_dropped: int = 0
    suspended: int = 0
    token_timeouts: int = 0
    refused_poses: int = 0
    refused_control: int = 0
    refused_config: int = 0
    unheld_poses: int = 0

    def as_dict(self) -> dict[str, int]:
        """Name -> count, in the exit line's order."""
        return asdict(self)


def worth_logging(n: int) -> bool:
    """Log the n-th of a kind of refusal: the first ten, then every hundredth."""
    return n <= 10 or n % 100 == 0


def is_world(source_zid: str | None, world_zid: str | None) -> bool:
    """True if a message's source session is the world's (always, when that is unknown)."""
    return world_zid is None or (source_zid is not None and source_zid == world_zid)


class SimClock:
    """The robot's sim clock: the newest pose's stamp, advanced by wall time x time_scale.

    Args:
        time_scale: sim seconds per wall second.
    """

    def __init__(self, time_scale: float) -> None:
        self.time_scale = time_scale
        self.tick = -1
        self.stamp_s = 0.0
        self.wall_s = 0.0

    @property
    def started(self) -> bool:
        """A pose has set the clock."""
        return self.tick >= 0

    def now_s(self, wall_s: float) -> float:
        """Sim time at monotonic wall time `wall_s`."""
        return self.stamp_s + (wall_s - self.wall_s) * self.time_scale

    def observe(self, tick: int, stamp_s: float, wall_s: float) -> None:
        """A pose of world tick `tick`, stamped `stamp_s`, arrived at `wall_s`: the clock
        moves to it if it is newer than the one it runs from."""
        if tick > self.tick:
            self.tick, self.stamp_s, self.wall_s = tick, stamp_s, wall_s

    def restart(self) -> None:
        """Forget the pose it runs from: the next accepted pose sets it (`started` is False
        until then, so no pose is refused as ahead of it)."""
        self.tick = -1


@dataclass
class WorldWatch:
    """What the robot knows of the world's liveliness token, in monotonic wall seconds.

    Args:
        alive: the token is present.
        seen: the token has been present at least once.
        gone_wall_s: when it vanished (None: present, or never seen).
        grace_s: how long it may stay away before the world counts as lost.
        resumed_wall_s: when this process last came back from a suspension.
    """

    alive: bool = False
    seen: bool = False
    gone_wall_s: float | None = None
    grace_s: float = WORLD_BLIP_GRACE_S
    resumed_wall_s: float = -math.inf

    def appeared(self, wall_s: float) -> float | None:
        """The token is present; returns how long it had been gone, or None if it was not."""
        gone = self.gone_wall_s
        self.alive = self.seen = True
        self.gone_wall_s = None
        return None if gone is None else wall_s - gone

    def vanished(self, wall_s: float) -> float | None:
        """The token is gone; returns the grace it gets, or None if it was not present.

        Right after this process's own suspension, whose link the lease surely closed, the
        grace is `REJOIN_GRACE_S`; otherwise `WORLD_BLIP_GRACE_S`."""
        if not self.alive:
            return None
        self.alive = False
        self.gone_wall_s = wall_s
        rejoining = wall_s - self.resumed_wall_s <= REJOIN_GRACE_S
        self.grace_s = REJOIN_GRACE_S if rejoining else WORLD_BLIP_GRACE_S
        return self.grace_s

    def lost(self, wall_s: float) -> str | None:
        """Why the robot leaves, if the token has been gone for longer than its grace."""
        gone = self.gone_wall_s
        if gone is None or wall_s - gone <= self.grace_s:
            return None
        if self.grace_s == REJOIN_GRACE_S:
            return f"world lost (token not back within {REJOIN_GRACE_S:.0f} s)"
        return "world lost (liveliness token gone)"


@dataclass(frozen=True)
class Planned:
    """A plan (or a brake) made on the newest pose at sim time `now_s`.

    Args:
        result: the planner's result, or a brake.
        now_s: the sim time it was made at.
        error: what the planner raised (the result is then a brake), or None.
    """

    result: PlanResult
    now_s: float
    error: Exception | None = None


@dataclass(frozen=True)
class RobotCommand:
    """A command to send, and the plan's internals for viewers (None for a brake).

    Args:
        robot_id: the robot.
        seq: the command's sequence number (`eifp_wire.clock.next_seq`).
        pose: the poses it was planned on.
        rx_ns: when the robot took those poses off its queue (monotonic ns).
        result: what to command.
        hold_s: how long the world may apply it.
        debug: the plan's internals, or None.
    """

    robot_id: int
    seq: int
    pose: PoseView
    rx_ns: int
    result: PlanResult
    hold_s: float
    debug: PlanDebugMsg | None = field(default=None, repr=False)

    def encode(self, clock_id: int, plan_start_ns: int, plan_end_ns: int,
               pub_ns: int) -> bytes:
        """The `CommandMsg` bytes, with the `WallStamps` of its way in their wire order."""
        r, pose = self.result, self.pose
        return encode_command(
            self.robot_id, self.seq, pose.t_s, float(r.v_mps), float(r.omega_radps),
            max(0.0, float(r.times.total_ms)), r.status, int(r.side),
            None if r.resolved_id is None else int(r.resolved_id), self.hold_s,
            [clock_id, pose.clock_id, pose.pub_ns, self.rx_ns, plan_start_ns, plan_end_ns,
             pub_ns])


class RobotCycle:
    """One robot's decisions, cycle by cycle (see the module docstring).

    Args:
        config: the robot's configuration from the world.
        controller: its controller.
        schedule: its planning slots.
        link: the injected pose link (None: none).
        world_zid: the world's Zenoh id; messages from other sessions are refused. None:
            nothing is checked.
        plan: False: brake every cycle without planning (``--no-plan``).
        refused_config: configuration replies refused before the cycle began.
    """

    def __init__(self, config: RunConfigMsg, controller: Controls, schedule: PlanSchedule, *,
                 link: FaultyLink[tuple[PoseView, int]] | None = None,
                 world_zid: str | None = None, plan: bool = True,
                 refused_config: int = 0) -> None:
        self.config = config
        self.robot_id = config.robot.id
        self.controller = controller
        self.schedule = schedule
        self.pose_link: FaultyLink[tuple[PoseView, int]] = (
            link if link is not None
            else FaultyLink(LinkFaults(), link_rng(0, LINK_POSES, self.robot_id)))
        self.world_zid = world_zid
        self.plan_enabled = plan
        self.keys = RunKeys(config.run_id)
        self.cells = CellSubscription(CellRule.of_config(config.planner), config.robot.start[:2])
        """The pose cells the robot holds; the node subscribes to them."""
        self.assembler = CellAssembler(
            config.known_ids, hold_s=HOLD_PERIODS * schedule.period_s,
            wait_s=ASSEMBLY_WAIT_TICKS / config.world_rate_hz / config.time_scale)
        self.assembler.hold(self.cells.cells or (), expected=True)
        self.cell_changes: list[CellChange] = []
        """Subscription changes for the node to make (`take_cell_changes`)."""
        self._key_cells: dict[str, Cell] = {}
        self._time_passed = (-1, -1.0)  # the (tick, time) of the last pose that passed
        self.counts = RobotCounters(refused_config=refused_config)
        self.clock = SimClock(config.time_scale)
        self.world = WorldWatch()
        self.seq = -1  # the last command's seq (`eifp_wire.clock.next_seq`); none yet
        self.compute_s = 0.0
        """How long [sim s] the robot expects its next plan to take, from sensing to
        sending: the longest recent plan time, decaying by `COMPUTE_DECAY` per plan, at most
        `STALE_PLAN_S`. The robot plans for the time its command will leave."""
        self.newest: PoseView | None = None
        self.newest_rx_ns = 0
        self.last_rx_wall_s: float | None = None
        self.notices: list[str] = []
        """Refusals and rejections worth a log line (`worth_logging`), for the edge to log
        and clear."""

    # --- counting ----------------------------------------------------------------------------

    def _note(self, verb: str, what: str, n: int, why: object) -> None:
        if worth_logging(n):
            self.notices.append(f"robot {self.robot_id}: {verb} {what} #{n}: {why}")

    def reject(self, what: str, exc: ProtocolError) -> None:
        """Count a malformed message."""
        self.counts.rejected += 1
        self._note("rejected", what, self.counts.rejected, exc)

    def refuse_pose(self, why: str) -> None:
        """Count a well-formed pose message refused (not the world's, or out of time)."""
        self.counts.refused_poses += 1
        self._note("refused", "pose message", self.counts.refused_poses, why)

    def take_notices(self) -> list[str]:
        """The notices since the last call."""
        out, self.notices = self.notices, []
        return out

    def summary_fields(self) -> dict[str, int]:
        """The counters, the assembler's (``cells_*``), the subscription changes and the
        last seq, as the exit line lists them."""
        return {**self.counts.as_dict(), **self.assembler.counts.as_dict(),
                "cell_changes": self.cells.changes, "seq": self.seq}

    def take_cell_changes(self) -> list[CellChange]:
        """The subscription changes since the last call, in order: for each, subscribe to
        what it adds before dropping what it drops."""
        out, self.cell_changes = self.cell_changes, []
        return out

    # --- the world's messages ----------------------------------------------------------------

    def from_world(self, source_zid: str | None) -> bool:
        """True if a message from session `source_zid` may be taken as the world's."""
        return is_world(source_zid, self.world_zid)

    def control(self, payload: bytes, source_zid: str | None) -> str | None:
        """A control message; returns the reason to leave (the run's end), or None.

        Only the world's session may end the run: another source is refused and counted."""
        if not self.from_world(source_zid):
            self.counts.refused_control += 1
            self._note("refused", "control message", self.counts.refused_control,
                       f"from {source_zid or 'an unnamed source'}")
            return None
        try:
            msg = ControlMsg.decode(payload)
        except ProtocolError as exc:
            self.reject("control message", exc)
            return None
        if msg.kind == "end":  # "start" needs no action: planning begins with the poses
            return f"end ({msg.reason})"
        return None

    def loop_stalled(self, stall_s: float, wall_s: float) -> bool:
        """The loop did not run for `stall_s` before `wall_s`; True if that was a suspension
        (counted, and the world's token then gets `REJOIN_GRACE_S`)."""
        if stall_s <= SUSPEND_GAP_S:
            return False
        self.counts.suspended += 1
        self.world.resumed_wall_s = wall_s
        # The clock ran on from a pose taken before the stop; if the world's sim time went
        # on further than the stall measured here (MAX_POSE_AHEAD_S or more), every pose
        # after it was refused as ahead, none could set the clock again, and the robot left
        # with "no poses" (tests/system/test_faults.py, SIGSTOP for 3 s, seen once in CI).
        # The next pose from the world's session sets it instead.
        self.clock.restart()
        return True

    def pose_timed_out(self, wall_s: float, timeout_s: float) -> bool:
        """No pose for `timeout_s` of wall time since the last one (or since a resumption)."""
        last = self.last_rx_wall_s
        return last is not None and wall_s - max(last, self.world.resumed_wall_s) > timeout_s

    def nap_s(self, wall_s: float, longest_s: float) -> float:
        """How long the loop may wait for a pose before the pose link releases one [wall s]."""
        nap_s = longest_s
        assembled = self.assembler.deadline_wall_s
        if assembled is not None:
            nap_s = min(nap_s, max(0.0, assembled - wall_s))
        due_s = self.pose_link.next_due_s
        if due_s is None:
            return nap_s
        return min(nap_s, max(0.0, (due_s - self.clock.now_s(wall_s)) / self.clock.time_scale))

    # --- sensing -------------------------------------------------------------------------------

    def _cell_of(self, key: str) -> Cell:
        """The cell of a pose key (`RunKeys.cell_of_poses`), remembered: a robot hears the
        same few keys every tick. Raises `ProtocolError`."""
        cell = self._key_cells.get(key)
        if cell is None:
            if len(self._key_cells) >= MAX_KEYS_REMEMBERED:
                self._key_cells.clear()
            cell = self._key_cells[key] = self.keys.cell_of_poses(key)[1]
        return cell

    def _valid(self, key: str, payload: bytes, wall_s: float) -> tuple[Cell, PosesMsg] | None:
        """The cell and message of one pose sample if it passes every check, else None
        (counted)."""
        try:
            cell = self._cell_of(key)
        except ProtocolError as exc:
            self.reject("pose message", exc)
            return None
        if not self.assembler.accepts(cell):
            self.counts.unheld_poses += 1
            return None
        try:
            msg = self.assembler.decode(cell, payload)
        except ProtocolError as exc:
            self.reject("pose message", exc)
            return None
        # The clock moves only on a pose that passed every check: a forged far-future
        # pose would otherwise make every genuine one look out of date. The cells of a tick
        # share its tick and time: they are checked once.
        if (msg.tick, msg.t_s) != self._time_passed:
            config = self.config
            why = check_pose_time(msg.tick, msg.t_s, world_rate_hz=config.world_rate_hz,
                                  time_limit_s=config.time_limit_s,
                                  clock_s=self.clock.now_s(wall_s) if self.clock.started
                                  else None, time_scale=config.time_scale)
            if why is not None:
                self.refuse_pose(f"{why}: tick {msg.tick}, t {msg.t_s:.3f} s")
                return None
            self._time_passed = (msg.tick, msg.t_s)
        return cell, msg

    def _assemble(self, samples: Sequence[tuple[str, bytes]], arrived_wall_s: float,
                  wall_s: float) -> PoseView | None:
        """Every valid message into the assembler; the newest view it releases (the older
        ones are ``skipped``)."""
        views: list[PoseView] = []
        assembler = self.assembler
        for key, payload in samples:
            valid = self._valid(key, payload, wall_s)
            if valid is None:
                continue
            cell, msg = valid
            self.last_rx_wall_s = arrived_wall_s
            self.clock.observe(msg.tick, msg.t_s, arrived_wall_s)
            forced = assembler.add(cell, msg, arrived_wall_s)
            if forced is not None:
                views.append(forced)
        view = assembler.ready(wall_s)
        if view is not None:
            views.append(view)
        self.counts.skipped += max(0, len(views) - 1)
        return views[-1] if views else None

    def _follow(self, change: CellChange) -> None:
        """Apply a subscription change to the assembler and queue it for the node."""
        if change.empty:
            return
        assembler = self.assembler
        assembler.hold(change.added, expected=False)
        if change.search:
            assembler.search()
        assembler.drop(change.dropped)
        if change.found:
            assembler.found(self.cells.cells or ())
        self.cell_changes.append(change)

    def _observe(self, view: PoseView) -> bool:
        """Hand a view to the controller; the robot's position in it moves its cells."""
        snapshot = view.snapshot
        rows = np.flatnonzero(snapshot.ids == self.robot_id)
        if not self.controller.observe(snapshot):
            self.counts.stale += 1
            if rows.size == 0:
                self._follow(self.cells.missed_self())
            return False
        x, y = snapshot.pose[int(rows[0]), :2].tolist()
        self._follow(self.cells.follow(x, y))
        return True

    def sense(self, samples: Sequence[tuple[str, bytes]], arrived_wall_s: float,
              wall_s: float) -> bool:
        """The pose ring's samples (key expression, payload), oldest first, taken off the
        queue at `arrived_wall_s`; returns True if a view newer than any observed before was
        released to the controller.

        Without injected faults the pose link is a no-op and is bypassed.
        """
        released: list[tuple[PoseView, int]] = []
        view = self._assemble(samples, arrived_wall_s, wall_s)
        if view is not None:
            released.append((view, round(view.rx_wall_s * 1e9)))
        link = self.pose_link
        if link.faults.active:
            now_s = self.clock.now_s(wall_s)
            for item in released:
                link.send(now_s, item)
            released = link.receive(now_s)
            self.counts.link_dropped = link.counts.dropped
        fresh = False
        for view, rx_ns in released:
            if self._observe(view):
                self.newest, self.newest_rx_ns = view, rx_ns
                fresh = True
        return fresh

    # --- planning ------------------------------------------------------------------------------

    def due(self) -> bool:
        """The newest pose's stamp has reached the next planning slot."""
        msg = self.newest
        return msg is not None and self.schedule.due(msg.t_s)

    def plan(self, now_s: float) -> Planned:
        """Plan on the newest pose at sim time `now_s` (call when `due`).

        The planner plans for when the command will leave (`now_s` + `compute_s`), so it
        forward-predicts by the pose's real age; a pose older than `STALE_PLAN_S`, or a
        planner that raises, gives a brake.
        """
        msg = self.newest
        assert msg is not None, "plan() without a pose"
        controller = self.controller
        try:
            if not self.plan_enabled:
                return Planned(controller.brake(), now_s)
            if now_s - msg.t_s > STALE_PLAN_S:
                self.counts.stale_plans += 1
                return Planned(controller.brake(), now_s)
            return Planned(controller.plan(now_s + self.compute_s), now_s)
        except Exception as exc:  # a planner bug must not leave the robot driving blind
            self.counts.plan_errors += 1
            return Planned(controller.brake(), now_s, exc)

    def command(self, planned: Planned, took_s: float) -> RobotCommand:
        """The command for a plan that took `took_s` of sim time from `plan` to sending.

        Later than it allowed for by more than the hold, the world stopped holding the
        previous command and braked the robot while this plan assumed it still applied: a
        brake is sent instead. The schedule moves on to the next slot.
        """
        msg = self.newest
        assert msg is not None, "command() without a pose"
        controller = self.controller
        result = planned.result
        if (result.status is not PlanStatus.STALE
                and took_s > self.compute_s + controller.command_hold_s):
            self.counts.late_plans += 1
            result = controller.brake()
        # Capped at STALE_PLAN_S: a plan a stop (SIGSTOP) stretched must not make the robot
        # plan seconds ahead for the rest of the run (the controller caps the age there too).
        self.compute_s = min(max(took_s, COMPUTE_DECAY * self.compute_s), STALE_PLAN_S)
        # On the clock of the poses (`eifp_wire.clock.next_seq`): a robot whose seq a forger pushed
        # up catches up as time passes.
        self.seq = next_seq(self.seq, msg.t_s)
        self.counts.plans += 1
        self.counts.overruns += self.schedule.planned(msg.t_s)
        return RobotCommand(
            self.robot_id, self.seq, msg, self.newest_rx_ns, result, controller.command_hold_s,
            PlanDebugMsg.from_result(self.robot_id, self.seq, planned.now_s, result))
