"""System tests: a rogue Zenoh client against a real distributed run (issue 30).

Two layers, each tested on its own:

- **Transport** (the default): mutual TLS with the run's CA and the world's access control.
  A client without a certificate, with a certificate of another CA, or dialling plain TCP
  cannot even open a session; a client holding a certificate of the run (robot 0's, the
  observer's) can connect, but everything it sends outside its rights is dropped by the
  world's router before anything reads it: the world and the robots count nothing.
- **Defence in depth** (``tls=False``: plain TCP, a rogue that can connect). The rogue sends
  (a) a command on robot 3's key with ``seq = 2**63 - 1``, (b) poses with a far-future tick
  and time (some with the world's source info copied), (c) ``ControlMsg("end")``, (d) a
  forged configuration reply, (e) a flood of well-formed messages on every key. Each fails:
  the run completes, every robot arrives, no contact, and every attempt is counted in the
  world's ``end`` event, robots.json and metrics.json.

Every process has a deadline; the test process opens its own sessions only after every
child was spawned (spawned with subprocess, never forked). It waits on conditions (events,
a reply, the robots' commands), each with a deadline; the sleeps left pace what the rogue
sends. Assertions read the run's structured output: events.jsonl, robots.json (the robots'
exit counters, as the launcher writes it) and metrics.json.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import pytest

from agent.process import ExitCode, SessionError, open_session
from agent.security import make_run_pki
from eifp_wire import (
    CommandMsg,
    ControlMsg,
    PosesMsg,
    RunConfigMsg,
    RunKeys,
    TlsFiles,
    next_seq,
    robot_cn,
    session_settings,
    tls_endpoint,
)
from orchestrator.analysis.rundir import metrics_from_run_dir, write_metrics
from orchestrator.experiments.distributed import (
    collect_robot_exits,
    free_tcp_endpoint,
    robot_command,
    spawn_logged,
    stop_processes,
    world_command,
)
from tests.system.test_distributed import (
    processes_of_run,
    read_events,
    unique_run_id,
    wait_exit,
    wait_for_event,
    write_scenario,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(180)]

STARTUP_S = 60.0
RUN_S = 60.0
ROBOTS = [0, 1, 2, 3]


def crossing(path: Path) -> Path:
    """Four robots, two crossing pairs, 6 m each: ~10 s of sim time."""
    return write_scenario(path, [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 1, "start": [0.0, -3.0, math.pi / 2], "goal": [0.0, 3.0]},
        {"id": 2, "start": [3.0, 8.0, math.pi], "goal": [-3.0, 8.0]},
        {"id": 3, "start": [0.0, 11.0, -math.pi / 2], "goal": [0.0, 5.0]},
    ], time_limit_s=40.0)


class Run:
    """A world and four robots started by hand, so the rogue can be in place in between."""

    def __init__(self, tmp_path: Path, tag: str, tls: bool, ca_dir: Path | None = None) -> None:
        self.run_id = unique_run_id(tag)
        self.out_dir = tmp_path / "run"
        self.out_dir.mkdir()
        self.scenario = crossing(tmp_path / "crossing.yaml")
        self.tls_dir = (self.out_dir / "tls") if tls else None
        endpoint = free_tcp_endpoint()
        self.endpoint = tls_endpoint(endpoint) if tls else endpoint
        if self.tls_dir is not None:
            make_run_pki(self.tls_dir, self.run_id, ROBOTS, ca_dir=ca_dir)
        self.world = spawn_logged(
            world_command(self.run_id, self.scenario, self.out_dir, self.endpoint,
                          time_scale=2.0, wait_robots_s=STARTUP_S, tls_dir=self.tls_dir),
            self.out_dir / "world.log")
        self.robots: dict[int, object] = {}

    def start_robots(self) -> None:
        for rid in ROBOTS:
            self.robots[rid] = spawn_logged(
                robot_command(self.run_id, rid, self.endpoint, startup_timeout_s=STARTUP_S,
                              tls_dir=self.tls_dir),
                self.out_dir / f"robot_{rid}.log")

    def finish(self) -> tuple[dict, dict, dict]:
        """Wait for the end; (end event, robots.json, metrics.json's end section)."""
        end = wait_for_event(self.out_dir, lambda e: e["kind"] == "end", RUN_S, self.world)
        assert wait_exit(self.world) == ExitCode.OK, self.log_tails()
        for proc in self.robots.values():
            assert wait_exit(proc) == ExitCode.OK, self.log_tails()
        robots = collect_robot_exits(self.out_dir)
        (self.out_dir / "robots.json").write_text(json.dumps(robots))
        write_metrics(self.out_dir, metrics_from_run_dir(self.out_dir))
        metrics = json.loads((self.out_dir / "metrics.json").read_text())
        return end, robots, metrics

    def log_tails(self, lines: int = 40) -> str:
        """The last lines of the world's and every robot's log: a failure's message carries
        them, since the temporary run directory is gone once pytest reports."""
        parts = []
        for log in sorted(self.out_dir.glob("*.log")):
            tail = log.read_text(errors="replace").splitlines()[-lines:]
            parts.append(f"--- {log.name} (last {len(tail)} lines)\n" + "\n".join(tail))
        return "\n".join(parts)

    def kill_all(self) -> None:
        stop_processes([self.world, *self.robots.values()], 0.0, 5.0)


@pytest.fixture
def runs(tmp_path: Path):
    made: list[Run] = []

    def make(tag: str, tls: bool, ca_dir: Path | None = None) -> Run:
        made.append(Run(tmp_path, tag, tls, ca_dir))
        return made[-1]

    yield make
    for run in made:
        run.kill_all()
        assert not processes_of_run(run.run_id), "orphan processes left behind"


def rogue_session(endpoint: str, tls: TlsFiles | None = None, attempts_s: float = 2.0,
                  **overrides: str):
    """A client session; raises `SessionError` if it cannot be opened within `attempts_s`."""
    settings = session_settings(mode="client", connect=[endpoint], connect_timeout_ms=500,
                                tls=tls)
    settings.update(overrides)
    return open_session(settings, deadline=time.monotonic() + attempts_s)


def until_forged_reply(session, key: str, payload: bytes) -> None:
    """Ask `key` until `payload` is among the replies (every reply read), or fail."""
    import zenoh

    deadline = time.monotonic() + STARTUP_S
    while True:
        replies = session.get(key, timeout=0.5, consolidation=zenoh.ConsolidationMode.NONE)
        if any(r.ok is not None and r.ok.payload.to_bytes() == payload for r in replies):
            return
        assert time.monotonic() < deadline, f"no forged reply on {key}"


def wait_world_ready(run: Run) -> None:
    wait_for_event(run.out_dir, lambda e: e["kind"] == "world_ready", STARTUP_S, run.world)


def first_pose(run: Run, session) -> tuple[PosesMsg, object]:
    """The first pose `session` receives once the run started (and its sample)."""
    import zenoh

    keys = RunKeys(run.run_id)
    # Every robot holds pose cell (0, 0): the one every forged pose below goes to.
    sub = session.declare_subscriber(keys.poses_cell(None, (0, 0)), zenoh.handlers.RingChannel(1))
    wait_for_event(run.out_dir, lambda e: e["kind"] == "start", STARTUP_S, run.world)
    deadline = time.monotonic() + RUN_S
    while (sample := sub.try_recv()) is None:
        assert time.monotonic() < deadline, "no pose from the world"
        time.sleep(0.005)
    sub.undeclare()
    return PosesMsg.decode(sample.payload.to_bytes()), sample


def assert_clean_finish(end: dict, metrics: dict) -> None:
    assert end["reason"] == "all_arrived" and end["success"], end
    assert end["contacts"] == 0 and end["lost"] == []
    assert sorted(end["arrived"]) == ROBOTS
    assert metrics["arrived"] == len(ROBOTS) and metrics["contacts"] == 0


# --- the transport: no certificate, no session; a certificate, only its rights -----------------


def test_with_tls_a_rogue_without_a_certificate_cannot_connect_and_a_stolen_one_is_powerless(
        runs, tmp_path: Path) -> None:

    run = runs("tls", tls=True)
    wait_world_ready(run)
    port = run.endpoint.rsplit(":", 1)[1]
    # No certificate at all (it trusts the run's CA, presents nothing).
    no_cert = session_settings(mode="client", connect=[run.endpoint], connect_timeout_ms=500)
    no_cert["transport/link/tls/root_ca_certificate"] = json.dumps(str(run.tls_dir / "ca.pem"))
    with pytest.raises(SessionError):
        open_session(no_cert, deadline=time.monotonic() + 2.0)
    # Plain TCP to the TLS port.
    with pytest.raises(SessionError):
        rogue_session(f"tcp/127.0.0.1:{port}")
    # A "robot-3" certificate from another CA.
    other = make_run_pki(tmp_path / "other-ca", run.run_id, [3])
    with pytest.raises(SessionError):
        rogue_session(run.endpoint, other[robot_cn(3)])

    run.start_robots()
    keys = RunKeys(run.run_id)
    # Robot 0's certificate (stolen) and the observer's: they connect, but the router drops
    # whatever they may not send. The observer may read everything.
    stolen = rogue_session(run.endpoint, TlsFiles.in_dir(run.tls_dir, robot_cn(0)))
    observer = rogue_session(run.endpoint, TlsFiles.in_dir(run.tls_dir, "observer"))
    try:
        real, sample = first_pose(run, observer)  # the observer may read everything
        for session in (stolen, observer):
            session.put(keys.cmd(3), CommandMsg(3, 2**63 - 1, real.t_s, 0.0, 0.0, 1.0,
                                                "ok").encode())
            session.put(keys.control, ControlMsg("end", real.t_s, "forged").encode(),
                        source_info=sample.source_info)
            for slot in range(5):
                session.put(keys.poses_cell(slot, (0, 0)), real.encode(),
                            source_info=sample.source_info)
        end, robots, metrics = run.finish()
    finally:
        for session in (stolen, observer):
            session.close()
    assert_clean_finish(end, metrics)
    # Dropped by the router: nothing reached the world's or the robots' checks.
    assert end["rejected"] == 0 and end["seq_jumps"] == 0, end
    assert robots["refused_poses"] == robots["refused_control"] == 0, robots
    assert all(p["reason"] == "end (all_arrived)" for p in robots["processes"])
    ready = read_events(run.out_dir)[0]
    assert ready["kind"] == "world_ready" and ready["tls"] is True


# --- defence in depth: plain TCP, a rogue that connects ----------------------------------------


def test_without_tls_every_forgery_fails_and_is_counted(runs) -> None:
    import zenoh

    run = runs("insecure", tls=False)
    wait_world_ready(run)
    keys = RunKeys(run.run_id)
    rogue = rogue_session(run.endpoint, attempts_s=STARTUP_S)
    try:
        # (d) A forged configuration for every robot (its goal moved), in place before the
        # robots ask: both replies reach a robot, which takes only the world's.
        forged_configs = {}
        scenario_robots = {0: (3.0, 0.0), 1: (0.0, 3.0), 2: (-3.0, 8.0), 3: (0.0, 5.0)}
        answered = []

        def forge_reply(query: zenoh.Query) -> None:
            rid = keys.robot_id_of_config(str(query.key_expr))
            if rid in forged_configs:
                query.reply(keys.config(rid), forged_configs[rid])
                answered.append(rid)

        from agent.core.config import PlannerConfig
        from agent.core.scenario import RobotSpec

        for rid, goal in scenario_robots.items():
            forged_configs[rid] = RunConfigMsg(
                run_id=run.run_id, robot=RobotSpec(rid, (0.0, 0.0, 0.0), (goal[0] + 50.0,
                                                                         goal[1])),
                planner=PlannerConfig(), goal_tolerance_m=0.25, control_rate_hz=10.0,
                world_rate_hz=50.0, time_scale=2.0, time_limit_s=40.0, cmd_timeout_s=0.5,
                known_ids=tuple(ROBOTS)).encode()
        queryable = rogue.declare_queryable(keys.config_all, forge_reply)
        # The declaration has reached the router once another client's query gets the
        # forged reply: only then may the robots ask.
        probe = rogue_session(run.endpoint, attempts_s=STARTUP_S)
        try:
            until_forged_reply(probe, keys.config(0), forged_configs[0])
        finally:
            probe.close()
        answered.clear()
        run.start_robots()
        cmds = rogue.declare_subscriber(keys.cmd_all, zenoh.handlers.RingChannel(64))
        real, sample = first_pose(run, rogue)
        world_source = sample.source_info
        # Every robot has commanded: its commands are replayed in (e).
        replays: list[tuple[str, bytes]] = []
        deadline = time.monotonic() + RUN_S
        while {key for key, _ in replays} != {keys.cmd(rid) for rid in ROBOTS}:
            assert time.monotonic() < deadline, f"not every robot commanded: {replays}"
            while (c := cmds.try_recv()) is not None:
                replays.append((str(c.key_expr), c.payload.to_bytes()))
            time.sleep(0.005)

        # (a) One command on robot 3's key with the largest seq.
        rogue.put(keys.cmd(3), CommandMsg(3, 2**63 - 1, real.t_s, 1.0, 1.0, 1.0,
                                          "ok").encode())
        # (b) Far-future poses on every slot: beyond the time limit, and ahead of the
        # robots' clocks (tick and time consistent); the world's source info copied, so
        # the time check is what refuses them; and once as the rogue itself.
        far = [PosesMsg(t_s=1.0e6, tick=50_000_000, robot_ids=real.robot_ids,
                        robot_pose=real.robot_pose, robot_radius_m=real.robot_radius_m,
                        obstacle_ids=real.obstacle_ids, obstacle_xy_m=real.obstacle_xy_m,
                        obstacle_radius_m=real.obstacle_radius_m),
               PosesMsg(t_s=real.t_s + 20.0, tick=real.tick + 1000,
                        robot_ids=real.robot_ids, robot_pose=real.robot_pose,
                        robot_radius_m=real.robot_radius_m, obstacle_ids=real.obstacle_ids,
                        obstacle_xy_m=real.obstacle_xy_m,
                        obstacle_radius_m=real.obstacle_radius_m)]
        for msg in far:
            for slot in range(5):
                rogue.put(keys.poses_cell(slot, (0, 0)), msg.encode(), source_info=world_source)
                rogue.put(keys.poses_cell(slot, (0, 0)), msg.encode())
            time.sleep(0.05)  # pacing: the two forgeries about two world ticks apart
        # (c) The end of the run, from the rogue's own session.
        rogue.put(keys.control, ControlMsg("end", real.t_s, "forged").encode())
        # (e) A flood of well-formed messages on every key for 2 s: poses of the present
        # (from the rogue), replays of the robots' own commands and of robot-0 seq 0, start
        # and end announcements, configuration queries.
        while (c := cmds.try_recv()) is not None:
            replays.append((str(c.key_expr), c.payload.to_bytes()))
        t0 = time.monotonic()
        sent = 0
        while time.monotonic() - t0 < 2.0:
            for slot in range(5):
                rogue.put(keys.poses_cell(slot, (0, 0)), real.encode())
            for rid in ROBOTS:
                rogue.put(keys.cmd(rid), CommandMsg(rid, 0, real.t_s, 1.0, 0.0, 1.0,
                                                    "ok").encode())
            for key, payload in replays:
                rogue.put(key, payload)
            rogue.put(keys.control, ControlMsg("start", real.t_s).encode())
            rogue.put(keys.control, ControlMsg("end", real.t_s, "flood").encode())
            rogue.get(keys.config(sent % len(ROBOTS)), timeout=0.1)
            sent += 1
            time.sleep(0.01)
        end, robots, metrics = run.finish()
        queryable.undeclare()
    finally:
        rogue.close()

    assert_clean_finish(end, metrics)
    assert all(p["reason"] == "end (all_arrived)" for p in robots["processes"]), robots
    # (a) refused as a jump, never stored: robot 3's own commands kept being applied.
    assert end["seq_jumps"] >= 1 and end["rejected_by_reason"].get("cmd.seq", 0) >= 1, end
    assert end["stale"] >= sent, end  # (e) the replays and the seq-0 commands
    # (b), (c), (e): poses and control not from the world, or from the future.
    assert robots["refused_poses"] >= len(ROBOTS) * 2, robots
    assert robots["refused_control"] >= len(ROBOTS), robots
    # (d) the rogue answered every robot's query; a robot that read a forged reply before
    # the world's refused it (it takes the first reply from the world and stops reading),
    # and every robot drove to the goal the world gave it (all arrived, above). Which reply
    # a robot reads first is a race that the machine's load decides, so how many were
    # refused here is not asserted beyond what was sent; the refusal itself is tested in
    # tests/unit/agent/test_startup.py (a reply not from the world is refused).
    assert set(answered) == set(ROBOTS), answered
    assert 0 <= robots["refused_config"] <= len(answered), robots
    # (b) with the world's source copied: refused by the robots' time check
    # (tests/unit/eifp_wire/test_clock.py) and counted in refused_poses with the poses refused
    # by source; the exit line has no per-reason split, so this run asserts the total.
    # In metrics.json.
    for key in ("seq_jumps", "refused_poses", "refused_control"):
        assert metrics["end"][key] >= 1, metrics["end"]
    # refused_config is recorded too, but may be 0: which reply a robot reads first is the
    # race (d) above describes (seen 0 once in CI on a loaded machine).
    assert 0 <= metrics["end"]["refused_config"] <= len(answered), metrics["end"]
    print(f"world: {end['seq_jumps']} seq jumps, {end['stale']} stale; robots refused "
          f"{robots['refused_poses']} poses, {robots['refused_control']} control, "
          f"{robots['refused_config']} configs; {sent} flood rounds")


def test_with_robot_1s_key_the_64_step_seq_walk_does_not_stop_robot_1(runs) -> None:
    """Issue 40: 300 commands on robot 1's key, stepping seq by 64 in 1.5 s (each a stop),
    froze robot 1 for the rest of the run (all accepted, exit 3). Now the world accepts a
    seq only as far as its time allows; the walk is refused past that, and robot 1, whose
    seq follows time, passes the forged ones and arrives."""
    run = runs("walk", tls=True)
    wait_world_ready(run)
    run.start_robots()
    keys = RunKeys(run.run_id)
    stolen = rogue_session(run.endpoint, TlsFiles.in_dir(run.tls_dir, robot_cn(1)),
                           attempts_s=STARTUP_S)
    try:
        real, _ = first_pose(run, stolen)
        seq = next_seq(-1, real.t_s)
        t0 = time.monotonic()
        for k in range(300):  # paced as in the issue: 300 in 1.5 s
            seq += 64
            stolen.put(keys.cmd(1), CommandMsg(1, seq, real.t_s, 0.0, 0.0, 1.0,
                                               "ok").encode())
            time.sleep(max(0.0, t0 + 0.005 * (k + 1) - time.monotonic()))
        end, robots, metrics = run.finish()
    finally:
        stolen.close()
    assert_clean_finish(end, metrics)  # robot 1 arrived too
    assert end["seq_jumps"] >= 200, end  # most of the walk refused
    assert all(p["reason"] == "end (all_arrived)" for p in robots["processes"]), robots
    print(f"walk: {300 - end['seq_jumps']} of 300 forged commands within the time bound; "
          f"{end['seq_jumps']} refused")


def test_a_certificate_of_another_run_from_the_same_ca_is_refused(runs, tmp_path: Path
                                                                  ) -> None:
    """Issue 40: with ``--tls-ca`` the access list checked the CN only, so robot 1's
    certificate of an earlier run by the same CA put commands in a new run, and that run's
    observer certificate read every command. Both now hold no right in this run: the CNs
    carry the run (`eifp_wire.access.scoped_cn`)."""
    import zenoh

    from agent.security import RunCA

    ca = RunCA("site-ca")
    ca_dir = tmp_path / "site-ca"
    ca_dir.mkdir()
    (ca_dir / "ca.pem").write_bytes(ca.cert_pem)
    from cryptography.hazmat.primitives import serialization

    (ca_dir / "ca.key").write_bytes(ca.key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption()))
    earlier = make_run_pki(tmp_path / "earlier", unique_run_id("earlier"), [1], ca_dir=ca_dir)
    run = runs("same-ca", tls=True, ca_dir=ca_dir)
    wait_world_ready(run)
    keys = RunKeys(run.run_id)
    # Same CA: the handshake succeeds, the access list gives these CNs nothing.
    old_robot = rogue_session(run.endpoint, earlier[robot_cn(1)], attempts_s=STARTUP_S)
    old_observer = rogue_session(run.endpoint, earlier["observer"], attempts_s=STARTUP_S)
    observer = rogue_session(run.endpoint, TlsFiles.in_dir(run.tls_dir, "observer"),
                             attempts_s=STARTUP_S)
    try:
        peeked_cmds = old_observer.declare_subscriber(keys.cmd_all,
                                                      zenoh.handlers.RingChannel(64))
        peeked_poses = old_observer.declare_subscriber(keys.poses_all,
                                                       zenoh.handlers.RingChannel(4))
        run.start_robots()
        real, _ = first_pose(run, observer)
        for k in range(300):  # stops on robot 1's key, each with a fresh, allowed seq
            old_robot.put(keys.cmd(1), CommandMsg(1, next_seq(-1, real.t_s) + k, real.t_s,
                                                  0.0, 0.0, 123.456, "ok").encode())
        end, robots, metrics = run.finish()
        assert peeked_cmds.try_recv() is None and peeked_poses.try_recv() is None
    finally:
        for session in (old_robot, old_observer, observer):
            session.close()
    assert_clean_finish(end, metrics)
    assert end["rejected"] == 0 and end["seq_jumps"] == 0, end  # dropped by the router
    applied = (run.out_dir / "commands.csv").read_text()
    assert ",123.4560," not in applied  # no forged command was applied


def test_the_world_refuses_to_listen_everywhere_without_tls(tmp_path: Path) -> None:
    scenario = crossing(tmp_path / "s.yaml")
    port = free_tcp_endpoint().rsplit(":", 1)[1]
    proc = spawn_logged(world_command("rogue-any", scenario, tmp_path / "out",
                                      f"tcp/0.0.0.0:{port}", wait_robots_s=5.0),
                        tmp_path / "world.log")
    assert wait_exit(proc) == ExitCode.BAD_INPUT
    # the run directory says why: it ended at once on the listener, before any session
    (end,) = read_events(tmp_path / "out")
    assert (end["kind"], end["reason"], end["flag"], end["success"]) == \
        ("end", "bad_input", "--listen", False)

