"""Launch one distributed run: a world process and one robot process per robot, on loopback.

The launcher opens no Zenoh session of its own (a session does not survive `fork`, and
children are started with `subprocess` anyway); the one exception is the live view's
passive client (``live``: `orchestrator.experiments.live.LiveBridge`), opened on a thread
after the world is spawned, which only subscribes. Every child gets its own process group so that a
terminal's Ctrl-C reaches only the launcher, which then tears the children down in order:
the world first (SIGTERM, so it records the end of the run), then the robots (SIGTERM,
then SIGKILL after a deadline). Teardown runs in ``finally``: no orphans on exceptions,
Ctrl-C or SIGTERM to the launcher.

Files written in `out_dir` besides the world's (scenario.yaml, trajectory.csv,
commands.csv, events.jsonl): ``world.log`` and ``robot_<id>.log`` (each process's stderr
and stdout; a robot's last line is ``robot <id> exit: reason=... code=... rejected=N ...``),
``robots.json`` (those exit lines parsed: every robot process's reason, code, counters and
the endpoint it dialled, from its first line ``robot <id> start: {...}``, and the total of
poses the robots rejected as malformed) and, with process faults,
``faults.jsonl`` (one line per signal sent: sim time, wall time, robot, action).

Faults (`world.sim.faults.FaultPlan`): link faults and per-robot timing reach the
processes as command-line options (``--latency-ms`` ... of ``python -m world`` for the
command links and of ``python -m agent`` for each robot's pose link, seeded with the plan's
seed). Process faults are the launcher's: it follows the sim time in trajectory.csv and
sends SIGKILL (kill), SIGSTOP then SIGCONT (stop) or SIGKILL then a new process with the
same id (restart, its log ``robot_<id>.restart<N>.log``) at the planned sim time, within
`FAULT_POLL_S` of wall time.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from agent.core.scenario import Scenario
from agent.files import append_line, open_new, replace_file
from agent.flags import endpoint_host, every_interface, unspecified_literal
from agent.process import PARENT_PID_ENV, raise_interrupt
from eifp_wire import OBSERVER_CN, TlsFiles, tls_endpoint, validate_run_id
from orchestrator.analysis.metrics import RunMetrics
from orchestrator.experiments.progress import (
    DistributedProgress,
    EventTail,
    distributed_progress,
    last_trajectory_time,
)
from world.scenario_file import load_scenario
from world.sim.faults import FaultPlan, ProcessFault

if TYPE_CHECKING:
    from orchestrator.experiments.live import LiveBridge
    from world.mcap_log import LiveView

WORLD_TERM_GRACE_S = 10.0
"""Wall time the world gets after SIGTERM to record the end and close, before SIGKILL."""
ROBOT_EXIT_GRACE_S = 5.0
"""Wall time robots get to leave on their own after the world ends, before SIGTERM."""
ROBOT_TERM_GRACE_S = 3.0
"""Wall time robots get after SIGTERM, before SIGKILL."""
EXIT_MARGIN_S = 60.0
"""Slack on the world's expected wall duration before the launcher gives up on it."""
POLL_S = 0.2
STARTUP_S_MIN = 30.0
STARTUP_S_PER_ROBOT = 0.5
"""The default start-up deadline is the larger of `STARTUP_S_MIN` and this per robot: every
spawned robot imports numpy, scipy, osqp and zenoh and opens a TLS session, so with more
robots than cores start-up grows with N."""
FAULT_POLL_S = 0.02
"""Wall period of the launcher's loop while process faults are pending."""
TLS_DIR = "tls"
"""Where a run's certificates go, under its run directory."""
REFUSED_COUNTERS = ("refused_poses", "refused_control", "refused_config")
"""Robot counters of well-formed messages refused as not the world's (totals in robots.json)."""
EXIT_LINE = re.compile(r"robot (\d+) exit: reason='([^']*)' code=(\d+)(.*)$", re.MULTILINE)
START_LINE = re.compile(r"robot (\d+) start: (\{.*\})[ \t\r]*$", re.MULTILINE)
"""A robot's first line (`agent.node`): its id, then a JSON object (``run``, ``connect``)."""


