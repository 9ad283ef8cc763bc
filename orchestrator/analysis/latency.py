"""Wall-clock latency of a distributed run by stage, from the commands' `WallStamps` (pure).

Every applied command carries the monotonic stamps of its way (`eifp_wire.TIMING_COLUMNS`:
the pose's publish, the robot's receive, plan start and end, the command's publish, the
world's receive and apply) and the ids of the clocks they were taken on. `wall_latency_ms`
turns a run's stamps (``timing.csv``) into percentiles per stage (`WALL_STAGES`,
`TRANSPORT_STAGE`), `wall_latency_ms_by_group` per router (`router_groups`); they are
``metrics.json``'s ``wall_latency_ms`` and ``wall_latency_ms_by_router``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from eifp_wire import TIMING_COLUMNS

WALL_STAGES: tuple[tuple[str, str, str, bool], ...] = (
    ("pose_to_robot", "pose_pub_ns", "pose_rx_ns", True),
    ("robot_wait", "pose_rx_ns", "plan_start_ns", False),
    ("plan", "plan_start_ns", "plan_end_ns", False),
    ("send", "plan_end_ns", "cmd_pub_ns", False),
    ("cmd_to_world", "cmd_pub_ns", "cmd_rx_ns", True),
    ("world_wait", "cmd_rx_ns", "applied_ns", False),
    ("sense_to_act", "pose_pub_ns", "cmd_rx_ns", False),
    ("end_to_end", "pose_pub_ns", "applied_ns", False),
)
"""(stage, from stamp, to stamp, crosses clocks). ``sense_to_act``: the world published a
pose -> the world received the command planned on it; ``end_to_end``: ... and applied it.
Both ends of those are the world's clock, so they hold across hosts too. A stage that
crosses clocks (world <-> robot) is measured only for commands whose robot shares the
world's clock (one host)."""
TRANSPORT_STAGE = "transport"
"""``sense_to_act`` less the robot's own time (pose received -> command published): the
pose's way out plus the command's way back, through every router between. Each of its two
differences is taken on one clock (the world's, the robot's), so it holds across hosts
without synchronised clocks."""
DIRECT_ROUTER = "world"
"""`router_groups` name of the robots connected to the world's own router."""


def _percentiles(ms: np.ndarray) -> dict[str, float | None]:
    return {"p50": round(float(np.percentile(ms, 50)), 3),
            "p99": round(float(np.percentile(ms, 99)), 3),
            "max": round(float(ms.max()), 3), "n": int(ms.size)}


def wall_latency_ms(stamps: np.ndarray) -> dict[str, dict[str, float | None]]:
    """p50, p99 and max [ms] and the count of every `WALL_STAGES` stage and of
    `TRANSPORT_STAGE`.

    Args:
        stamps: (K, 9) int64, one row per applied command, columns `TIMING_COLUMNS`
            (0: not stamped).

    Returns:
        stage -> {"p50", "p99", "max", "n"}; stages with no measurable command are left out.
    """
    stamps = np.asarray(stamps, dtype=np.int64).reshape(-1, len(TIMING_COLUMNS))
    col = {name: stamps[:, k] for k, name in enumerate(TIMING_COLUMNS)}
    same_clock = (col["robot_clock"] == col["world_clock"]) & (col["robot_clock"] != 0)
    out: dict[str, dict[str, float | None]] = {}
    for stage, start, end, crosses in WALL_STAGES:
        ok = (col[start] > 0) & (col[end] > 0)
        if crosses:
            ok &= same_clock
        ms = (col[end][ok] - col[start][ok]) / 1e6
        if ms.size:
            out[stage] = _percentiles(ms)
    ends = ("pose_pub_ns", "pose_rx_ns", "cmd_pub_ns", "cmd_rx_ns")
    ok = np.all([col[name] > 0 for name in ends], axis=0)
    world_ns = col["cmd_rx_ns"][ok] - col["pose_pub_ns"][ok]
    robot_ns = col["cmd_pub_ns"][ok] - col["pose_rx_ns"][ok]
    if world_ns.size:
        out[TRANSPORT_STAGE] = _percentiles((world_ns - robot_ns) / 1e6)
    return out


def router_groups(robot_ids: Iterable[int], relays: Mapping[str, Iterable[int]]
                  ) -> dict[str, list[int]]:
    """Router name -> the robots connected to it: each relay's robots (`relays`, the world's
    ``--relay`` list by certificate name), and `DIRECT_ROUTER` for the rest (those that
    dial the world's router). Empty without relays."""
    if not relays:
        return {}
    behind = {name: sorted(int(i) for i in ids) for name, ids in relays.items()}
    relayed = {i for ids in behind.values() for i in ids}
    direct = sorted(int(i) for i in robot_ids if int(i) not in relayed)
    return {DIRECT_ROUTER: direct, **behind} if direct else behind


def wall_latency_ms_by_group(robot: np.ndarray, stamps: np.ndarray,
                             groups: Mapping[str, Iterable[int]]
                             ) -> dict[str, dict[str, dict[str, float | None]]]:
    """`wall_latency_ms` of the commands of each group of robots.

    Args:
        robot: (K,) the robot id of each row of `stamps`.
        stamps: (K, 9) as `wall_latency_ms`.
        groups: group name -> its robot ids (e.g. `router_groups`).
    """
    robot = np.asarray(robot, dtype=np.int64).reshape(-1)
    stamps = np.asarray(stamps, dtype=np.int64).reshape(-1, len(TIMING_COLUMNS))
    if robot.size != stamps.shape[0]:
        raise ValueError(f"{robot.size} robot ids for {stamps.shape[0]} rows of stamps")
    return {name: wall_latency_ms(stamps[np.isin(robot, np.fromiter(ids, dtype=np.int64))])
            for name, ids in groups.items()}
