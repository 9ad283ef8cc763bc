"""Process plumbing shared by every process of a run: exit codes, stop on signals, Zenoh
sessions and the parent-death signal.

The robot (`agent.node`), the world (`world.node`), the fleet launcher (`agent.fleet`) and
the orchestrator's process edges all use these; nothing below the runtime layer imports
this module (it imports zenoh).
"""

from __future__ import annotations

import contextlib
import ctypes
import enum
import functools
import logging
import os
import signal
import threading
import time
import zlib
from collections.abc import Callable, Iterable, Iterator, Mapping
from types import FrameType
from typing import TYPE_CHECKING, Any, TypeAlias, overload

import zenoh

if TYPE_CHECKING:
    from eifp_wire import TlsFiles

log = logging.getLogger(__name__)

SampleSubscriber: TypeAlias = zenoh.Subscriber[zenoh.Handler[zenoh.Sample]]
"""A subscriber read by polling (`try_recv`): `declare_subscriber` without a callback."""

CLOSE_TIMEOUT_S = 3.0
"""Wall time `close_session` waits for Zenoh to close before giving up on it."""
RETRY_PAUSE_S = 0.1
"""Wall time between two attempts of `open_session`."""
PR_SET_PDEATHSIG = 1
"""Linux prctl option: the signal a process gets when its parent dies."""
PARENT_PID_ENV = "EIFP_PARENT_PID"
"""Set by a launcher to its pid: the child dies with it (`die_with_launcher`)."""


class ExitCode(enum.IntEnum):
    """Exit status of every eifp-swarm process and of the `orchestrator` CLI.

    One table for all: a robot, the world and the orchestrator give the same number the same
    meaning. The README lists them.
    """

    OK = 0
    """The run completed: every robot arrived, no contact (a robot: it was told to end)."""
    CONTACT = 1
    """The run ended with at least one contact."""
    BAD_INPUT = 2
    """A bad flag, scenario file, configuration or output path; the message names it."""
    INCOMPLETE = 3
    """The time limit came before every robot arrived (no contact)."""
    ROBOT_LOST = 4
    """A robot process was lost during the run (crashed, killed or hung), no contact."""
    WORLD_LOST = 5
    """The world process crashed or vanished (a robot: the world's token disappeared)."""
    TRANSPORT = 6
    """No Zenoh session could be opened or kept (endpoint unreachable, TLS refused)."""
    ERROR = 7
    """An unexpected internal error; the traceback is in the log."""
    INTERRUPTED = 130
    """Stopped by SIGINT, SIGTERM or SIGHUP (`STOP_SIGNALS`)."""

    @classmethod
    def of_run(cls, *, contacts: int, all_arrived: bool, robots_lost: bool,
               interrupted: bool = False) -> ExitCode:
        """The status of a run that ended: a contact outranks a lost robot, which outranks
        an interruption, which outranks a time-out."""
        if contacts > 0:
            return cls.CONTACT
        if robots_lost:
            return cls.ROBOT_LOST
        if interrupted:
            return cls.INTERRUPTED
        return cls.OK if all_arrived else cls.INCOMPLETE

    @classmethod
    def worst(cls, codes: Iterable[int]) -> ExitCode:
        """The worst of several runs' endings (`ENDING_SEVERITY`), OK for none.

        A status outside the table (a child killed by a signal: negative) counts as
        INTERRUPTED, so a batch never reports ERROR unless one of its runs did (and that
        run's log has the traceback).
        """
        worst = cls.OK
        for code in codes:
            known = cls(code) if code in cls._value2member_map_ else cls.INTERRUPTED
            if ENDING_SEVERITY.index(known) > ENDING_SEVERITY.index(worst):
                worst = known
        return worst


ENDING_SEVERITY = (ExitCode.OK, ExitCode.INCOMPLETE, ExitCode.INTERRUPTED, ExitCode.ROBOT_LOST,
                   ExitCode.CONTACT, ExitCode.BAD_INPUT, ExitCode.TRANSPORT, ExitCode.WORLD_LOST,
                   ExitCode.ERROR)
"""Endings from best to worst, for a batch of runs (`ExitCode.worst`): within a run's own
outcomes the order of `ExitCode.of_run` (a contact outranks a lost robot, which outranks
an interruption, which outranks a time-out); then the runs that could not be judged (bad
input, no transport, no world), and last an internal error."""


STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
"""The signals that stop a process cleanly: Ctrl-C, ``kill``/systemd/Docker, and a closed
terminal. Each is handled like SIGINT by every process of a run and the orchestrator."""


