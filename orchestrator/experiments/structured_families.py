"""Structured scene families: rooms, a room emptying through one door, corridors meeting in
a crossing, a dead-end corridor, a packed parking block, robots in pockets, random walls.

Not a family of issue 39's list and not in the default suite (`benchmark.SUITE`): these are
the kinds of scene the planner's liveness rules (`agent.planning.routing`, `liveness`,
`passages`, `make_way`) are meant to carry beyond the families they were tuned on, kept
apart so that the suite's table stays the one the README reports and these remain a
held-out check (`orchestrator benchmark --families structured`, `benchmark.STRUCTURED_SUITE`).
docs/results.md, "Structured scenes", has their figures.

Pure, like `families` and `liveness_families`: a generator takes the robot count and a
`numpy.random.Generator` and returns a validated `Scenario` at the families' scale (robot
radius 0.5 m, v_max 1.1 m/s, d_safety 0.3 m). Walls are rows of touching static discs
(`WALL_DISC_RADIUS_M`, centres at most `WALL_DISC_SPACING_M` apart, as in
`liveness_families`); an opening is a clear gap between the edges of the discs either side.
Widths are drawn from the ranges named in each docstring, so a seed may make a corridor two
robots can pass each other in with their margins, or one they cannot.

The time limit (`route_time_limit_s`) is 4x the ideal time + 60 s, more generous than the
other families' 3x + 30 s, and the ideal time is that of the longest *route* round the walls
rather than of the straight line (which in rooms would be far too short): robots here wait
their turn at one-lane doors and for parked robots to step aside, and the question these
scenes ask is whether every robot gets there.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from agent.core.scenario import ObstacleSpec, RobotSpec, Scenario
from agent.planning.routing import StaticMap, route_or_tight
from orchestrator.experiments.liveness_families import (
    WALL_DISC_RADIUS_M,
    tile_stretch,
)
from orchestrator.experiments.scenario_blocks import (
    COORD_DECIMALS,
    D_SAFETY_M,
    ROBOT_RADIUS_M,
    make_scenario,
    require,
    robot_spec,
)
from world.scenario_file import ScenarioError

Point = tuple[float, float]
Opening = tuple[float, float]
"""An opening in a wall: (centre, clear width), the centre as arc length from its start [m]."""

ROOM_SIDE_M = 9.0
"""Clear side of a room of `rooms` [m]."""
ROOM_DOOR_M = (1.6, 3.0)
"""Door widths of `rooms` [m]: from one robot wide (1.0 m and its margins) to two."""
EVACUATE_ROOM_M = 14.0
EVACUATE_DOOR_M = (2.8, 3.4)
CORRIDOR_WIDTH_M = (2.6, 3.2)
"""Clear widths of `cross_corridors` and `dead_end` [m]: around 4 r + 3 d_safety (2.9 m),
the width two robots need to pass each other with full margins."""
ARM_LENGTH_M = 13.0
DEAD_END_LENGTH_M = 16.0
PARKING_SPACING_M = 1.5
"""Centre distance of neighbouring goals of `parking` [m] (0.5 m between parked robots)."""
PARKING_RING_M = 12.0
POCKET_DEPTH_M = 2.4
POCKET_WIDTH_M = 2.2
RANDOM_WALLS_SIDE_M = 26.0
RANDOM_WALLS = 6
RANDOM_WALL_LENGTH_M = (4.0, 9.0)
CLEAR_OF_WALLS_M = 1.2
"""Random starts and goals keep this much from every wall disc's edge [m]."""
SPACING_M = 2.5
"""Random starts (and goals) are at least this far apart [m], as in `random_scenario`."""
MAX_TRIES = 20_000


