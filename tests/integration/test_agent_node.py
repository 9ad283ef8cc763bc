"""The robot process's edge (`agent.node`): the pose inbox, the CPU tokens and meter, and what
a robot process imports. Its decisions are tested in tests/unit/agent/test_robot_cycle.py."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import zenoh

from agent import node as agent_node
from agent.core.config import PlannerConfig
from agent.core.scenario import RobotSpec
from agent.node import CpuMeter, PoseInbox, cpu_token
from agent.planning.controller import RobotController
from agent.process import StallWatch
from agent.robot_cycle import RobotCycle
from eifp_wire import PosesMsg, RunConfigMsg, RunKeys
from world.sim.cells import CellRule
from world.sim.schedule import PlanSchedule


def test_a_robot_process_imports_only_what_it_needs() -> None:
    """After building and warming up an eifp-mpc robot: no YAML, plotting, ORCA, orchestrator
    or psutil in the process (each costs start-up CPU and memory in 128 processes)."""
    code = """
import json, sys
import agent.node
from agent.startup import make_controller, warm_up
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


# --- CPU tokens --------------------------------------------------------------------------------

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


def _work(tokens: _Tokens, wanted: bool) -> bool | None:
    with cpu_token(tokens, wanted, StallWatch()) as held:
        tokens.log.append(f"work held={tokens.held}")
        return held


def test_a_robot_senses_and_plans_holding_a_cpu_token_and_gives_it_back() -> None:
    tokens = _Tokens(available=True)
    assert _work(tokens, wanted=True) is True
    assert tokens.log == ["acquire", "work held=True", "release"]


def test_without_a_token_in_time_a_robot_works_anyway_and_is_told_so() -> None:
    tokens = _Tokens(available=False)
    assert _work(tokens, wanted=True) is False  # the node counts it as a token_timeout
    assert tokens.log == ["timeout", "work held=False"]


def test_no_token_is_taken_without_a_pose_to_work_on() -> None:
    tokens = _Tokens(available=True)
    assert _work(tokens, wanted=False) is None
    assert tokens.log == ["work held=False"]


def test_the_token_is_given_back_when_the_work_raises() -> None:
    tokens = _Tokens(available=True)
    with pytest.raises(RuntimeError), cpu_token(tokens, True, StallWatch()):
        raise RuntimeError("planner bug")
    assert tokens.log[-1] == "release" and not tokens.held


# --- the pose inbox ----------------------------------------------------------------------------

KEYS = RunKeys("r")
RULE = CellRule.of_config(PlannerConfig())


class _Sample:
    """A Zenoh sample as the pose inbox sees one: its key, a payload and where it came from."""

    def __init__(self, data: bytes, zid: str | None = None,
                 key: str = KEYS.poses_cell(0, (0, 0))) -> None:
        self.key_expr = key
        self.payload = zenoh.ZBytes(data)
        self.source_info = (None if zid is None else
                            SimpleNamespace(source_id=SimpleNamespace(zid=zid, eid=1),
                                            source_sn=1))


def _pose(tick: int, t_s: float) -> bytes:
    """The message of cell (0, 0), which holds both robots."""
    return PosesMsg(t_s=t_s, tick=tick, robot_ids=[0, 1],
                    robot_pose=[[0, 0, 0], [5, 0, 3.1]], robot_radius_m=[0.5, 0.5],
                    obstacle_ids=[], obstacle_xy_m=np.zeros((0, 2)),
                    obstacle_radius_m=[]).encode()


def _tick(tick: int, t_s: float) -> list[_Sample]:
    """The samples of one tick for a robot at the origin: each of its cells, only (0, 0)
    not empty."""
    empty = PosesMsg(t_s=t_s, tick=tick, robot_ids=[], robot_pose=np.zeros((0, 3)),
                     robot_radius_m=[], obstacle_ids=[], obstacle_xy_m=np.zeros((0, 2)),
                     obstacle_radius_m=[]).encode()
    return [_Sample(_pose(tick, t_s) if cell == (0, 0) else empty,
                    key=KEYS.poses_cell(0, cell)) for cell in sorted(RULE.needed(0.0, 0.0))]


