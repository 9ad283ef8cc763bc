"""Tests of the robot process's pure parts: the sim-time plan schedule and the arguments."""

from __future__ import annotations

import threading
import time
from collections import deque

import numpy as np
import pytest

from agent import node as agent_node
from agent.core.config import PlannerConfig
from agent.core.scenario import RobotSpec
from agent.core.types import PlanResult, PlanStatus
from agent.node import (
    AgentOptions,
    PlanSchedule,
    RobotNode,
    make_controller,
    parse_args,
    plan_phase_s,
)
from agent.process import ExitCode, StallWatch, StopFlag
from eifp_wire import CommandMsg, RunConfigMsg


def test_schedule_plans_on_first_pose_then_every_period() -> None:
    schedule = PlanSchedule(0.1)
    planned = []
    for tick in range(26):  # poses every 0.02 s of sim time, 0.00 .. 0.50
        stamp = tick * 0.02
        if schedule.due(stamp):
            planned.append(round(stamp, 6))
            assert schedule.planned(stamp) == 0
    assert planned == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]
    assert schedule.skipped == 0


def test_schedule_starts_at_first_stamp_seen() -> None:
    schedule = PlanSchedule(0.1)
    assert schedule.due(3.14)
    schedule.planned(3.14)
    assert not schedule.due(3.2)
    assert schedule.due(3.24)


def test_schedule_skips_missed_slots_instead_of_a_backlog() -> None:
    schedule = PlanSchedule(0.1)
    schedule.due(0.0)
    schedule.planned(0.0)
    # The robot was stalled: the next pose it sees is stamped 0.36 (slots 0.1..0.3 passed).
    assert schedule.due(0.36)
    assert schedule.planned(0.36) == 2  # 0.2 and 0.3 skipped (0.1 is the one planned late)
    assert not schedule.due(0.38)
    assert schedule.due(0.4)
    assert schedule.skipped == 2


def test_schedule_tolerates_float_accumulation() -> None:
    schedule = PlanSchedule(0.1)
    stamp = 0.0
    plans = 0
    for _ in range(5000):  # stamps accumulated as the world does: t += dt
        if schedule.due(stamp):
            schedule.planned(stamp)
            plans += 1
        stamp += 0.02
    assert plans == 1000 and schedule.skipped == 0


def test_schedule_on_a_phase_plans_on_its_slots_only() -> None:
    schedule = PlanSchedule(0.1, phase_s=0.04)
    planned = []
    for tick in range(26):  # poses every 0.02 s: 0.00 .. 0.50
        stamp = tick * 0.02
        if schedule.due(stamp):
            planned.append(round(stamp, 6))
            assert schedule.planned(stamp) == 0
    assert planned == [0.04, 0.14, 0.24, 0.34, 0.44]
    assert schedule.skipped == 0


def test_schedule_on_a_phase_joins_at_the_next_slot() -> None:
    schedule = PlanSchedule(0.1, phase_s=0.04)
    assert not schedule.due(3.16)  # a robot that starts late keeps its phase
    assert schedule.next_s == pytest.approx(3.24)
    assert schedule.due(3.24)


def test_plan_phases_spread_robots_evenly_over_the_ticks() -> None:
    phases = [plan_phase_s(rid, 0.1, 0.02) for rid in range(20)]
    ticks = [round(p / 0.02) for p in phases]
    assert all(abs(p - 0.02 * t) < 1e-12 for p, t in zip(phases, ticks))
    assert sorted(set(ticks)) == [0, 1, 2, 3, 4]
    assert all(ticks.count(t) == 4 for t in range(5))  # 20 robots: 4 plan on each tick
    assert plan_phase_s(7, 0.1, 0.1) == 0.0  # one tick per period: everyone on it


def test_schedule_rejects_bad_period() -> None:
    with pytest.raises(ValueError):
        PlanSchedule(0.0)


def test_parse_args() -> None:
    opts = parse_args(["--run", "r-1", "--id", "3", "--connect", "tcp/127.0.0.1:7447"])
    assert opts == AgentOptions(run_id="r-1", robot_id=3, connect="tcp/127.0.0.1:7447")
    opts = parse_args(
        [
            "--run",
            "r",
            "--id",
            "0",
            "--connect",
            "tcp/h:1",
            "--control-rate-hz",
            "20",
            "--startup-timeout-s",
            "5",
        ]
    )
    assert opts.control_rate_hz == 20.0 and opts.startup_timeout_s == 5.0


