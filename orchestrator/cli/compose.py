"""`orchestrator compose`: the steps of the docker-compose demo (scenario, await)."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.flags import non_negative_int, positive, run_id
from agent.process import ExitCode
from orchestrator.cli.common import BadInput
from orchestrator.experiments.compose import (
    DEFAULT_CONNECT,
    DEFAULT_RUNS_DIR,
    SetupOptions,
    await_and_report,
    make_certs,
    prepare_scenario,
)

# --------------------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------------------

def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = sub.add_parser(
        "compose", help="steps of the docker-compose demo",
        description="Steps of the docker-compose demo (compose.yaml): the run's certificates, "
                    "the world's scenario and the orchestrator's watch and report.")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--setup", required=True,
                        help="setup_a..setup_g, a family or a scenario .yaml file")
    common.add_argument("--agents", type=int, help="robot count (scalable setups, families)")
    common.add_argument("--planner", help="every robot uses this planner")
    common.add_argument("--seed", type=non_negative_int, default=0, help="seeds the random family")
    common.add_argument("--robots", type=int,
                        help="robot services in the compose file; the scenario must match")
    common.add_argument("--run", required=True, type=run_id, help="run id")
    common.add_argument("--runs-dir", type=Path, default=DEFAULT_RUNS_DIR,
                        help=f"the shared volume (default {DEFAULT_RUNS_DIR})")
    sub = parser.add_subparsers(dest="step", required=True)
    sub.add_parser("scenario", parents=[common],
                   help="write <runs-dir>/<run>/scenario.input.yaml for the world")
    p = sub.add_parser("await", parents=[common],
                       help="wait for the robots and the run's end, then write the report")
    p.add_argument("--connect", default=DEFAULT_CONNECT,
                   help=f"the world's router (default {DEFAULT_CONNECT})")
    p.add_argument("--startup-timeout-s", type=positive, default=300.0,
                   help="wall deadline for the world to come up")
    p.add_argument("--time-scale", type=positive, default=1.0,
                   help="the world's sim seconds per wall second (sizes the wait)")
    p.add_argument("--live", action="store_true",
                   help="serve the run live to Foxglove (WebSocket) while it runs")
    p.add_argument("--live-port", type=int, default=8765, help="port of the live view")
    p.add_argument("--live-host", default="127.0.0.1",
                   help="address the live view binds (0.0.0.0 in a container whose port is "
                        "published)")
    p.add_argument("--tls", type=Path, default=None, metavar="DIR",
                   help="mutual TLS with DIR/ca.pem, DIR/orchestrator.pem, DIR/orchestrator.key")
    c = sub.add_parser("certs", help="the run's CA and certificates, one directory per service")
    c.add_argument("--run", required=True, type=run_id, help="run id")
    c.add_argument("--robots", required=True, type=int, help="robot services (ids 0..N-1)")
    c.add_argument("--out", required=True, type=Path,
                   help="<out>/<cn>/ for world, orchestrator, observer, robot-<id>")
    c.add_argument("--world-host", action="append", default=None,
                   help="a name clients dial the world by (default: world)")
    c.add_argument("--relay", action="append", type=_relay_hosts, default=[],
                   metavar="NAME[=HOST,...]",
                   help="a relay router's certificate router-NAME, for the names its host is "
                        "dialled by (always router-NAME, localhost, 127.0.0.1); repeatable")
    parser.set_defaults(func=run)


def _relay_hosts(text: str) -> tuple[str, tuple[str, ...]]:
    """``NAME[=HOST,...]`` of ``compose certs --relay``."""
    from eifp_wire import router_cn

    name, _, hosts = text.partition("=")
    try:
        router_cn(name)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc
    return name, tuple(h.strip() for h in hosts.split(",") if h.strip())


def run(args: argparse.Namespace) -> int:
    """``orchestrator compose STEP ...``; returns the exit status."""
    if args.step == "certs":
        if not 0 < args.robots <= 4096:
            raise BadInput(f"--robots: expected 1..4096, got {args.robots}")
        make_certs(args.run, args.robots, args.out, tuple(args.world_host or ("world",)),
                   relays=dict(args.relay))
        return ExitCode.OK
    options = SetupOptions(setup=args.setup, agents=args.agents, planner=args.planner,
                           seed=args.seed, robots=args.robots, run_id=args.run,
                           runs_dir=args.runs_dir)
    if args.step == "scenario":
        prepare_scenario(options)
        return ExitCode.OK
    live = (args.live_host, args.live_port) if args.live else None
    return await_and_report(options, args.connect, args.startup_timeout_s, args.time_scale,
                            args.tls, live=live)