def free_tcp_endpoint(host: str = "127.0.0.1") -> str:
    """A ``tcp/<host>:<port>`` endpoint on a port that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        port = sock.getsockname()[1]
    return f"tcp/{host}:{port}"


def _tls_args(tls_dir: Path | None) -> list[str]:
    return [] if tls_dir is None else ["--tls", str(Path(tls_dir).resolve())]


def world_command(run_id: str, scenario_path: Path, out_dir: Path, endpoint: str, *,
                  rate_hz: float = 50.0, time_scale: float = 1.0, wait_robots_s: float = 30.0,
                  extra_args: Sequence[str] = (), tls_dir: Path | None = None) -> list[str]:
    """Command line of a world process (a router listening on `endpoint`; with `tls_dir`,
    mutual TLS and the run's access control)."""
    return [
        sys.executable, "-m", "world", "--run", run_id,
        "--scenario", str(Path(scenario_path).resolve()), "--listen", endpoint,
        "--rate-hz", repr(float(rate_hz)), "--time-scale", repr(float(time_scale)),
        "--out", str(Path(out_dir).resolve()), "--wait-robots-s", repr(float(wait_robots_s)),
        *_tls_args(tls_dir), *extra_args,
    ]


def robot_command(run_id: str, robot_id: int, endpoint: str, *,
                  startup_timeout_s: float = 30.0, extra_args: Sequence[str] = (),
                  tls_dir: Path | None = None) -> list[str]:
    """Command line of one robot process (a client of the router at `endpoint`)."""
    return [
        sys.executable, "-m", "agent", "--run", run_id, "--id", str(int(robot_id)),
        "--connect", endpoint, "--startup-timeout-s", repr(float(startup_timeout_s)),
        *_tls_args(tls_dir), *extra_args,
    ]


def prepare_tls(out_dir: Path, run_id: str, robot_ids: Sequence[int],
                endpoints: Iterable[str], ca_dir: Path | None = None) -> Path:
    """The run's certificates in ``<out_dir>/tls`` (`agent.security.make_run_pki`); the world's
    certificate names every host of `endpoints`. Returns the directory."""
    from agent.security import make_run_pki

    hosts = [h for h in map(endpoint_host, endpoints) if h and not unspecified_literal(h)]
    tls_dir = Path(out_dir) / TLS_DIR
    make_run_pki(tls_dir, run_id, robot_ids, world_hosts=hosts, ca_dir=ca_dir)
    return tls_dir


def transport_info(endpoints: Sequence[str], tls_dir: Path | None) -> dict[str, Any]:
    """What run.json records of the transport: the endpoints a tool joins as a Zenoh client,
    whether TLS is on, and (with TLS) the CA and the read-only observer's certificate."""
    info: dict[str, Any] = {"endpoints": list(dict.fromkeys(endpoints)), "tls": tls_dir is not None}
    if tls_dir is not None:
        d = Path(tls_dir).resolve()
        info.update(ca=str(d / "ca.pem"), observer_cert=str(d / "observer.pem"),
                    observer_key=str(d / "observer.key"), access_control=True)
    return info


def _link_args(plan: FaultPlan) -> list[str]:
    links = plan.links
    if not links.active:
        return []
    return ["--latency-ms", repr(links.latency_ms), "--jitter-ms", repr(links.jitter_ms),
            "--drop", repr(links.drop), "--dup", repr(links.dup),
            "--reorder", repr(links.reorder), "--fault-seed", str(plan.seed)]


def world_fault_args(plan: FaultPlan | None) -> list[str]:
    """Options of ``python -m world`` for the plan's command-link faults."""
    return [] if plan is None else _link_args(plan)


def world_lost_grace_args(plan: FaultPlan | None, *, time_scale: float,
                          startup_timeout_s: float) -> list[str]:
    """``--lost-grace-s`` of ``python -m world`` for a plan whose robots come back: a
    stopped robot is lost from the lease until it resumes (its stop's duration), a restarted
    one until its new process is up (at most the start-up deadline, in sim time). Without
    such faults the world's default (`world.world_cycle.LOST_GRACE_S`) stands."""
    if plan is None:
        return []
    back_s = [f.duration_s + 1.0 for f in plan.process if f.kind == "stop"]
    back_s += [startup_timeout_s * time_scale for f in plan.process if f.kind == "restart"]
    return ["--lost-grace-s", repr(float(max(back_s)))] if back_s else []


def robot_fault_args(plan: FaultPlan | None, robot_id: int) -> list[str]:
    """Options of ``python -m agent`` for the plan's pose-link and timing faults."""
    if plan is None:
        return []
    args = _link_args(plan)
    timing = plan.timing_of(robot_id)
    if timing.control_rate_hz is not None:
        args += ["--control-rate-hz", repr(timing.control_rate_hz)]
    if timing.phase_s:
        args += ["--control-phase-s", repr(timing.phase_s)]
    if timing.plan_delay_ms:
        args += ["--plan-delay-ms", repr(timing.plan_delay_ms)]
    if not plan.compensate_latency:
        args.append("--no-latency-compensation")
    return args


class ProcessFaultScheduler:
    """Sends the plan's process faults to the robot processes at their sim time.

    Args:
        faults: the process faults.
        robots: robot id -> its current process (replaced on restart).
        respawn: starts a new process for a robot id, given the restart count.
        log_path: ``faults.jsonl``.
    """

    def __init__(self, faults: Sequence[ProcessFault], robots: dict[int, subprocess.Popen[bytes]],
                 respawn: Callable[[int, int], subprocess.Popen[bytes]], log_path: Path) -> None:
        self.todo = sorted(faults, key=lambda f: f.at_s)
        self.resume: list[tuple[float, int]] = []  # (sim time, robot) of pending SIGCONTs
        self.robots = robots
        self.respawn = respawn
        self.log_path = log_path
        self.restarts: dict[int, int] = {}
        self.stopped: set[int] = set()

    @property
    def pending(self) -> bool:
        return bool(self.todo or self.resume)

    def _log(self, sim_t_s: float, robot_id: int, action: str) -> None:
        line = json.dumps({"t": round(sim_t_s, 4), "wall": time.time(), "robot": robot_id,
                           "action": action}) + "\n"
        append_line(self.log_path, line)

    def poll(self, sim_t_s: float) -> None:
        """Send every fault due by sim time `sim_t_s`."""
        while self.resume and self.resume[0][0] <= sim_t_s:
            _, rid = self.resume.pop(0)
            _signal_group(self.robots[rid], signal.SIGCONT)
            self.stopped.discard(rid)
            self._log(sim_t_s, rid, "SIGCONT")
        while self.todo and self.todo[0].at_s <= sim_t_s:
            f = self.todo.pop(0)
            proc = self.robots[f.robot_id]
            if f.kind == "stop":
                _signal_group(proc, signal.SIGSTOP)
                self.stopped.add(f.robot_id)
                self.resume.append((f.at_s + f.duration_s, f.robot_id))
                self.resume.sort()
                self._log(sim_t_s, f.robot_id, "SIGSTOP")
                continue
            _signal_group(proc, signal.SIGKILL)
            proc.wait()
            self._log(sim_t_s, f.robot_id, "SIGKILL")
            if f.kind == "restart":
                n = self.restarts[f.robot_id] = self.restarts.get(f.robot_id, 0) + 1
                self.robots[f.robot_id] = self.respawn(f.robot_id, n)
                self._log(sim_t_s, f.robot_id, "restarted")

    def release(self) -> None:
        """SIGCONT every robot still stopped (before teardown signals it)."""
        for rid in sorted(self.stopped):
            _signal_group(self.robots[rid], signal.SIGCONT)
        self.stopped.clear()


def robot_starts(log_text: str) -> list[dict[str, Any]]:
    """The start lines in a robot's log, parsed: ``robot`` (its id), ``run`` and
    ``connect`` (the endpoint it dialled); a line that is not valid JSON is left out."""
    starts = []
    for m in START_LINE.finditer(log_text):
        try:
            fields = json.loads(m.group(2))
        except ValueError:
            continue
        if isinstance(fields, dict):
            starts.append({**fields, "robot": int(m.group(1))})
    return starts


def collect_robot_exits(out_dir: Path) -> dict[str, Any]:
    """Every robot process's exit line, parsed, with the endpoint it dialled (``connect``,
    from its start line; written as robots.json by the launcher)."""
    processes = []
    for log in sorted(Path(out_dir).glob("robot_*.log")):
        text = log.read_text(errors="replace")
        dialled = {s["robot"]: s.get("connect") for s in robot_starts(text)}
        for m in EXIT_LINE.finditer(text):
            counters = {k: int(v) for k, v in re.findall(r"(\w+)=(\d+)", m.group(4))}
            rid = int(m.group(1))
            processes.append({"robot": rid, "log": log.name, "connect": dialled.get(rid),
                              "reason": m.group(2), "code": int(m.group(3)), **counters})
    return {"processes": processes,
            "rejected_poses": sum(p.get("rejected", 0) for p in processes),
            "stale_poses": sum(p.get("stale", 0) for p in processes),
            **{k: sum(p.get(k, 0) for p in processes) for k in REFUSED_COUNTERS}}
def fleet_command(run_id: str, robot_ids: Sequence[int], endpoint: str, log_dir: Path, *,
                  startup_timeout_s: float = 30.0,
                  robot_endpoints: Mapping[int, str] | None = None,
                  nice: int = 0, cpu_tokens: int | None = None,
                  tls_dir: Path | None = None,
                  robot_args: Sequence[str] = ()) -> list[str]:
    """Command line of one `agent.fleet` process that forks every robot process
    (`cpu_tokens` None: the fleet's default, none; `robot_args` go to every robot)."""
    overrides = [arg for rid, ep in sorted((robot_endpoints or {}).items())
                 for arg in ("--connect-id", f"{int(rid)}={ep}")]
    return [
        sys.executable, "-m", "agent.fleet", "--run", run_id,
        "--ids", ",".join(str(int(r)) for r in robot_ids), "--connect", endpoint,
        "--log-dir", str(Path(log_dir).resolve()),
        "--startup-timeout-s", repr(float(startup_timeout_s)), "--nice", str(int(nice)),
        *(() if cpu_tokens is None else ("--cpu-tokens", str(int(cpu_tokens)))),
        *_tls_args(tls_dir), *overrides,
        *(f"--robot-arg={arg}" for arg in robot_args),
    ]


def spawn_logged(args: list[str], log_path: Path) -> subprocess.Popen[bytes]:
    """Start `args` in its own process group, stdout and stderr into `log_path`."""
    log: IO[bytes] = open_new(log_path, "wb")
    try:
        return subprocess.Popen(
            args, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
            start_new_session=True,  # own process group: Ctrl-C reaches only the launcher
            cwd=Path(__file__).resolve().parent.parent,
            # The child dies with this process (agent.process.die_with_launcher).
            env={**os.environ, "PYTHONUNBUFFERED": "1", PARENT_PID_ENV: str(os.getpid())},
        )
    finally:
        log.close()  # the child holds its own descriptor


def _signal_group(proc: subprocess.Popen[bytes], signum: int) -> None:
    if proc.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signum)


