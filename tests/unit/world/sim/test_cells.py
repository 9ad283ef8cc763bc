"""The pose grid (`world.sim.cells`): cells of points, cells covering a disc, the subscription
rule with its margin and hysteresis, and the views it gives a robot moving across borders."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.config import PlannerConfig, paper_config
from agent.core.types import PoseSnapshot
from agent.planning.controller import MAX_COMPENSATED_AGE_S
from agent.planning.estimation import ESTIMATION_MARGIN_M, ESTIMATION_WINDOW_S
from world.sim.cells import (
    HISTORY_MARGIN_M,
    HYSTERESIS_M,
    MAX_CLOSING_SPEED_MPS,
    PUBLISH_SLACK_M,
    SELF_MISSES,
    CellRule,
    CellSubscription,
    ViewMerger,
    canonical_order,
    cell_of,
    cells_near,
    cells_of,
    covering,
    merge_parts,
    split_cells,
)

RULE = CellRule.of_config(PlannerConfig())
coords = st.floats(-1e3, 1e3, allow_nan=False)
sizes = st.floats(5.0, 100.0)
radii = st.floats(0.0, 100.0)


def _gap_m(x: float, y: float, cell: tuple[int, int], size_m: float) -> float:
    """Distance from (x, y) to the nearest point of a cell's square."""
    i, j = cell
    dx = max((i - 0.5) * size_m - x, 0.0, x - (i + 0.5) * size_m)
    dy = max((j - 0.5) * size_m - y, 0.0, y - (j + 0.5) * size_m)
    return math.hypot(dx, dy)


# --- the radii -------------------------------------------------------------------------------

def test_the_default_radii_and_cell_size() -> None:
    """Sensing 10 m: estimated to 15 m, subscribed from 18.75 m, dropped beyond 20 m, 20 m
    cells; the margins rest on the controller's own assumption of 5 m/s closing speed."""
    assert MAX_CLOSING_SPEED_MPS == ESTIMATION_MARGIN_M / MAX_COMPENSATED_AGE_S
    assert abs(HISTORY_MARGIN_M - ESTIMATION_WINDOW_S * MAX_CLOSING_SPEED_MPS) < 1e-12
    assert (RULE.see_radius_m, RULE.add_radius_m, RULE.drop_radius_m, RULE.size_m) == (
        pytest.approx(15.0), pytest.approx(18.75), pytest.approx(20.0), pytest.approx(20.0))
    assert RULE.drop_radius_m - RULE.add_radius_m == HYSTERESIS_M
    # The paper's profile senses 1 km: cells of 1010 m, a scenario is one to four cells.
    assert CellRule.of_config(paper_config()).size_m == pytest.approx(1010.0)


def test_a_rule_with_radii_out_of_order_is_refused() -> None:
    with pytest.raises(ValueError):
        CellRule(see_radius_m=10.0, add_radius_m=9.0, drop_radius_m=12.0, size_m=12.0)
    with pytest.raises(ValueError):
        CellRule(see_radius_m=10.0, add_radius_m=11.0, drop_radius_m=12.0, size_m=0.0)


# --- geometry --------------------------------------------------------------------------------

def test_the_origin_is_the_centre_of_cell_zero() -> None:
    assert cell_of(0.0, 0.0, 20.0) == (0, 0)
    assert cell_of(9.999, -10.0, 20.0) == (0, -1 + 1) == (0, 0)
    assert cell_of(10.0, -10.001, 20.0) == (1, -1)
    assert cells_of(np.array([[0.0, 0.0], [10.0, -10.001], [-30.0, 29.9]]), 20.0).tolist() == [
        [0, 0], [1, -1], [-1, 1]]


@given(coords, coords, sizes)
def test_a_point_lies_in_the_square_of_its_cell(x: float, y: float, size: float) -> None:
    i, j = cell_of(x, y, size)
    assert (i - 0.5) * size <= x + 1e-9 and x < (i + 0.5) * size + 1e-9
    assert (j - 0.5) * size <= y + 1e-9 and y < (j + 0.5) * size + 1e-9
    assert cells_of(np.array([[x, y]]), size).tolist() == [[i, j]]


