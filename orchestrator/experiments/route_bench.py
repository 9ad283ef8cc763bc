"""Route-graph benchmark: how long a robot takes to build its routes over a large map.

    orchestrator bench --routes ROWS[,ROWS...]

Each row of the table is a walled hall (`halls`): 30 m wide, shelf rows of wall 5 m apart,
each row two walls with a 4 m gap in the middle, all of touching discs of radius 0.6 m
1.2 m apart (the walls of the `wall_door` family). For each hall it builds the visibility
graph (`agent.planning.routing.VisibilityGraph.build`) at the two clearances a robot of
radius 0.5 m uses (the full one, with d_safety 0.3 m, and the tight one), extends the full
one by five robot discs (a re-route round a knot, `VisibilityGraph.with_discs`), and plans
one route from the bottom left corner to the top right. Wall time, `time.perf_counter`,
one build each, in this process. Figures only: nothing here asserts a time budget.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from agent.planning.routing import (
    ROUTE_MARGIN_M,
    TIGHT_MARGIN_M,
    StaticMap,
    VisibilityGraph,
    plan_route,
)

ROBOT_RADIUS_M = 0.5
D_SAFETY_M = 0.3
HALL_HALF_WIDTH_M = 15.0
ROW_SPACING_M = 5.0
WALL_DISC_RADIUS_M = 0.6
WALL_DISC_SPACING_M = 1.2


def _line(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float]]:
    n = max(1, round(math.hypot(x1 - x0, y1 - y0) / WALL_DISC_SPACING_M))
    return [(x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n) for k in range(n + 1)]


def halls(rows: int) -> StaticMap:
    """The walled hall with `rows` shelf rows (module docstring): about 60 + 16 per row
    discs, 5 (rows + 1) m deep."""
    w, top = HALL_HALF_WIDTH_M, ROW_SPACING_M * (rows + 1)
    step = WALL_DISC_SPACING_M
    pts = (_line(-w, 0.0, w, 0.0) + _line(-w, top, w, top) + _line(-w, step, -w, top - step)
           + _line(w, step, w, top - step))
    for r in range(1, rows + 1):
        y = ROW_SPACING_M * r
        pts += _line(-w + 4.0, y, -2.0, y) + _line(2.0, y, w - 4.0, y)
    return StaticMap(np.array(pts), np.full(len(pts), WALL_DISC_RADIUS_M))


def time_route_graphs(rows: Sequence[int]) -> list[dict[str, float]]:
    """One row of figures per hall (module docstring)."""
    out = []
    full_m = ROBOT_RADIUS_M + D_SAFETY_M + ROUTE_MARGIN_M
    tight_m = ROBOT_RADIUS_M + TIGHT_MARGIN_M
    for n_rows in rows:
        static = halls(n_rows)
        t0 = time.perf_counter()
        graph = VisibilityGraph.build(static, full_m)
        t1 = time.perf_counter()
        VisibilityGraph.build(static, tight_m, doorways=False)  # as route_or_tight
        t2 = time.perf_counter()
        knot = np.column_stack((np.linspace(-1.5, 1.5, 5), np.full(5, ROW_SPACING_M)))
        graph.with_discs(knot, np.full(5, ROBOT_RADIUS_M))
        t3 = time.perf_counter()
        top = ROW_SPACING_M * (n_rows + 1)
        start = np.array([-HALL_HALF_WIDTH_M + 2.0, 2.5])
        goal = np.array([HALL_HALF_WIDTH_M - 2.0, top - 2.5])
        route = plan_route(start, goal, static, full_m, graph)
        t4 = time.perf_counter()
        out.append({"rows": float(n_rows), "discs": float(len(static)),
                    "nodes": float(graph.nodes_m.shape[0]), "edges": float(graph.edges.shape[0]),
                    "build_full_s": t1 - t0, "build_tight_s": t2 - t1,
                    "with_discs_s": t3 - t2, "route_s": t4 - t3,
                    "route_m": route.length_m if route is not None else math.nan})
    return out


def format_route_rows(rows: list[dict[str, float]]) -> str:
    """The table `orchestrator bench --routes` prints."""
    head = ("rows  discs  nodes  edges   build full s  build tight s  with 5 discs s  "
            "route ms  route m")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['rows']:4.0f}  {r['discs']:5.0f}  {r['nodes']:5.0f}  {r['edges']:6.0f}"
                     f"  {r['build_full_s']:12.3f}  {r['build_tight_s']:13.3f}"
                     f"  {r['with_discs_s']:14.3f}  {1e3 * r['route_s']:8.1f}"
                     f"  {r['route_m']:7.1f}")
    return "\n".join(lines)