@pytest.mark.parametrize(
    "argv",
    [
        ["--run", "bad/run", "--id", "0", "--connect", "tcp/h:1"],
        ["--run", "r", "--id", "-1", "--connect", "tcp/h:1"],
        ["--run", "r", "--id", "0"],
        ["--run", "r", "--id", "0", "--connect", "tcp/h:1", "--control-rate-hz", "0"],
        ["--run", "r", "--id", "0", "--connect", "tcp/h:1", "--control-rate-hz", "nan"],
    ],
)
def test_parse_args_rejects(argv) -> None:
    with pytest.raises(SystemExit):
        parse_args(argv)


@pytest.mark.parametrize("planner", ["eifp-mpc", "orca"])
def test_make_controller_builds_the_planner_for_the_control_period(planner: str) -> None:
    config = RunConfigMsg(
        run_id="r-1", robot=RobotSpec(0, (0.0, 0.0, 0.0), (5.0, 0.0), planner=planner),
        planner=PlannerConfig(), goal_tolerance_m=0.25, control_rate_hz=20.0,
        world_rate_hz=50.0, time_scale=1.0, time_limit_s=60.0, cmd_timeout_s=0.5,
        known_ids=(0,))
    controller = make_controller(config, 0.05)
    assert controller.control_period_s == 0.05
    assert controller.planner.name == planner and controller.planner.control_period_s == 0.05


def test_a_distributed_robot_routes_over_the_map_the_world_sends() -> None:
    """The static map of the world's `RunConfigMsg` reaches the robot's planner, which
    routes over it (a wall it has not sensed yet)."""
    from orchestrator.experiments.families import resolve
    from world.node import run_configs

    scenario = resolve("wall_door", agents=6, seed=3)
    options = type("Options", (), dict(run_id="r-1", control_rate_hz=10.0, rate_hz=50.0,
                                       time_scale=1.0, cmd_timeout_s=0.5))()
    spec = scenario.robots[0]
    config = RunConfigMsg.decode(run_configs(scenario, options)[spec.id])
    static = [o for o in scenario.obstacles if o.velocity == (0.0, 0.0)]
    assert len(config.static_map) == len(static) > 0
    controller = make_controller(config, 0.1)
    guide = controller.planner.guide
    assert guide is not None and guide.routes
    assert set(guide.static.ids.tolist()) == {o.id for o in static}
    np.testing.assert_allclose(guide.static.center_m, [o.center for o in static])


def test_schedule_with_a_phase_plans_on_absolute_slots() -> None:
    schedule = PlanSchedule(0.1, phase_s=0.04)
    planned = []
    for tick in range(20):
        stamp = tick * 0.02 + 0.3  # the first pose the robot sees is stamped 0.30
        if schedule.due(stamp):
            planned.append(round(stamp, 6))
            schedule.planned(stamp)
    assert planned == [0.34, 0.44, 0.54, 0.64]


def test_parse_fault_options() -> None:
    from world.sim.link import LinkFaults

    opts = parse_args(["--run", "r", "--id", "1", "--connect", "tcp/h:1", "--latency-ms", "100",
                       "--jitter-ms", "30", "--drop", "0.1", "--dup", "0.05", "--reorder", "0.02",
                       "--fault-seed", "9", "--control-phase-s", "0.05", "--plan-delay-ms", "40",
                       "--no-latency-compensation"])
    assert opts.link == LinkFaults(100.0, 30.0, 0.1, 0.05, 0.02)
    assert opts.fault_seed == 9 and opts.control_phase_s == 0.05 and opts.plan_delay_ms == 40.0
    assert not opts.compensate_latency
    assert parse_args(["--run", "r", "--id", "1", "--connect", "tcp/h:1"]).compensate_latency
    for bad in (["--drop", "1.5"], ["--latency-ms", "-1"], ["--plan-delay-ms", "inf"]):
        with pytest.raises(SystemExit):
            parse_args(["--run", "r", "--id", "1", "--connect", "tcp/h:1", *bad])