@contextlib.contextmanager
def interrupt_on_stop_signals() -> Iterator[None]:
    """Inside the block, SIGTERM and SIGHUP raise `KeyboardInterrupt` in the main thread, as
    SIGINT does: the orchestrator's interrupted-run path (status ``interrupted``, partial
    metrics, exit `ExitCode.INTERRUPTED`) then serves all three. Handlers restored after."""
    previous = {s: signal.signal(s, raise_interrupt) for s in STOP_SIGNALS
                if s != signal.SIGINT}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def raise_interrupt(signum: int, frame: FrameType | None = None) -> None:
    """A signal handler: raise `KeyboardInterrupt` (named after the signal), as SIGINT does."""
    raise KeyboardInterrupt(signal.Signals(signum).name)


class StopFlag:
    """Set by a stop signal (`STOP_SIGNALS`); loops poll it and leave, so sessions and files
    are closed."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self.count = 0

    def __call__(self, signum: int, frame: FrameType | None = None) -> None:
        self.signum = signum
        self.count += 1

    def __bool__(self) -> bool:
        return self.signum is not None


@contextlib.contextmanager
def stop_on_signals(
        signums: tuple[signal.Signals, ...] = STOP_SIGNALS,
) -> Iterator[StopFlag]:
    """Route `signums` to a fresh `StopFlag` inside the block; restore the handlers after.

    Without a handler, SIGTERM would kill a process before it closes its session (and, as
    PID 1 of a container, be ignored); with it, the loop leaves cleanly.
    """
    stop = StopFlag()
    previous = {s: signal.signal(s, stop) for s in signums}
    try:
        yield stop
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


ONE_THREAD_RUNTIME = ("(app: (worker_threads: 1), rx: (handover: app), tx: (handover: app), "
                      "net: (handover: app), acc: (handover: app))")
"""Zenoh's runtimes (``ZENOH_RUNTIME``, RON) folded onto one worker thread. A robot's one
link carries a pose and a command per control period; by default Zenoh runs it on five
runtimes of six threads, and every message wakes two or three of them."""


def use_one_zenoh_thread() -> None:
    """Run this process's Zenoh on one thread (`ONE_THREAD_RUNTIME`), unless the environment
    sets ``ZENOH_RUNTIME`` already. Call before the process opens its first session: Zenoh
    reads the setting once, when it starts its runtimes."""
    os.environ.setdefault("ZENOH_RUNTIME", ONE_THREAD_RUNTIME)


def enqueue_on_receive(put: Callable[[zenoh.Sample], object]
                       ) -> Callable[[zenoh.Sample], object]:
    """A subscriber handler that calls `put(sample)` on the Zenoh thread that received it.

    `put` should be a C-level call that never blocks (``queue.SimpleQueue.put``): it then
    runs no Python frame, and no thread of the process is woken but the one waiting on the
    queue. Zenoh's default for a Python callable runs it on a thread of its own, which a
    sample wakes before it wakes the reader (zenoh-python's ``Callback(indirect=False)``,
    marked unstable: without it, that default).
    """
    try:
        return zenoh.handlers.Callback(put, indirect=False)
    except TypeError:
        return put


class StallWatch:
    """Finds the loop's stalls: wall time in which its thread neither ran nor knowingly waited.

    A process that was stopped (SIGSTOP) or not scheduled at all for a while shows a wall
    gap between two loop iterations that its thread's CPU time and its waits do not explain;
    a long plan (CPU time) or a long nap (a wait) does not. Each wait is counted up to what
    was asked for (`waited`): a nap that a stop stretched past its time-out counts as the
    time-out, the rest as a stall.

    Args:
        wall: the wall clock [s] (`time.monotonic`).
        cpu: this thread's CPU clock [s] (`time.thread_time`).
    """

    def __init__(self, wall: Callable[[], float] = time.monotonic,
                 cpu: Callable[[], float] = time.thread_time) -> None:
        self._wall = wall
        self._cpu = cpu
        self._last: tuple[float, float] | None = None
        self._waited_s = 0.0

    def waited(self, seconds: float, asked_s: float) -> None:
        """The loop blocked `seconds` of wall time on a wait with time-out `asked_s`."""
        self._waited_s += min(max(seconds, 0.0), asked_s)

    def tick(self) -> float:
        """Call at the top of each loop iteration; returns the stall since the previous call
        [s] (wall time minus this thread's CPU time minus the waits; 0 on the first call)."""
        wall, cpu = self._wall(), self._cpu()
        last, waited = self._last, self._waited_s
        self._last, self._waited_s = (wall, cpu), 0.0
        if last is None:
            return 0.0
        return max(0.0, (wall - last[0]) - (cpu - last[1]) - waited)


class SessionError(RuntimeError):
    """No Zenoh session could be opened before the deadline (the message says why)."""


def zenoh_config(settings: Mapping[str, Any]) -> zenoh.Config:
    """A `zenoh.Config` with every (key path -> JSON5 value) of `settings` inserted."""
    conf = zenoh.Config()
    for key, value in settings.items():
        conf.insert_json5(key, value)
    return conf


@overload
def open_session(settings: Mapping[str, Any], *, deadline: float | None = None,
                 stop: None = None) -> zenoh.Session: ...
@overload
def open_session(settings: Mapping[str, Any], *, deadline: float | None = None,
                 stop: StopFlag) -> zenoh.Session | None: ...
def open_session(settings: Mapping[str, Any], *, deadline: float | None = None,
                 stop: StopFlag | None = None) -> zenoh.Session | None:
    """Open a Zenoh session with `settings` (`eifp_wire.transport.session_settings`).

    Args:
        settings: key path -> JSON5 value, inserted into a fresh config.
        deadline: `time.monotonic()` until which a failed open is retried (a router not up
            yet); None: one attempt.
        stop: polled between attempts.

    Returns:
        The session, or None if `stop` was set first.

    Raises:
        SessionError: the last attempt's error, once the deadline has passed.
    """
    conf = zenoh_config(settings)
    last_error = "no attempt"
    while not stop:
        try:
            return zenoh.open(conf)
        except zenoh.ZError as exc:
            last_error = str(exc)
        if deadline is None or time.monotonic() > deadline:
            raise SessionError(last_error)
        time.sleep(RETRY_PAUSE_S)
    return None


def check_tls_files(files: TlsFiles) -> str | None:
    """Why the `eifp_wire.transport.TlsFiles` `files` cannot be used (one missing or
    unreadable), or None.

    Checked before opening: zenoh would otherwise retry a client's connection forever, or
    fail with an unrelated hint."""
    for what, path in (("CA certificate", files.ca), ("certificate", files.cert),
                       ("private key", files.key)):
        if not os.access(path, os.R_OK):
            return f"{what} {path} is missing or unreadable"
    return None


def close_session(session: zenoh.Session, timeout_s: float = CLOSE_TIMEOUT_S) -> bool:
    """Close `session`, waiting at most `timeout_s`; False if the close is still stuck.

    Closing waits for peers to acknowledge (up to 10 s inside zenoh); a hung peer must not
    keep a process from exiting once its work is done.
    """
    done = threading.Event()

    def _close() -> None:
        try:
            session.close()
        except zenoh.ZError as exc:
            log.warning("closing the session: %s", exc)
        finally:
            done.set()

    threading.Thread(target=_close, name="zenoh-close", daemon=True).start()
    return done.wait(timeout_s)


def die_with_parent(parent_pid: int, signum: int = signal.SIGKILL) -> None:
    """Have the kernel send `signum` to this process when its parent dies (Linux).

    Called first thing in a child (`subprocess.Popen(preexec_fn=...)` or after a fork), so
    a SIGKILLed orchestrator leaves no orphaned world or robot. If the parent is already
    gone, exits at once.
    """
    # Not Linux: no prctl; the launcher's teardown of the process group still applies.
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signum))
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(int(ExitCode.ERROR))


def die_with_launcher() -> None:
    """`die_with_parent` if the launcher set `PARENT_PID_ENV` (the orchestrator does)."""
    text = os.environ.get(PARENT_PID_ENV, "")
    if text.isdigit():
        die_with_parent(int(text))


BOOT_ID_PATH = "/proc/sys/kernel/random/boot_id"


@functools.cache
def monotonic_clock_id() -> int:
    """A 31-bit id of this host's `time.monotonic_ns` clock: the kernel's boot id, hashed.

    Processes (and containers) of one host share the clock and so the id; stamps taken on
    hosts with different ids cannot be subtracted. 1 where the boot id cannot be read.
    """
    try:
        with open(BOOT_ID_PATH, encoding="ascii") as f:
            boot = f.read().strip()
    except OSError:
        return 1
    return (zlib.crc32(boot.encode("ascii")) & 0x7FFFFFFF) or 1
