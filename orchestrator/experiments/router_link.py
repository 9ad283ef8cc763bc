"""Bytes on the link between two hosts' routers (``orchestrator scale --router-link``).

    orchestrator scale --router-link --agents 32,48,64 --time-scale 0.25 --out DIR

The topology of `compose.routers.yaml`, as local processes: host A runs the world, whose
session is host A's router, and the robots in host A's region, which dial it; host B runs
a relay router (`world.router`) and the robots in host B's region, which dial the relay.
The relay dials the world through a `byte_proxy.CountingProxy`: the link between the
hosts, every byte counted each way. Mutual TLS on every link and access control on both
routers: the world's (``--relay b=<ids>``, `eifp_wire.access.access_control`) and the
relay's (``--tls``, `eifp_wire.access.relay_access_control`).

The plane is split at a vertical border (`border_layout`): tiles of the `circles` family
(8-robot antipodal circles, 19 m apart), host B's robots in one column of tiles
(`HOST_B_ROBOTS`), host A's robots in columns of as many tiles beside it, filled from the
border outwards, so a larger N adds robots far from the border. Three cases per N:

- ``near``: host B's column next to host A's nearest one (rims 3 m apart, as in
  ``circles``); the robots of host A within the cells host B's robots hold are the
  border population, the same for every N.
- ``far``: host B's column `FAR_GAP_COLUMNS` empty columns away: no robot of host A in
  any cell host B's robots hold.
- ``direct``: ``near`` without a relay: host B's robots dial the world across the link
  themselves (as in `orchestrator.experiments.scale` with ``--hosts``), each receiving its
  own copy of its cells.

Per case it reports the bytes that crossed the link per second of sim time, each way, in
the control phase (the world's ``start`` to the first ``robot_left``, both wall-stamped),
against two references: what a pose stream of the whole fleet would carry (one message
of all N discs every world tick, each tick crossing once: computed from the encoder) and
the pose payload bytes host B's robots received (their exit lines), which is what would
cross without a relay. Figures only; nothing here asserts a budget.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import secrets
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agent.core.scenario import RobotSpec, Scenario

HOST_B_ROBOTS = 16
"""Robots on host B: one column of two 8-robot circles."""
FAR_GAP_COLUMNS = 3
"""Empty tile columns between the hosts' robots in the ``far`` case (57 m: more than a
robot's held cells reach, two cells of 20 m plus its circle)."""
LINK_SECONDS = 12.0
"""Sim seconds of a run unless ``--seconds`` says otherwise (the rates are steady well
before: every robot holds its cells from its start)."""
CASES = ("near", "far", "direct")
WORLD_ZID = "e1f5"
"""The world's fixed Zenoh id: robots behind the relay check their poses' source against it."""
RELAY_NAME = "b"
RELAY_EXIT_S = 15.0
"""Wall time the relay gets to leave on its own once the run is over."""
RATE_HZ = 50.0
"""The world's tick rate (its default)."""


@dataclass(frozen=True)
class LinkLayout:
    """A scenario split between two hosts at the vertical line ``x = border_x_m``.

    Args:
        scenario: every robot, host A's first (ids 0..), then host B's.
        host_b: ids of the robots in host B's region (x > border_x_m).
        border: ids of host A's robots whose start cell is a cell some robot of host B
            holds at its start (`world.sim.cells.CellRule.needed`): the poses of host A
            that host B needs.
        border_x_m: the border [m].
        case: ``near`` or ``far``.
    """

    scenario: Scenario
    host_b: tuple[int, ...]
    border: tuple[int, ...]
    border_x_m: float
    case: str

    @property
    def host_a(self) -> tuple[int, ...]:
        b = set(self.host_b)
        return tuple(r.id for r in self.scenario.robots if r.id not in b)


