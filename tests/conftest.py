"""Shared test configuration: each directory is a layer, marked by where it lives.

- ``tests/unit``: pure functions and classes, in-process, fast (mirrors the modules);
- ``tests/integration``: lockstep runs of small scenes, the CLI in-process, loopback Zenoh
  sessions; a second or less each;
- ``tests/scenarios``: whole lockstep setups and crowds, with and without link faults,
  seconds to minutes each;
- ``tests/system``: real processes: world and robots over Zenoh, relays, and the CLI's
  commands that start processes (sweep, stress, paper);
- ``tests/docker``: the docker-compose demo.

Plain ``pytest`` runs unit and integration (the fast loop, `testpaths` in pyproject.toml);
``pytest tests`` runs every layer (what `.ci/run` does).

Hypothesis runs under one of two profiles: ``ci`` draws every property test's full count of
examples (`tests.examples.examples`; Hypothesis's default of 100 where a test names none),
``fast`` half of each. The profile is ``HYPOTHESIS_PROFILE`` if set (`.ci/run` sets ``ci``),
else ``ci`` when the session reaches past the fast loop (``pytest tests``, or any path in
scenarios, system or docker) and ``fast`` otherwise.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest
from hypothesis import settings

from tests.examples import CI_EXAMPLES, FAST_EXAMPLES

REPO_ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("unit", "integration", "scenarios", "system", "docker")
FAST_LOOP = ("unit", "integration")
"""The layers plain ``pytest`` runs (`testpaths`)."""

settings.register_profile("ci", max_examples=CI_EXAMPLES)
settings.register_profile("fast", max_examples=FAST_EXAMPLES)


def hypothesis_profile(args: list[str]) -> str:
    """``HYPOTHESIS_PROFILE``, else ``ci`` if any of the session's `args` reaches past the
    fast loop (tests/ itself, a layer outside `FAST_LOOP`, or a path above tests/), else
    ``fast``."""
    chosen = os.environ.get("HYPOTHESIS_PROFILE")
    if chosen:
        return chosen
    tests_dir = REPO_ROOT / "tests"
    for arg in args:
        path = Path(arg.split("::")[0]).resolve()
        if path == tests_dir or tests_dir in path.parents:
            inside = path.relative_to(tests_dir).parts
            if not inside or inside[0] not in FAST_LOOP:
                return "ci"
        elif path in tests_dir.parents:
            return "ci"
    return "fast"


def pytest_configure(config: pytest.Config) -> None:
    """Load the Hypothesis profile before any test module is imported (their example
    counts are read at decoration time)."""
    settings.load_profile(hypothesis_profile(list(config.args)))


def pytest_report_header(config: pytest.Config) -> str:
    """Say which Hypothesis profile the session runs."""
    return f"hypothesis profile: {settings.get_current_profile_name()}"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test with its layer (the directory under tests/ it lives in)."""
    tests_dir = REPO_ROOT / "tests"
    for item in items:
        try:
            layer = Path(item.fspath).resolve().relative_to(tests_dir).parts[0]
        except ValueError:
            continue
        if layer in LAYERS:
            item.add_marker(getattr(pytest.mark, layer))


@pytest.fixture
def repo_root() -> Path:
    """The repository's root directory (where pyproject.toml is)."""
    return REPO_ROOT


@pytest.fixture
def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