def test_a_robot_process_imports_only_what_it_needs() -> None:
    """After building and warming up an eifp-mpc robot: no YAML, plotting, ORCA, orchestrator
    or psutil in the process (each costs start-up CPU and memory in 128 processes)."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    code = """
import json, sys
from agent.node import make_controller, warm_up
from eifp_wire import RunConfigMsg
from agent.core.config import PlannerConfig
from agent.core.scenario import RobotSpec
spec = RobotSpec(0, (0.0, 0.0, 0.0), (10.0, 0.0), planner="eifp-mpc")
cfg = RunConfigMsg(run_id="t", robot=spec, planner=PlannerConfig(), goal_tolerance_m=0.25,
                   control_rate_hz=10.0, world_rate_hz=50.0, time_scale=1.0,
                   time_limit_s=10.0, cmd_timeout_s=0.5, known_ids=(0, 1))
make_controller(cfg, 0.1)
warm_up(cfg, 0.1)
print(json.dumps(sorted(sys.modules)))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[2], timeout=60)
    modules = set(json.loads(out.stdout.strip().splitlines()[-1]))
    assert {"zenoh", "osqp", "agent.planning.mpc", "agent.planning.eifp"} <= modules
    unneeded = {"yaml", "matplotlib", "PIL", "pyrvo", "agent.planning.orca", "psutil"}
    assert not (modules & unneeded), modules & unneeded
    assert not any(m.startswith("orchestrator") for m in modules)


class _Tokens:
    """A CpuTokens stand-in that records what the robot did while holding one."""

    def __init__(self, available: bool) -> None:
        self.available = available
        self.held = False
        self.log: list[str] = []

    def acquire(self, block: bool = True, timeout: float | None = None) -> bool:
        assert timeout is not None and timeout > 0.0  # never an unbounded wait
        self.held = self.available
        self.log.append("acquire" if self.available else "timeout")
        return self.available

    def release(self) -> None:
        assert self.held
        self.held = False
        self.log.append("release")


def _node_with(tokens: _Tokens, *, ring: bool, fresh: bool = True) -> RobotNode:
    """A RobotNode without a session: only what sense_and_plan touches."""
    node = object.__new__(RobotNode)
    node.cpu_tokens = tokens
    node.pose_ring = deque(["sample"] if ring else [])
    node.counts = {"token_timeouts": 0}
    node.cpu_s = {"sense": 0.0, "plan": 0.0, "send": 0.0}
    node.world_alive = True
    node.stalls = StallWatch()

    def poll_poses() -> bool:
        tokens.log.append(f"poll held={tokens.held}")
        return fresh

    def plan_and_send(cpu_start_s: float | None = None) -> None:
        tokens.log.append(f"plan held={tokens.held}")

    node.poll_poses = poll_poses  # type: ignore[method-assign]
    node.plan_and_send = plan_and_send  # type: ignore[method-assign]
    return node


def test_a_robot_senses_and_plans_holding_a_cpu_token_and_gives_it_back() -> None:
    tokens = _Tokens(available=True)
    assert _node_with(tokens, ring=True).sense_and_plan() is True
    assert tokens.log == ["acquire", "poll held=True", "plan held=True", "release"]


def test_without_a_token_in_time_a_robot_plans_anyway_and_counts_it() -> None:
    tokens = _Tokens(available=False)
    node = _node_with(tokens, ring=True)
    assert node.sense_and_plan() is True
    assert tokens.log == ["timeout", "poll held=False", "plan held=False"]
    assert node.counts["token_timeouts"] == 1


def test_no_token_is_taken_without_a_pose_to_work_on() -> None:
    tokens = _Tokens(available=True)
    assert _node_with(tokens, ring=False, fresh=False).sense_and_plan() is False
    assert tokens.log == ["poll held=False"]


def test_the_token_is_given_back_when_planning_raises() -> None:
    tokens = _Tokens(available=True)
    node = _node_with(tokens, ring=True)

    def boom(cpu_start_s: float | None = None) -> None:
        raise RuntimeError("planner bug")

    node.plan_and_send = boom  # type: ignore[method-assign]
    with pytest.raises(RuntimeError):
        node.sense_and_plan()
    assert tokens.log[-1] == "release" and not tokens.held


