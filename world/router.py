"""A relay router: robots on another host reach the world through it (``python -m world.router``).

The world's session is the run's router (`world.node`). A host that runs robots but not the
world runs one relay: a Zenoh session in router mode that listens for that host's robots and
dials the world's router. The world's poses then cross the link between the two hosts once
per tick and fan out on the relay's host; each robot's commands cross it once.

Security (with ``--tls``): the relay presents the certificate ``router-<name>`` to the
robots and to the world's router, and enforces `eifp_wire.access.relay_access_control`: the robots
``--robots`` may use their own keys only (as on the world's router), any other identity of
the run may connect and do nothing, and the link to the world's router carries the rest.
The world's router, started with ``--relay <name>=<ids>``, lets this certificate speak for
those robots only (`eifp_wire.access.access_control`). Without ``--tls``: plain TCP, nothing is
enforced, and the relay listens on one address only.

A relay serves one run: it leaves once the world's liveliness token has come and gone and
none of its robots is still alive (`RunFollower`), on SIGTERM/SIGINT, or if the world has not
appeared within ``--wait-world-s``.

Exit status (`agent.process.ExitCode`): OK when the run is over or on a signal; TRANSPORT if
the session could not be opened or the world never appeared; BAD_INPUT for bad arguments or
TLS files.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import zenoh

from agent import flags as argtypes
from agent.process import (
    ExitCode,
    SessionError,
    StopFlag,
    check_tls_files,
    close_session,
    die_with_launcher,
    open_session,
    stop_on_signals,
)
from eifp_wire import (
    ProtocolError,
    RunKeys,
    TlsFiles,
    relay_access_control,
    router_cn,
    session_settings,
)

POLL_S = 0.05
"""Wall period of the watch loop."""

log = logging.getLogger("router")


@dataclass(frozen=True)
class RouterOptions:
    """Command-line options of a relay router.

    Args:
        run_id: the run (its key prefix and the ACL's keys).
        name: the relay's name; its certificate is ``router-<name>``.
        robot_ids: the robots that reach the world through this relay.
        listen: endpoint its robots dial, e.g. ``tls/0.0.0.0:7447``.
        connect: the world's router, e.g. ``tls/world:7447`` (dialled and redialled in the
            background: the relay may start first).
        tls_dir: directory with ``ca.pem``, ``router-<name>.pem`` and ``.key``: mutual TLS
            and `eifp_wire.access.relay_access_control`. None: plain TCP, nothing enforced.
        wait_world_s: wall deadline for the world's token to appear.
    """

    run_id: str
    name: str
    robot_ids: tuple[int, ...]
    listen: str
    connect: str
    tls_dir: Path | None = None
    wait_world_s: float = 300.0


def parse_args(argv: list[str] | None = None) -> RouterOptions:
    """Parse ``python -m world.router`` arguments."""
    parser = argtypes.Parser(prog="python -m world.router",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--run", required=True, type=argtypes.run_id, help="run id")
    parser.add_argument("--name", required=True,
                        help="the relay's name (its certificate: router-NAME)")
    parser.add_argument("--robots", required=True, type=argtypes.robot_ids, metavar="IDS",
                        help="the robots behind this relay, e.g. 2,3 or 8-15")
    parser.add_argument("--listen", required=True, type=argtypes.endpoint,
                        help="endpoint the robots dial, e.g. tls/0.0.0.0:7447")
    parser.add_argument("--connect", required=True, type=argtypes.endpoint,
                        help="the world's router, e.g. tls/<world host>:7447")
    parser.add_argument("--tls", type=Path, default=None, metavar="DIR",
                        help="mutual TLS with DIR/ca.pem, DIR/router-NAME.pem, "
                             "DIR/router-NAME.key, and the relay's access control")
    parser.add_argument("--wait-world-s", type=argtypes.positive, default=300.0,
                        help="wall deadline for the world to appear")
    args = parser.parse_args(argv)
    try:
        router_cn(args.name)
    except ValueError as exc:
        parser.error(f"--name: {exc}")
    return RouterOptions(run_id=args.run, name=args.name, robot_ids=args.robots,
                         listen=args.listen, connect=args.connect, tls_dir=args.tls,
                         wait_world_s=args.wait_world_s)


def router_settings(options: RouterOptions) -> dict[str, str]:
    """The relay's Zenoh settings: a router on `options.listen` that dials `options.connect`;
    with TLS, mutual TLS as ``router-<name>`` and `eifp_wire.access.relay_access_control`.

    Raises:
        ValueError: a plain endpoint with TLS, plain TCP on every interface, or a TLS file
            that is missing or unreadable.
    """
    tls = None
    acl = None
    if options.tls_dir is not None:
        tls = TlsFiles.in_dir(options.tls_dir, router_cn(options.name))
        problem = check_tls_files(tls)
        if problem:
            raise ValueError(f"--tls {options.tls_dir}: {problem}")
        acl = relay_access_control(options.run_id, options.robot_ids)
    if tls is None and argtypes.every_interface(options.listen):
        raise argtypes.FlagError("--listen", f"--listen {options.listen}: every interface "
                                 "only with --tls (mutual TLS and access control); plain "
                                 "TCP listens on one address")
    # A router dials its connect endpoints in the background and redials a lost link
    # (connect/timeout_ms -1 with exit_on_failure false, the router default).
    return session_settings(mode="router", listen=[options.listen], connect=[options.connect],
                            tls=tls, acl=acl)


class RunFollower:
    """When a relay's run is over: the world has been seen and has left, and none of the
    relay's robots is alive. Robots leave on the world's ``end``; a relay that left while
    they are still connected would cut them off, e.g. across a short outage of the link
    between hosts, which takes the world's token with it until the link is back."""

    def __init__(self) -> None:
        self.world_seen = False
        self.world_alive = False
        self.robots_alive: set[int] = set()

    def world(self, alive: bool) -> None:
        self.world_alive = alive
        self.world_seen |= alive

    def robot(self, robot_id: int, alive: bool) -> None:
        if alive:
            self.robots_alive.add(robot_id)
        else:
            self.robots_alive.discard(robot_id)

    @property
    def over(self) -> bool:
        return self.world_seen and not self.world_alive and not self.robots_alive