def stop_processes(procs: Sequence[subprocess.Popen[bytes]], wait_first_s: float,
                   term_grace_s: float) -> None:
    """Let `procs` exit within wait_first_s, then SIGTERM, then SIGKILL; reap all of them."""
    deadline = time.monotonic() + wait_first_s
    while any(p.poll() is None for p in procs) and time.monotonic() < deadline:
        time.sleep(0.05)
    for p in procs:
        _signal_group(p, signal.SIGTERM)
    deadline = time.monotonic() + term_grace_s
    while any(p.poll() is None for p in procs) and time.monotonic() < deadline:
        time.sleep(0.05)
    for p in procs:
        _signal_group(p, signal.SIGKILL)
    for p in procs:
        p.wait()


def run_distributed(
    scenario_path: Path,
    out_dir: Path,
    run_id: str,
    *,
    rate_hz: float = 50.0,
    time_scale: float = 1.0,
    endpoint: str | None = None,
    startup_timeout_s: float | None = None,
    extra_world_args: Sequence[str] = (),
    on_progress: Callable[[DistributedProgress], None] | None = None,
    faults: FaultPlan | None = None,
    robot_endpoints: Mapping[int, str] | None = None,
    robot_launcher: str = "spawn",
    robot_nice: int = 0,
    cpu_tokens: int | None = None,
    tls: bool = True,
    tls_ca: Path | None = None,
    robot_args: Sequence[str] = (),
    live: LiveView | None = None,
) -> int:
    """Run one scenario as real processes; return the world's exit status.

    Args:
        scenario_path: scenario YAML file.
        out_dir: run directory (created); the world writes its files there, the launcher
            adds world.log and robot_<id>.log.
        run_id: run id (safe characters; prefixes every key expression).
        rate_hz: world tick rate in sim time.
        time_scale: sim seconds per wall second.
        endpoint: the world's router endpoint; default: a free TCP port on 127.0.0.1.
        startup_timeout_s: deadline for robots to connect and for all of them to be alive;
            default `default_startup_timeout_s` of the scenario's robot count.
        extra_world_args: appended to the world's command line.
        on_progress: called with a `DistributedProgress` about every `POLL_S`.
        faults: link, timing and process faults to inject (see the module docstring).
        robot_endpoints: robot id -> the endpoint it connects to, for robots that reach
            the world through another address (as from another host); the others use
            `endpoint` (which then usually listens on ``0.0.0.0``).
        robot_launcher: ``"spawn"``: one ``python -m agent`` per robot; ``"fork"``: one
            ``python -m agent.fleet`` that imports and warms up once and forks every robot
            process (faster start-up, less memory; its own log is ``fleet.log``).
        robot_nice: with ``"fork"``, robots run this much nicer than the world (>= 0).
        cpu_tokens: with ``"fork"``, robots computing at once (None or 0: no tokens).
        tls: mutual TLS and the run's access control (`prepare_tls`: certificates in
            ``<out_dir>/tls``); `endpoint` and `robot_endpoints` become ``tls/...``. False:
            plain TCP, which `endpoint` may then not listen on every interface with.
        tls_ca: sign the run's certificates with this CA (``ca.pem``, ``ca.key``) instead of
            a fresh one whose key is never written.
        robot_args: further ``python -m agent`` arguments for every robot (``--no-plan``).
        live: a live Foxglove server; a passive Zenoh client in this process
            (`orchestrator.experiments.live.LiveBridge`) republishes the run to it.

    Returns:
        The world's exit status (`agent.process.ExitCode`); a world killed by signal N
        gives 128 + N.
    """
    validate_run_id(run_id)
    if robot_launcher == "fork" and faults is not None:
        raise ValueError("robot_launcher='fork' cannot inject faults: use 'spawn'")
    if robot_launcher not in ("spawn", "fork"):
        raise ValueError(f"robot_launcher must be 'spawn' or 'fork', got {robot_launcher!r}")
    launch = _Launch.prepare(scenario_path, Path(out_dir), run_id, endpoint=endpoint,
                             startup_timeout_s=startup_timeout_s, faults=faults,
                             robot_endpoints=robot_endpoints, tls=tls, tls_ca=tls_ca,
                             robot_args=robot_args)
    world_cmd = world_command(
        run_id, scenario_path, launch.out_dir, launch.endpoint, rate_hz=rate_hz,
        time_scale=time_scale, wait_robots_s=launch.startup_timeout_s,
        extra_args=[*world_fault_args(faults),
                    *world_lost_grace_args(faults, time_scale=time_scale,
                                           startup_timeout_s=launch.startup_timeout_s),
                    *extra_world_args],
        tls_dir=launch.tls_dir)
    if faults is not None:
        faults.check(launch.robot_ids)
    # A world that cannot keep pace runs slower than time_scale: be generous before giving up.
    world_limit_s = (2.0 * launch.startup_timeout_s
                     + 3.0 * launch.scenario.time_limit_s / time_scale + EXIT_MARGIN_S)
    children = _Children(launch)
    with _torn_down_on_exit(children.teardown):
        t0 = time.monotonic()
        children.world = spawn_logged(world_cmd, launch.out_dir / "world.log")
        if live is not None:
            children.bridge = launch.live_bridge(live)
        if robot_launcher == "fork":  # one process group: teardown reaches every robot
            children.robots.append(spawn_logged(
                launch.fleet_command(robot_nice=robot_nice, cpu_tokens=cpu_tokens),
                launch.out_dir / "fleet.log"))
            current: dict[int, subprocess.Popen[bytes]] = {}
        else:
            current = {rid: children.spawn_robot(rid) for rid in launch.robot_ids}
        children.scheduler = ProcessFaultScheduler(faults.process if faults else (), current,
                                                   children.spawn_robot,
                                                   launch.out_dir / "faults.jsonl")
        code = children.supervise(t0, world_limit_s, on_progress)
        return code if code >= 0 else 128 - code


