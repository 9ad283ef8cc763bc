"""Command-line flags shared by every entry point (`python -m agent`, `python -m world`,
`orchestrator ...`): argparse types and the one definition of the link-fault flags.

Each raises `argparse.ArgumentTypeError`, so a bad flag is a usage error (exit status 2)
naming the flag and the value. Every entry point builds its parser with `Parser`: a usage
error is one line (the value cut to `MAX_SHOWN_CHARS`), never a traceback.
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import re
import socket
import sys
from typing import NoReturn

from eifp_wire import ProtocolError, router_cn, validate_run_id, validate_zid
from world.sim.link import LinkFaults

MAX_SHOWN_CHARS = 200
"""A usage error's message is cut to this many characters (a flag's value may be huge)."""
USAGE_ERROR = 2
"""Exit status of a usage error: `agent.process.ExitCode.BAD_INPUT` (not imported here:
this module stays free of zenoh)."""


class FlagError(ValueError):
    """Flags a process refuses together, each valid on its own (plain TCP on every interface,
    ``--relay`` without ``--tls`` ...): `flag` names the one at fault, the message says why.
    The world records it in its ``end`` event (``reason`` bad_input, ``flag``)."""

    def __init__(self, flag: str, message: str) -> None:
        super().__init__(message)
        self.flag = flag


class Parser(argparse.ArgumentParser):
    """An `argparse.ArgumentParser` whose usage errors are one line on stderr and exit
    status 2 (BAD_INPUT): ``<prog>: error: <message> (see --help)``. Subparsers are made
    of the same class."""

    def error(self, message: str) -> NoReturn:
        message = " ".join(message.split())
        if len(message) > MAX_SHOWN_CHARS:
            message = message[:MAX_SHOWN_CHARS - 3] + "..."
        sys.stderr.write(f"{self.prog}: error: {message} (see --help)\n")
        sys.exit(USAGE_ERROR)


def non_negative_int(text: str) -> int:
    """An integer >= 0 (seeds)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return value


_ENDPOINT_RE = re.compile(r"(tcp|tls)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):([0-9]{1,5})")


def endpoint(text: str) -> str:
    """A Zenoh endpoint ``tcp/HOST:PORT`` or ``tls/HOST:PORT`` (HOST a name, an IPv4
    address or a bracketed IPv6 address; PORT 0..65535), returned unchanged."""
    m = _ENDPOINT_RE.fullmatch(text)
    ok = m is not None and int(m.group(3)) <= 65535
    if ok and m is not None and m.group(2).startswith("["):
        try:
            ipaddress.IPv6Address(m.group(2)[1:-1])
        except ValueError:
            ok = False
    if not ok:
        raise argparse.ArgumentTypeError(
            f"expected tcp/HOST:PORT or tls/HOST:PORT (e.g. tcp/127.0.0.1:7447), got {text!r}")
    return text


def endpoint_host(text: str) -> str:
    """The host of ``proto/HOST:PORT`` (brackets of an IPv6 literal removed)."""
    return text.partition("/")[2].rpartition(":")[0].strip("[]")


def every_interface(text: str) -> bool:
    """Whether listening on the endpoint `text` listens on every interface: its host is an
    unspecified address however spelt (``0.0.0.0``, ``0``, ``::``, ``[::0]``,
    ``[0:0:0:0:0:0:0:0]``, ``0x0``, ...) or a name that resolves to one. A name that does not
    resolve counts as every interface too: nothing says where it would listen."""
    host = endpoint_host(text)
    try:
        return _unspecified(host)
    except ValueError:
        pass
    try:  # inet_aton's spellings ("0", "0x0", "0.0") and names, as the OS resolves them
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        return True
    return any(_unspecified(str(info[4][0]).split("%")[0]) for info in infos)


def unspecified_literal(host: str) -> bool:
    """Whether `host` is an IP literal of every interface (no name is resolved: False for
    names, which may resolve only on another host)."""
    try:
        return _unspecified(host)
    except ValueError:
        return False


def _unspecified(address: str) -> bool:
    """Whether the IP literal `address` is unspecified (IPv4-mapped ``::ffff:0.0.0.0``
    too); ValueError if it is not an IP literal."""
    ip = ipaddress.ip_address(address)
    mapped = getattr(ip, "ipv4_mapped", None)
    return ip.is_unspecified or (mapped is not None and mapped.is_unspecified)


