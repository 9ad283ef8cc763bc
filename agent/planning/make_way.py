"""Making way at the goal: a parked robot steps aside for a robot that stands pressed
against it.

Not in the paper (arXiv 2508.08264). A robot at its goal stops planning and stands
(`agent.planning.planners.arrived_result`); the others plan round it. Where it stands in
the only way to another robot's goal (on the centre line of a corridor 2.6-3.2 m wide
with goals further down it, or in a doorway), no way round exists: the other robot's
liveness rules (`agent.planning.liveness`) re-route, squeeze and yield, and it stands in
front of the parked robot until the time limit. On four-armed corridor crossings with
three robots per arm (scenes written for this, none of the benchmark families), 5-6 of 12
robots never arrived, each standing 0.2 m from a parked robot.

Robots never tell each other where they are going, so a parked robot cannot know that it
is in the way. What it senses is a robot that came up to it after it parked and stays
pressed against it: within `PRESS_GAP_M` (surface to surface) for `PRESS_S` without a
break. It then steps aside (`aside_point`): across the line from that robot to its goal,
as far as `radius + presser radius + d_safety + ASIDE_MARGIN_M` (the presser then passes
with its whole inflated disc clear), or as far as the room there allows (`WALL_GAP_M` from
static discs, `ROOM_GAP_M` from every other sensed robot, or no closer than it is now to a
robot already nearer than that, so the step does not press on a third robot). Of the two
sides it takes the one with more room; on equal room the presser's left (the robot passes
it on its own right, the head-on convention of `agent.planning.encounters`). With no room
across (goals packed 1.5 m apart: a neighbour 0.5 m off on either side), it steps on along
the line instead, away from the presser, which opens its spot for the presser to go on
from. It goes there with the ordinary planner, stands there, and returns to its goal once
the presser is `PASSED_M` beyond the inflated radius L from the goal, or after
`HOLD_MAX_S`. When it would return, the robot stays aside for the next robot of a queue
instead: one standing where going back would press on it (within L of the goal, or the
press gap of the robot), which has not had a turn in this spell aside.

A blocked robot does not always press. In a corridor too narrow to pass the parked robot,
one that wants past loops or shuffles in front of it, 0.4-1.7 m off, inside the press gap
for at most a second at a time (`dead_end` 6, tuning seeds 102, 105 and 109: 100 s of it,
to the time limit). So where the parked robot closes the way (`closes_passage`: no room
for the other robot on either side of it, from the static map), a robot that *lingers*,
within `LINGER_GAP_M` for `LINGER_S` without a break while it keeps moving
(`LINGER_MOVE_M`), counts as a presser too. In the open, or beside a single wall, there is
a way round, and neighbours that park nearby stand still: neither lingers. A lingerer has
gone by only once it is `PASSED_M` beyond L on the far side of the goal from where it
lingered, or `LINGER_GONE_M` beyond L on any side: one that loops out and back has not.

A robot that has parked once is *home* while it is within its radius of its goal
(`HOME_FRACTION`), also outside the arrival tolerance: back from a step aside, a crowd may
keep it from the last few centimetres, and it must still make way there.

Why it ends (`MakeWay.refuge`): a robot steps aside only for a press that *began after it
first parked* (robots already within the gap when it arrives, such as neighbours parked at
their own goals, never count until they have left it, or have moved `PRESENT_DRIFT_M`
within it, or, in a passage it closes, travelled `PRESENT_PATH_M` in all: no parked
neighbour does, a robot stuck against it does; once per robot), for
one presser at a time, for at most `HOLD_MAX_S`; a presser that has not gone by when that
runs out counts as parked there too (it does not need the way, or cannot take it), so it
never sends the robot aside again until it has left the gap (a lingerer that has not
gone by likewise, until it has left the linger gap). A spell aside waits for each
robot of a queue at most once. Every press therefore sends the robot aside at most once,
and two robots parked next to each other cannot keep stepping aside for each other (a
robot released by its drift presses like one that came up later). Robots that came up
while the robot stood aside, and were not waited for, are pressers when it is back.

Choices the scenes left open:

- The presser's heading is not used to choose the side: a robot stuck in front of another
  turns on the spot and reverses (`turning`, liveness rule 3), so where it faces says
  little about where it is going. The direction across is fixed by where the presser
  stands.
- Only robots press, not obstacles; moving obstacles have their own rule
  (`agent.planning.goal_guard`), which comes first.
- With no room across or along (`MIN_ASIDE_M`), the robot stays.
- Tuned on the structured scenes' tuning seeds (100-105, `--families structured`) and
  checked on the liveness families' (docs/results.md, "Making way, farther").

Stateful per robot (the press clocks), but no clock or I/O of its own: the planning cycle
passes the time and what the robot senses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from agent.core.types import Others
from agent.planning.routing import StaticMap

PRESS_GAP_M = 0.5
"""A robot this close to a parked one, surface to surface, presses on it [m]. A stuck
robot stands 0.1-0.3 m from whoever blocks it (its squeeze margin, d_safety); robots
parked at goals 2.5 m apart or more (the benchmark's grids and platoons) are 1.5 m apart."""

PRESS_S = 3.0
"""How long a press must last, without a break, before the parked robot steps aside [s]:
robots that pass close by and go on do not press."""

ASIDE_MARGIN_M = 0.1
"""How far beyond the presser's inflated disc (r + r_presser + d_safety from its line)
the step aside aims, room permitting [m]."""

MIN_ASIDE_M = 0.3
"""A step aside shorter than this is not taken: it opens nothing [m]."""

STEP_M = 0.05
"""Resolution of the search across the line [m]."""

WALL_GAP_M = 0.15
"""The gap a refuge keeps from static discs [m]: the braking guard's 0.05 m plus room to
track to it."""

ROOM_GAP_M = PRESS_GAP_M + 0.1
"""The gap a refuge keeps from every sensed robot but the presser [m]: more than the press
gap, so a robot standing aside presses on nobody."""

PASSED_M = 0.5
"""The presser has gone by once it is this far beyond L (r + r_presser + d_safety) from
the goal [m]."""

PRESENT_DRIFT_M = 0.5
"""A robot already within the press gap when this one arrived is not a presser (a
neighbour parked at its own goal) until it leaves the gap, or until it has moved this far
from where it stood then without leaving it [m]: a parked neighbour does not move, a robot
stuck against this one shuffles (`cross_corridors` 12, seed 112, one of the extra tuning
seeds: a robot pressed 0.2-0.4 m against one that parked in front of it, moving up to
0.8 m about, for 90 s, and was never a presser). Once per robot."""

PRESENT_PATH_M = 1.0
"""Where the parked robot closes the way past it (`closes_passage`), a robot present on
arrival is a presser once its centre has travelled this far in all within the gap [m]: a
robot wedged against it in a corridor, turning on the spot and shuffling a few centimetres
at a time, never drifts `PRESENT_DRIFT_M` (`cross_corridors` 12, tuning seed 111: 0.1-0.2 m
about one spot for 70 s, between two parked robots), where a parked neighbour does not
move at all."""

HOLD_MAX_S = 15.0
"""The longest a robot stands aside for one presser [s]: one that parks beside the goal
never goes by."""

VIEW_SLACK_M = 0.3
"""How much farther than a gap a parked robot looks (`PRESS_VIEW_M`, `LINGER_VIEW_M`): a
robot closing in is seen a cycle early rather than late [m]."""

PRESS_VIEW_M = PRESS_GAP_M + VIEW_SLACK_M
"""At its goal, the press rules see the others only while a robot is this close (surface
to surface) [m]; otherwise no one (out of sight: a presser has gone). The parked robot's
controller estimates the others only while a robot is within the larger of this and
`LINGER_VIEW_M` (`agent.planning.controller.RobotController._robot_close`)."""

LINGER_GAP_M = 1.5
"""In a passage the parked robot closes (`closes_passage`), a robot this close, surface to
surface, that keeps moving (`LINGER_MOVE_M`), lingers by it [m]: a robot blocked there
loops or shuffles 0.4-1.7 m off, inside the press gap for at most a second at a time
(`dead_end` 6, tuning seeds 102, 105 and 109)."""

LINGER_MOVE_M = 0.2
"""A lingerer keeps moving: it has moved this far from where it last stood within the last
`LINGER_STILL_S` [m]. A neighbour parked at its own goal nearby (goals 2.4 m apart along a
dead-end corridor leave a 1.4 m gap) stands still and never lingers."""

LINGER_STILL_S = 2.0
"""See `LINGER_MOVE_M` [s]."""

LINGER_VIEW_M = LINGER_GAP_M + VIEW_SLACK_M
"""The linger rule's view: see `PRESS_VIEW_M` [m]."""

LINGER_S = 5.0
"""How long a robot must linger, without a break, before the parked robot steps aside for
it [s]: a robot driving by at 1 m/s stays within `LINGER_GAP_M` for up to about 4 s."""

LINGER_GONE_M = 1.5
"""A lingerer has gone by once it is `PASSED_M` beyond L from the goal on the far side
from where it lingered, or this far beyond L on any side [m]: one that loops out 1-2 m and
back has not gone by."""

PASS_SQUEEZE_M = 0.1
"""The gap a robot passing beside the parked one keeps from it, at the tightest, when
`closes_passage` asks whether it could pass [m]."""

HOME_FRACTION = 1.0
"""A robot that has parked once is *home* while it is within this fraction of its own
radius of its goal [-]: it still covers the goal spot, and make_way treats it as parked.
Back from a step aside, a robot that a crowd keeps from the last few centimetres to its
goal (outside the arrival tolerance) would otherwise plan like any other robot and never
step aside again, while the robots behind it wait on it for good (`dead_end` 6, tuning
seed 100: 0.29 m from its goal with two robots pressed against it for 80 s)."""


def aside_point(goal_m: np.ndarray, radius_m: float, presser_m: np.ndarray,
                presser_radius_m: float, others: Others, presser: int, d_safety_m: float,
                static: StaticMap | None = None) -> np.ndarray | None:
    """Where a robot parked at `goal_m` stands aside for the robot at `presser_m`, or None
    when neither side nor the way on along the line has `MIN_ASIDE_M` of room.

    Args:
        goal_m: (2,) the parked robot's goal.
        radius_m: its radius.
        presser_m: (2,) the pressing robot's position; presser_radius_m its radius.
        others: every disc the parked robot senses; the robots among them, but the
            presser (index `presser`), must stay `ROOM_GAP_M` from the refuge, or no
            closer than they are to the goal (`_room`).
        d_safety_m: the safety margin of Eq. (8).
        static: the scenario's static discs; the refuge keeps `WALL_GAP_M` from them.

    Returns:
        (2,) the refuge: across the line from the presser to the goal, or on along it,
        away from the presser, when neither side has room; or None.
    """
    goal = np.asarray(goal_m, dtype=float)
    axis = goal - np.asarray(presser_m, dtype=float)
    length = math.hypot(axis[0], axis[1])
    along = axis / length if length > 1e-9 else np.array([1.0, 0.0])
    left = np.array([-along[1], along[0]])
    want = radius_m + presser_radius_m + d_safety_m + ASIDE_MARGIN_M
    steps = np.arange(1, int(math.floor(want / STEP_M + 1e-9)) + 1) * STEP_M
    robots = others.is_robot.copy()
    if 0 <= presser < robots.size:
        robots[presser] = False
    robot_m, robot_r = others.position_m[robots], others.radius_m[robots]
    best: tuple[float, np.ndarray] | None = None
    for normal in (left, -left):  # left first: it wins a tie
        reach, point = _reach(goal, normal, steps, radius_m, robot_m, robot_r, static)
        if point is not None and (best is None or reach > best[0] + STEP_M / 2):
            best = (reach, point)
    if best is not None and best[0] >= MIN_ASIDE_M - 1e-9:
        return best[1]
    # No room across (goals packed 1.5 m apart): on along the line, away from the
    # presser, which opens the spot for it to go on from.
    reach, point = _reach(goal, along, steps, radius_m, robot_m, robot_r, static)
    return point if point is not None and reach >= MIN_ASIDE_M - 1e-9 else None


def closes_passage(goal_m: np.ndarray, radius_m: float, other_m: np.ndarray,
                   other_radius_m: float, static: StaticMap | None) -> bool:
    """Whether a robot parked at `goal_m` closes the way of the robot at `other_m` past
    it: on neither side of the line from that robot to the goal can a disc of its radius
    pass `PASS_SQUEEZE_M` from the parked robot and `WALL_GAP_M` from every static disc
    (checked where it would be abreast of the goal, and 0.3 m before and after). In the
    open, or beside one wall, the way stays open; in a corridor or a doorway narrower than
    two robots and a squeeze, it is closed."""
    if static is None or not len(static.radius_m):
        return False
    goal = np.asarray(goal_m, dtype=float)
    axis = goal - np.asarray(other_m, dtype=float)
    length = math.hypot(axis[0], axis[1])
    along = axis / length if length > 1e-9 else np.array([1.0, 0.0])
    left = np.array([-along[1], along[0]])
    offset = radius_m + other_radius_m + PASS_SQUEEZE_M
    shifts = np.array([-0.3, 0.0, 0.3])[:, None] * along
    for normal in (left, -left):
        points = goal + offset * normal + shifts
        gap = (np.linalg.norm(points[:, None, :] - static.center_m[None, :, :], axis=2)
               - static.radius_m[None, :] - other_radius_m)
        if (gap >= WALL_GAP_M).all():
            return False
    return True


def _reach(goal: np.ndarray, direction: np.ndarray, steps: np.ndarray, radius_m: float,
           robot_m: np.ndarray, robot_radius_m: np.ndarray, static: StaticMap | None
           ) -> tuple[float, np.ndarray | None]:
    """How far from `goal` along `direction` the robot can step (the steps up to the
    first point without room, `_room`), and that point (None: not one step)."""
    points = goal + steps[:, None] * direction
    ok = _room(points, goal, radius_m, robot_m, robot_radius_m, static)
    reach = int(np.argmin(ok)) if not ok.all() else ok.size
    return (float(steps[reach - 1]), points[reach - 1]) if reach else (0.0, None)


def _room(points: np.ndarray, goal: np.ndarray, radius_m: float, robot_m: np.ndarray,
          robot_radius_m: np.ndarray, static: StaticMap | None) -> np.ndarray:
    """(P,) whether each point keeps `ROOM_GAP_M` from the robots, or at least the gap
    it has at the goal from those nearer than that (a step away from a neighbour parked
    0.5 m off is room, a step towards it is not), and `WALL_GAP_M` from the static discs."""
    ok = np.ones(points.shape[0], dtype=bool)
    if robot_m.shape[0]:
        gap = (np.linalg.norm(points[:, None, :] - robot_m[None, :, :], axis=2)
               - robot_radius_m[None, :] - radius_m)
        at_goal = np.linalg.norm(robot_m - goal, axis=1) - robot_radius_m - radius_m
        ok &= (gap >= np.minimum(ROOM_GAP_M, at_goal - 1e-9)[None, :]).all(axis=1)
    if static is not None and len(static.radius_m):
        gap = (np.linalg.norm(points[:, None, :] - static.center_m[None, :, :], axis=2)
               - static.radius_m[None, :] - radius_m)
        ok &= (gap >= WALL_GAP_M).all(axis=1)
    return ok


@dataclass(frozen=True)
class _Spell:
    """A robot's spell within `LINGER_GAP_M` of a parked one."""

    since_s: float
    """When it began."""
    anchor_m: np.ndarray
    """Where the robot stood when it last moved `LINGER_MOVE_M`."""
    moved_s: float
    """When that was."""


@dataclass
class _Aside:
    presser: int
    refuge_m: np.ndarray
    since_s: float
    lingered_from_m: np.ndarray | None = None
    """Where a lingerer stood when the robot stepped aside for it (None: a presser)."""


@dataclass
class MakeWay:
    """The press clocks of one parked robot (`refuge` each cycle once it has parked)."""

    _press: dict[int, float] = field(default_factory=dict)
    """id -> when its current press began (only presses that began while parked here)."""
    _present: set[int] = field(default_factory=set)
    """Robots within the press gap when the robot first arrived, and pressers that did not
    go by while it stood aside: not pressers until they leave the gap."""
    _handed: set[int] = field(default_factory=set)
    """Robots it has stood aside for since it last came back to its goal: none is waited
    for twice in one spell aside."""
    _spots: dict[int, np.ndarray] = field(default_factory=dict)
    """id -> where a robot present on arrival stood then (`PRESENT_DRIFT_M`)."""
    _travel: dict[int, tuple[np.ndarray, float]] = field(default_factory=dict)
    """id -> where a robot present on arrival was last seen, and how far it has travelled
    since the robot arrived (`PRESENT_PATH_M`)."""
    _linger: dict[int, _Spell] = field(default_factory=dict)
    """id -> its current spell within `LINGER_GAP_M` (robots not near on arrival)."""
    _near: set[int] = field(default_factory=set)
    """Robots within `LINGER_GAP_M` when the robot first arrived, and lingerers that did
    not go by while it stood aside: not lingerers until they leave that gap."""
    _aside: _Aside | None = None
    _here: bool = False
    _arrived: bool = False
    steps: int = 0
    """How many times the robot stepped aside (for tests and reports)."""
    handovers: int = 0
    """How many times it stayed aside for the next robot of a queue (`_next_in_queue`)."""

    def reset(self) -> None:
        """Forget every clock."""
        self._press.clear()
        self._present.clear()
        self._spots.clear()
        self._travel.clear()
        self._linger.clear()
        self._near.clear()
        self._handed.clear()
        self._aside = None
        self._here = False
        self._arrived = False

    def refuge(self, now_s: float, goal_m: np.ndarray, radius_m: float,
               ego_m: np.ndarray, at_goal: bool, others: Others, d_safety_m: float,
               static: StaticMap | None = None) -> np.ndarray | None:
        """Where the robot should stand this cycle instead of its goal, or None.

        Args:
            now_s: the cycle's time.
            goal_m: (2,) the robot's goal; radius_m its radius; ego_m (2,) its position.
            at_goal: whether it is parked at its goal now.
            others: what it senses (robots and obstacles).
            d_safety_m: the safety margin of Eq. (8).
            static: the scenario's static discs.
        """
        full = others
        if len(others):
            gaps = (np.hypot(*(others.position_m - ego_m).T) - others.radius_m - radius_m)
            if at_goal and not (others.is_robot & (gaps <= PRESS_VIEW_M)).any():
                others = Others.empty()  # the press rules see no one (`PRESS_VIEW_M`)
        ids = others.ids
        if self._aside is not None:
            held = self._hold_aside(self._aside, now_s, goal_m, radius_m, ego_m, others,
                                    full, d_safety_m, static)
            if held is not None:
                return held
        gaps = (np.hypot(*(full.position_m - ego_m).T) - full.radius_m - radius_m
                if len(full) else np.zeros(0))
        near = {int(i) for i in full.ids[full.is_robot & (gaps <= LINGER_GAP_M)]}
        close = {int(i) for i in full.ids[full.is_robot & (gaps <= PRESS_GAP_M)]}
        home = at_goal or (self._arrived and float(np.hypot(*(ego_m - goal_m)))
                           <= HOME_FRACTION * radius_m)
        if not home:
            self._here = False
            self._press.clear()
            self._linger.clear()
            return None
        if not self._here:  # (re)arrived
            self._here = True
            self._press.clear()
            self._linger.clear()
            self._handed.clear()
            if not self._arrived:  # whoever is this close on arrival does not count
                self._arrived = True
                self._present = set(close)
                self._near = set(near)
                self._travel = {}
                self._spots = {int(i): others.position_m[k].copy()
                               for k, i in enumerate(ids) if int(i) in close}
        self._present &= close
        self._near &= near
        self._release_drifted(others, goal_m, radius_m, static)
        self._press = {i: self._press.get(i, now_s) for i in sorted(close - self._present)}
        due = sorted((t, i) for i, t in self._press.items() if now_s - t >= PRESS_S)
        for _, presser in due:
            k = int(np.flatnonzero(ids == presser)[0])
            refuge = aside_point(goal_m, radius_m, others.position_m[k],
                                 float(others.radius_m[k]), others, k, d_safety_m, static)
            if refuge is not None:
                self._aside = _Aside(presser, refuge, now_s)
                self.steps += 1
                return refuge
        return self._lingered(now_s, goal_m, radius_m, full, near, d_safety_m, static)

    def _hold_aside(self, aside: _Aside, now_s: float, goal_m: np.ndarray, radius_m: float,
                    ego_m: np.ndarray, others: Others, full: Others, d_safety_m: float,
                    static: StaticMap | None) -> np.ndarray | None:
        """While the robot stands aside: the refuge while its presser has not gone by and
        `HOLD_MAX_S` has not run out; then the refuge for the next robot of a queue, if
        any; else None (the spell ends and the robot goes back). `others` is what the press
        rules see (`PRESS_VIEW_M`), `full` everyone (a lingerer's view)."""
        lingered = aside.lingered_from_m is not None
        gone = self._gone(aside.presser, goal_m, radius_m, full if lingered else others,
                          d_safety_m, aside.lingered_from_m)
        if not gone and now_s - aside.since_s < HOLD_MAX_S:
            return aside.refuge_m
        if not gone:  # it stays: parked, or cannot go either
            self._present.add(aside.presser)
            self._near.add(aside.presser)
        self._handed.add(aside.presser)
        self._aside = None
        self._press.clear()
        self._linger.clear()
        follow = self._next_in_queue(goal_m, radius_m, ego_m, others, d_safety_m)
        if follow is None:
            return None
        # let the queue through without going back in between
        k = int(np.flatnonzero(others.ids == follow)[0])
        refuge = aside_point(goal_m, radius_m, others.position_m[k],
                             float(others.radius_m[k]), others, k, d_safety_m, static)
        self._aside = _Aside(follow, aside.refuge_m if refuge is None else refuge, now_s)
        self.handovers += 1
        return self._aside.refuge_m

    def _lingered(self, now_s: float, goal_m: np.ndarray, radius_m: float, others: Others,
                  near: set[int], d_safety_m: float, static: StaticMap | None
                  ) -> np.ndarray | None:
        """Step aside for a robot that has lingered within `LINGER_GAP_M` for `LINGER_S`
        where this robot closes its way past (`closes_passage`); None: no such robot.
        Lingerers are pressers that keep their distance: blocked in a corridor, a robot
        loops or shuffles in front of the parked one, mostly outside the press gap."""
        ids = others.ids
        spells: dict[int, _Spell] = {}
        for rid in sorted(near - self._near - self._present):
            where = others.position_m[int(np.flatnonzero(ids == rid)[0])]
            spell = self._linger.get(rid)
            if spell is None:
                spell = _Spell(now_s, where.copy(), now_s)
            elif float(np.hypot(*(where - spell.anchor_m))) >= LINGER_MOVE_M:
                spell = _Spell(spell.since_s, where.copy(), now_s)
            spells[rid] = spell
        self._linger = spells
        due = sorted((spell.since_s, rid) for rid, spell in spells.items()
                     if now_s - spell.since_s >= LINGER_S
                     and now_s - spell.moved_s <= LINGER_STILL_S)
        for _, rid in due:
            k = int(np.flatnonzero(ids == rid)[0])
            where, r_k = others.position_m[k], float(others.radius_m[k])
            if not closes_passage(goal_m, radius_m, where, r_k, static):
                continue
            refuge = aside_point(goal_m, radius_m, where, r_k, others, k, d_safety_m, static)
            if refuge is not None:
                self._aside = _Aside(rid, refuge, now_s, where.copy())
                self.steps += 1
                return refuge
        return None

    def _release_drifted(self, others: Others, goal_m: np.ndarray, radius_m: float,
                         static: StaticMap | None) -> None:
        """Robots present on arrival that have moved `PRESENT_DRIFT_M` from where they
        stood then (still within the gap: the others left it), or, where this robot closes
        their way past it (`closes_passage`), have travelled `PRESENT_PATH_M` in all since
        it arrived, are present no longer."""
        for rid, spot in list(self._spots.items()):
            where = np.flatnonzero(others.ids == rid)
            if rid not in self._present or where.size == 0:
                del self._spots[rid]
                self._travel.pop(rid, None)
                continue
            k = int(where[0])
            here = others.position_m[k]
            last, path = self._travel.get(rid, (spot, 0.0))
            path += float(np.hypot(*(here - last)))
            self._travel[rid] = (here.copy(), path)
            if float(np.hypot(*(here - spot))) > PRESENT_DRIFT_M or (
                    path >= PRESENT_PATH_M and closes_passage(
                        goal_m, radius_m, here, float(others.radius_m[k]), static)):
                self._present.discard(rid)
                del self._spots[rid]
                self._travel.pop(rid, None)

    @staticmethod
    def _gone(robot: int, goal_m: np.ndarray, radius_m: float, others: Others,
              d_safety_m: float, lingered_from_m: np.ndarray | None = None) -> bool:
        """Whether `robot` is out of sight or `PASSED_M` beyond L from the goal; a lingerer
        (`lingered_from_m`: where it lingered) only on the far side of the goal from there,
        or `LINGER_GONE_M` beyond L on any side."""
        where = np.flatnonzero(others.ids == robot)
        if where.size == 0:
            return True
        big_l = radius_m + d_safety_m + float(others.radius_m[where[0]])
        offset = others.position_m[where[0]] - goal_m
        dist = float(np.hypot(*offset))
        if lingered_from_m is None:
            return dist >= big_l + PASSED_M
        axis = goal_m - lingered_from_m
        length = float(np.hypot(*axis))
        beyond = float(offset @ axis) / length if length > 1e-9 else 0.0
        return beyond >= big_l + PASSED_M or dist >= big_l + LINGER_GONE_M

    def _next_in_queue(self, goal_m: np.ndarray, radius_m: float, ego_m: np.ndarray,
                       others: Others, d_safety_m: float) -> int | None:
        """The robot the one standing aside stays aside for next, when its presser has
        gone by or its time ran out (None: none): of the robots that stand where going back
        would press on them (within L = r + r_j + d_safety of the goal, or `PRESS_GAP_M`
        of the robot where it stands aside), are not present (parked there) and have not
        had a turn this spell, the nearest to the goal. Neighbours parked at their own
        goals farther than L off (goals 1.5 m apart or more) are never in the queue."""
        best: tuple[float, int] | None = None
        for k in np.flatnonzero(others.is_robot):
            rid = int(others.ids[k])
            if rid in self._present or rid in self._handed:
                continue
            r_j = float(others.radius_m[k])
            dist = float(np.hypot(*(others.position_m[k] - goal_m)))
            gap = float(np.hypot(*(others.position_m[k] - ego_m))) - r_j - radius_m
            if dist >= radius_m + r_j + d_safety_m and gap > PRESS_GAP_M:
                continue
            if best is None or dist < best[0]:
                best = (dist, rid)
        return None if best is None else best[1]