@dataclass(frozen=True)
class _Launch:
    """What one distributed run starts: where, with which certificates and arguments.

    Args:
        run_id: the run id.
        out_dir: the run directory (made by `prepare`).
        scenario: the run's scenario.
        endpoint: the world's router endpoint.
        robot_endpoints: robot id -> the endpoint it dials instead of `endpoint`.
        joined: the endpoints a client joins the run at (run.json's ``zenoh``).
        tls_dir: the run's certificates, or None (plain TCP).
        startup_timeout_s: the start-up deadline.
        faults: the faults to inject, or None.
        robot_args: further ``python -m agent`` arguments for every robot.
    """

    run_id: str
    out_dir: Path
    scenario: Scenario
    endpoint: str
    robot_endpoints: Mapping[int, str]
    joined: list[str]
    tls_dir: Path | None
    startup_timeout_s: float
    faults: FaultPlan | None
    robot_args: Sequence[str]

    @staticmethod
    def prepare(scenario_path: Path, out_dir: Path, run_id: str, *, endpoint: str | None,
                startup_timeout_s: float | None, faults: FaultPlan | None,
                robot_endpoints: Mapping[int, str] | None, tls: bool, tls_ca: Path | None,
                robot_args: Sequence[str]) -> _Launch:
        """Load the scenario, make the run directory, settle the endpoints, make the
        certificates and record the transport in run.json (see `run_distributed`)."""
        scenario = load_scenario(scenario_path)  # fail early, in the caller's process
        out_dir.mkdir(parents=True, exist_ok=True)
        endpoint = endpoint or free_tcp_endpoint()
        robot_ids = [spec.id for spec in scenario.robots]
        if startup_timeout_s is None:
            startup_timeout_s = default_startup_timeout_s(len(robot_ids))
        dialled = dict(robot_endpoints or {})
        if tls:
            endpoint = tls_endpoint(endpoint)
            dialled = {rid: tls_endpoint(ep) for rid, ep in dialled.items()}
        elif every_interface(endpoint):
            raise ValueError(f"{endpoint}: listening on every interface needs TLS")
        joined = [*dialled.values()] or [endpoint]
        tls_dir = (prepare_tls(out_dir, run_id, robot_ids, [endpoint, *joined], tls_ca)
                   if tls else None)
        _record_transport(out_dir, transport_info(joined, tls_dir))
        return _Launch(run_id, out_dir, scenario, endpoint, dialled, joined, tls_dir,
                       startup_timeout_s, faults, robot_args)

    @property
    def robot_ids(self) -> list[int]:
        return [spec.id for spec in self.scenario.robots]

    def robot_command(self, rid: int) -> list[str]:
        """The command line of robot `rid`'s process."""
        return robot_command(self.run_id, rid, self.robot_endpoints.get(rid, self.endpoint),
                             startup_timeout_s=self.startup_timeout_s,
                             extra_args=[*robot_fault_args(self.faults, rid), *self.robot_args],
                             tls_dir=self.tls_dir)

    def fleet_command(self, *, robot_nice: int, cpu_tokens: int | None) -> list[str]:
        """The command line of the one `agent.fleet` process that forks every robot."""
        return fleet_command(self.run_id, self.robot_ids, self.endpoint, self.out_dir,
                             startup_timeout_s=self.startup_timeout_s,
                             robot_endpoints=self.robot_endpoints, nice=robot_nice,
                             cpu_tokens=cpu_tokens, robot_args=self.robot_args,
                             tls_dir=self.tls_dir)

    def live_bridge(self, live: LiveView) -> LiveBridge:
        """A started passive client republishing the run to `live`; read-only: the
        observer's certificate (the access control lets it subscribe)."""
        from orchestrator.experiments.live import LiveBridge

        endpoint = self.endpoint if not every_interface(self.endpoint) else self.joined[0]
        tls = (TlsFiles.in_dir(self.tls_dir, OBSERVER_CN) if self.tls_dir is not None
               else None)
        return LiveBridge(self.run_id, endpoint, self.scenario, live, tls=tls).start()