class _Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class _Sample:
    def __init__(self, data: bytes, source_info: object = None) -> None:
        self.payload = _Payload(data)
        self.source_info = source_info


def test_the_robot_takes_a_pose_off_its_queue_when_it_arrives_and_clocks_from_then() -> None:
    import time

    node = _pose_node(None)
    node.pose_queue.put(_Sample(_pose(10, 0.2).encode()))
    before = time.monotonic()
    node.wait_for_poses()  # returns at once: a pose is waiting
    assert len(node.pose_ring) == 1 and node.pose_queue.empty()
    assert before <= node.pose_rx_wall <= time.monotonic()
    node.pose_rx_wall -= 0.03  # as if it had been taken off 30 ms ago
    assert node.poll_poses() is True and not node.pose_ring
    assert node.last_rx_wall == node.pose_rx_wall == node.clock_wall
    assert node.sim_now() == pytest.approx(0.2 + 0.03, abs=0.01)  # the pose is 30 ms old


def test_without_poses_the_robot_waits_at_most_its_nap() -> None:
    import time

    node = _pose_node(None)
    node.pose_link = type(node.pose_link)(node.pose_link.faults, None)
    node.stalls.tick()
    t0 = time.monotonic()
    node.wait_for_poses()
    waited = time.monotonic() - t0
    assert not node.pose_ring
    assert waited >= agent_node.MAX_NAP_S * 0.9  # no poll: one wait for the whole nap
    # The nap is a wait the loop asked for, not a stall (only what it overran by is).
    assert node.stalls.tick() <= max(0.0, waited - agent_node.MAX_NAP_S) + 0.05


def test_a_stall_is_counted_as_a_suspension_and_a_nap_is_not() -> None:
    """The loop counts ``suspended`` when `StallWatch` reports more than SUSPEND_GAP_S."""
    from types import SimpleNamespace

    node = _pose_node(None)
    node.stop = StopFlag()
    node.counts["suspended"] = 0
    node.control_sub = node.world_sub = SimpleNamespace(empty=lambda: True)
    node.world_seen, node.world_gone_wall, node.last_rx_wall = True, None, None
    node.resumed_wall = -float("inf")
    node.cmd_pub = node.debug_pub = SimpleNamespace(undeclare=lambda: None)
    node.cpu_s = {"sense": 0.0, "plan": 0.0, "send": 0.0}
    stalls = iter([0.0, agent_node.SUSPEND_GAP_S * 0.9, agent_node.SUSPEND_GAP_S + 0.1, 0.0])
    node.stalls = SimpleNamespace(tick=lambda: next(stalls))
    passes = []

    def sense_and_plan() -> bool:
        passes.append(node.counts["suspended"])
        if len(passes) == 4:
            node.stop(15)  # as SIGTERM would
        return False

    node.sense_and_plan = sense_and_plan
    node.wait_for_poses = lambda: None
    assert node.run(startup_deadline=float("inf")) == ("signal", ExitCode.OK)
    assert passes == [0, 0, 1, 1]
    assert node.resumed_wall > 0.0


def _source(zid: str):
    from types import SimpleNamespace

    return SimpleNamespace(source_id=SimpleNamespace(zid=zid, eid=1), source_sn=1)


def _pose_node(world_zid: str | None):
    import queue
    from types import SimpleNamespace

    from agent.planning.controller import RobotController
    from eifp_wire import PoseDecoder
    from world.sim.link import FaultyLink, LinkFaults

    node = object.__new__(RobotNode)
    node.robot_id = 0
    node.pose_queue = queue.SimpleQueue()
    node.pose_ring = deque(maxlen=2)
    node.pose_rx_wall = 0.0
    node.stalls = StallWatch()
    node.decoder = PoseDecoder({0, 1})
    node.counts = {k: 0 for k in ("rejected", "skipped", "stale", "link_dropped",
                                  "refused_poses", "refused_control")}
    node.last_rx_wall = None
    node.world_zid = world_zid
    node.clock_tick, node.clock_stamp_s, node.clock_wall = -1, 0.0, 0.0
    node.config = SimpleNamespace(time_scale=1.0, world_rate_hz=50.0, time_limit_s=60.0)
    node.pose_link = FaultyLink(LinkFaults(), None)
    node.controller = RobotController(RobotSpec(0, (0.0, 0.0, 0.0), (10.0, 0.0)),
                                      PlannerConfig(), 0.25)
    node.newest = None
    return node


