"""The two orchestration steps of the docker-compose demo (compose.yaml, docker/entrypoint.sh).

``orchestrator compose scenario``: in the world's container, before the world starts. Resolves
the setup as ``orchestrator run`` does, checks that it has as many robots as the compose file
has robot services, sets aside an earlier run directory of the same run id (a second
``docker compose up`` on the same volume) and writes the scenario file the world is started
with: ``<runs-dir>/<run>/scenario.input.yaml``.

``orchestrator compose await``: the orchestrator's container, a Zenoh client of the world's
router (explicit endpoint, no multicast: Docker bridges carry none). It waits until every
robot's liveliness token is present (the world then starts the run), follows the run, and
once the world's token is gone (the world closes its run directory before its session) writes
``metrics.json``, ``trajectory.png``, ``report.txt`` and ``run.json`` into the run directory.

Exit status of ``await``: as ``orchestrator run`` (`agent.process.ExitCode`); TRANSPORT
when the world never came up, WORLD_LOST when it never left or left no trajectory.
"""

from __future__ import annotations

import datetime as dt
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from agent.core.scenario import Scenario
from agent.process import (
    ExitCode,
    SampleSubscriber,
    SessionError,
    StopFlag,
    close_session,
    open_session,
    stop_on_signals,
)
from world.scenario_file import ScenarioError, dump_scenario

DEFAULT_CONNECT = "tls/world:7447"
CONTAINER_UID = 1000
"""The user every service runs as (Dockerfile): owner of the certificates `make_certs` writes."""
DEFAULT_RUNS_DIR = Path("/runs")
SCENARIO_FILE = "scenario.input.yaml"
CONNECT_ATTEMPT_MS = 1000
"""Each attempt to open the session waits this long for the router (then retries)."""
POLL_S = 0.2
"""Wall period of the watch loop."""
RUN_MARGIN_S = 60.0
"""Slack on the run's expected wall duration before the orchestrator gives up on the world."""

if TYPE_CHECKING:
    import zenoh

    from eifp_wire import RunKeys

log = logging.getLogger("orchestrator")


@dataclass(frozen=True)
class SetupOptions:
    """What both steps resolve the same way (they run in different containers).

    Args:
        setup: setup name, family or scenario file (as ``orchestrator run``).
        agents: robot count for scalable setups and families (None: the setup's own).
        planner: every robot uses this planner (None: the scenario's).
        seed: seeds the random family.
        robots: robot services in the compose file; the scenario must have that many robots
            (None: not checked).
        run_id: run id (the key-expression prefix and the run directory's name).
        runs_dir: the shared volume's mount point.
    """

    setup: str
    agents: int | None
    planner: str | None
    seed: int
    robots: int | None
    run_id: str
    runs_dir: Path

    @property
    def run_dir(self) -> Path:
        return self.runs_dir / self.run_id

    def resolve(self) -> Scenario:
        """The scenario; raises `ScenarioError` if it does not match the robot services."""
        from orchestrator.experiments.families import resolve

        scenario = resolve(self.setup, agents=self.agents, seed=self.seed, planner=self.planner)
        if self.robots is not None and len(scenario.robots) != self.robots:
            raise ScenarioError(
                f"{self.setup}: has {len(scenario.robots)} robots but the compose file runs "
                f"{self.robots} robot services (ROBOTS); use the matching compose file, e.g. "
                "compose.setup-g.yaml for setup_g")
        ids = sorted(r.id for r in scenario.robots)
        if self.robots is not None and ids != list(range(self.robots)):
            raise ScenarioError(f"{self.setup}: robot ids {ids} are not 0..{self.robots - 1}, "
                                "the ROBOT_ID values of the robot services")
        return scenario


def set_aside(run_dir: Path) -> Path | None:
    """Rename a non-empty `run_dir` to the first free ``<run_dir>.<n>``; the new name or None."""
    if not run_dir.is_dir() or not any(run_dir.iterdir()):
        return None
    n = 1
    while (target := run_dir.with_name(f"{run_dir.name}.{n}")).exists():
        n += 1
    run_dir.rename(target)
    return target


def prepare_scenario(options: SetupOptions) -> Path:
    """Resolve the setup and write the world's scenario file into a fresh run directory."""
    scenario = options.resolve()
    previous = set_aside(options.run_dir)
    if previous is not None:
        log.warning("%s held an earlier run: moved to %s", options.run_dir, previous)
    path = options.run_dir / SCENARIO_FILE
    dump_scenario(scenario, path)
    log.info("run %s: %s, %d robots -> %s", options.run_id, scenario.name,
             len(scenario.robots), path)
    return path