def test_the_robot_takes_a_pose_off_its_queue_when_it_arrives_and_clocks_from_then() -> None:
    spec = RobotSpec(0, (0.0, 0.0, 0.0), (10.0, 0.0))
    config = RunConfigMsg(run_id="r", robot=spec, planner=PlannerConfig(), goal_tolerance_m=0.25,
                          control_rate_hz=10.0, world_rate_hz=50.0, time_scale=1.0,
                          time_limit_s=60.0, cmd_timeout_s=0.5, known_ids=(0, 1))
    cycle = RobotCycle(config, RobotController(spec, PlannerConfig(), 0.25), PlanSchedule(0.1))
    inbox = PoseInbox(None)
    for sample in _tick(10, 0.2):
        inbox.queue.put(sample)
    before = time.monotonic()
    waited_s, refused = inbox.wait(1.0)  # returns at once: a tick's cells are waiting
    assert len(inbox.ring) == 9 and inbox.queue.empty() and refused == []
    assert before <= inbox.rx_wall_s <= time.monotonic() and waited_s < 0.5
    # As if it had been taken off 30 ms ago:
    assert cycle.sense(inbox.take(), inbox.rx_wall_s - 0.03, time.monotonic()) is True
    assert not inbox.ring and cycle.newest is not None and cycle.newest.parts == 9
    assert cycle.clock.now_s(time.monotonic()) == pytest.approx(0.2 + 0.03, abs=0.01)


def test_without_poses_the_robot_waits_at_most_its_nap() -> None:
    inbox = PoseInbox(None)
    stalls = StallWatch()
    stalls.tick()
    t0 = time.monotonic()
    waited_s, _ = inbox.wait(agent_node.MAX_NAP_S)
    assert time.monotonic() - t0 >= agent_node.MAX_NAP_S * 0.9  # one wait for the whole nap
    assert waited_s >= agent_node.MAX_NAP_S * 0.9 and not inbox.ring
    # The nap is a wait the loop asked for, not a stall (only what it overran by is).
    stalls.waited(waited_s, agent_node.MAX_NAP_S)
    assert stalls.tick() <= max(0.0, waited_s - agent_node.MAX_NAP_S) + 0.05


def test_poses_not_from_the_world_never_enter_the_ring() -> None:
    inbox = PoseInbox("aa")
    for _ in range(3):  # a flood of forged poses, then the world's
        inbox.queue.put(_Sample(_pose(10, 0.2), None))
        inbox.queue.put(_Sample(_pose(10, 0.2), "bb"))
    inbox.queue.put(_Sample(_pose(10, 0.2), "aa"))
    _, refused = inbox.wait(1.0)
    assert len(inbox.ring) == 1 and refused == [None, "bb"] * 3


def test_the_ring_keeps_the_newest_poses_only() -> None:
    inbox = PoseInbox(None, size=2)
    for tick in range(5):
        inbox.queue.put(_Sample(_pose(tick, 0.02 * tick)))
    inbox.wait(1.0)
    key = KEYS.poses_cell(0, (0, 0))
    assert inbox.take() == [(key, _pose(3, 0.06)), (key, _pose(4, 0.08))]


# --- the CPU meter -----------------------------------------------------------------------------

def _burn(cpu_s: float) -> None:
    """Spin until this thread has used `cpu_s` of CPU."""
    end = time.thread_time() + cpu_s
    while time.thread_time() < end:
        pass


def test_the_cpu_meter_splits_the_main_thread_and_charges_the_other_threads() -> None:
    meter = CpuMeter()
    assert meter.summary() == {}  # the loop never started
    meter.start()
    _burn(0.05)  # this thread: 20 ms of it counted as planning, the rest is the loop's
    meter.add("plan", 0.02)
    other = threading.Thread(target=_burn, args=(0.05,))  # as Zenoh's threads would
    other.start()
    other.join()
    got = meter.summary()
    assert list(got) == [f"cpu_{p}_us" for p in ("sense", "plan", "send", "loop", "threads")]
    assert got["cpu_plan_us"] == 20_000 and got["cpu_sense_us"] == got["cpu_send_us"] == 0
    assert 29_000 <= got["cpu_loop_us"] < 1_000_000
    assert 49_000 <= got["cpu_threads_us"] < 1_000_000