def _pose(tick: int, t_s: float):
    from eifp_wire import PosesMsg

    return PosesMsg(t_s=t_s, tick=tick, robot_ids=[0, 1],
                    robot_pose=[[0, 0, 0], [5, 0, 3.1]], robot_radius_m=[0.5, 0.5],
                    obstacle_ids=[], obstacle_xy_m=np.zeros((0, 2)), obstacle_radius_m=[])


def test_poses_not_from_the_world_never_enter_the_ring() -> None:
    node = _pose_node("aa")
    for _ in range(3):  # a flood of forged poses, then the world's
        node.pose_queue.put(_Sample(_pose(10, 0.2).encode(), None))
        node.pose_queue.put(_Sample(_pose(10, 0.2).encode(), _source("bb")))
    node.pose_queue.put(_Sample(_pose(10, 0.2).encode(), _source("aa")))
    node.wait_for_poses()
    assert len(node.pose_ring) == 1 and node.counts["refused_poses"] == 6


def test_a_malformed_pose_is_rejected_and_counted_and_the_next_one_observed() -> None:
    node = _pose_node(None)
    node.pose_ring.append(_Sample(b"\x93garbage"))
    assert node.poll_poses() is False and node.counts["rejected"] == 1
    node.pose_ring.append(_Sample(_pose(10, 0.2).encode()))
    node.pose_ring.append(_Sample(b"\x81\xa6schema\x04"))  # newer, but malformed
    assert node.poll_poses() is True
    assert node.counts["rejected"] == 2 and node.newest.tick == 10


def test_the_clock_moves_only_on_a_pose_that_passed_every_check() -> None:
    import time

    node = _pose_node("aa")
    node.pose_rx_wall = time.monotonic()
    node.pose_ring.append(_Sample(_pose(10, 0.2).encode(), _source("aa")))
    assert node.poll_poses() is True
    assert node.clock_tick == 10 and node.clock_stamp_s == 0.2
    # Far future, and ahead of the clock (tick and time consistent): refused, clock kept.
    for tick, t_s in ((50_000_000, 1.0e6), (1000, 20.0), (11, 5.0)):
        node.pose_rx_wall = time.monotonic()
        node.pose_ring.append(_Sample(_pose(tick, t_s).encode(), _source("aa")))
        assert node.poll_poses() is False
        assert node.clock_tick == 10 and node.clock_stamp_s == 0.2
    assert node.counts["refused_poses"] == 3
    # The next genuine pose is observed as usual.
    node.pose_ring.append(_Sample(_pose(15, 0.3).encode(), _source("aa")))
    assert node.poll_poses() is True and node.clock_tick == 15


def test_control_is_obeyed_only_from_the_worlds_session() -> None:
    from eifp_wire import ControlMsg

    node = _pose_node("aa")
    end = ControlMsg("end", 1.0, "all_arrived").encode()
    queue = deque([_Sample(end, None), _Sample(end, _source("bb"))])
    node.control_sub = type("Sub", (), {"try_recv": lambda self: queue.popleft()
                                        if queue else None})()
    node.poll_control()  # both refused: no exit
    assert node.counts["refused_control"] == 2
    queue.append(_Sample(end, _source("aa")))
    with pytest.raises(agent_node._Exit) as caught:
        node.poll_control()
    assert caught.value.reason == "end (all_arrived)" and caught.value.code == ExitCode.OK


