"""argparse types shared by the process entry points (`python -m agent`, `python -m world`,
`orchestrator compose`).

Each raises `argparse.ArgumentTypeError`, so a bad flag is a usage error (exit status 2)
naming the flag and the value.
"""

from __future__ import annotations

import argparse
import math

from protocol import ProtocolError, validate_run_id


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