def _group_sizes(n: int) -> list[int]:
    """n robots in circles of at most `CIRCLES_GROUP`, as even as the `circles` family."""
    from orchestrator.experiments.families import CIRCLES_GROUP

    groups = math.ceil(n / CIRCLES_GROUP)
    return [n // groups + (1 if g < n % groups else 0) for g in range(groups)]


def border_layout(n: int, case: str = "near", host_b_robots: int = HOST_B_ROBOTS
                  ) -> LinkLayout:
    """N robots in `circles` tiles, `host_b_robots` of them in host B's column of tiles.

    Host A's tiles fill columns of as many tiles as host B's (rows ``y`` centred on 0) from
    the border outwards (x = 0, -19, -38, ... m); host B's column stands at x = 19 m
    (``near``) or `FAR_GAP_COLUMNS` columns farther (``far``). The border is halfway
    between the two hosts' nearest columns.

    Raises:
        ValueError: an unknown case, or fewer than 2 robots on either host.
    """
    from orchestrator.experiments.families import (
        CIRCLES_PITCH_M,
        CIRCLES_TIME_LIMIT_S,
        circle_tile,
    )
    from orchestrator.experiments.scenario_blocks import make_scenario
    from world.sim.cells import CellRule

    if case not in ("near", "far"):
        raise ValueError(f"case must be 'near' or 'far', got {case!r}")
    if host_b_robots < 2 or n - host_b_robots < 2:
        raise ValueError(f"--agents {n}: host B holds {host_b_robots} robots and host A "
                         "needs at least 2 more")
    b_sizes, a_sizes = _group_sizes(host_b_robots), _group_sizes(n - host_b_robots)
    rows = len(b_sizes)

    def row_y(r: int) -> float:
        return (r - (rows - 1) / 2.0) * CIRCLES_PITCH_M

    b_x = CIRCLES_PITCH_M * (1 + (FAR_GAP_COLUMNS if case == "far" else 0))
    robots: list[RobotSpec] = []
    for g, size in enumerate(a_sizes):
        robots += circle_tile((-(g // rows) * CIRCLES_PITCH_M, row_y(g % rows)), size, g,
                              first_id=len(robots))
    n_a = len(robots)
    for r, size in enumerate(b_sizes):
        robots += circle_tile((b_x, row_y(r)), size, len(a_sizes) + r, first_id=len(robots))
    scenario = make_scenario(
        f"border_{case}_{n}", f"{n} robots in antipodal circles of up to 8, {n - n_a} of them "
        f"on host B ({case} the border)", robots, time_limit_s=CIRCLES_TIME_LIMIT_S)
    rule = CellRule.of_config(scenario.planner_config)
    held = set().union(*(rule.needed(r.start[0], r.start[1]) for r in robots[n_a:]))
    border = tuple(r.id for r in robots[:n_a] if rule.cell_of(r.start[0], r.start[1]) in held)
    return LinkLayout(scenario, tuple(r.id for r in robots[n_a:]), border, b_x / 2.0, case)


def whole_fleet_bytes_per_tick(scenario: Scenario) -> int:
    """Bytes of one pose message of every disc at the start (the stream before the pose
    grid): what each world tick would send across the link to a host with robots on every
    pose slot."""
    from eifp_wire import PosesMsg
    from world.world_cycle import WorldCycle

    cycle = WorldCycle(scenario, "router-link", cmd_timeout_s=1e6)
    return len(PosesMsg.from_snapshot(cycle.sim.snapshot()).encode())


def control_window(events: Sequence[dict[str, Any]]) -> tuple[float, float, float] | None:
    """(wall start, wall end, sim seconds) of the control phase: the world's ``start`` to
    the first ``robot_left`` (robots leave within milliseconds of the world's end
    message), sim time to the ``end`` event's; None if the run never started or ended."""
    start = next((e for e in events if e.get("kind") == "start" and "wall" in e), None)
    end = next((e for e in events if e.get("kind") == "end"), None)
    left = [float(e["wall"]) for e in events if e.get("kind") == "robot_left" and "wall" in e]
    if start is None or end is None or not left:
        return None
    return float(start["wall"]), min(left), float(end["t"]) - float(start["t"])


def received_by(exits: dict[str, Any], robot_ids: Sequence[int]) -> int:
    """Pose payload bytes the robots `robot_ids` received (robots.json's exit lines)."""
    ids = set(robot_ids)
    return sum(int(p.get("rx_pose_bytes", 0)) for p in exits.get("processes", ())
               if p.get("robot") in ids)


def link_row(layout: LinkLayout, *, relay: bool, down_b: int, up_b: int,
             window: tuple[float, float, float] | None, exits: dict[str, Any],
             links: int, world_status: int, time_scale: float, wall_s: float,
             acl: Sequence[str]) -> dict[str, Any]:
    """One table row (see the module docstring)."""
    n = len(layout.scenario.robots)
    sim_s = window[2] if window else None
    per_s = (lambda b: b / sim_s) if sim_s else (lambda b: None)
    fleet_tick_b = whole_fleet_bytes_per_tick(layout.scenario)
    rx_b = received_by(exits, layout.host_b)
    return {
        "case": layout.case if relay else "direct",
        "agents": n,
        "host_b_robots": len(layout.host_b),
        "border_robots": len(layout.border),
        "link_down_bytes_s": per_s(down_b),
        "link_up_bytes_s": per_s(up_b),
        "link_bytes_s": per_s(down_b + up_b),
        "whole_fleet_bytes_s": fleet_tick_b * RATE_HZ,
        "host_b_rx_pose_bytes_s": per_s(rx_b),
        "links": links,
        "acl_routers": list(acl),
        "sim_s": sim_s,
        "wall_s": wall_s,
        "time_scale": time_scale,
        "world_status": world_status,
    }


class RelayWatch(threading.Thread):
    """Which addresses a relay process dials, sampled every `period_s` until `stop()`:
    every established TCP connection of `pid` whose local port is not `listen_port` (its
    robots'), as ``host:port`` of the far end. Zenoh could open a second link to a router
    it learns of by gossip; the link proxy then would not see every byte."""

    def __init__(self, pid: int, listen_port: int, period_s: float = 1.0) -> None:
        super().__init__(name="relay-watch", daemon=True)
        self.pid, self.listen_port, self.period_s = pid, listen_port, period_s
        self.dialled: set[str] = set()
        self._done = threading.Event()

    def stop(self) -> None:
        self._done.set()
        self.join()

    def run(self) -> None:
        import psutil

        while not self._done.wait(self.period_s):
            try:
                conns = psutil.Process(self.pid).net_connections(kind="tcp")
            except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
                return
            self.dialled |= {f"{c.raddr.ip}:{c.raddr.port}" for c in conns
                             if c.status == psutil.CONN_ESTABLISHED and c.raddr
                             and c.laddr.port != self.listen_port}


def _start_relay(run_id: str, ids: str, link_ep: str, out_dir: Path, ca_dir: Path, *,
                 wait_world_s: float) -> tuple[subprocess.Popen[bytes], RelayWatch, str]:
    """Host B's relay router (``python -m world.router --tls``: its access control on),
    with a certificate from `ca_dir`, dialling the world at `link_ep`, and a `RelayWatch`
    on it; returns both and the endpoint its robots dial."""
    from agent.security import make_run_pki
    from orchestrator.experiments.distributed import free_tcp_endpoint, spawn_logged

    tls_b = out_dir / "tls-host-b"
    make_run_pki(tls_b, run_id, (), relays={RELAY_NAME: ()}, ca_dir=ca_dir)
    relay_ep = "tls/" + free_tcp_endpoint().removeprefix("tcp/")
    proc = spawn_logged(
        [sys.executable, "-m", "world.router", "--run", run_id, "--name", RELAY_NAME,
         "--robots", ids, "--listen", relay_ep, "--connect", link_ep,
         "--tls", str(tls_b.resolve()), "--wait-world-s", repr(wait_world_s)],
        out_dir / "router_b.log")
    watch = RelayWatch(proc.pid, int(relay_ep.rsplit(":", 1)[1]))
    watch.start()
    return proc, watch, relay_ep


def run_case(n: int, case: str, *, time_scale: float, seconds: float, out_root: Path,
             startup_timeout_s: float, host_b_robots: int = HOST_B_ROBOTS,
             tls_ca: Path | None = None) -> dict[str, Any]:
    """One run of `case` (`CASES`) with n robots; returns its row.

    `tls_ca`: a CA directory (``ca.pem``, ``ca.key``) to sign every certificate with; None:
    a fresh CA whose key lives in a temporary directory for the run only."""
    from agent.security import RunCA
    from orchestrator.analysis.rundir import read_events, write_json
    from orchestrator.experiments.byte_proxy import CountingProxy
    from orchestrator.experiments.distributed import (
        free_tcp_endpoint,
        run_distributed,
        stop_processes,
    )
    from world.scenario_file import dump_scenario

    relay = case != "direct"
    layout = border_layout(n, "near" if case == "direct" else case, host_b_robots)
    scenario = dataclasses.replace(layout.scenario, time_limit_s=float(seconds))
    out_dir = out_root / f"{case}_{n}"
    if out_dir.exists():
        raise SystemExit(f"error: {out_dir} already exists; choose another --out")
    out_dir.mkdir(parents=True)
    scenario_path = out_dir / "scenario.input.yaml"
    dump_scenario(scenario, scenario_path)
    run_id = f"link-{case}-{n}-{secrets.token_hex(4)}"
    ids = ",".join(map(str, layout.host_b))
    write_json(out_dir / "run.json", {"setup": "router-link", "run": run_id, "case": case,
                                      "agents": n,
                                      "host_b": list(layout.host_b),
                                      "border": list(layout.border),
                                      "time_scale": time_scale, "mode": "distributed"})
    world_ep = free_tcp_endpoint()
    host, port = world_ep.removeprefix("tcp/").rsplit(":", 1)
    relay_proc, watch = None, None
    t0 = time.monotonic()
    # A fresh CA lives only as long as the run: the relay's certificate is signed by it
    # before the run starts, the run's own (`run_distributed`) after.
    with contextlib.ExitStack() as stack:
        proxy = stack.enter_context(CountingProxy((host, int(port))))
        if tls_ca is None:
            ca_dir = Path(stack.enter_context(
                tempfile.TemporaryDirectory(prefix="router-link-ca-")))
            RunCA(run_id).write(ca_dir)
        else:
            ca_dir = Path(tls_ca)
        link_ep = f"tls/127.0.0.1:{proxy.port}"
        world_args: list[str] = []
        robot_args: list[str] = []
        if relay:
            relay_proc, watch, relay_ep = _start_relay(
                run_id, ids, link_ep, out_dir, ca_dir, wait_world_s=startup_timeout_s + 30.0)
            world_args = ["--relay", f"{RELAY_NAME}={ids}", "--zid", WORLD_ZID]
            robot_args = ["--world-zid", WORLD_ZID]
            dialled = dict.fromkeys(layout.host_b, relay_ep)
        else:
            dialled = dict.fromkeys(layout.host_b, link_ep)
        try:
            status = run_distributed(
                scenario_path, out_dir, run_id, rate_hz=RATE_HZ, time_scale=time_scale,
                endpoint=world_ep, robot_endpoints=dialled,
                startup_timeout_s=startup_timeout_s, robot_launcher="fork", tls=True,
                tls_ca=ca_dir, extra_world_args=world_args, robot_args=robot_args)
        finally:
            if relay_proc is not None and watch is not None:
                stop_processes([relay_proc], RELAY_EXIT_S, 5.0)
                watch.stop()
        events = read_events(out_dir / "events.jsonl")
        window = control_window(events)
        down = proxy.counter.between("downstream", *window[:2]) if window else 0
        up = proxy.counter.between("upstream", *window[:2]) if window else 0
        links = proxy.connections
    try:
        exits = json.loads((out_dir / "robots.json").read_text())
    except (OSError, ValueError):
        exits = {}
    ready = next((e for e in events if e.get("kind") == "world_ready"), {})
    acl = (["world"] if ready.get("tls") else []) + (
        [f"router-{RELAY_NAME}"] if relay and ready.get("relays") else [])
    row = link_row(layout, relay=relay, down_b=down, up_b=up, window=window, exits=exits,
                   links=links, world_status=status, time_scale=time_scale,
                   wall_s=time.monotonic() - t0, acl=acl)
    row["run_id"] = run_id
    row["relay_dialled"] = sorted(watch.dialled) if watch is not None else []
    row["relay_dialled_only_link"] = watch is None or watch.dialled <= {
        link_ep.removeprefix("tls/")}
    return row


def _fmt(value: object, scale: float = 1.0, digits: int = 1) -> str:
    return "-" if not isinstance(value, int | float) else f"{value / scale:.{digits}f}"


def format_link_rows(rows: Sequence[dict[str, Any]]) -> str:
    """The printed table, one row per case and N (kB = 1000 bytes, per sim second)."""
    from orchestrator.analysis.report import format_table

    head = ["case", "N", "host B", "border", "link kB/s down / up", "per host-B robot kB/s",
            "whole fleet kB/s", "host B robots rx kB/s", "TCP links", "ACL on", "sim s", "wall s"]
    body = [[r["case"], str(r["agents"]), str(r["host_b_robots"]), str(r["border_robots"]),
             f"{_fmt(r['link_down_bytes_s'], 1e3)} / {_fmt(r['link_up_bytes_s'], 1e3)}",
             _fmt(None if r["link_bytes_s"] is None
                  else r["link_bytes_s"] / r["host_b_robots"], 1e3, 2),
             _fmt(r["whole_fleet_bytes_s"], 1e3), _fmt(r["host_b_rx_pose_bytes_s"], 1e3),
             str(r["links"]) + ("" if r.get("relay_dialled_only_link", True) else " + bypass"),
             ",".join(r["acl_routers"]) or "-", _fmt(r["sim_s"]),
             _fmt(r["wall_s"], digits=0)] for r in rows]
    return format_table(head, body)


def run_router_link(args: argparse.Namespace, out_root: Path) -> list[dict[str, Any]]:
    """Every case of `CASES` for every N of ``args.agents``; rows, written to
    ``router_link.json`` after each run."""
    from orchestrator.analysis.rundir import write_json

    rows: list[dict[str, Any]] = []
    for n in args.agents:
        border_layout(n)  # refuse a bad N before any run
    for n in args.agents:
        for case in CASES:
            print(f"router link: {case} N={n} ...", file=sys.stderr, flush=True)
            rows.append(run_case(n, case, time_scale=args.time_scale,
                                 seconds=args.seconds or LINK_SECONDS, out_root=out_root,
                                 startup_timeout_s=args.startup_timeout_s,
                                 tls_ca=getattr(args, "tls_ca_dir", None)))
            write_json(out_root / "router_link.json", {"argv": ["orchestrator", *args.argv],
                                                        "rows": rows})
    return rows