def test_a_configuration_reply_not_from_the_world_is_refused() -> None:
    import time
    from types import SimpleNamespace

    from agent.process import StopFlag
    from eifp_wire import RunKeys

    good = RunConfigMsg(run_id="r1", robot=RobotSpec(id=3, start=(0.0, 0.0, 0.0),
                                                      goal=(5.0, 0.0)),
                        planner=PlannerConfig(), goal_tolerance_m=0.25, control_rate_hz=10.0,
                        world_rate_hz=50.0, time_scale=1.0, time_limit_s=60.0,
                        cmd_timeout_s=0.5, known_ids=(3,))
    forged = RunConfigMsg(**{**good.__dict__, "robot": RobotSpec(id=3, start=(0.0, 0.0, 0.0),
                                                                 goal=(50.0, 0.0))})

    def reply(msg, zid):
        data = msg.encode()
        return SimpleNamespace(ok=SimpleNamespace(payload=SimpleNamespace(
            to_bytes=lambda: data)), err=None, replier_id=SimpleNamespace(zid=zid))

    session = SimpleNamespace(get=lambda key, timeout, **kw: [reply(forged, "bb"),
                                                              reply(good, "aa")])
    counts: dict[str, int] = {}
    got = agent_node.fetch_config(session, RunKeys("r1"), 3, StopFlag(),
                                  time.monotonic() + 1.0, "aa", counts)
    assert got.robot.goal == (5.0, 0.0) and counts == {"refused_config": 1}


class _Liveliness:
    """A world-liveliness subscriber whose samples the test queues."""

    def __init__(self) -> None:
        self.queue: deque = deque()

    def try_recv(self):
        return self.queue.popleft() if self.queue else None


def _world_watcher(monkeypatch, clock: list[float]) -> tuple[RobotNode, _Liveliness]:
    import agent.node

    monkeypatch.setattr(agent.node.time, "monotonic", lambda: clock[0])
    node = object.__new__(RobotNode)
    node.robot_id = 0
    node.world_sub = _Liveliness()
    node.world_alive = node.world_seen = True
    node.world_gone_wall = None
    node.world_grace_s = agent.node.WORLD_BLIP_GRACE_S
    node.resumed_wall = -float("inf")
    node.poll_control = lambda: None
    return node, node.world_sub


def _token(kind_name: str):
    from types import SimpleNamespace

    import zenoh

    return SimpleNamespace(kind=getattr(zenoh.SampleKind, kind_name))


def test_a_world_token_that_blinks_back_within_the_grace_keeps_the_robot(monkeypatch) -> None:
    from agent.node import WORLD_BLIP_GRACE_S

    clock = [100.0]
    node, sub = _world_watcher(monkeypatch, clock)
    sub.queue.append(_token("DELETE"))
    node.poll_world()  # gone: no exit yet, and no command meanwhile
    assert node.world_alive is False
    clock[0] += 0.8 * WORLD_BLIP_GRACE_S
    node.poll_world()
    sub.queue.append(_token("PUT"))
    node.poll_world()
    assert node.world_alive is True and node.world_gone_wall is None
    clock[0] += 10.0
    node.poll_world()  # long after: nothing pending, nothing raised


def test_a_world_token_gone_for_longer_than_the_grace_ends_the_robot(monkeypatch) -> None:
    from agent.node import WORLD_BLIP_GRACE_S, _Exit
    from agent.process import ExitCode

    clock = [100.0]
    node, sub = _world_watcher(monkeypatch, clock)
    sub.queue.append(_token("DELETE"))
    node.poll_world()
    clock[0] += 1.01 * WORLD_BLIP_GRACE_S
    with pytest.raises(_Exit) as gone:
        node.poll_world()
    assert gone.value.code == ExitCode.WORLD_LOST
    assert gone.value.reason == "world lost (liveliness token gone)"


def test_after_its_own_suspension_a_robot_waits_the_longer_rejoin_grace(monkeypatch) -> None:
    from agent.node import REJOIN_GRACE_S, WORLD_BLIP_GRACE_S, _Exit

    clock = [100.0]
    node, sub = _world_watcher(monkeypatch, clock)
    node.resumed_wall = 99.5  # its loop just came back from a stall
    sub.queue.append(_token("DELETE"))
    node.poll_world()
    clock[0] += 2.0 * WORLD_BLIP_GRACE_S
    node.poll_world()  # still waiting
    clock[0] = 100.0 + 1.01 * REJOIN_GRACE_S
    with pytest.raises(_Exit, match="not back within"):
        node.poll_world()