@settings(max_examples=300)
@given(coords, coords, radii, sizes, st.floats(0.0, 1.0), st.floats(0.0, 2 * math.pi))
def test_every_point_within_the_radius_is_in_a_covering_cell(
        x: float, y: float, r: float, size: float, frac: float, angle: float) -> None:
    cells = covering(x, y, r, size)
    qx, qy = x + frac * r * math.cos(angle), y + frac * r * math.sin(angle)
    assert cell_of(qx, qy, size) in cells
    assert cell_of(x, y, size) in cells


@given(coords, coords, radii, sizes)
def test_every_covering_cell_has_a_point_within_the_radius(x: float, y: float, r: float,
                                                           size: float) -> None:
    for cell in covering(x, y, r, size):
        assert _gap_m(x, y, cell, size) <= r + 1e-5


@given(st.lists(st.tuples(coords, coords), min_size=1, max_size=8), radii, sizes)
def test_cells_near_points_hold_every_covering_cell(points: list[tuple[float, float]],
                                                    r: float, size: float) -> None:
    near = cells_near(np.array(points), r, size)
    for x, y in points:
        assert covering(x, y, r, size) <= near


def test_a_disc_of_the_add_radius_needs_at_most_three_by_three_cells() -> None:
    for x, y in ((0.0, 0.0), (9.99, 9.99), (10.0, -10.0), (3.0, 7.0)):
        held = RULE.update(RULE.needed(x, y), x, y)
        assert len(held) <= 9
        assert max(i for i, _ in held) - min(i for i, _ in held) <= 2


# --- the subscription rule -------------------------------------------------------------------

@given(coords, coords, st.lists(st.tuples(st.integers(-60, 60), st.integers(-60, 60)),
                                max_size=20))
def test_an_update_holds_what_is_needed_and_nothing_beyond_the_drop_radius(
        x: float, y: float, held: list[tuple[int, int]]) -> None:
    new = RULE.update(held, x, y)
    assert RULE.needed(x, y) <= new
    assert all(_gap_m(x, y, c, RULE.size_m) <= RULE.drop_radius_m + 1e-5 for c in new)


def test_hysteresis_a_robot_dithering_at_a_border_does_not_resubscribe() -> None:
    """Cell (1, 0) (x from 10 m) is needed from x = -8.75 m; a robot going back and forth
    between -8.0 and -9.5 m adds it once and keeps it (dropped only beyond -10 m)."""
    sub = CellSubscription(RULE, (-9.5, 0.0))
    assert sub.cells is not None and (1, 0) not in sub.cells
    changes = [sub.follow(x, 0.0) for x in (-8.0, -9.5, -8.0, -9.5, -9.9)]
    assert changes[0].added == {(1, 0)} and all(c.empty for c in changes[1:])
    assert sub.follow(-10.1, 0.0).dropped == {(1, 0)}


def test_a_subscription_change_adds_before_it_drops() -> None:
    sub = CellSubscription(RULE, (0.0, 0.0))
    change = sub.follow(31.0, 0.0)  # a jump of a cell and a half
    assert change.added and change.dropped and not change.added & change.dropped
    assert sub.cells == change.added | (RULE.needed(0.0, 0.0) - change.dropped)
    assert sub.changes == len(change.added) + len(change.dropped)


def test_a_robot_that_misses_itself_searches_at_once_before_it_was_located() -> None:
    sub = CellSubscription(RULE, (0.0, 0.0))
    change = sub.missed_self()
    assert change.search and change.dropped == RULE.needed(0.0, 0.0) and sub.cells is None
    assert sub.holds((123, -45)) and sub.missed_self().empty  # searching already
    found = sub.follow(100.0, 0.0)
    assert found.found and found.added == RULE.needed(100.0, 0.0) == sub.cells


