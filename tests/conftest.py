"""Shared test configuration: each directory is a layer, marked by where it lives.

- ``tests/unit``: pure functions and classes, in-process, fast (mirrors the modules);
- ``tests/integration``: lockstep runs, the CLI in-process, loopback Zenoh sessions;
- ``tests/scenarios``: whole lockstep scenarios under faults, tens of seconds each;
- ``tests/system``: real world and robot processes over Zenoh;
- ``tests/docker``: the docker-compose demo.

Plain ``pytest`` runs unit and integration (the fast loop, `testpaths` in pyproject.toml);
``pytest tests`` runs every layer (what `.ci/run` does).
"""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("unit", "integration", "scenarios", "system", "docker")


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