def test_a_configuration_out_of_range_is_refused_and_named_at_start_up() -> None:
    # The world's reply carries threats.t_max_s = -1 (typed right, out of range): the
    # robot must not build a controller from it, and leaves at its start-up deadline naming
    # the field. A fake session stands in for Zenoh: fetch_config only calls get().
    import time
    from types import SimpleNamespace

    import msgpack

    from agent import node
    from eifp_wire import RunKeys

    good = RunConfigMsg(run_id="r1", robot=RobotSpec(id=3, start=(0.0, 0.0, 0.0),
                                                      goal=(5.0, 0.0)),
                        planner=PlannerConfig(), goal_tolerance_m=0.25, control_rate_hz=10.0,
                        world_rate_hz=50.0, time_scale=1.0, time_limit_s=60.0,
                        cmd_timeout_s=0.5, known_ids=(3,))
    body = msgpack.unpackb(good.encode())
    body["planner"]["threats"]["t_max_s"] = -1.0
    payload = msgpack.packb(body, use_bin_type=True)
    reply = SimpleNamespace(ok=SimpleNamespace(
        payload=SimpleNamespace(to_bytes=lambda: payload)), err=None, replier_id=None)
    asked = []
    session = SimpleNamespace(get=lambda key, timeout, **kw: asked.append(key) or [reply])
    with pytest.raises(node._Exit) as caught:
        node.fetch_config(session, RunKeys("r1"), 3, StopFlag(),
                          deadline=time.monotonic() + 0.25)
    assert caught.value.code == ExitCode.BAD_INPUT
    assert "config.planner.threats: t_max_s: must be > 0" in caught.value.reason
    assert asked  # it did ask, and kept asking until the deadline
    # the same reply with the field in range is taken
    body["planner"]["threats"]["t_max_s"] = 6.0
    payload = msgpack.packb(body, use_bin_type=True)
    got = node.fetch_config(session, RunKeys("r1"), 3, StopFlag(),
                            deadline=time.monotonic() + 1.0)
    assert got.planner.threats.t_max_s == 6.0


def _burn(cpu_s: float) -> None:
    """Spin until this thread has used `cpu_s` of CPU."""
    end = time.thread_time() + cpu_s
    while time.thread_time() < end:
        pass


def test_cpu_summary_splits_the_main_thread_and_charges_the_other_threads() -> None:
    node = object.__new__(RobotNode)
    node.cpu_s = {"sense": 0.0, "plan": 0.0, "send": 0.0}
    node.cpu_start = None
    node.counts, node.seq = {"plans": 3}, 3
    assert node.cpu_summary() == {}  # the loop never started
    node.cpu_start = (time.thread_time(), time.process_time())
    _burn(0.05)  # this thread: 20 ms of it counted as planning, the rest is the loop's
    node.cpu_s["plan"] = 0.02
    other = threading.Thread(target=_burn, args=(0.05,))  # as Zenoh's threads would
    other.start()
    other.join()
    got = node.cpu_summary()
    assert set(got) == {f"cpu_{p}_us" for p in ("sense", "plan", "send", "loop", "threads")}
    assert got["cpu_plan_us"] == 20_000 and got["cpu_sense_us"] == got["cpu_send_us"] == 0
    assert 29_000 <= got["cpu_loop_us"] < 1_000_000
    assert 49_000 <= got["cpu_threads_us"] < 1_000_000
    assert "plans=3 seq=3 cpu_sense_us=0 cpu_plan_us=20000 cpu_send_us=0" in node.summary()


class _Controller:
    """Plans (1, 0.5), recording the time it plans for; each plan lets the next of `plans_s`
    of sim time pass. Brakes to (0, 0)."""

    command_hold_s = 0.15

    def __init__(self, clock: list[float], plans_s: list[float]) -> None:
        self.clock, self.plans_s = clock, list(plans_s)
        self.planned_for: list[float] = []

    def plan(self, now_s: float) -> PlanResult:
        self.planned_for.append(now_s)
        self.clock[0] += self.plans_s.pop(0)
        return PlanResult(v_mps=1.0, omega_radps=0.5, status=PlanStatus.OK,
                          waypoints_m=np.zeros((2, 2)))

    def brake(self) -> PlanResult:
        return PlanResult(v_mps=0.0, omega_radps=0.0, status=PlanStatus.STALE,
                          waypoints_m=np.zeros((2, 2)))