def line_discs(a: Point, b: Point, openings: Sequence[Opening] = (), first_id: int = -1
               ) -> list[ObstacleSpec]:
    """A straight wall of touching discs from a to b (the end discs' edges on a and b),
    with clear openings.

    Args:
        a, b: its ends [m].
        openings: (centre, width) along it, in arc length from a [m]; each solid stretch
            must hold at least one disc.
        first_id: id of the first disc; the next count down.
    """
    ax, ay = a
    length = math.hypot(b[0] - ax, b[1] - ay)
    ux, uy = (b[0] - ax) / length, (b[1] - ay) / length
    edges = [0.0, *(s for c, w in sorted(openings) for s in (c - w / 2.0, c + w / 2.0)), length]
    discs: list[ObstacleSpec] = []
    for lo, hi in zip(edges[::2], edges[1::2]):
        for s in tile_stretch(lo, hi):
            centre = (round(ax + ux * s, COORD_DECIMALS) + 0.0,
                      round(ay + uy * s, COORD_DECIMALS) + 0.0)
            discs.append(ObstacleSpec(id=first_id - len(discs), center=centre,
                                      radius_m=WALL_DISC_RADIUS_M))
    return discs


def _walls(lines: Sequence[tuple[Point, Point, Sequence[Opening]]]) -> list[ObstacleSpec]:
    """Several `line_discs` walls, ids -1, -2, ... across all of them."""
    discs: list[ObstacleSpec] = []
    for a, b, openings in lines:
        discs += line_discs(a, b, openings, first_id=-1 - len(discs))
    return discs


def _uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return round(float(rng.uniform(*bounds)), 2)


ROUTE_LIMIT_FACTOR = 4.0
ROUTE_LIMIT_MARGIN_S = 60.0


def route_time_limit_s(robots: Sequence[RobotSpec], obstacles: Sequence[ObstacleSpec]) -> float:
    """`ROUTE_LIMIT_FACTOR` x the longest route's time at v_max + `ROUTE_LIMIT_MARGIN_S`,
    rounded up to 10 s (the route of `routing.route_or_tight`, the one a robot takes with
    the default planner)."""
    static = StaticMap(np.array([o.center for o in obstacles], dtype=float).reshape(-1, 2),
                       np.array([o.radius_m for o in obstacles], dtype=float))
    longest = 0.0
    for r in robots:
        start, goal = np.array(r.start[:2]), np.array(r.goal)
        route = route_or_tight(start, goal, static, r.radius_m, D_SAFETY_M)
        length = route.length_m if route is not None else float(np.hypot(*(goal - start)))
        longest = max(longest, length / r.limits.v_max_mps)
    return math.ceil((ROUTE_LIMIT_FACTOR * longest + ROUTE_LIMIT_MARGIN_S) / 10.0) * 10.0


def _scenario(name: str, description: str, pairs: Sequence[tuple[Point, Point]],
              walls: Sequence[ObstacleSpec]) -> Scenario:
    robots = [robot_spec(i, s, g) for i, (s, g) in enumerate(pairs)]
    return make_scenario(name, description, robots, obstacles=walls,
                         time_limit_s=route_time_limit_s(robots, walls))


def _clear_points(n: int, rng: np.random.Generator, boxes: Sequence[tuple[float, float, float,
                  float]], walls: Sequence[ObstacleSpec], taken: Sequence[Point] = ()
                  ) -> list[Point]:
    """n random points, each in one of `boxes` (x0, y0, x1, y1; chosen uniformly), at least
    `CLEAR_OF_WALLS_M` from every wall disc's edge and `SPACING_M` from each other and from
    `taken`."""
    centres = np.array([o.center for o in walls], dtype=float).reshape(-1, 2)
    radii = np.array([o.radius_m for o in walls], dtype=float)
    points: list[Point] = []
    for _ in range(MAX_TRIES):
        if len(points) == n:
            return points
        x0, y0, x1, y1 = boxes[int(rng.integers(len(boxes)))]
        p = (round(float(rng.uniform(x0, x1)), 2), round(float(rng.uniform(y0, y1)), 2))
        if centres.size and (np.hypot(*(centres - p).T) - radii).min() < CLEAR_OF_WALLS_M:
            continue
        if any(math.dist(p, q) < SPACING_M for q in (*points, *taken)):
            continue
        points.append(p)
    raise ScenarioError(f"could not place {n} points clear of the walls")


