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
robot holds one while it senses and plans (`agent.node.cpu_token`), so at
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
from typing import TYPE_CHECKING

from agent.flags import Parser
from agent.process import PARENT_PID_ENV, STOP_SIGNALS, die_with_launcher, die_with_parent

if TYPE_CHECKING:  # the child imports agent.node itself, after the fork
    from agent.node import CpuTokens

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
    from agent.startup import warm_up
    from eifp_wire import RunConfigMsg

    for k, name in enumerate(PLANNER_NAMES):
        spec = RobotSpec(k, (0.0, 0.0, 0.0), (10.0, 0.0), planner=name)
        warm_up(RunConfigMsg(
            run_id="warm-up", robot=spec, planner=PlannerConfig(), goal_tolerance_m=0.25,
            control_rate_hz=10.0, world_rate_hz=50.0, time_scale=1.0, time_limit_s=10.0,
            cmd_timeout_s=0.5, known_ids=(k, k + 1)), 0.1)


def _child(argv: list[str], log_path: Path, parent_pid: int, nice: int = 0,
           ready_fd: int | None = None, cpu_tokens: CpuTokens | None = None) -> None:
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

        code = agent_main(argv, on_ready=_ready, cpu_tokens=cpu_tokens)
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


def _bad_args(args: argparse.Namespace) -> str | None:
    """What is wrong with the fleet's arguments, or None."""
    if args.nice < 0:
        return f"--nice must be >= 0, got {args.nice}"
    if args.max_starting < 1:
        return f"--max-starting must be >= 1, got {args.max_starting}"
    if args.cpu_tokens < 0:
        return f"--cpu-tokens must be >= 0, got {args.cpu_tokens}"
    unknown = sorted(set(dict(args.connect_id)) - set(args.ids))
    if unknown:
        return f"--connect-id for robots not in --ids: {unknown}"
    return None


class _StartSlots:
    """The children between their fork and their ready report, at most `limit` at once.

    A child reports ready by writing its pid and a newline to `ready_w` (`_child`); one that
    exits, or has been starting for `READY_TIMEOUT_S`, frees its slot too.
    """

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.starting: dict[int, float] = {}  # pid -> monotonic fork time, until ready
        self.exited: dict[int, int] = {}  # pid -> wait status, reaped while forking
        self.ready_r, self.ready_w = os.pipe()
        os.set_blocking(self.ready_r, False)
        self._buffered = b""

    def wait(self, pending: list[int]) -> None:
        """Until a slot is free or a signal is `pending`."""
        while len(self.starting) >= self.limit and not pending:
            with contextlib.suppress(InterruptedError):
                select.select([self.ready_r], [], [], 0.05)
            with contextlib.suppress(BlockingIOError, InterruptedError):
                self._buffered += os.read(self.ready_r, 4096)
            *lines, self._buffered = self._buffered.split(b"\n")
            for line in lines:
                self.starting.pop(int(line), None)
            self._reap_starting()
            now = time.monotonic()
            for pid, t0 in list(self.starting.items()):
                if now - t0 > READY_TIMEOUT_S:
                    self.starting.pop(pid)

    def _reap_starting(self) -> None:
        """Reap the children that died while starting (their status is kept for later)."""
        while True:
            try:
                pid, status = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                return
            if pid == 0:
                return
            self.exited[pid] = status
            self.starting.pop(pid, None)

    def started(self, pid: int) -> None:
        self.starting[pid] = time.monotonic()

    def close(self) -> None:
        os.close(self.ready_w)
        os.close(self.ready_r)


def _fork(argv: list[str], log_path: Path, parent: int, nice: int, slots: _StartSlots,
          cpu_tokens: CpuTokens | None) -> int:
    """Fork one robot process; returns its pid, with the forwarded signals still blocked
    (the caller unblocks them once it knows the child, so that a signal reaches it too).
    In the child the signals wait until it has its own handlers (`_forward` never runs
    there); the child never returns."""
    signal.pthread_sigmask(signal.SIG_BLOCK, FORWARDED)
    pid = os.fork()
    if pid == 0:
        for signum in FORWARDED:
            signal.signal(signum, signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, FORWARDED)
        os.close(slots.ready_r)
        _child(argv, log_path, parent, nice, slots.ready_w, cpu_tokens)
    return pid


def _reap(children: dict[int, int], exited: dict[int, int]) -> int:
    """Wait for every child (those in `exited` already are); returns the largest robot exit
    status (128 + N for a robot killed by signal N)."""
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


def run_fleet(args: argparse.Namespace) -> int:
    """Warm up, fork one child per robot, pass signals on, reap; returns the exit status.

    At most ``args.max_starting`` children are starting up at once: the next is forked when
    a starting child reports ready (its token is declared), exits, or has been starting
    for `READY_TIMEOUT_S`.
    """
    problem = _bad_args(args)
    if problem:
        log.error("%s", problem)
        return 2
    # A POSIX semaphore in shared memory, inherited by every child (see agent.node.cpu_token).
    cpu_tokens = (multiprocessing.get_context("fork").Semaphore(args.cpu_tokens)
                  if args.cpu_tokens else None)
    overrides = dict(args.connect_id)
    args.log_dir.mkdir(parents=True, exist_ok=True)
    warm_up_planners()
    gc.collect()
    gc.freeze()  # children never scan (and so never copy) the parent's objects
    parent = os.getpid()
    children: dict[int, int] = {}
    pending: list[int] = []
    slots = _StartSlots(args.max_starting)

    def _forward(signum: int, frame: FrameType | None) -> None:
        pending.append(signum)
        for pid in list(children):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signum)

    previous = {s: signal.signal(s, _forward) for s in FORWARDED}
    try:
        for rid in args.ids:
            slots.wait(pending)
            if pending:
                break
            argv = robot_argv(args.run, rid, overrides.get(rid, args.connect),
                              args.startup_timeout_s, args.robot_arg, args.tls)
            pid = _fork(argv, args.log_dir / f"robot_{rid}.log", parent, args.nice, slots,
                        cpu_tokens)
            children[pid] = rid
            slots.started(pid)
            signal.pthread_sigmask(signal.SIG_UNBLOCK, FORWARDED)
        slots.close()
        log.info("fleet: %d robot processes forked, %d CPU tokens", len(children),
                 args.cpu_tokens)
        return _reap(children, slots.exited)
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