@dataclass
class _Children:
    """The processes of one distributed run, and what tears them down."""

    launch: _Launch
    world: subprocess.Popen[bytes] | None = None
    robots: list[subprocess.Popen[bytes]] = field(default_factory=list)
    scheduler: ProcessFaultScheduler | None = None
    bridge: LiveBridge | None = None

    def spawn_robot(self, rid: int, restart: int = 0) -> subprocess.Popen[bytes]:
        """Start robot `rid`'s process (its `restart`-th replacement if > 0)."""
        name = f"robot_{rid}.log" if not restart else f"robot_{rid}.restart{restart}.log"
        proc = spawn_logged(self.launch.robot_command(rid), self.launch.out_dir / name)
        self.robots.append(proc)
        return proc

    def supervise(self, t0: float, world_limit_s: float,
                  on_progress: Callable[[DistributedProgress], None] | None) -> int:
        """Until the world exits (or overruns `world_limit_s` and is stopped): send the
        process faults when due, report progress; returns the world's return code."""
        world, scheduler = self.world, self.scheduler
        assert world is not None and scheduler is not None
        out_dir, n_robots = self.launch.out_dir, len(self.launch.robot_ids)
        tail = EventTail(out_dir / "events.jsonl")
        while True:
            try:
                world.wait(timeout=FAULT_POLL_S if scheduler.pending else POLL_S)
                break
            except subprocess.TimeoutExpired:
                pass
            if scheduler.pending:
                scheduler.poll(last_trajectory_time(out_dir / "trajectory.csv"))
            if time.monotonic() - t0 > world_limit_s:
                stop_processes([world], 0.0, WORLD_TERM_GRACE_S)
                break
            if on_progress is not None:
                tail.poll()
                on_progress(distributed_progress(tail.events, out_dir, t0, n_robots, self.robots))
        if on_progress is not None:
            tail.poll()
            on_progress(distributed_progress(tail.events, out_dir, t0, n_robots, self.robots))
        return world.returncode

    def teardown(self) -> None:
        """The world first (so it records the end), then the robots; robots.json."""
        if self.bridge is not None:
            self.bridge.stop()
        if self.world is not None:
            stop_processes([self.world], 0.0, WORLD_TERM_GRACE_S)
        if self.scheduler is not None:
            self.scheduler.release()
        stop_processes(self.robots, ROBOT_EXIT_GRACE_S, ROBOT_TERM_GRACE_S)
        with contextlib.suppress(OSError):
            out_dir = self.launch.out_dir
            replace_file(out_dir / "robots.json",
                         (json.dumps(collect_robot_exits(out_dir), indent=1) + "\n").encode())