def rooms(n: int, rng: np.random.Generator) -> Scenario:
    """A 3 x 3 block of rooms `ROOM_SIDE_M` square; the inner walls have doors 1.6-3.0 m
    wide at random places, on a random spanning tree of the rooms plus two more (so some
    rooms have two ways in). Each robot starts in a random room and goes to a random point
    of another room."""
    require(2 <= n <= 18, f"rooms: --agents must be in [2, 18], got {n}")
    side, k = ROOM_SIDE_M, 3
    pitch = side + 2.0 * WALL_DISC_RADIUS_M  # wall centre line to wall centre line
    half = k * pitch / 2.0
    # inner wall segments between neighbouring rooms (a, b): room index = row * k + col
    segments: dict[tuple[int, int], tuple[Point, Point]] = {}
    for row in range(k):
        for col in range(k):
            x, y, here = -half + col * pitch, -half + row * pitch, row * k + col
            if col + 1 < k:  # the wall to the room on the right
                segments[(here, here + 1)] = ((x + pitch, y), (x + pitch, y + pitch))
            if row + 1 < k:  # the wall to the room above
                segments[(here, here + k)] = ((x, y + pitch), (x + pitch, y + pitch))
    # a random spanning tree (random-order Kruskal), then two more doors
    order = [list(segments)[i] for i in rng.permutation(len(segments))]
    parent = list(range(k * k))

    def find(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    doors = []
    for a, b in order:
        if find(a) != find(b):
            parent[find(a)] = find(b)
            doors.append((a, b))
    doors += [e for e in order if e not in doors][:2]
    lines: list[tuple[Point, Point, Sequence[Opening]]] = []
    for edge, (a, b) in segments.items():
        openings: tuple[Opening, ...] = ()
        if edge in doors:
            width = _uniform(rng, ROOM_DOOR_M)
            room = pitch - width
            centre = round(float(rng.uniform(width / 2.0 + 1.2, pitch - width / 2.0 - 1.2)), 2)
            require(room > 2.4, "rooms: door too wide")
            openings = ((centre, width),)
        lines.append((a, b, openings))
    for a, b in (((-half, -half), (half, -half)), ((half, -half), (half, half)),
                 ((half, half), (-half, half)), ((-half, half), (-half, -half))):
        lines.append((a, b, ()))
    walls = _walls(lines)
    boxes = [(-half + c * pitch + 0.6, -half + r_ * pitch + 0.6,
              -half + (c + 1) * pitch - 0.6, -half + (r_ + 1) * pitch - 0.6)
             for r_ in range(k) for c in range(k)]
    starts = _clear_points(n, rng, boxes, walls)
    goals: list[Point] = []
    for s in starts:
        own = next(i for i, (x0, y0, x1, y1) in enumerate(boxes)
                   if x0 <= s[0] <= x1 and y0 <= s[1] <= y1)
        others = [b for i, b in enumerate(boxes) if i != own]
        goals += _clear_points(1, rng, others, walls, taken=goals)
    return _scenario(f"rooms_{n}", f"{n} robots in a 3 x 3 block of {side:g} m rooms with "
                     f"{len(doors)} doors {ROOM_DOOR_M[0]:g}-{ROOM_DOOR_M[1]:g} m wide, each to "
                     "another room", list(zip(starts, goals)), walls)


def evacuate(n: int, rng: np.random.Generator) -> Scenario:
    """n robots on a grid 2.5 m apart in a room `EVACUATE_ROOM_M` square leave through one
    door 2.8-3.4 m wide in its east wall (centre moved up to 2 m along it) for random goals
    in the open beyond."""
    require(2 <= n <= 24, f"evacuate: --agents must be in [2, 24], got {n}")
    h = EVACUATE_ROOM_M / 2.0 + WALL_DISC_RADIUS_M
    width = _uniform(rng, EVACUATE_DOOR_M)
    door = round(h + float(rng.uniform(-2.0, 2.0)), 2)  # arc length along the east wall
    walls = _walls([((-h, -h), (h, -h), ()), ((h, -h), (h, h), ((door, width),)),
                    ((h, h), (-h, h), ()), ((-h, h), (-h, -h), ())])
    # starts on a grid 2.5 m apart inside (random sequential placement cannot pack them),
    # a seeded choice of its slots, each moved by up to 0.2 m
    grid = np.arange(-5.0, 5.01, SPACING_M)
    slots = [(float(x), float(y)) for x in grid for y in grid]
    require(n <= len(slots), f"evacuate: --agents must be at most {len(slots)}, got {n}")
    moved = np.round(rng.uniform(-0.2, 0.2, size=(n, 2)), 2).tolist()
    starts = [(slots[i][0] + dx, slots[i][1] + dy)
              for i, (dx, dy) in zip(rng.permutation(len(slots))[:n].tolist(), moved)]
    goals = _clear_points(n, rng, [(h + 6.0, -h - 4.0, h + 16.0, h + 4.0)], walls)
    return _scenario(f"evacuate_{n}", f"{n} robots leave a {EVACUATE_ROOM_M:g} m room through "
                     f"one door {width:g} m wide", list(zip(starts, goals)), walls)


def cross_corridors(n: int, rng: np.random.Generator) -> Scenario:
    """Four corridors (`ARM_LENGTH_M` long, each pair of opposite arms 2.6-3.2 m clear)
    meet in a crossing; n/4 robots per arm go to points on the other arms, every arm's
    goals on the axis 2.5 m apart, assigned at random (never the robot's own arm)."""
    require(n >= 4 and n % 4 == 0 and n <= 16, f"cross_corridors: --agents must be 4, 8, 12 "
            f"or 16, got {n}")
    per_arm = n // 4
    widths = (_uniform(rng, CORRIDOR_WIDTH_M), _uniform(rng, CORRIDOR_WIDTH_M))
    wx, wy = (w / 2.0 + WALL_DISC_RADIUS_M for w in widths)  # wall centre lines of x, y arms
    end = ARM_LENGTH_M
    lines: list[tuple[Point, Point, Sequence[Opening]]] = []
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):  # one L per quadrant: along the x arm, then the y arm
            # a disc on the corner (sx wy, sy wx), the y arm's wall touching it
            lines.append(((sx * end, sy * wx), (sx * (wy - WALL_DISC_RADIUS_M), sy * wx), ()))
            lines.append(((sx * wy, sy * (wx + WALL_DISC_RADIUS_M)), (sx * wy, sy * end), ()))
    walls = _walls(lines)
    arms = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))
    slots = [4.5 + 2.5 * j for j in range(per_arm)]
    across = np.round(rng.uniform(-0.25, 0.25, size=(4, per_arm)), 2).tolist()
    starts = [(ux * (s + 1.0) + uy * across[a][j], uy * (s + 1.0) + ux * across[a][j])
              for a, (ux, uy) in enumerate(arms) for j, s in enumerate(slots)]
    start_arm = [a for a in range(4) for _ in slots]
    goal_slots = [(a, s) for a in range(4) for s in slots]
    for _ in range(MAX_TRIES):
        perm = rng.permutation(len(goal_slots))
        if all(goal_slots[p][0] != start_arm[i] for i, p in enumerate(perm)):
            break
    else:
        raise ScenarioError("cross_corridors: no assignment off every robot's own arm")
    goals = [(arms[goal_slots[p][0]][0] * goal_slots[p][1],
              arms[goal_slots[p][0]][1] * goal_slots[p][1]) for p in perm]
    return _scenario(f"cross_corridors_{n}", f"four corridors ({widths[0]:g} and {widths[1]:g} m "
                     f"clear) meet in a crossing; {per_arm} robots per arm go to other arms",
                     list(zip(starts, goals)), walls)