def make_certs(run_id: str, robots: int, out: Path, world_hosts: tuple[str, ...] = ("world",),
               relays: Mapping[str, tuple[str, ...]] | None = None) -> list[Path]:
    """``orchestrator compose certs``: the run's CA and certificates, one directory per service
    under `out` (``<out>/<cn>/``: ``ca.pem``, ``<cn>.pem``, ``<cn>.key``; compose mounts each
    as a volume of that service alone, so no service holds another's key). The CA key is
    never written. `relays`: relay router name -> the names its host is dialled by (a
    ``router-<name>`` certificate each). Run as root (the one-shot ``certs`` service), the
    files are handed to `CONTAINER_UID`. Returns the directories."""
    import os

    from agent.security import make_run_pki

    files = make_run_pki(out, run_id, range(robots), world_hosts=world_hosts, relays=relays,
                         split=True)
    dirs = [Path(f.cert).parent for f in files.values()]
    if os.geteuid() == 0:
        for d in dirs:
            for path in (d, *d.iterdir()):
                os.chown(path, CONTAINER_UID, CONTAINER_UID)
    log.info("run %s: certificates of %s in %s", run_id, ", ".join(sorted(files)), out)
    return dirs


# --------------------------------------------------------------------------------------
# await
# --------------------------------------------------------------------------------------

def _open_session(connect: str, deadline: float, stop: StopFlag,
                  tls_dir: Path | None = None) -> zenoh.Session | None:
    """A client session to `connect`, retrying until `deadline` (monotonic); None if not.
    With `tls_dir`: mutual TLS as the ``orchestrator`` identity."""
    from eifp_wire import ORCHESTRATOR_CN, TlsFiles, session_settings

    tls = TlsFiles.in_dir(tls_dir, ORCHESTRATOR_CN) if tls_dir is not None else None
    try:
        settings = session_settings(mode="client", connect=[connect],
                                    connect_timeout_ms=CONNECT_ATTEMPT_MS, tls=tls)
    except ValueError as exc:
        log.error("%s", exc)
        return None
    try:
        return open_session(settings, deadline=deadline, stop=stop)
    except SessionError as exc:  # the router is not up (or `world` does not resolve)
        log.error("cannot connect to %s: %s", connect, exc)
        return None


@dataclass
class RunWatch:
    """What the orchestrator has seen of the run over Zenoh (liveliness only)."""

    robot_ids: frozenset[int]
    alive: set[int]
    world_seen: bool = False
    world_gone: bool = False
    all_alive_once: bool = False


def _drain(watch: RunWatch, robot_sub: SampleSubscriber, world_sub: SampleSubscriber,
           keys: RunKeys) -> None:
    """Apply the liveliness changes waiting in the two channels; log what changed."""
    import zenoh

    from eifp_wire import ProtocolError

    n = len(watch.robot_ids)
    while (sample := robot_sub.try_recv()) is not None:
        try:
            rid = keys.robot_id_of_alive(sample.key_expr)
        except ProtocolError:
            continue
        if rid not in watch.robot_ids:
            log.warning("robot %d is alive but not in the scenario", rid)
        elif sample.kind == zenoh.SampleKind.PUT and rid not in watch.alive:
            watch.alive.add(rid)
            log.info("robot %d alive (%d/%d)", rid, len(watch.alive), n)
            if len(watch.alive) == n and not watch.all_alive_once:
                watch.all_alive_once = True
                log.info("every robot is alive: the world starts the run")
        elif sample.kind == zenoh.SampleKind.DELETE and rid in watch.alive:
            watch.alive.discard(rid)
            log.info("robot %d left (%d/%d alive)", rid, len(watch.alive), n)
    while (sample := world_sub.try_recv()) is not None:
        if sample.kind == zenoh.SampleKind.PUT and not watch.world_seen:
            watch.world_seen = True
            log.info("world is up")
        elif sample.kind == zenoh.SampleKind.DELETE and watch.world_seen:
            watch.world_gone = True
            log.info("world left: its run directory is complete")


def watch_run(options: SetupOptions, scenario: Scenario, connect: str, startup_timeout_s: float,
              time_scale: float, stop: StopFlag, tls_dir: Path | None = None) -> str:
    """Follow the run over Zenoh until the world leaves; returns why the watch ended.

    Returns:
        ``"done"`` (the world left), ``"no_world"`` (no session or no world token before the
        startup deadline), ``"world_stuck"`` (the world outlived the run's wall budget) or
        ``"signal"``.
    """
    from eifp_wire import RunKeys
    from orchestrator.analysis.console import ProgressLine
    from orchestrator.experiments.progress import EventTail, distributed_progress

    keys = RunKeys(options.run_id)
    t0 = time.monotonic()
    session = _open_session(connect, t0 + startup_timeout_s, stop, tls_dir)
    if session is None:
        return "signal" if stop else "no_world"
    watch = RunWatch(frozenset(r.id for r in scenario.robots), set())
    progress = ProgressLine(f"{scenario.name} docker")
    tail = EventTail(options.run_dir / "events.jsonl")
    try:
        robot_sub = session.liveliness().declare_subscriber(keys.alive_robot_all, history=True)
        world_sub = session.liveliness().declare_subscriber(keys.alive_world, history=True)
        log.info("connected to %s; waiting for the world and %d robots", connect,
                 len(watch.robot_ids))
        # A world that cannot keep pace runs slower than time_scale: be generous.
        budget_s = 2.0 * startup_timeout_s + 3.0 * scenario.time_limit_s / time_scale + RUN_MARGIN_S
        while not watch.world_gone:
            if stop:
                return "signal"
            _drain(watch, robot_sub, world_sub, keys)
            now = time.monotonic()
            if not watch.world_seen and now - t0 > startup_timeout_s:
                log.error("no world on %s for run %s after %.0f s", connect, options.run_id,
                          startup_timeout_s)
                return "no_world"
            if now - t0 > budget_s:
                log.error("the world is still running after %.0f s; giving up", budget_s)
                return "world_stuck"
            if watch.all_alive_once:
                tail.poll()
                progress(distributed_progress(tail.events, options.run_dir, t0,
                                              len(watch.robot_ids), ()))
            time.sleep(POLL_S)
        return "done"
    finally:
        progress.done()
        if not close_session(session):
            log.warning("closing the session timed out")


