"""Many robot processes from one launch: import and warm up once, then fork one per robot.

    python -m agent.fleet --run R --connect EP --ids 0,1,2 --log-dir DIR
                          [--connect-id 1=tcp/127.0.0.2:7447 ...] [--startup-timeout-s S]

Each robot is still its own OS process with its own Zenoh session, liveliness token, loop
and exit status: the child runs exactly what ``python -m agent`` runs (`agent.node.main`).
The difference is where it comes from. A fresh ``python -m agent`` spends ~0.4 s of CPU on
the interpreter, importing numpy, scipy, osqp and zenoh and planning a first time; 128 of
them starting together keep 2 cores busy for ~25 s. Here the parent does that once (it
plans once with every planner, then `gc.freeze()`), and forks: a child is ready in
milliseconds and shares the parent's pages until it writes to them (copy-on-write), which
also lowers each robot's PSS.

The parent never opens a Zenoh session (a session does not survive a fork; importing the
module is fine: its runtimes start with the first session). A child writes its stdout and
stderr to ``DIR/robot_<id>.log`` and dies with the parent (``PR_SET_PDEATHSIG``). The
parent passes SIGTERM/SIGINT on to the children still running, reaps them all, logs each
exit and exits 0 if every robot did, else the largest robot exit status. With ``--nice N``
the robots run N steps nicer than the parent (a world sharing their machine stays ahead).

Start-up is throttled: at most ``--max-starting`` (`MAX_STARTING`) children are between
their fork and their liveliness token at once; each reports ready through a pipe and the
parent forks the next. Robots forked in one burst all connect, query and warm up at the
same moment, which on a loaded host can starve the router's Zenoh threads past the 1 s
transport lease: the world then drops most of them and they leave (docs/scale.md).

CPU tokens (``--cpu-tokens N``, off by default): the children share a semaphore of N; a
robot holds one while it senses and plans (`agent.node.RobotNode.sense_and_plan`), so at
most N compute at once, each to the end of its cycle, instead of 100 runnable robots
time-sliced against each other (and against the world) when they want more CPU than the
host has. It is off by default: it keeps every robot's lease, but the wait for a token adds
to every late cycle, so more cycles miss their deadline (docs/scale.md).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import logging
import multiprocessing
import os
import select
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

from agent.flags import Parser
from agent.process import PARENT_PID_ENV, STOP_SIGNALS, die_with_launcher, die_with_parent

log = logging.getLogger("fleet")

FORWARDED = STOP_SIGNALS
MAX_STARTING = 8
"""Robots starting at once (connect, fetch the configuration, warm up, declare): 128 started
together starve the router's and each other's Zenoh threads past the 1 s transport lease."""
READY_TIMEOUT_S = 5.0
"""A child that has not reported ready after this long no longer holds up the next fork."""


def _ids(text: str) -> list[int]:
    try:
        ids = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        ids = []
    if not ids or min(ids) < 0 or len(set(ids)) != len(ids):
        raise argparse.ArgumentTypeError(f"expected distinct robot ids >= 0, got {text!r}")
    return ids


def _override(text: str) -> tuple[int, str]:
    rid, sep, endpoint = text.partition("=")
    if not sep or not rid.strip().isdigit() or not endpoint.strip():
        raise argparse.ArgumentTypeError(f"expected ID=ENDPOINT, got {text!r}")
    return int(rid), endpoint.strip()


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="python -m agent.fleet",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--run", required=True, help="run id")
    parser.add_argument("--ids", required=True, type=_ids, help="robot ids, comma-separated")
    parser.add_argument("--connect", required=True, help="router endpoint (tcp/HOST:PORT)")
    parser.add_argument("--connect-id", type=_override, action="append", default=[],
                        metavar="ID=ENDPOINT", help="robot ID connects here instead")
    parser.add_argument("--robot-arg", action="append", default=[], metavar="ARG",
                        help="a further `python -m agent` argument for every robot "
                             "(repeatable; e.g. --robot-arg=--no-plan)")
    parser.add_argument("--log-dir", required=True, type=Path, help="robot_<id>.log go here")
    parser.add_argument("--startup-timeout-s", default="30.0",
                        help="passed to every robot (python -m agent)")
    parser.add_argument("--max-starting", type=int, default=MAX_STARTING,
                        help="robots starting up at once: the next is forked when one has "
                             f"declared its liveliness token (default {MAX_STARTING})")
    parser.add_argument("--cpu-tokens", type=int, default=0,
                        help="robots computing at once (e.g. the number of CPUs; default 0: "
                             "no tokens, every robot competes for the CPU; see docs/scale.md)")
    parser.add_argument("--nice", type=int, default=0,
                        help="robot processes add this to their niceness (>= 0; e.g. 5 keeps "
                             "a world on the same machine ahead of them)")
    parser.add_argument("--tls", default=None, metavar="DIR",
                        help="passed to every robot: mutual TLS with the certificates in DIR")
    return parser


def robot_argv(run_id: str, robot_id: int, endpoint: str, startup_timeout_s: str,
               extra: Sequence[str] = (), tls_dir: str | None = None) -> list[str]:
    """The ``python -m agent`` arguments of one robot."""
    return ["--run", run_id, "--id", str(robot_id), "--connect", endpoint,
            "--startup-timeout-s", startup_timeout_s,
            *(("--tls", tls_dir) if tls_dir else ()), *extra]


def warm_up_planners() -> None:
    """Import every planner and plan once with each (a throwaway robot), before forking."""
    from agent.core.config import PLANNER_NAMES, PlannerConfig
    from agent.core.scenario import RobotSpec
    from agent.node import warm_up
    from eifp_wire import RunConfigMsg

    for k, name in enumerate(PLANNER_NAMES):
        spec = RobotSpec(k, (0.0, 0.0, 0.0), (10.0, 0.0), planner=name)
        warm_up(RunConfigMsg(
            run_id="warm-up", robot=spec, planner=PlannerConfig(), goal_tolerance_m=0.25,
            control_rate_hz=10.0, world_rate_hz=50.0, time_scale=1.0, time_limit_s=10.0,
            cmd_timeout_s=0.5, known_ids=(k, k + 1)), 0.1)


def _child(argv: list[str], log_path: Path, parent_pid: int, nice: int = 0,
           ready_fd: int | None = None, cpu_tokens: object | None = None) -> None:
    """In the forked child: become ``python -m agent`` with its own log; never returns.

    Once its liveliness token is declared the child writes its pid and a newline to
    `ready_fd` and closes it (one write of a few bytes: atomic on a pipe).
    """
    code = 1

    def _ready() -> None:
        if ready_fd is not None:
            with contextlib.suppress(OSError):
                os.write(ready_fd, f"{os.getpid()}\n".encode())
                os.close(ready_fd)

    try:
        die_with_parent(parent_pid)
        os.environ[PARENT_PID_ENV] = str(parent_pid)  # the robot's own check sees the fleet
        if nice > 0:
            os.nice(nice)
        fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        logging.root.handlers.clear()  # the robot sets up its own (agent.node.main)
        from agent.node import main as agent_main

        code = agent_main(argv, on_ready=_ready, cpu_tokens=cpu_tokens)  # type: ignore[arg-type]
    except SystemExit as exc:  # argparse errors
        code = exc.code if isinstance(exc.code, int) else 2
    except BaseException:  # noqa: BLE001 - report, then leave with a failure status
        import traceback

        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


def run_fleet(args: argparse.Namespace) -> int:
    """Warm up, fork one child per robot, pass signals on, reap; returns the exit status.

    At most ``args.max_starting`` children are starting up at once: the next is forked when
    a starting child reports ready (its token is declared), exits, or has been starting
    for `READY_TIMEOUT_S`.
    """
    if args.nice < 0:
        log.error("--nice must be >= 0, got %d", args.nice)
        return 2
    if args.max_starting < 1:
        log.error("--max-starting must be >= 1, got %d", args.max_starting)
        return 2
    n_tokens = args.cpu_tokens
    if n_tokens < 0:
        log.error("--cpu-tokens must be >= 0, got %d", n_tokens)
        return 2
    # A POSIX semaphore in shared memory, inherited by every child (see
    # agent.node.RobotNode.sense_and_plan).
    cpu_tokens = multiprocessing.get_context("fork").Semaphore(n_tokens) if n_tokens else None
    overrides = dict(args.connect_id)
    unknown = sorted(set(overrides) - set(args.ids))
    if unknown:
        log.error("--connect-id for robots not in --ids: %s", unknown)
        return 2
    args.log_dir.mkdir(parents=True, exist_ok=True)
    warm_up_planners()
    gc.collect()
    gc.freeze()  # children never scan (and so never copy) the parent's objects
    parent = os.getpid()
    children: dict[int, int] = {}
    pending: list[int] = []
    starting: dict[int, float] = {}  # pid -> monotonic fork time, until ready
    exited: dict[int, int] = {}  # pid -> wait status, reaped while forking
    ready_r, ready_w = os.pipe()
    os.set_blocking(ready_r, False)
    buffered = b""

    def _wait_for_a_start_slot() -> None:
        nonlocal buffered
        while len(starting) >= args.max_starting and not pending:
            with contextlib.suppress(InterruptedError):
                select.select([ready_r], [], [], 0.05)
            with contextlib.suppress(BlockingIOError, InterruptedError):
                buffered += os.read(ready_r, 4096)
            *lines, buffered = buffered.split(b"\n")
            for line in lines:
                starting.pop(int(line), None)
            while True:  # children that died while starting
                try:
                    pid, status = os.waitpid(-1, os.WNOHANG)
                except ChildProcessError:
                    break
                if pid == 0:
                    break
                exited[pid] = status
                starting.pop(pid, None)
            now = time.monotonic()
            for pid, t0 in list(starting.items()):
                if now - t0 > READY_TIMEOUT_S:
                    starting.pop(pid)

    def _forward(signum: int, frame: FrameType | None) -> None:
        pending.append(signum)
        for pid in list(children):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signum)

    previous = {s: signal.signal(s, _forward) for s in FORWARDED}
    try:
        for rid in args.ids:
            _wait_for_a_start_slot()
            if pending:
                break
            argv = robot_argv(args.run, rid, overrides.get(rid, args.connect),
                              args.startup_timeout_s, args.robot_arg, args.tls)
            # Signals wait until the child has its own handlers (never run _forward there).
            signal.pthread_sigmask(signal.SIG_BLOCK, FORWARDED)
            pid = os.fork()
            if pid == 0:
                for signum in FORWARDED:
                    signal.signal(signum, signal.SIG_DFL)
                signal.pthread_sigmask(signal.SIG_UNBLOCK, FORWARDED)
                os.close(ready_r)
                _child(argv, args.log_dir / f"robot_{rid}.log", parent, args.nice, ready_w,
                       cpu_tokens)
            children[pid] = rid
            starting[pid] = time.monotonic()
            signal.pthread_sigmask(signal.SIG_UNBLOCK, FORWARDED)
        os.close(ready_w)
        os.close(ready_r)
        log.info("fleet: %d robot processes forked, %d CPU tokens", len(children), n_tokens)
        worst = 0
        while children:
            if exited:
                pid, status = exited.popitem()
            else:
                try:
                    pid, status = os.waitpid(-1, 0)
                except ChildProcessError:
                    break
                except InterruptedError:
                    continue
            rid = children.pop(pid, None)
            if rid is None:
                continue
            code = os.waitstatus_to_exitcode(status)
            code = code if code >= 0 else 128 - code
            worst = max(worst, code)
            log.info("fleet: robot %d (pid %d) exited %d", rid, pid, code)
        return worst
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m agent.fleet``."""
    die_with_launcher()
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format="%(asctime)s fleet %(levelname)s %(message)s")
    return run_fleet(build_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