def dead_end(n: int, rng: np.random.Generator) -> Scenario:
    """n robots waiting outside the mouth of a dead-end corridor (2.6-3.2 m clear,
    `DEAD_END_LENGTH_M` long) go to goals along its axis, 2.4 m apart from the closed end,
    assigned in random order (the first in may park in front of a later one's goal)."""
    require(2 <= n <= 6, f"dead_end: --agents must be in [2, 6], got {n}")
    width = _uniform(rng, CORRIDOR_WIDTH_M)
    w = width / 2.0 + WALL_DISC_RADIUS_M
    length = DEAD_END_LENGTH_M
    r = WALL_DISC_RADIUS_M
    walls = _walls([((0.0, -w), (length, -w), ()), ((0.0, w), (length, w), ()),
                    ((length - r, -w + r), (length - r, w - r), ())])  # the closed end
    goals = [(round(length - 1.9 - 2.4 * j, 2), 0.0) for j in range(n)]
    goals = [goals[i] for i in rng.permutation(n)]
    starts = _clear_points(n, rng, [(-10.0, -6.0, -3.0, 6.0)], walls)
    return _scenario(f"dead_end_{n}", f"{n} robots to goals along a dead-end corridor {width:g} m "
                     f"clear, in random order", list(zip(starts, goals)), walls)