def write_report(options: SetupOptions, scenario: Scenario, time_scale: float,
                 started: str, connect: str = DEFAULT_CONNECT, tls_dir: Path | None = None
                 ) -> int:
    """metrics.json, trajectory.png, report.txt and run.json of the finished run; the status."""
    from orchestrator.analysis.console import run_summary
    from orchestrator.analysis.plots import write_run_plots
    from orchestrator.analysis.rundir import (
        RunDirError,
        metrics_from_run_dir,
        read_events,
        read_json,
        run_ending,
        write_json,
        write_metrics,
    )

    run_dir = options.run_dir
    planners = sorted({r.planner for r in scenario.robots})
    planner = planners[0] if len(planners) == 1 else "mixed"
    started_info = {
        "setup": options.setup, "scenario": scenario.name, "planner": planner,
        "seed": options.seed, "mode": "docker-compose", "agents": len(scenario.robots),
        "run_id": options.run_id, "time_scale": time_scale, "started": started,
        "zenoh": {"endpoints": [connect], "tls": tls_dir is not None,
                  **({"ca": str(Path(tls_dir) / "ca.pem"), "access_control": True}
                     if tls_dir is not None else {})},
    }
    write_json(run_dir / "run.json", started_info)
    events = read_events(run_dir / "events.jsonl")
    end: dict[str, Any] = next((e for e in reversed(events) if e.get("kind") == "end"), {})
    try:
        metrics = metrics_from_run_dir(run_dir)
    except (RunDirError, OSError, ValueError) as exc:
        log.error("no metrics for %s: %s", run_dir, exc)
        ending = run_ending(None, end, crashed=True)
        write_json(run_dir / "run.json", {**started_info, **ending.as_json(),
                                          "finished": _now()})
        return ending.exit_code
    write_metrics(run_dir, metrics)
    write_run_plots(run_dir, gif=False)
    content = read_json(run_dir / "metrics.json")
    ending = run_ending(content, end)
    write_json(run_dir / "run.json", {**started_info, **ending.as_json(), "finished": _now()})
    lines = [run_summary(content, f"{scenario.name} {planner} docker-compose"), "",
             f"run {options.run_id}: status {ending.status}, exit code {ending.exit_code}, "
             f"end reason {end.get('reason', 'unknown (no end event)')}"]
    for e in events:
        if e.get("kind") == "startup_timeout":
            lines.append(f"robots never alive before the world's deadline: {e.get('missing')}")
    if end.get("lost"):
        lines.append(f"robots lost during the run: {end['lost']}")
    lines.append(f"files: {run_dir}")
    text = "\n".join(lines) + "\n"
    (run_dir / "report.txt").write_text(text, encoding="utf-8")
    print(text, flush=True)
    return ending.exit_code


def _now() -> str:
    return dt.datetime.now().isoformat(timespec="seconds")


def await_and_report(options: SetupOptions, connect: str, startup_timeout_s: float,
                     time_scale: float, tls_dir: Path | None = None,
                     live: tuple[str, int] | None = None) -> int:
    """The orchestrator container: watch the run, then write the report; the exit status.

    With `live` (host, port), a live Foxglove view of the run is served meanwhile
    (`orchestrator.experiments.live`: a passive Zenoh client of the world's router)."""
    scenario = options.resolve()
    started = dt.datetime.now().isoformat(timespec="seconds")
    view = bridge = None
    if live is not None:
        from orchestrator.experiments.live import LiveBridge, start_live_view

        view = start_live_view(live[0], live[1], scenario)
        tls = None
        if tls_dir is not None:
            from eifp_wire import ORCHESTRATOR_CN, TlsFiles

            tls = TlsFiles.in_dir(tls_dir, ORCHESTRATOR_CN)
        bridge = LiveBridge(options.run_id, connect, scenario, view, tls=tls).start()
    try:
        with stop_on_signals() as stop:
            outcome = watch_run(options, scenario, connect, startup_timeout_s, time_scale, stop,
                                tls_dir)
    finally:
        if bridge is not None:
            bridge.stop()
        if view is not None:
            view.stop()
    if outcome == "signal":
        log.warning("stopped by signal %s before the run ended", stop.signum)
        return ExitCode.INTERRUPTED
    if outcome == "no_world":
        return ExitCode.TRANSPORT
    if outcome != "done":
        return ExitCode.WORLD_LOST
    return write_report(options, scenario, time_scale, started, connect, tls_dir)