def test_a_located_robot_searches_only_after_missing_itself_several_times() -> None:
    sub = CellSubscription(RULE, (0.0, 0.0))
    sub.follow(0.0, 0.0)
    for _ in range(SELF_MISSES - 1):
        assert sub.missed_self().empty
    assert sub.missed_self().search and sub.cells is None
    sub.follow(1.0, 0.0)
    assert sub.self_misses == 0 and sub.cells is not None


# --- views -----------------------------------------------------------------------------------

def _snapshot(xy: np.ndarray, ids: np.ndarray, tick: int = 3) -> PoseSnapshot:
    pose = np.zeros((len(ids), 3))
    pose[:, :2] = xy
    pose[:, 2] = np.where(ids >= 0, 0.1 * ids, 0.0)
    return PoseSnapshot(stamp_s=0.06, tick=tick, ids=ids, pose=pose,
                        radius_m=np.full(len(ids), 0.5))


def test_split_then_merge_of_every_cell_gives_the_snapshot_in_canonical_order() -> None:
    rng = np.random.default_rng(4)
    ids = np.array([0, 1, 2, 3, 4, 5, -1, -2, -3])
    snap = _snapshot(rng.uniform(-50, 50, (len(ids), 2)), ids)
    parts = split_cells(snap, 20.0)
    assert len(parts) > 3
    for cell, part in parts.items():
        assert (cells_of(part.pose[:, :2], 20.0) == cell).all()
        assert part.tick == 3 and part.stamp_s == 0.06
    view = merge_parts(parts, None, snap.stamp_s, snap.tick)
    np.testing.assert_array_equal(view.ids, ids)
    np.testing.assert_array_equal(view.pose, snap.pose)
    one = next(iter(parts))
    only = merge_parts(parts, [one, (999, 999)], 0.06, 3)
    assert sorted(only.ids.tolist()) == sorted(parts[one].ids.tolist())


def test_canonical_order_is_robots_by_id_then_obstacles_from_minus_one() -> None:
    ids = np.array([-2, 7, -1, 0, 3])
    assert ids[canonical_order(ids)].tolist() == [0, 3, 7, -1, -2]


def test_the_merger_hands_out_the_same_ids_while_the_parts_repeat() -> None:
    a = _snapshot(np.array([[1.0, 0.0], [2.0, 0.0]]), np.array([4, -1]))
    b = _snapshot(np.array([[30.0, 0.0]]), np.array([2]))
    for part in (a, b):
        part.ids.flags.writeable = False
    merger = ViewMerger()
    first = merger.merge([a, b], 0.0, 1)
    second = merger.merge([a, b], 0.02, 2)
    assert first.ids.tolist() == [2, 4, -1] and second.ids is first.ids
    assert not first.ids.flags.writeable
    assert second.pose[:, 0].tolist() == [30.0, 1.0, 2.0]
    c = _snapshot(np.array([[30.0, 1.0]]), np.array([2]))  # other ids: merged afresh
    assert merger.merge([a, c], 0.04, 3).ids is not first.ids
    assert merger.merge([], 0.0, 0).ids.shape == (0,)


def test_the_world_publishes_every_cell_a_robot_holds() -> None:
    """A robot's cells lie within the drop radius of where it saw itself; the world
    publishes every cell within that plus `PUBLISH_SLACK_M` of where it is now."""
    rng = np.random.default_rng(7)
    for _ in range(50):
        seen = rng.uniform(-100, 100, 2)
        now = seen + rng.uniform(-1, 1, 2) * PUBLISH_SLACK_M / math.sqrt(2)
        held = RULE.update(RULE.needed(*(seen - 1.0)), *seen)
        assert held <= RULE.published(np.array([now, [500.0, 500.0]]))


# --- a robot moving across cell borders ------------------------------------------------------