MAZE_HALF_WIDTH_M = 12.0
"""The maze's walls run from x = -12 to 12 m [m]."""
MAZE_CORRIDOR_M = (2.8, 3.6)
"""Clear width between two of the maze's walls [m]: around two robots with their margins
(`passages.two_lane_width_m`, 3.3 m)."""
MAZE_DOOR_M = (2.8, 3.2)
"""Clear width of each of its doors [m]."""


def maze(n: int, rng: np.random.Generator) -> Scenario:
    """Three parallel walls `MAZE_HALF_WIDTH_M` x 2 long, 2.8-3.6 m clear apart, each with
    one door 2.8-3.2 m wide 3-8 m off the middle, the middle wall's on the other side from
    the outer two's, closed at both ends by side walls a little longer; n/2 robots below go
    to points above, mirrored through the middle, and n/2 above go the other way, so the
    two flows meet head-on in the corridors and doors (found on a probe of this kind,
    `maze_counterflow`, docs/results.md, "A maze with counterflow")."""
    require(n >= 2 and n % 2 == 0 and n <= 16, f"maze: --agents must be even, 2 to 16, got {n}")
    spacing = _uniform(rng, MAZE_CORRIDOR_M) + 2.0 * WALL_DISC_RADIUS_M
    half = MAZE_HALF_WIDTH_M
    side = 1.0 if rng.uniform() < 0.5 else -1.0
    lines: list[tuple[Point, Point, Sequence[Opening]]] = []
    for k, y in enumerate((-spacing, 0.0, spacing)):
        offset = side * (1.0 if k != 1 else -1.0) * _uniform(rng, (3.0, 8.0))
        lines.append(((-half, y), (half, y), ((half + offset, _uniform(rng, MAZE_DOOR_M)),)))
    top = spacing + 3.0
    for x in (-half - 1.0, half + 1.0):
        lines.append(((x, -top - 1.0), (x, top + 1.0), ()))
    walls = _walls(lines)
    per_side = n // 2
    xs = _spread(per_side, rng, -half + 2.0, half - 2.0, SPACING_M)
    pairs = [((x, -top), (-x, top)) for x in xs] + [((x, top), (-x, -top)) for x in xs]
    return _scenario(f"maze_{n}", f"{per_side} robots each way through three walls "
                     f"{spacing - 2.0 * WALL_DISC_RADIUS_M:.2f} m clear apart, one door each",
                     pairs, walls)


def _spread(k: int, rng: np.random.Generator, lo: float, hi: float, gap: float) -> list[float]:
    """k random values in [lo, hi], at least `gap` apart, sorted."""
    for _ in range(MAX_TRIES):
        xs = sorted(round(float(v), 2) for v in rng.uniform(lo, hi, size=k))
        if all(b - a >= gap for a, b in zip(xs, xs[1:])):
            return xs
    raise ScenarioError(f"could not spread {k} points {gap} m apart")


def parking(n: int, rng: np.random.Generator) -> Scenario:
    """n robots from a ring of radius `PARKING_RING_M` to goals packed `PARKING_SPACING_M`
    apart (0.5 m between parked robots) in a block 4 wide, assigned at random."""
    require(2 <= n <= 20, f"parking: --agents must be in [2, 20], got {n}")
    cols = min(4, n)
    rows = math.ceil(n / cols)
    step = PARKING_SPACING_M
    block = [((c - (cols - 1) / 2.0) * step, (r - (rows - 1) / 2.0) * step)
             for r in range(rows) for c in range(cols)][:n]
    phase = float(rng.uniform(0.0, 2.0 * math.pi))
    starts = [(PARKING_RING_M * math.cos(phase + 2.0 * math.pi * k / n),
               PARKING_RING_M * math.sin(phase + 2.0 * math.pi * k / n)) for k in range(n)]
    goals = [block[i] for i in rng.permutation(n)]
    return _scenario(f"parking_{n}", f"{n} robots from a ring to goals packed "
                     f"{PARKING_SPACING_M:g} m apart", list(zip(starts, goals)), ())