def positive(text: str) -> float:
    """A finite number > 0."""
    value = float(text)
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def non_negative(text: str) -> float:
    """A finite number >= 0."""
    value = float(text)
    if not (math.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text!r}")
    return value


def probability(text: str) -> float:
    """A number in [0, 1]."""
    value = non_negative(text)
    if value > 1.0:
        raise argparse.ArgumentTypeError(f"must be a probability in [0, 1], got {text!r}")
    return value


def run_id(text: str) -> str:
    """A run id that is safe in a key expression and a directory name."""
    try:
        return validate_run_id(text)
    except ProtocolError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def positive_int(text: str) -> int:
    """An integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return value


def robot_ids(text: str) -> tuple[int, ...]:
    """Distinct robot ids >= 0: comma-separated ids or ranges, e.g. ``2,3`` or ``8-15,20``."""
    ids: list[int] = []
    try:
        for part in (p.strip() for p in text.split(",")):
            lo, sep, hi = part.partition("-")
            ids += range(int(lo), int(hi) + 1) if sep else [int(part)]
    except ValueError:
        ids = []
    if not ids or min(ids) < 0 or len(set(ids)) != len(ids):
        raise argparse.ArgumentTypeError(f"expected distinct robot ids >= 0 (e.g. 2,3 or 8-15), "
                                         f"got {text!r}")
    return tuple(ids)


def relay(text: str) -> tuple[str, tuple[int, ...]]:
    """``NAME=IDS``: the relay router ``router-<NAME>`` carries robots IDS (`robot_ids`)."""
    name, sep, ids = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected NAME=IDS (e.g. b=2,3), got {text!r}")
    try:
        router_cn(name)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc
    return name, robot_ids(ids)


def zid(text: str) -> str:
    """A Zenoh session id: 1..32 lowercase hex digits, no leading zero."""
    try:
        return validate_zid(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def count_list(text: str, minimum: int, what: str, example: str) -> list[int]:
    """A comma-separated list of whole numbers, each >= `minimum`, named `what` in the
    error (e.g. "robot counts", with `example` "2,8,16")."""
    try:
        counts = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        counts = []
    if not counts or min(counts) < minimum:
        raise argparse.ArgumentTypeError(f"expected {what} >= {minimum} (e.g. {example}), "
                                         f"got {text!r}")
    return counts


def robot_counts(text: str) -> list[int]:
    """A comma-separated list of robot counts, each >= 2 (bench, scale)."""
    return count_list(text, 2, "robot counts", "2,8,16")


def shelf_rows(text: str) -> list[int]:
    """A comma-separated list of shelf row counts, each >= 1 (bench --routes)."""
    return count_list(text, 1, "shelf row counts", "2,8,14")


def add_link_fault_flags(parser: argparse.ArgumentParser, what: str) -> argparse._ArgumentGroup:
    """The link-fault flags (``--latency-ms``, ``--jitter-ms``, ``--drop``, ``--dup``,
    ``--reorder``), validated, in a group titled for `what` ("the pose link", ...).

    `link_faults` turns the parsed values into a `world.sim.link.LinkFaults`.
    """
    group = parser.add_argument_group(f"injected faults on {what} (sim time)")
    group.add_argument("--latency-ms", type=non_negative, default=0.0,
                       help="fixed delay [ms]")
    group.add_argument("--jitter-ms", type=non_negative, default=0.0,
                       help="uniform jitter half-width [ms] (100 +- 30: --jitter-ms 30)")
    group.add_argument("--drop", type=probability, default=0.0, help="loss probability")
    group.add_argument("--dup", type=probability, default=0.0,
                       help="duplication probability")
    group.add_argument("--reorder", type=probability, default=0.0,
                       help="probability a message is held back (overtaken by later ones)")
    return group


def link_faults(args: argparse.Namespace) -> LinkFaults:
    """The `LinkFaults` of the flags `add_link_fault_flags` declared."""
    return LinkFaults(latency_ms=args.latency_ms, jitter_ms=args.jitter_ms, drop=args.drop,
                      dup=args.dup, reorder=args.reorder)