def _drive(rule: CellRule, seed: int) -> tuple[str | None, int]:
    """A robot drives at 1.1 m/s for 60 s, weaving, among 40 discs (robots and obstacles)
    driving at up to 3.9 m/s (closing speeds up to 5 m/s), in a view every 0.1 s; after
    each view it moves its cells with its own position in it, so each view is of the cells
    chosen one view earlier. Returns the first failure (None: none) and the cell borders
    the robot crossed."""
    rng = np.random.default_rng(seed)
    dt_s, steps, n = 0.1, 600, 40
    ego = rng.uniform(-30, 30, 2)
    heading, phase = rng.uniform(0, 2 * math.pi, 2)
    others = ego + rng.uniform(-45, 45, (n, 2))
    velocity = rng.normal(size=(n, 2))
    velocity *= (rng.uniform(0, 3.9, n) / np.linalg.norm(velocity, axis=1))[:, None]
    sub = CellSubscription(rule, ego)
    window = round(ESTIMATION_WINDOW_S / dt_s - 0.5)  # 7 views back
    history: list[np.ndarray] = []
    crossings = 0
    for step in range(steps):
        seen = np.array([sub.holds((int(i), int(j))) for i, j in cells_of(others, rule.size_m)])
        near = np.linalg.norm(others - ego, axis=1) <= rule.see_radius_m
        if not seen[near].all():
            return f"view {step}: a disc within reach is missing", crossings
        if not all(back[near].all() for back in history[-window:]):
            return f"view {step}: a disc within reach has no full history", crossings
        history.append(seen)
        before = cell_of(*ego, rule.size_m)
        sub.follow(*ego)  # its own position in the view it just observed
        # Weaving within +-0.5 rad of one direction: at least 58 m from start to end.
        way = heading + 0.5 * math.sin(step / 20.0 + phase)
        ego = ego + 1.1 * dt_s * np.array([math.cos(way), math.sin(way)])
        crossings += cell_of(*ego, rule.size_m) != before
        others += velocity * dt_s
        turn = rng.uniform(-0.2, 0.2, n)
        c, s = np.cos(turn), np.sin(turn)
        velocity = np.stack([c * velocity[:, 0] - s * velocity[:, 1],
                             s * velocity[:, 0] + c * velocity[:, 1]], axis=1)
    return None, crossings


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_a_robot_crossing_cell_borders_never_misses_a_neighbour_in_range(seed: int) -> None:
    """In every view of `_drive`, every disc within the controller's reach (15 m) is there,
    and was in each view of the estimation window before (0.7 s: the history its velocity
    estimate fits)."""
    failure, crossings = _drive(RULE, seed)
    assert failure is None
    assert crossings >= 1


def test_without_the_history_margin_a_neighbour_arrives_without_history() -> None:
    """The same drive with cells subscribed only at the controller's reach: some disc comes
    within reach without a full window of history (the check can fail)."""
    bare = CellRule(see_radius_m=RULE.see_radius_m, add_radius_m=RULE.see_radius_m,
                    drop_radius_m=RULE.see_radius_m, size_m=RULE.size_m)
    failures = [_drive(bare, seed)[0] for seed in range(5)]
    assert any(f is not None and "history" in f for f in failures)


def test_the_lockstep_view_is_the_discs_of_the_cells_held() -> None:
    """The view `merge_parts` gives a robot holds exactly the discs in its cells."""
    rng = np.random.default_rng(3)
    ids = np.concatenate([np.arange(60), -np.arange(1, 11)])
    snap = _snapshot(rng.uniform(-80, 80, (70, 2)), ids)
    sub = CellSubscription(RULE, (5.0, -3.0))
    view = merge_parts(split_cells(snap, RULE.size_m), sub.cells, snap.stamp_s, snap.tick)
    held = [sub.holds((int(i), int(j))) for i, j in cells_of(snap.pose[:, :2], RULE.size_m)]
    expected = ids[np.array(held)]
    assert sorted(view.ids.tolist()) == sorted(expected.tolist())
    near = np.linalg.norm(snap.pose[:, :2] - [5.0, -3.0], axis=1) <= RULE.add_radius_m
    assert set(ids[near].tolist()) <= set(view.ids.tolist())