def pocket(n: int, rng: np.random.Generator) -> Scenario:
    """n robots, each starting inside a U-shaped pocket (`POCKET_WIDTH_M` clear,
    `POCKET_DEPTH_M` deep) whose back wall stands between it and its goal, 18 m across:
    the robot has to leave the pocket away from its goal first. Pockets alternate sides,
    4.5 m apart (moved up to 0.5 m), each goal up to 1 m off its start's line."""
    require(2 <= n <= 8, f"pocket: --agents must be in [2, 8], got {n}")
    r = WALL_DISC_RADIUS_M
    w = POCKET_WIDTH_M / 2.0 + r  # side walls' centre lines from the pocket's axis
    lines: list[tuple[Point, Point, Sequence[Opening]]] = []
    pairs: list[tuple[Point, Point]] = []
    for k in range(n):
        y = round((k - (n - 1) / 2.0) * 4.5 + float(rng.uniform(-0.5, 0.5)), 2)
        sign = -1.0 if k % 2 == 0 else 1.0
        back = sign * 7.6  # the back wall's centre line, towards the goal side
        outer = sign * (7.6 + POCKET_DEPTH_M)  # the open end
        for side in (-w, w):
            lines.append(((outer, y + side), (back - sign * r, y + side), ()))
        lines.append(((back, y - w + r), (back, y + w - r), ()))
        goal = (round(-sign * 9.0, 2), round(y + float(rng.uniform(-1.0, 1.0)), 2))
        pairs.append(((sign * 9.0, y), goal))
    return _scenario(f"pocket_{n}", f"{n} robots start in U-shaped pockets open away from their "
                     "goals", pairs, _walls(lines))


def random_walls(n: int, rng: np.random.Generator) -> Scenario:
    """`RANDOM_WALLS` straight walls 4-9 m long at random places and angles in a
    `RANDOM_WALLS_SIDE_M` square, n random starts and goals clear of them, each goal at
    least a third of the side from its start."""
    require(2 <= n <= 24, f"random_walls: --agents must be in [2, 24], got {n}")
    half = RANDOM_WALLS_SIDE_M / 2.0
    lines: list[tuple[Point, Point, Sequence[Opening]]] = []
    for _ in range(RANDOM_WALLS):
        cx, cy = (float(v) for v in rng.uniform(-half + 3.0, half - 3.0, size=2))
        length, angle = _uniform(rng, RANDOM_WALL_LENGTH_M), float(rng.uniform(0.0, math.pi))
        dx, dy = math.cos(angle) * length / 2.0, math.sin(angle) * length / 2.0
        lines.append(((round(cx - dx, 2), round(cy - dy, 2)),
                      (round(cx + dx, 2), round(cy + dy, 2)), ()))
    walls = _walls(lines)
    static = StaticMap(np.array([o.center for o in walls], dtype=float),
                       np.array([o.radius_m for o in walls], dtype=float))
    box = [(-half, -half, half, half)]
    starts: list[Point] = []
    goals: list[Point] = []
    for _ in range(MAX_TRIES):
        if len(starts) == n:
            break
        s, = _clear_points(1, rng, box, walls, taken=starts)
        g, = _clear_points(1, rng, box, walls, taken=goals)
        if math.dist(s, g) < RANDOM_WALLS_SIDE_M / 3.0 or route_or_tight(
                np.array(s), np.array(g), static, ROBOT_RADIUS_M, D_SAFETY_M) is None:
            continue  # too short, or walled off
        starts.append(s)
        goals.append(g)
    require(len(starts) == n, f"random_walls: could not place {n} robots")
    return _scenario(f"random_walls_{n}", f"{n} robots, random starts and goals among "
                     f"{RANDOM_WALLS} random walls in a {RANDOM_WALLS_SIDE_M:g} m square",
                     list(zip(starts, goals)), walls)


GENERATORS: dict[str, Callable[[int, np.random.Generator], Scenario]] = {
    "rooms": rooms, "evacuate": evacuate, "cross_corridors": cross_corridors,
    "dead_end": dead_end, "parking": parking, "pocket": pocket, "random_walls": random_walls,
    "maze": maze,
}
"""Family name -> generator (`families.FAMILIES` has their default sizes and summaries)."""
