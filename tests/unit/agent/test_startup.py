"""How a robot process starts (`agent.startup`): its options, its configuration, its controller."""

from __future__ import annotations

import time
from types import SimpleNamespace

import msgpack
import numpy as np
import pytest

from agent.core.config import PlannerConfig
from agent.core.scenario import RobotSpec
from agent.process import ExitCode, StopFlag
from agent.startup import AgentOptions, RobotExit, fetch_config, make_controller, parse_args
from eifp_wire import RunConfigMsg, RunKeys


def _config(robot: RobotSpec, **fields: object) -> RunConfigMsg:
    values: dict = dict(run_id="r1", robot=robot, planner=PlannerConfig(), goal_tolerance_m=0.25,
                        control_rate_hz=10.0, world_rate_hz=50.0, time_scale=1.0,
                        time_limit_s=60.0, cmd_timeout_s=0.5, known_ids=(robot.id,))
    return RunConfigMsg(**{**values, **fields})


def test_parse_args() -> None:
    opts = parse_args(["--run", "r-1", "--id", "3", "--connect", "tcp/127.0.0.1:7447"])
    assert opts == AgentOptions(run_id="r-1", robot_id=3, connect="tcp/127.0.0.1:7447")
    opts = parse_args(["--run", "r", "--id", "0", "--connect", "tcp/h:1",
                       "--control-rate-hz", "20", "--startup-timeout-s", "5"])
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
def test_parse_args_rejects(argv: list[str]) -> None:
    with pytest.raises(SystemExit):
        parse_args(argv)


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


@pytest.mark.parametrize("planner", ["eifp-mpc", "orca"])
def test_make_controller_builds_the_planner_for_the_control_period(planner: str) -> None:
    config = _config(RobotSpec(0, (0.0, 0.0, 0.0), (5.0, 0.0), planner=planner),
                     control_rate_hz=20.0)
    controller = make_controller(config, 0.05)
    assert controller.control_period_s == 0.05
    assert controller.planner.name == planner and controller.planner.control_period_s == 0.05


def test_a_distributed_robot_routes_over_the_map_the_world_sends() -> None:
    """The static map of the world's `RunConfigMsg` reaches the robot's planner, which
    routes over it (a wall it has not sensed yet)."""
    from orchestrator.experiments.families import resolve
    from world.node import run_configs

    scenario = resolve("wall_door", agents=6, seed=3)
    options = SimpleNamespace(run_id="r-1", control_rate_hz=10.0, rate_hz=50.0, time_scale=1.0,
                              cmd_timeout_s=0.5)
    spec = scenario.robots[0]
    config = RunConfigMsg.decode(run_configs(scenario, options)[spec.id])
    static = [o for o in scenario.obstacles if o.velocity == (0.0, 0.0)]
    assert len(config.static_map) == len(static) > 0
    controller = make_controller(config, 0.1)
    guide = controller.planner.guide
    assert guide is not None and guide.routes
    assert set(guide.static.ids.tolist()) == {o.id for o in static}
    np.testing.assert_allclose(guide.static.center_m, [o.center for o in static])


def _reply(payload: bytes, zid: str | None) -> SimpleNamespace:
    return SimpleNamespace(ok=SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda: payload)),
                           err=None,
                           replier_id=None if zid is None else SimpleNamespace(zid=zid))


def test_a_configuration_reply_not_from_the_world_is_refused() -> None:
    good = _config(RobotSpec(id=3, start=(0.0, 0.0, 0.0), goal=(5.0, 0.0)))
    forged = _config(RobotSpec(id=3, start=(0.0, 0.0, 0.0), goal=(50.0, 0.0)))
    # A fake session stands in for Zenoh: fetch_config only calls get().
    session = SimpleNamespace(get=lambda key, timeout, **kw: [_reply(forged.encode(), "bb"),
                                                              _reply(good.encode(), "aa")])
    counts: dict[str, int] = {}
    got = fetch_config(session, RunKeys("r1"), 3, StopFlag(),
                       time.monotonic() + 1.0, "aa", counts)
    assert got.robot.goal == (5.0, 0.0) and counts == {"refused_config": 1}


def test_a_configuration_reply_from_no_named_session_is_refused() -> None:
    # Zenoh's `Reply.replier_id` may be None; with the world's id known such a reply is
    # not the world's: refused and counted, and the world's own reply is still taken.
    good = _config(RobotSpec(id=3, start=(0.0, 0.0, 0.0), goal=(5.0, 0.0)))
    session = SimpleNamespace(get=lambda key, timeout, **kw: [_reply(good.encode(), None),
                                                              _reply(good.encode(), "aa")])
    counts: dict[str, int] = {}
    got = fetch_config(session, RunKeys("r1"), 3, StopFlag(),
                       time.monotonic() + 1.0, "aa", counts)
    assert got == good and counts == {"refused_config": 1}


def test_a_configuration_out_of_range_is_refused_and_named_at_start_up() -> None:
    # The world's reply carries threats.t_max_s = -1 (typed right, out of range): the
    # robot must not build a controller from it, and leaves at its start-up deadline naming
    # the field.
    good = _config(RobotSpec(id=3, start=(0.0, 0.0, 0.0), goal=(5.0, 0.0)))
    body = msgpack.unpackb(good.encode())
    body["planner"]["threats"]["t_max_s"] = -1.0
    replies = [_reply(msgpack.packb(body, use_bin_type=True), None)]
    asked = []
    session = SimpleNamespace(get=lambda key, timeout, **kw: asked.append(key) or replies)
    with pytest.raises(RobotExit) as caught:
        fetch_config(session, RunKeys("r1"), 3, StopFlag(),
                     deadline=time.monotonic() + 0.25)
    assert caught.value.code == ExitCode.BAD_INPUT
    assert "config.planner.threats: t_max_s: must be > 0" in caught.value.reason
    assert asked  # it did ask, and kept asking until the deadline
    # the same reply with the field in range is taken
    body["planner"]["threats"]["t_max_s"] = 6.0
    replies[0] = _reply(msgpack.packb(body, use_bin_type=True), None)
    got = fetch_config(session, RunKeys("r1"), 3, StopFlag(),
                       deadline=time.monotonic() + 1.0)
    assert got.planner.threats.t_max_s == 6.0