@contextlib.contextmanager
def _torn_down_on_exit(teardown: Callable[[], None]) -> Iterator[None]:
    """Run the block, then `teardown` however the block ends.

    In the main thread, SIGTERM and SIGHUP interrupt the block (`raise_interrupt`: it
    unwinds through the teardown, then the caller's interrupted-run path), and the teardown
    runs with SIGINT, SIGTERM and SIGHUP ignored: it is bounded (`WORLD_TERM_GRACE_S` +
    `ROBOT_EXIT_GRACE_S` + `ROBOT_TERM_GRACE_S`), and a second Ctrl-C or SIGTERM must not
    cut it short and leave orphans. The previous handlers are back afterwards.
    """
    in_main = threading.current_thread() is threading.main_thread()
    previous = ({s: signal.signal(s, raise_interrupt) for s in (signal.SIGTERM, signal.SIGHUP)}
                if in_main else {})
    try:
        yield
    finally:
        if in_main:
            previous[signal.SIGINT] = signal.signal(signal.SIGINT, signal.SIG_IGN)
            for signum in (signal.SIGTERM, signal.SIGHUP):
                signal.signal(signum, signal.SIG_IGN)
        try:
            teardown()
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler if handler is not None else signal.SIG_DFL)


def _record_transport(out_dir: Path, info: dict[str, Any]) -> None:
    """Add ``zenoh`` (`transport_info`) to the run directory's run.json (made if absent)."""
    from orchestrator.analysis.rundir import read_json, write_json

    path = Path(out_dir) / "run.json"
    write_json(path, {**read_json(path), "zenoh": info})


