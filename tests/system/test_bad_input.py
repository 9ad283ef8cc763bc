"""Bad input at the processes themselves (issue 40): `python -m world.router` and
`python -m world` refuse in one line with exit 2 (BAD_INPUT). The in-process checks of every
entry point are in tests/integration/test_bad_input.py."""

from __future__ import annotations

import subprocess
import sys

import pytest

from agent.process import ExitCode
from tests.integration.test_bad_input import ROOT, SETUP_D, one_line_error

pytestmark = pytest.mark.system


def test_the_relay_router_process_refuses_tcp_0_with_exit_2():
    proc = subprocess.run([sys.executable, "-m", "world.router", "--run", "r", "--name", "b",
                           "--robots", "1", "--listen", "tcp/0:7447", "--connect",
                           "tcp/127.0.0.1:7447"], capture_output=True, text=True, timeout=60,
                          cwd=ROOT)
    assert proc.returncode == ExitCode.BAD_INPUT
    assert "every interface" in one_line_error(proc.stderr)


def test_world_out_that_is_a_file_is_one_line_exit_2(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    proc = subprocess.run([sys.executable, "-m", "world", "--run", "r", "--scenario",
                           str(SETUP_D), "--out", str(blocker)], capture_output=True, text=True,
                          timeout=60, cwd=ROOT)
    assert proc.returncode == ExitCode.BAD_INPUT
    assert "not a directory" in one_line_error(proc.stderr)