def follow_run(session: zenoh.Session, options: RouterOptions, stop: StopFlag) -> int:
    """Watch the world's and the relay's robots' liveliness until the run is over."""
    keys = RunKeys(options.run_id)
    mine = frozenset(options.robot_ids)
    world_sub = session.liveliness().declare_subscriber(keys.alive_world, history=True)
    robot_sub = session.liveliness().declare_subscriber(keys.alive_robot_all, history=True)
    follower = RunFollower()
    deadline = time.monotonic() + options.wait_world_s
    upstream: list[str] = []
    while not stop:
        links = sorted(str(z) for z in session.info.routers_zid())
        if links != upstream:
            log.info("router %s: linked to router(s) %s", options.name, links or "none")
            upstream = links
        while (sample := world_sub.try_recv()) is not None:
            alive = sample.kind == zenoh.SampleKind.PUT
            follower.world(alive)
            log.info("router %s: the world %s", options.name, "is up" if alive else "left")
        while (sample := robot_sub.try_recv()) is not None:
            try:
                rid = keys.robot_id_of_alive(sample.key_expr)
            except ProtocolError:
                continue
            if rid in mine:
                follower.robot(rid, sample.kind == zenoh.SampleKind.PUT)
        if follower.over:
            log.info("router %s: the run is over", options.name)
            return ExitCode.OK
        if not follower.world_seen and time.monotonic() > deadline:
            log.error("router %s: the world did not appear at %s within %.0f s", options.name,
                      options.connect, options.wait_world_s)
            return ExitCode.TRANSPORT
        time.sleep(POLL_S)
    log.info("router %s: stopped by a signal", options.name)
    return ExitCode.OK


def run_router(options: RouterOptions) -> int:
    """Run a relay router for one run; returns its exit status."""
    try:
        settings = router_settings(options)
    except ValueError as exc:
        log.error("%s", exc)
        return ExitCode.BAD_INPUT
    with stop_on_signals() as stop:
        try:
            session = open_session(settings)
        except SessionError as exc:
            log.error("router %s: cannot open the Zenoh session on %s: %s", options.name,
                      options.listen, exc)
            return ExitCode.TRANSPORT
        log.info("router %s: run %s, robots %s, listening on %s, dialling %s (%s)",
                 options.name, options.run_id, ",".join(map(str, options.robot_ids)),
                 options.listen, options.connect,
                 "mutual TLS and access control" if options.tls_dir else "plain TCP")
        try:
            code = follow_run(session, options, stop)
        except BaseException:
            close_session(session)
            raise
        if not close_session(session):
            log.error("router %s: session close timed out; leaving without it", options.name)
            logging.shutdown()
            os._exit(code)
        return code


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m world.router``."""
    die_with_launcher()
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s router %(levelname)s %(message)s")
    return run_router(parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