def _planning_node(plans_s: list[float]) -> tuple[RobotNode, list[float], list[CommandMsg]]:
    """A RobotNode without a session whose plans take `plans_s` of sim time, one by one;
    returns it, its sim clock and the commands it sends."""
    from types import SimpleNamespace

    clock = [10.0]
    sent: list[CommandMsg] = []
    node = object.__new__(RobotNode)
    node.robot_id, node.seq, node.clock_id, node.newest_rx_ns = 0, 0, 1, 0
    node.newest = SimpleNamespace(t_s=9.98, clock_id=1, pub_ns=0)
    node.schedule = SimpleNamespace(due=lambda t_s: True, planned=lambda t_s: 0)
    node.options = SimpleNamespace(plan=True, plan_delay_ms=0.0)
    node.config = SimpleNamespace(time_scale=1.0)
    node.controller = _Controller(clock, plans_s)
    node.sim_now = lambda: clock[0]  # type: ignore[method-assign]
    node.counts = {"plans": 0, "overruns": 0, "stale_plans": 0, "late_plans": 0,
                   "plan_errors": 0}
    node.cpu_s = {"sense": 0.0, "plan": 0.0, "send": 0.0}
    node.stalls = StallWatch()
    node.compute_s = 0.0
    node.cmd_pub = SimpleNamespace(put=lambda payload: sent.append(CommandMsg.decode(payload)))
    node.debug_pub = SimpleNamespace(put=lambda payload: None)
    return node, clock, sent


@pytest.mark.parametrize(("plan_s", "late"), [(0.002, False), (0.14, False), (0.16, True),
                                              (0.4, True)])
def test_a_plan_later_than_the_hold_is_sent_as_a_brake(plan_s: float, late: bool) -> None:
    """With no slow plan before it, a plan that took longer than the command hold is sent as a
    stop, and counted."""
    node, _, sent = _planning_node([plan_s])
    node.plan_and_send()
    msg = sent[0]
    assert (msg.v_mps, msg.omega_radps) == ((0.0, 0.0) if late else (1.0, 0.5))
    assert msg.status == ("stale" if late else "ok")
    assert node.counts["late_plans"] == int(late) and node.counts["plans"] == 1


def test_the_robot_plans_for_when_its_command_will_leave() -> None:
    """After a slow plan, the next is planned that much ahead and is not late for taking as
    long; the expectation decays by COMPUTE_DECAY per plan."""
    node, clock, sent = _planning_node([0.2, 0.3, 0.01, 0.01])
    times = []
    for _ in range(4):
        times.append(clock[0])
        node.plan_and_send()
    planned_for = node.controller.planned_for
    assert planned_for[0] == pytest.approx(times[0])  # nothing expected yet
    assert planned_for[1] == pytest.approx(times[1] + 0.2)
    assert planned_for[2] == pytest.approx(times[2] + 0.3)
    assert planned_for[3] == pytest.approx(times[3] + 0.3 * agent_node.COMPUTE_DECAY)
    # 0.2 > 0 + 0.15: late; 0.3 <= 0.2 + 0.15: allowed for; the quick ones are on time.
    assert [m.status for m in sent] == ["stale", "ok", "ok", "ok"]
    assert node.counts["late_plans"] == 1


def test_a_plan_stretched_by_a_stop_does_not_make_the_robot_plan_seconds_ahead() -> None:
    """A plan that took 3 s (the process stopped mid-plan) is late; what the robot expects
    of its next plans is capped at STALE_PLAN_S."""
    node, clock, sent = _planning_node([3.0, 0.01])
    node.plan_and_send()
    assert sent[0].status == "stale" and node.compute_s == agent_node.STALE_PLAN_S
    before = clock[0]
    node.newest.t_s = before - 0.02  # a fresh pose after the stop
    node.plan_and_send()
    assert node.controller.planned_for[1] == pytest.approx(before + agent_node.STALE_PLAN_S)
