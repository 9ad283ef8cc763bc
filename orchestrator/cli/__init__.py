"""The `orchestrator` command line: one dispatch table, one module per subcommand.

Every subcommand module has `add_parser(subparsers)` and `run(args) -> int`. Exit statuses
are `agent.process.ExitCode` (listed in the README).
"""

from __future__ import annotations

import argparse
import io
import logging
import sys
import threading
import traceback
from collections.abc import Callable, Sequence
from types import ModuleType

from agent.files import UnsafePathError
from agent.flags import Parser
from agent.process import ExitCode, interrupt_on_stop_signals
from agent.security import PkiError
from orchestrator.cli import (
    bench,
    benchmark,
    catalog,
    compose,
    paper,
    report,
    run,
    scale,
    stress,
    sweep,
)
from orchestrator.cli.common import BadInput
from world.scenario_file import ScenarioError

COMMANDS: dict[str, ModuleType] = {
    "list": catalog,
    "run": run,
    "sweep": sweep,
    "stress": stress,
    "report": report,
    "paper": paper,
    "bench": bench,
    "benchmark": benchmark,
    "scale": scale,
    "compose": compose,
}
"""Subcommand name -> its module (in the order `orchestrator --help` lists them)."""


def build_parser() -> argparse.ArgumentParser:
    """The parser of every subcommand in `COMMANDS`."""
    parser = Parser(
        prog="orchestrator",
        description="Run, sweep and report decentralised multi-robot collision avoidance "
                    "(IFP, eIFP, eIFP-MPC, ORCA).")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in COMMANDS.values():
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `orchestrator` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                            format="%(asctime)s orchestrator %(levelname)s %(message)s")
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return int(exc.code or 0)
    args.argv = argv
    if threading.current_thread() is not threading.main_thread():
        return guarded(args.func, args)
    with interrupt_on_stop_signals():  # SIGTERM, SIGHUP: as Ctrl-C (exit 130, partial run)
        return guarded(args.func, args)


MAX_ERROR_CHARS = 300
"""A bad-input message is cut to this many characters, on one line."""


def one_line(text: str) -> str:
    """`text` on one line, cut to `MAX_ERROR_CHARS`."""
    text = " ".join(text.split())
    return text if len(text) <= MAX_ERROR_CHARS else text[:MAX_ERROR_CHARS - 3] + "..."


def guarded(func: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run a subcommand and map its failure to an exit status (a traceback only for bugs)."""
    try:
        return int(func(args))
    except (ScenarioError, BadInput, PkiError, UnsafePathError) as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return ExitCode.BAD_INPUT
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return ExitCode.INTERRUPTED
    except Exception as exc:  # noqa: BLE001 - the CLI's last line: report, exit ERROR
        buf = io.StringIO()
        traceback.print_exc(file=buf)
        print(buf.getvalue().rstrip(), file=sys.stderr)
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return ExitCode.ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
