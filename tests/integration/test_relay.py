"""Two routers on loopback, in-process: the world's router (access control with a relay) and
a relay router on "another host" (`eifp_wire.access.relay_access_control`) that dials it, with robot
clients behind each. What each router lets through, with real Zenoh sessions and the run's
certificates: robots behind the relay reach the world and back; each router drops what its
own robots may not send; a relay's certificate speaks only for the robots behind it."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from agent.process import ExitCode, zenoh_config
from agent.security import make_run_pki
from eifp_wire import (
    WORLD_CN,
    RunKeys,
    TlsFiles,
    access_control,
    relay_access_control,
    robot_cn,
    router_cn,
    session_settings,
    tls_endpoint,
)
from orchestrator.experiments.distributed import free_tcp_endpoint
from world.router import RunFollower, parse_args, router_settings

pytestmark = pytest.mark.timeout(90)

RUN = "relay-test"
WORLD_ZID = "e1f0a5"
ROBOTS = (0, 1, 2, 3)
BEHIND_B = (2, 3)
DEADLINE_S = 10.0
QUIET_S = 1.0
"""How long a message that should be dropped is waited for."""


def until(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


class Hosts:
    """The world's router (host A) and relay ``router-b`` (host B), with the run's PKI."""

    def __init__(self, tmp_path: Path) -> None:
        self.keys = RunKeys(RUN)
        self.tls_dir = tmp_path / "tls"
        self.files = make_run_pki(self.tls_dir, RUN, ROBOTS, relays={"b": (), "c": ()})
        self.a = tls_endpoint(free_tcp_endpoint())
        self.b = tls_endpoint(free_tcp_endpoint())
        self.sessions: list[zenoh.Session] = []
        self.world = self.open(session_settings(
            mode="router", listen=[self.a], tls=self.files[WORLD_CN], zid=WORLD_ZID,
            acl=access_control(RUN, ROBOTS, relays={"b": BEHIND_B, "c": (1,)})))
        self.relay = self.open(session_settings(
            mode="router", listen=[self.b], connect=[self.a], tls=self.files[router_cn("b")],
            acl=relay_access_control(RUN, BEHIND_B)))
        until(lambda: any(str(z) == WORLD_ZID for z in self.relay.info.routers_zid()),
              "the relay's link to the world's router")

    def open(self, settings: dict[str, str]) -> zenoh.Session:
        session = zenoh.open(zenoh_config(settings))
        self.sessions.append(session)
        return session

    def client(self, cn: str, endpoint: str) -> zenoh.Session:
        tls: TlsFiles = self.files[cn]
        return self.open(session_settings(mode="client", connect=[endpoint],
                                          connect_timeout_ms=5000, tls=tls))

    def close(self) -> None:
        for s in reversed(self.sessions):
            s.close()


@pytest.fixture
def hosts(tmp_path: Path) -> Iterator[Hosts]:
    h = Hosts(tmp_path)
    try:
        yield h
    finally:
        h.close()


def received(sub: zenoh.Subscriber, wait_s: float = QUIET_S) -> list[str]:
    """Keys of the samples `sub` got within `wait_s`."""
    time.sleep(wait_s)
    out = []
    while (sample := sub.try_recv()) is not None:
        out.append(str(sample.key_expr))
    return out


def test_robots_behind_the_relay_reach_the_world_and_back(hosts: Hosts) -> None:
    k = hosts.keys
    cmds = hosts.world.declare_subscriber(k.cmd_all)
    robot2 = hosts.client(robot_cn(2), hosts.b)
    poses = robot2.declare_subscriber(k.poses_all)
    pub = robot2.declare_publisher(k.cmd(2))
    until(lambda: pub.matching_status.matching, "robot 2's publisher to match the world")
    pub.put(b"c2")
    until(lambda: cmds.try_recv() is not None, "robot 2's command at the world")
    world_pub = hosts.world.declare_publisher(k.poses_cell(0, (-1, 2)))
    until(lambda: world_pub.matching_status.matching, "the world's poses to match robot 2")
    world_pub.put(b"p")
    sample = None

    def got_pose() -> bool:
        nonlocal sample
        sample = poses.try_recv()
        return sample is not None

    until(got_pose, "the world's poses at robot 2")
    # Configuration: the world's queryable answers through both routers, with its own id.
    # The queryable's declaration reaches the relay asynchronously: ask until it answers, as a
    # robot does at start-up.
    hosts.world.declare_queryable(k.config_all, lambda q: q.reply(q.key_expr, b"cfg"))
    repliers: list[str] = []

    def answered() -> bool:
        nonlocal repliers
        repliers = [str(r.replier_id.zid) for r in robot2.get(k.config(2), timeout=1.0) if r.ok]
        return bool(repliers)

    until(answered, "the world's configuration at robot 2")
    assert repliers == [WORLD_ZID]
    # Liveliness: robot 2's token is seen at the world.
    alive = hosts.world.liveliness().declare_subscriber(f"{k.prefix}/alive/**", history=True)
    robot2.liveliness().declare_token(k.alive_robot(2))
    until(lambda: (s := alive.try_recv()) is not None and str(s.key_expr) == k.alive_robot(2),
          "robot 2's token at the world")


def test_each_router_drops_what_its_robots_may_not_send(hosts: Hosts) -> None:
    k = hosts.keys
    cmds = hosts.world.declare_subscriber(k.cmd_all)
    robot2 = hosts.client(robot_cn(2), hosts.b)
    robot0 = hosts.client(robot_cn(0), hosts.a)
    poses_at_0 = robot0.declare_subscriber(k.poses_all)
    own = robot2.declare_publisher(k.cmd(2))
    until(lambda: own.matching_status.matching, "robot 2's publisher to match the world")
    for key in (k.cmd(0), k.cmd(3), k.cmd(2)):
        robot2.put(key, b"x")
    robot2.put(k.poses_cell(0, (0, 0)), b"forged")
    robot2.put(k.control, b"forged")
    alive = hosts.world.liveliness().declare_subscriber(f"{k.prefix}/alive/**", history=True)
    robot2.liveliness().declare_token(k.alive_robot(0))
    robot2.liveliness().declare_token(k.alive_world)
    assert received(cmds) == [k.cmd(2)]
    assert received(poses_at_0, 0.0) == []
    assert received(alive, 0.0) == []
    # A robot of host A holding its own certificate gets nothing through the relay.
    robot0_via_b = hosts.client(robot_cn(0), hosts.b)
    robot0_via_b.put(k.cmd(0), b"x")
    assert received(cmds) == []


def test_a_relay_certificate_speaks_only_for_its_robots(hosts: Hosts) -> None:
    """A client holding router-b's certificate connects to the world's router directly: it may
    put the commands of robots 2 and 3 (as the relay may), never robot 0's or poses."""
    k = hosts.keys
    cmds = hosts.world.declare_subscriber(k.cmd_all)
    robot0 = hosts.client(robot_cn(0), hosts.a)
    poses_at_0 = robot0.declare_subscriber(k.poses_all)
    rogue = hosts.client(router_cn("b"), hosts.a)
    allowed = rogue.declare_publisher(k.cmd(3))
    until(lambda: allowed.matching_status.matching, "router-b's robot-3 key to match the world")
    for key in (k.cmd(0), k.cmd(1), k.cmd(3)):
        rogue.put(key, b"x")
    rogue.put(k.poses_cell(0, (0, 0)), b"forged")
    assert received(cmds) == [k.cmd(3)]
    assert received(poses_at_0, 0.0) == []


