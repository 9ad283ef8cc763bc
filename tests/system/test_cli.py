"""The `orchestrator` CLI where it starts processes: the real process's exit status, `sweep`
(one subprocess per run), `stress` and `paper` (pools of spawned worker processes). The
in-process commands are in tests/integration/test_cli.py."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import pytest

from agent.process import ExitCode
from orchestrator.cli import main
from tests.integration.test_cli import BAD

pytestmark = pytest.mark.system


def test_bad_scenario_exit_status_of_the_real_process(tmp_path):
    path = tmp_path / "setup_x.yaml"
    path.write_text(BAD)
    proc = subprocess.run([sys.executable, "-m", "orchestrator", "run", str(path)],
                          capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 2
    assert "setup_x.yaml: robots[1].start" in proc.stderr


def test_sweep_runs_subprocesses_and_writes_tables(tmp_path, capsys):
    out = tmp_path / "sweep"
    rc = main(["sweep", "--setups", "a", "--planners", "ifp", "--seeds", "1",
               "--mode", "lockstep", "--jobs", "1", "--out", str(out)])
    assert rc in (0, 1)
    with open(out / "sweep.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 1 and rows[0]["planner"] == "ifp" and rows[0]["exit"] in ("0", "1")
    assert json.loads((out / "sweep.json").read_text())["runs"][0]["setup"] == "a"
    assert (out / "a-ifp-0" / "metrics.json").exists()
    captured = capsys.readouterr()
    assert "a-ifp-0: exit" in captured.err and "ifp" in captured.out
    assert main(["sweep", "--setups", "setup_q", "--planners", "ifp", "--out",
                 str(tmp_path / "bad")]) == 2


def test_sweep_of_runs_that_time_out_exits_incomplete_not_error(tmp_path, capsys):
    # Two robots that cannot arrive in 1 s: every run times out (exit 3), and so does the
    # sweep; it used to exit 7 ("internal error; the traceback is in the log") with none.
    setup = tmp_path / "short.yaml"
    setup.write_text("name: short\ntime_limit: 1\nrobots:\n"
                     "  - {id: 0, start: [-5, 0, 0], goal: [5, 0]}\n"
                     "  - {id: 1, start: [0, -5, 1.5708], goal: [0, 5]}\n")
    out = tmp_path / "sweep"
    rc = main(["sweep", "--setups", str(setup), "--planners", "ifp", "--seeds", "2",
               "--mode", "lockstep", "--jobs", "2", "--out", str(out)])
    assert rc == ExitCode.INCOMPLETE
    rows = list(csv.DictReader((out / "sweep.csv").read_text().splitlines()))
    assert [r["exit"] for r in rows] == ["3", "3"]
    assert "exit 3 (INCOMPLETE), the worst ending of its runs" in capsys.readouterr().err
    run = json.loads((out / rows[0]["dir"] / "run.json").read_text())
    assert (run["status"], run["end_reason"]) == ("timed-out", "time_limit")


def test_stress_writes_table_rows_and_envelope(tmp_path, capsys):
    out = tmp_path / "stress"
    rc = main(["stress", "setup_a", "--sweep", "latency_ms=0,40", "--planners", "ifp",
               "--seeds", "2", "--jobs", "2", "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "largest level at which every run arrived without contact" in text
    assert "max_latency_ms" in text
    with open(out / "stress.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 4 and {r["latency_ms"] for r in rows} == {"0.0", "40.0"}
    content = json.loads((out / "stress.json").read_text())
    assert [t["runs"] for t in content["table"]] == [2, 2]
    assert content["envelope"][0]["planner"] == "ifp"
    run = next(r for r in content["rows"] if r["latency_ms"] == 40.0 and r["seed"] == 1)
    faults = json.loads((out / run["dir"] / "events.jsonl").read_text().splitlines()[0])
    assert faults["faults"]["links"]["jitter_ms"] == pytest.approx(12.0)  # 0.3 x 40 ms
    assert faults["faults"]["seed"] == 1
    # At latency 0 the links change nothing; seed 1's start jitter still tells it from 0.
    zero = {r["seed"]: out / r["dir"] / "scenario.yaml" for r in content["rows"]
            if r["latency_ms"] == 0.0}
    assert zero[0].read_text() != zero[1].read_text()


def test_stress_applies_robot_faults_to_every_run(tmp_path, capsys):
    # setup A, robot 1 killed at 8 s (head-on, 9 m before they meet): every run of the
    # sweep has the kill; robot 0 arrives past the stopped robot, without contact.
    out = tmp_path / "stress"
    rc = main(["stress", "setup_a", "--sweep", "latency_ms=0,50", "--planners", "eifp-mpc",
               "--seeds", "1", "--kill-robot", "1@8", "--out", str(out)])
    assert rc == ExitCode.ROBOT_LOST  # the worst ending of its runs: a robot was lost
    content = json.loads((out / "stress.json").read_text())
    assert len(content["rows"]) == 2
    for row in content["rows"]:
        events = [json.loads(x) for x in
                  (out / row["dir"] / "events.jsonl").read_text().splitlines()]
        lost = [e for e in events if e["kind"] == "robot_lost"]
        assert [(e["robot"], e["t"]) for e in lost] == [(1, pytest.approx(8.0, abs=0.03))]
        assert [e["robot"] for e in events if e["kind"] == "arrived"] == [0]
        assert events[0]["faults"]["process"][0]["kind"] == "kill"
        assert row["contacts"] == 0 and row["success"] is False and row["arrived"] == 1
        assert row["exit"] == ExitCode.ROBOT_LOST and row["lost"] == 1
        # The run ends once robot 0 has arrived: the killed robot does not hold it open.
        assert events[-1]["reason"] == "arrived_or_lost"
    assert [t["arrived_frac"] for t in content["table"]] == [0.5, 0.5]
    # The lost robot is the fault's, not the planner's: the levels are in the envelope.
    assert content["envelope"][0]["max_latency_ms"] == 50.0
    assert "arrived_frac" in capsys.readouterr().out


def test_stress_without_a_sweep_runs_the_base_faults_as_given(tmp_path):
    # No --sweep: one level at --latency-ms (it used to be swept at 0 ms, silently).
    out = tmp_path / "stress"
    rc = main(["stress", "setup_a", "--planners", "ifp", "--seeds", "1", "--latency-ms", "100",
               "--jitter-ms", "30", "--drop", "0.1", "--out", str(out)])
    assert rc == 0
    (row,) = json.loads((out / "stress.json").read_text())["rows"]
    assert row["latency_ms"] == 100.0
    start = json.loads((out / row["dir"] / "events.jsonl").read_text().splitlines()[0])
    assert start["faults"]["links"] == pytest.approx(
        {"latency_ms": 100.0, "jitter_ms": 30.0, "drop": 0.1, "dup": 0.0, "reorder": 0.0,
         "reorder_delay_ms": 50.0})


def test_paper_command_writes_table_i_beside_ours(tmp_path, capsys):
    out = tmp_path / "paper"
    assert main(["paper", "--setups", "setup_a", "--seeds", "1", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "plan ms paper" in printed and "expected shape" in printed
    for name in ("table.txt", "table.csv", "paper.json", "paper_all.png"):
        assert (out / name).stat().st_size > 0, name
    shape = json.loads((out / "paper.json").read_text())["shape"]
    assert [s["setup"] for s in shape] == ["setup_a"]
    assert set(shape[0]["oscillations"]) == {"ifp", "eifp", "eifp-mpc"}
