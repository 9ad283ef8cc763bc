"""System tests (issue 40): `orchestrator run` as users and service managers start and stop it.

- Two runs started at the same moment with the default ``--out`` both complete, each in its
  own directory, each run.json naming its own world's endpoint (they used to share one
  directory and both fail).
- SIGTERM (``kill``, systemd, Docker) and SIGHUP (a closed terminal) end a distributed run
  as Ctrl-C does: exit 130, ``status: interrupted``, partial metrics.json, no orphans (SIGTERM
  used to leave run.json without a status and no metrics, exit 143).
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from agent.process import ExitCode
from tests.system.test_distributed import (
    STARTUP_S,
    processes_of_run,
    read_events,
    wait_for_event,
    write_scenario,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]
RUN_S = 150.0


def head_on(path: Path) -> Path:
    return write_scenario(path, [
        {"id": 0, "start": [-3.0, 0.0, 0.0], "goal": [3.0, 0.0]},
        {"id": 1, "start": [3.0, 0.05, math.pi], "goal": [-3.0, 0.05]},
    ], time_limit_s=40.0)


def orchestrator_run(scenario: Path, cwd: Path, *args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "orchestrator", "run", str(scenario), "--quiet",
         "--time-scale", "2", *args],
        cwd=cwd, env={**os.environ, "PYTHONPATH": str(ROOT)}, start_new_session=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(proc: subprocess.Popen, timeout_s: float = RUN_S) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail("orchestrator run did not finish in time")
    return proc.returncode, out, err


def test_two_runs_started_at_once_with_default_names_both_complete(tmp_path: Path) -> None:
    scenario = head_on(tmp_path / "head_on.yaml")
    procs = [orchestrator_run(scenario, tmp_path) for _ in range(2)]
    results = [finish(p) for p in procs]
    for code, _, err in results:
        assert code == ExitCode.OK, err
    dirs = sorted((tmp_path / "runs").iterdir())
    assert len(dirs) == 2, dirs
    endpoints = []
    for d in dirs:
        info = json.loads((d / "run.json").read_text())
        ready = next(e for e in read_events(d) if e["kind"] == "world_ready")
        assert info["status"] == "complete" and info["zenoh"]["endpoints"] == [ready["endpoint"]]
        assert (d / "metrics.json").is_file() and d.stat().st_mode & 0o777 == 0o700
        endpoints.append(ready["endpoint"])
    assert endpoints[0] != endpoints[1]
    printed = sorted(r[1].strip().splitlines()[-1] for r in results)
    assert printed == sorted(str(Path("runs") / d.name) for d in dirs)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_end_a_distributed_run_as_interrupted(tmp_path: Path,
                                                                 signum: int) -> None:
    scenario = head_on(tmp_path / "head_on.yaml")
    out = tmp_path / "run"
    proc = orchestrator_run(scenario, tmp_path, "--out", str(out))
    run_id = None
    try:
        ready = wait_for_event(out, lambda e: e["kind"] == "world_ready", STARTUP_S)
        run_id = ready["run"]
        wait_for_event(out, lambda e: e["kind"] == "start", STARTUP_S)
        proc.send_signal(signum)
        code, _, err = finish(proc, 60.0)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert code == ExitCode.INTERRUPTED, err
    assert "Traceback" not in err
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted" and info["exit_code"] == ExitCode.INTERRUPTED
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["partial"] is True
    assert run_id is not None and not processes_of_run(run_id), "orphan processes left behind"