def test_a_relay_process_serves_its_run_and_leaves_once_it_is_over(hosts: Hosts) -> None:
    """``python -m world.router`` (relay c, robot 1): it dials the world, serves robot 1, and
    leaves only once the world has left and robot 1 too (a relay that left first would cut
    its robots off)."""
    k = hosts.keys
    world_token = hosts.world.liveliness().declare_token(k.alive_world)
    alive = hosts.world.liveliness().declare_subscriber(k.alive_robot(1), history=True)
    endpoint = tls_endpoint(free_tcp_endpoint())
    relay = subprocess.Popen(
        [sys.executable, "-m", "world.router", "--run", RUN, "--name", "c", "--robots", "1",
         "--listen", endpoint, "--connect", hosts.a, "--tls", str(hosts.tls_dir),
         "--wait-world-s", "30"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(relay.stdout or ()), daemon=True)
    reader.start()
    try:
        until(lambda: any("the world is up" in line for line in lines) or relay.poll() is not None,
              "the relay to see the world")
        robot1 = hosts.client(robot_cn(1), endpoint)
        token = robot1.liveliness().declare_token(k.alive_robot(1))
        until(lambda: alive.try_recv() is not None, "robot 1's token at the world, via relay c")
        world_token.undeclare()
        until(lambda: any("the world left" in line for line in lines), "the relay to see the "
              "world leave")
        assert relay.poll() is None, "".join(lines)  # robot 1 is still connected through it
        token.undeclare()
        assert relay.wait(timeout=DEADLINE_S) == ExitCode.OK, "".join(lines)
    finally:
        if relay.poll() is None:
            relay.kill()
        relay.wait(timeout=DEADLINE_S)
        reader.join(timeout=DEADLINE_S)
        if relay.stdout is not None:
            relay.stdout.close()
    assert any("the run is over" in line for line in lines), "".join(lines)


def test_run_follower_waits_for_the_world_and_then_for_its_robots() -> None:
    f = RunFollower()
    assert not f.over            # the world has not come yet
    f.robot(2, True)
    f.world(True)
    f.world(False)
    assert not f.over            # robot 2 is still connected (e.g. the link between hosts
    f.world(True)                # was down for a moment)
    f.world(False)
    f.robot(2, False)
    assert f.over


def test_relay_arguments_and_settings(tmp_path: Path) -> None:
    make_run_pki(tmp_path, RUN, ROBOTS, relays={"b": ()})
    opts = parse_args(["--run", RUN, "--name", "b", "--robots", "2-3", "--listen",
                       "tls/0.0.0.0:7447", "--connect", "tls/world:7447", "--tls",
                       str(tmp_path)])
    assert opts.robot_ids == (2, 3)
    settings = router_settings(opts)
    assert '"s-upstream"' in settings["access_control"]
    for bad in (["--name", "B"], ["--robots", "x"]):
        with pytest.raises(SystemExit):
            parse_args(["--run", RUN, "--name", "b", "--robots", "2", "--listen", "l",
                        "--connect", "c", *bad])
    plain = parse_args(["--run", RUN, "--name", "b", "--robots", "2", "--listen",
                        "tcp/0.0.0.0:7447", "--connect", "tcp/world:7447"])
    with pytest.raises(ValueError, match="every interface"):
        router_settings(plain)
    missing = parse_args(["--run", RUN, "--name", "z", "--robots", "2", "--listen",
                          "tls/0.0.0.0:7447", "--connect", "tls/world:7447", "--tls",
                          str(tmp_path)])
    with pytest.raises(ValueError, match="missing or unreadable"):
        router_settings(missing)
    assert ExitCode.OK == 0