def default_startup_timeout_s(n_robots: int) -> float:
    """The start-up deadline of a run of `n_robots` robot processes (see `STARTUP_S_PER_ROBOT`)."""
    return max(STARTUP_S_MIN, STARTUP_S_PER_ROBOT * n_robots)


def run_scenario_distributed(scenario: Scenario, out_dir: Path, seed: int, *,
                             time_scale: float = 1.0,
                             on_progress: Callable[[DistributedProgress], None] | None = None,
                             faults: FaultPlan | None = None,
                             live: LiveView | None = None, tls: bool = True,
                             tls_ca: Path | None = None, robot_launcher: str = "spawn"
                             ) -> tuple[RunMetrics | None, int]:
    """One resolved scenario as real processes, with its metrics: `orchestrator run`'s path.

    Writes `scenario.input.yaml` into out_dir, runs `run_distributed` (50 Hz world, a run
    id from the scenario name, the seed and a random token) and, when the world left a
    trajectory, computes and writes `metrics.json`. `tls`, `tls_ca`, `robot_launcher`: as
    `run_distributed`.

    Returns:
        (the metrics, or None when the run left no readable trajectory; the world's exit
        status).
    """
    import secrets

    from orchestrator.analysis.rundir import (
        RunDirError,
        metrics_from_run_dir,
        safe_name,
        write_metrics,
    )
    from world.scenario_file import dump_scenario

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    scenario_path = out_dir / "scenario.input.yaml"
    dump_scenario(scenario, scenario_path)
    run_id = f"{safe_name(scenario.name)[:24]}-{seed}-{secrets.token_hex(4)}"
    status = run_distributed(scenario_path, out_dir, run_id, rate_hz=50.0,
                             time_scale=time_scale, on_progress=on_progress, faults=faults,
                             live=live, tls=tls, tls_ca=tls_ca,
                             robot_launcher=robot_launcher)
    if not (out_dir / "trajectory.csv").exists():
        return None, status
    try:
        metrics = metrics_from_run_dir(out_dir)
    except RunDirError:
        return None, status
    write_metrics(out_dir, metrics)
    return metrics, status
