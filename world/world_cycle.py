"""The world's per-tick decisions (pure): which robots are in, which commands apply, when to end.

The world process (`world.node.WorldNode`) is the Zenoh edge around one `WorldCycle`: it
drains its channels into the cycle's methods (key expressions and payloads, as bytes), sends
what they return, writes the events they queue (`WorldEvent`, adding the wall time where
asked) and logs their notices. Nothing here reads a clock, touches Zenoh or writes a file:
sim time is the `WorldSim`'s own (`WorldCycle.sim`), stepped by `WorldCycle.step`.

- **Liveliness** (`WorldCycle.liveliness`): a robot's token appearing is ``robot_joined``
  (``robot_rejoined`` after a loss: it is back online, its command link cleared); one
  disappearing before the end is ``robot_lost`` (offline: it brakes and stays as an obstacle),
  after the end ``robot_left``; a token of an id not in the run is ``unknown_robot``.
- **Commands** (`admit_command`, `release_commands`): a malformed one is rejected (counted,
  tallied by key and reason, the first `MAX_REJECT_EVENTS` as ``rejected`` events); one whose
  ``seq`` is beyond what the time allows (``seq_jumps``) or planned on a pose from the future
  (``future_cmds``) is refused the same way. The rest pass through their robot's command link
  (`world.sim.link.FaultyLink`); of what the links release, a ``seq`` that is not newer than
  the robot's last is ``stale``, the others apply (zero-order hold, ``commands``).
- **The end** (`end_reason`): every robot arrived, or every robot arrived or was lost for
  ``lost_grace_s`` of sim time, or the time limit.
- **Poses** (`pose_cells`): the tick's poses as one message per cell of the pose grid
  within reach of a robot, empty or not (`world.sim.cells.CellRule.published`,
  `eifp_wire.pose_cells.cell_payloads`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from agent.core.scenario import Scenario
from eifp_wire import (
    MAX_CMD_AHEAD_S,
    CommandMsg,
    PlanDebugMsg,
    PosesMsg,
    ProtocolError,
    RunKeys,
    check_seq,
    max_seq,
)
from eifp_wire.pose_cells import cell_payloads
from world.sim.cells import Cell, CellRule
from world.sim.dynamics import WorldSim
from world.sim.link import LINK_COMMANDS, FaultyLink, LinkFaults, link_rng

MAX_REJECT_EVENTS = 100
"""Only this many ``rejected`` events are written (a flood must not fill the disk)."""
MAX_TALLY_KEYS = 64
"""Distinct keys (and reasons) tallied in the ``end`` event; the rest count as ``other``."""
LOST_GRACE_S = 5.0
"""Default sim time a lost robot is waited for (``--lost-grace-s``) before it no longer holds
the run open: once every robot has arrived or been lost this long, the run ends
(``arrived_or_lost``) instead of running on to its time limit. Five lease periods: a robot
whose link merely dropped is back well within it."""
TIME_EPS_S = 1e-9
"""Tolerance on sim-time comparisons (the world's time is a sum of float ticks)."""


@dataclass
class WorldCounters:
    """What the world counts; the ``end`` event lists them in this order.

    Args:
        commands: commands applied.
        rejected: messages rejected (malformed, or refused by a bound).
        stale: commands whose ``seq`` was not newer than the robot's last.
        queries: configuration queries answered.
        bad_queries: configuration queries for no robot of the run.
        overruns: ticks the loop fell more than a period behind (counted by the edge).
        plans: plan-debug messages recorded.
        seq_jumps: commands refused for a ``seq`` beyond what the time allows.
        future_cmds: commands refused for a pose stamp ahead of the world's time.
    """

    commands: int = 0
    rejected: int = 0
    stale: int = 0
    queries: int = 0
    bad_queries: int = 0
    overruns: int = 0
    plans: int = 0
    seq_jumps: int = 0
    future_cmds: int = 0

    def as_dict(self) -> dict[str, int]:
        """Name -> count, in the ``end`` event's order."""
        return asdict(self)


@dataclass(frozen=True)
class WorldEvent:
    """An event for ``events.jsonl``.

    Args:
        kind: the event's kind.
        t_s: sim time.
        fields: its fields.
        wall: the edge adds the wall time (Unix) as ``wall``, where detection latency matters.
    """

    kind: str
    t_s: float
    fields: dict[str, Any] = field(default_factory=dict)
    wall: bool = False


@dataclass(frozen=True)
class AppliedCommand:
    """A command the world applied: its robot, the message and when it arrived (monotonic ns)."""

    robot_id: int
    msg: CommandMsg
    rx_ns: int


def tally(counts: dict[str, int], name: str) -> None:
    """Count `name`, or ``other`` once `MAX_TALLY_KEYS` distinct names are taken."""
    if name not in counts and len(counts) >= MAX_TALLY_KEYS:
        name = "other"
    counts[name] = counts.get(name, 0) + 1


class WorldCycle:
    """The world's decisions, tick by tick (see the module docstring).

    Args:
        scenario: the run's scenario.
        run_id: the run id (its key expressions).
        cmd_timeout_s: sim time after which a robot without a fresh command brakes.
        link: faults injected on every robot's command link.
        fault_seed: seeds the command links (with the link kind and the robot id).
        lost_grace_s: sim time a lost robot may still come back before it no longer holds
            the run open.
        configs: robot id -> its encoded `RunConfigMsg`, served on configuration queries.
    """

    def __init__(self, scenario: Scenario, run_id: str, *, cmd_timeout_s: float,
                 link: LinkFaults | None = None, fault_seed: int = 0,
                 lost_grace_s: float = LOST_GRACE_S,
                 configs: Mapping[int, bytes] | None = None) -> None:
        self.keys = RunKeys(run_id)
        self.scenario = scenario
        self.sim = WorldSim(scenario, cmd_timeout_s=cmd_timeout_s)
        self.robot_ids = frozenset(int(r) for r in self.sim.robot_ids)
        self.cell_rule = CellRule.of_config(scenario.planner_config)
        self.known_ids = self.robot_ids | {o.id for o in scenario.obstacles}
        self.lost_grace_s = lost_grace_s
        self.configs = dict(configs or {})
        faults = link if link is not None else LinkFaults()
        self.cmd_links: dict[int, FaultyLink[tuple[int, CommandMsg]]] = {
            rid: FaultyLink(faults, link_rng(fault_seed, LINK_COMMANDS, rid))
            for rid in sorted(self.robot_ids)}
        self.alive: set[int] = set()
        self.lost_at_s: dict[int, float] = {}
        """Sim time each robot that is lost now was lost."""
        self.last_seq: dict[int, int] = {}
        self.ended = False
        self.counts = WorldCounters()
        self.rejected_by_key: dict[str, int] = {}
        self.rejected_by_reason: dict[str, int] = {}
        self.events: list[WorldEvent] = []
        self.notices: list[str] = []
        """Warnings worth a log line, for the edge to log and clear."""

    @property
    def lost(self) -> set[int]:
        """Robots whose process is lost (and not back)."""
        return set(self.lost_at_s)

    def _event(self, kind: str, wall: bool = False, **fields: Any) -> None:
        self.events.append(WorldEvent(kind, self.sim.t_s, fields, wall))

    def take_events(self) -> list[WorldEvent]:
        """The events queued since the last call, in order."""
        out, self.events = self.events, []
        return out

    def take_notices(self) -> list[str]:
        """The notices since the last call."""
        out, self.notices = self.notices, []
        return out

    # --- liveliness and configuration ------------------------------------------------------

    def liveliness(self, key: str, present: bool) -> None:
        """A robot liveliness token under `key` appeared (`present`) or vanished."""
        try:
            rid = self.keys.robot_id_of_alive(key)
        except ProtocolError:
            rid = None
        if rid is None or rid not in self.robot_ids:
            if present:
                self._event("unknown_robot", key=key)
            return
        if present:
            self._joined(rid)
        elif rid in self.alive:
            self._left(rid)

    def _joined(self, rid: int) -> None:
        if rid in self.alive:
            return
        self.alive.add(rid)
        if rid not in self.lost_at_s:
            self._event("robot_joined", wall=True, robot=rid)
            return
        del self.lost_at_s[rid]
        # The same process, or a new one: either numbers on from the time of its poses
        # (`eifp_wire.clock.next_seq`), so its last seq stays the bar (an old command replayed now
        # is still stale).
        self.cmd_links[rid].clear()
        self.sim.set_offline(rid, False)
        self._event("robot_rejoined", wall=True, robot=rid)
        self.notices.append(f"robot {rid} rejoined")

    def _left(self, rid: int) -> None:
        self.alive.discard(rid)
        if self.ended:
            self._event("robot_left", wall=True, robot=rid)
            return
        self.lost_at_s[rid] = self.sim.t_s
        self.sim.set_offline(rid, True)
        self._event("robot_lost", wall=True, robot=rid)
        self.notices.append(f"robot {rid} lost (liveliness token gone): braking it")

    def config_reply(self, key: str) -> tuple[str, bytes] | None:
        """The reply (key, payload) to a configuration query on `key`; None: there is no
        such robot (counted in ``bad_queries``)."""
        try:
            rid = self.keys.robot_id_of_config(key)
            payload = self.configs[rid]
        except (ProtocolError, KeyError):
            self.counts.bad_queries += 1
            return None
        self.counts.queries += 1
        return self.keys.config(rid), payload

    # --- commands and plans ------------------------------------------------------------------

    def reject(self, reason: str, key: str) -> None:
        """Count a rejected message and tally its key and reason (the field or kind of error,
        e.g. ``cmd.v``, not its value)."""
        self.counts.rejected += 1
        n = self.counts.rejected
        tally(self.rejected_by_key, key[:200])
        tally(self.rejected_by_reason, reason.split(":", 1)[0][:80])
        if n <= MAX_REJECT_EVENTS:
            self._event("rejected", key=key[:200], reason=reason[:200])
        if n in (1, 10, 100) or n % 1000 == 0:
            self.notices.append(f"rejected message #{n} on {key[:200]}: {reason[:200]}")

    def admit_command(self, key: str, payload: bytes, rx_ns: int) -> None:
        """Validate a command that arrived on `key` at `rx_ns` and send it into its robot's
        command link, or reject it."""
        t_s = self.sim.t_s
        try:
            rid = self.keys.robot_id_of_cmd(key)
        except ProtocolError as exc:
            self.reject(f"key: {exc}", key)
            return
        try:
            msg = CommandMsg.decode(payload, known_ids=self.robot_ids, expected_robot_id=rid)
        except ProtocolError as exc:
            self.reject(str(exc), key)
            return
        # Bounds a forged but well-formed command cannot pass: a seq beyond what the time
        # allows (which would make the robot's genuine commands stale), a plan from the future.
        if check_seq(msg.seq, None, world_t_s=t_s) == "seq_jump":
            self.counts.seq_jumps += 1
            self.reject(f"cmd.seq: {msg.seq} is beyond {max_seq(t_s)}, the bound at "
                        f"{t_s:.3f} s", key)
            return
        if msg.pose_stamp_s > t_s + MAX_CMD_AHEAD_S:
            self.counts.future_cmds += 1
            self.reject(f"cmd.pose_stamp: {msg.pose_stamp_s:.3f} s is ahead of the world's "
                        f"{t_s:.3f} s", key)
            return
        self.cmd_links[rid].send(t_s, (rx_ns, msg))

    def release_commands(self) -> list[AppliedCommand]:
        """Apply what the command links release now, the newest ``seq`` per robot only
        (zero-order hold); returns the commands applied, in order."""
        applied = []
        t_s = self.sim.t_s
        for rid, link in self.cmd_links.items():
            for rx_ns, msg in link.receive(t_s):
                if check_seq(msg.seq, self.last_seq.get(rid), world_t_s=t_s) is not None:
                    self.counts.stale += 1
                    continue
                self.last_seq[rid] = msg.seq
                self.sim.set_command(rid, msg.v_mps, msg.omega_radps, msg.hold_s)
                self.counts.commands += 1
                applied.append(AppliedCommand(rid, msg, rx_ns))
        return applied

    def plan_debug(self, key: str, payload: bytes) -> tuple[int, PlanDebugMsg] | None:
        """A robot's plan internals to record (robot id, message), or None if rejected."""
        try:
            rid = self.keys.robot_id_of_debug(key)
            msg = PlanDebugMsg.decode(payload, known_ids=self.known_ids, expected_robot_id=rid)
        except ProtocolError as exc:
            self.reject(str(exc), key)
            return None
        self.counts.plans += 1
        return rid, msg

    # --- poses ---------------------------------------------------------------------------------

    def published_cells(self) -> frozenset[Cell]:
        """The cells the world publishes now: every cell within reach of a robot."""
        return self.cell_rule.published(self.sim.pose[:, :2])

    def pose_cells(self, pub_ns: int = 0, clock_id: int = 0) -> list[tuple[Cell, bytes]]:
        """The current tick's poses, one payload per published cell, cells sorted (each a
        `PosesMsg` stamped `pub_ns` on clock `clock_id`)."""
        msg = PosesMsg.from_snapshot(self.sim.snapshot(), pub_ns=pub_ns, clock_id=clock_id)
        return cell_payloads(msg, self.published_cells(), self.cell_rule.size_m)

    # --- stepping and the end ----------------------------------------------------------------

    def step(self, dt_s: float) -> None:
        """Step the world by `dt_s` of sim time; arrivals, contacts and command timeouts are
        queued as events."""
        events = self.sim.step(dt_s)
        for rid in events.arrivals:
            self._event("arrived", robot=rid)
        for a, b, overlap in events.new_contacts:
            self._event("contact", a=a, b=b, overlap_m=round(overlap, 6))
            self.notices.append(f"contact {a}-{b}, overlap {overlap:.3f} m at "
                                f"t={self.sim.t_s:.2f}")
        for rid in events.timeouts:
            self._event("cmd_timeout", robot=rid)

    def arrived_or_gone(self) -> bool:
        """Every robot has arrived or has been lost for `lost_grace_s`."""
        gone_before = self.sim.t_s - self.lost_grace_s + TIME_EPS_S
        waiting = [int(r) for r in self.sim.robot_ids[~self.sim.arrived]]
        return all(self.lost_at_s.get(r, math.inf) <= gone_before for r in waiting)

    def end_reason(self) -> str | None:
        """Why the run ends after this tick, or None to go on."""
        if self.sim.all_arrived():
            return "all_arrived"
        if self.lost_at_s and self.arrived_or_gone():
            return "arrived_or_lost"
        if self.sim.t_s >= self.scenario.time_limit_s - TIME_EPS_S:
            return "time_limit"
        return None

    def end(self, reason: str, **extra: Any) -> WorldEvent:
        """The run is over: the ``end`` event (`extra`: further fields, after the counters).

        From now on a robot whose token vanishes has left, not been lost.
        """
        self.ended = True
        sim = self.sim
        fields: dict[str, Any] = dict(
            reason=reason, success=self.success, all_arrived=sim.all_arrived(),
            arrived=[int(r) for r in sim.robot_ids[sim.arrived]], contacts=sim.contact_count,
            ticks=sim.tick,
            min_gap_m=round(sim.min_gap_m, 6) if math.isfinite(sim.min_gap_m) else None,
            lost=sorted(self.lost_at_s), cmd_timeouts=sim.timeout_count,
            cmd_hold_expiries=sim.hold_expiry_count, **self.counts.as_dict(),
            rejected_by_key=self.rejected_by_key, rejected_by_reason=self.rejected_by_reason,
            cmd_link={k: sum(getattr(link.counts, k) for link in self.cmd_links.values())
                      for k in ("dropped", "duplicated", "reordered")},
            **extra)
        return WorldEvent("end", sim.t_s, fields)

    @property
    def success(self) -> bool:
        """Every robot arrived, with no contact."""
        return bool(self.sim.all_arrived()) and self.sim.contact_count == 0
