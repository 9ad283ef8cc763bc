"""The `orchestrator` CLI: list, run (lockstep and the distributed glue), exit statuses,
sweep, report and the bench hook."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from agent.process import ExitCode
from orchestrator.cli import main

METRIC_KEYS = ("robots", "arrived", "success", "contacts", "min_gap_m", "path_ratio_mean",
               "time_ratio_mean", "oscillations_per_robot", "side_flips_per_robot",
               "plan_ms_p50", "plan_ms_p99", "sim_latency_ms_p50", "sim_latency_ms_p99",
               "deadline_miss_rate", "per_robot")
SMALL = str(Path(__file__).parent / "data" / "crossing_6m.yaml")
"""Two robots crossing, 6 m each: a whole run of about 6 s of sim time, for the tests that
need a run but not a particular setup."""
BAD = """\
name: bad
time_limit: 60
robots:
  - {id: 0, start: [0, 0, 0], goal: [5, 0]}
  - {id: 1, start: [0, 5], goal: [5, 5]}
"""


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory) -> Path:
    """Two lockstep runs of setup_a (ifp, seeds 0 and 1 with start jitter)."""
    root = tmp_path_factory.mktemp("runs")
    for seed in (0, 1):
        rc = main(["run", "setup_a", "--mode", "lockstep", "--planner", "ifp", "--seed",
                   str(seed), "--start-jitter-m", "0.5", "--out", str(root / f"s{seed}"),
                   "--quiet"])
        assert rc in (0, 1)
    return root


def test_list_shows_setups_families_and_planners(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in ("setup_a", "setup_g", "circle", "crossing", "random", "eifp-mpc", "orca"):
        assert name in out


def test_bad_scenario_exits_2_naming_file_and_field(tmp_path, capsys):
    path = tmp_path / "setup_x.yaml"
    path.write_text(BAD)
    assert main(["run", str(path), "--mode", "lockstep"]) == 2
    err = capsys.readouterr().err
    assert "setup_x.yaml" in err and "robots[1].start: expected [x, y, theta]" in err


@pytest.mark.parametrize(("argv", "message"), [
    (["run", "setup_z"], "unknown setup or family"),
    (["run", "setup_a", "--agents", "5"], "fixed size of 2 robots"),
    (["run", "setup_a", "--start-jitter-m", "-1"], "jitter must be >= 0"),
    (["run", "setup_a", "--time-scale", "0"], "--time-scale: must be > 0"),
])
def test_bad_options_exit_2(argv, message, capsys):
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_usage_errors_exit_2(capsys):
    assert main(["run", "setup_a", "--planner", "rrt"]) == 2
    assert main([]) == 2


def test_lockstep_run_of_setup_a_writes_everything(two_runs, capsys):
    run = two_runs / "s0"
    for name in ("scenario.yaml", "trajectory.csv", "commands.csv", "events.jsonl",
                 "metrics.json", "run.json", "trajectory.png"):
        assert (run / name).stat().st_size > 0, name
    metrics = json.loads((run / "metrics.json").read_text())
    for key in METRIC_KEYS:
        assert key in metrics, key
    assert metrics["robots"] == 2 and len(metrics["per_robot"]) == 2
    info = json.loads((run / "run.json").read_text())
    assert info["scenario"] == "setup_a" and info["planner"] == "ifp" and info["seed"] == 0
    # the numerics' versions, which a lockstep run's numbers depend on
    import numpy
    import osqp
    assert info["versions"]["numpy"] == numpy.__version__
    assert info["versions"]["osqp"] == osqp.__version__
    assert set(info["versions"]) == {"python", "numpy", "scipy", "osqp", "pyrvo"}
    # ... and the processor: numpy picks its SIMD kernels on it at run time
    assert set(info["cpu"]) == {"model", "machine", "numpy_simd"}
    assert info["cpu"]["machine"] and isinstance(info["cpu"]["numpy_simd"], list)


def test_run_exit_status_follows_success_and_prints_summary(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["run", SMALL, "--mode", "lockstep", "--planner", "ifp", "--out", str(out)])
    captured = capsys.readouterr()
    success = json.loads((out / "metrics.json").read_text())["success"]
    assert rc == (0 if success else 1)
    assert "robots arrived" in captured.out and str(out) in captured.out
    assert "crossing_6m ifp lockstep" in captured.err  # the progress line
    # The same directory again is refused rather than mixed.
    assert main(["run", SMALL, "--mode", "lockstep", "--out", str(out)]) == 2


def test_distributed_mode_calls_run_distributed_and_computes_metrics(tmp_path, monkeypatch,
                                                                     capsys):
    from orchestrator.experiments import distributed
    from orchestrator.experiments.lockstep import run_lockstep
    from world.scenario_file import load_scenario

    calls = {}

    def fake(scenario_path, out_dir, run_id, *, rate_hz, time_scale, on_progress, faults,
             live, tls, tls_ca, robot_launcher):
        calls.update(path=Path(scenario_path), run_id=run_id, rate_hz=rate_hz,
                     time_scale=time_scale, faults=faults, live=live, tls=tls, tls_ca=tls_ca,
                     launcher=robot_launcher)
        run_lockstep(load_scenario(scenario_path), out_dir, on_progress=on_progress)
        (Path(out_dir) / "metrics.json").unlink()  # the world does not write metrics
        return 0

    monkeypatch.setattr(distributed, "run_distributed", fake)
    out = tmp_path / "dist"
    rc = main(["run", SMALL, "--planner", "ifp", "--time-scale", "4", "--out", str(out)])
    assert rc in (0, 1)
    assert calls["tls"] is True and calls["tls_ca"] is None  # secure by default
    assert calls["time_scale"] == 4.0 and calls["rate_hz"] == 50.0
    assert calls["faults"] is None and calls["live"] is None  # no fault flag, no --live
    assert calls["launcher"] == "spawn"  # two robots: one process each
    assert calls["path"].parent == out and calls["run_id"].startswith("crossing_6m-0-")
    assert json.loads((out / "metrics.json").read_text())["robots"] == 2
    run_json = json.loads((out / "run.json").read_text())
    assert run_json["mode"] == "distributed" and run_json["launcher"] == "spawn"


def test_distributed_world_crash_without_files_exits_world_lost(tmp_path, monkeypatch, capsys):
    from orchestrator.experiments import distributed

    monkeypatch.setattr(distributed, "run_distributed", lambda *a, **k: 139)
    assert main(["run", "setup_a", "--out", str(tmp_path / "x")]) == ExitCode.WORLD_LOST
    assert "world exit status 139" in capsys.readouterr().err


def test_report_over_two_runs_prints_table_and_writes_plots(two_runs, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["report", str(two_runs / "s0"), str(two_runs / "s1"), "--paper",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "2 runs" in text and "setup_a" in text and "ifp" in text
    assert "±" in text  # mean ± std over the two seeds
    assert "54.286" in text and "502.26" in text  # the paper's Table I
    assert "oscillations per robot by cause" in text and "threat_switch" in text
    group = json.loads((out / "report.json").read_text())["groups"][0]
    assert sum(group["reversal_causes_per_robot"].values()) == pytest.approx(
        group["oscillations_per_robot"]["mean"])
    for name in ("report_plan_ms_mean.png", "report_oscillations_per_robot.png",
                 "report_path_length_mean_m.png", "report_time_to_goal_mean_s.png",
                 "report_all.png", "report.csv", "report.json"):
        assert (out / name).stat().st_size > 0, name
    with open(out / "report.csv") as f:
        rows = list(csv.DictReader(f))
    assert rows[0]["setup"] == "setup_a" and rows[0]["runs"] == "2"


def test_report_flags_identical_runs_and_writes_under_runs_by_default(two_runs, tmp_path,
                                                                    monkeypatch, capsys):
    import shutil

    shutil.copytree(two_runs / "s0", tmp_path / "copy" / "s0")  # the same run twice
    monkeypatch.chdir(tmp_path)
    assert main(["report", str(two_runs / "s0"), str(tmp_path / "copy")]) == 0
    text = capsys.readouterr().out
    assert "warning: setup_a ifp: 2 runs but only 1 distinct trajectories" in text
    # Several DIRs and no --out: a new directory under the git-ignored runs/, not ./report.
    assert not (tmp_path / "report").exists()
    (written,) = (tmp_path / "runs").glob("report-*")
    saved = json.loads((written / "report.json").read_text())
    assert saved["identical_runs"] == [{"setup": "setup_a", "planner": "ifp", "distinct": 1,
                                        "runs": 2}]
    # Two different seeds (with start jitter) are not flagged.
    assert main(["report", str(two_runs), "--out", str(tmp_path / "r2")]) == 0
    assert "warning" not in capsys.readouterr().out


def test_every_seed_changes_a_run_of_a_fixed_setup(tmp_path, capsys):
    # A scenario file does not draw from the seed: a nonzero seed gets a small start jitter drawn
    # from it (`common.SEED_JITTER_M`), so seeds 1 and 2 differ; seed 0 runs it as written.
    from orchestrator.cli.common import SEED_JITTER_M

    for seed in (0, 1, 2):
        assert main(["run", SMALL, "--mode", "lockstep", "--planner", "ifp", "--seed",
                     str(seed), "--out", str(tmp_path / f"s{seed}"), "--quiet"]) in (0, 1)
    err = capsys.readouterr().err
    assert f"seed 1 moves each start by up to {SEED_JITTER_M:g} m" in err
    assert "seed 0" not in err
    jitter = [json.loads((tmp_path / f"s{s}" / "run.json").read_text())["start_jitter_m"]
              for s in (0, 1, 2)]
    assert jitter == [0.0, SEED_JITTER_M, SEED_JITTER_M]
    starts = [(tmp_path / f"s{s}" / "trajectory.csv").read_text().splitlines()[1:3]
              for s in (0, 1, 2)]
    assert len({tuple(x) for x in starts}) == 3, starts
    # --start-jitter-m 0 still runs a seed as written; a seeded family gets no jitter.
    assert main(["run", SMALL, "--mode", "lockstep", "--planner", "ifp", "--seed", "1",
                 "--start-jitter-m", "0", "--out", str(tmp_path / "s1as"), "--quiet"]) in (0, 1)
    assert (tmp_path / "s1as" / "trajectory.csv").read_bytes() == \
        (tmp_path / "s0" / "trajectory.csv").read_bytes()
    from orchestrator.cli.common import start_jitter_m

    assert start_jitter_m("random", 3, None) == 0.0  # its seed already moves every robot
    assert start_jitter_m("setup_g", 3, None) == SEED_JITTER_M
    assert start_jitter_m("setup_g", 3, 0.2) == 0.2


def test_report_of_an_empty_directory_exits_2(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert main(["report", str(tmp_path / "missing")]) == 2


def test_unexpected_errors_exit_error(monkeypatch, capsys):
    from orchestrator.cli import catalog

    def boom(args):
        raise RuntimeError("kaput")

    monkeypatch.setattr(catalog, "run", boom)  # build_parser binds the module's function
    assert main(["list"]) == ExitCode.ERROR
    assert "RuntimeError: kaput" in capsys.readouterr().err


# --- fault flags and stress -----------------------------------------------------------------

def test_run_with_fault_flags_in_lockstep_records_the_plan(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["run", SMALL, "--mode", "lockstep", "--planner", "ifp", "--quiet",
               "--latency-ms", "50", "--jitter-ms", "15", "--drop", "0.1", "--slow-robot", "0:20",
               "--out", str(out)])
    assert rc == 0
    faults = json.loads((out / "run.json").read_text())["faults"]
    assert faults["links"]["latency_ms"] == 50.0 and faults["links"]["drop"] == 0.1
    assert faults["timing"]["0"]["plan_delay_ms"] == 20.0
    start = json.loads((out / "events.jsonl").read_text().splitlines()[0])
    assert start["faults"]["links"]["jitter_ms"] == 15.0
    assert json.loads((out / "metrics.json").read_text())["sim_latency_ms_p50"] >= 100.0


@pytest.mark.parametrize("flags, message", [
    (["--drop", "2"], "drop"),
    (["--kill-robot", "9@3"], "no robot 9"),
    (["--stop-robot", "0@3"], "expected I@T:DUR"),
    (["--slow-robot", "0"], "expected I:MS"),
    (["--latency-ms", "-5"], "--latency-ms"),
    (["--robot-rate", "0:15"], "must divide 50 Hz"),
])
def test_bad_fault_flags_exit_2_with_the_flag_named(tmp_path, capsys, flags, message):
    rc = main(["run", "setup_a", "--mode", "lockstep", "--out", str(tmp_path / "x"), *flags])
    assert rc == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["--kill-robot", "9@3"], "no robot 9"),
    (["--stop-robot", "0@3"], "expected I@T:DUR"),
    (["--robot-rate", "0:15"], "must divide 50 Hz"),
    (["--latency-ms", "-5"], "argument --latency-ms: must be"),
    (["--sweep", "speed=1,2"], "KEY one of"),
    (["--sweep", "drop=0,3"], "drop"),
    (["--sweep", "latency_ms=a"], "numbers"),
    (["--planners", "magic"], "unknown"),
])
def test_stress_rejects_bad_options(tmp_path, capsys, argv, message):
    assert main(["stress", "setup_a", "--out", str(tmp_path / "s"), *argv]) == 2
    assert message in capsys.readouterr().err


def test_run_with_the_paper_profile_records_it(tmp_path):
    from agent.core.config import is_paper_config
    from world.scenario_file import load_scenario

    out = tmp_path / "paper"
    rc = main(["run", SMALL, "--mode", "lockstep", "--profile", "paper", "--quiet",
               "--start-jitter-m", "0.05", "--out", str(out)])
    assert rc in (ExitCode.OK, ExitCode.CONTACT, ExitCode.INCOMPLETE)
    assert json.loads((out / "run.json").read_text())["profile"] == "paper"
    assert is_paper_config(load_scenario(out / "scenario.yaml").planner_config)
    assert (out / "metrics.json").is_file()


# --- how a run ends -------------------------------------------------------------------------


def test_a_complete_run_records_its_status_and_end(tmp_path):
    out = tmp_path / "a"
    assert main(["run", SMALL, "--mode", "lockstep", "--quiet", "--out", str(out)]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete" and info["exit_code"] == 0 and info["lost"] == []
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["partial"] is False
    assert metrics["end"]["reason"] == "all_arrived" and metrics["end"]["lost"] == []


def test_an_interrupted_run_leaves_partial_metrics_and_report_says_so(tmp_path, monkeypatch,
                                                                      capsys):
    from orchestrator.experiments import lockstep

    real = lockstep.run_lockstep

    def interrupted(scenario, out_dir, *, on_progress=None, **kw):
        def progress(p):
            if p.sim_t_s >= 3.0:
                raise KeyboardInterrupt
        return real(scenario, out_dir, on_progress=progress, **kw)

    monkeypatch.setattr(lockstep, "run_lockstep", interrupted)
    out = tmp_path / "runs" / "cut"
    assert main(["run", SMALL, "--mode", "lockstep", "--quiet", "--out", str(out)]) \
        == ExitCode.INTERRUPTED
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["partial"] is True and metrics["arrived"] == 0
    monkeypatch.setattr(lockstep, "run_lockstep", real)
    assert main(["run", SMALL, "--mode", "lockstep", "--quiet",
                 "--out", str(tmp_path / "runs" / "whole")]) == 0
    capsys.readouterr()
    assert main(["report", str(tmp_path / "runs"), "--out", str(tmp_path / "rep")]) == 0
    printed = capsys.readouterr().out
    assert "1 partial runs" in printed and "cut" in printed and "1 runs" in printed


def test_unwritable_out_and_too_many_agents_are_one_line_errors(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["run", "setup_a", "--mode", "lockstep", "--out", str(blocker / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: --out: cannot write to") and "\n" not in err
    assert main(["run", "circle", "--agents", "100000", "--mode", "lockstep",
                 "--out", str(tmp_path / "big")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--agents: must be in [1, 4096]" in err and "\n" not in err


def test_benchmark_quick_one_case_writes_the_table_files(tmp_path, capsys):
    out = tmp_path / "bq"
    rc = main(["benchmark", "--quick", "--families", "swap_pairs", "--max-cases", "1",
               "--jobs", "1", "--out", str(out)])
    assert rc == 0
    printed = capsys.readouterr().out
    for name in ("benchmark.csv", "benchmark.json", "benchmark.md", "benchmark.png"):
        assert (out / name).stat().st_size > 0
    rows = list(csv.DictReader((out / "benchmark.csv").read_text().splitlines()))
    assert [(r["case"], r["planner"]) for r in rows] == [("swap_pairs_4", "eifp-mpc"),
                                                        ("swap_pairs_4", "orca")]
    assert all(r["runs"] == "1" for r in rows)
    saved = json.loads((out / "benchmark.json").read_text())
    assert saved["suite"]["seeds"] == [0] and saved["suite"]["cases"] == ["swap_pairs_4"]
    assert [r["seed"] for r in saved["runs"]] == [0, 0]
    for run in saved["runs"]:  # ordinary run directories, with metrics
        metrics = json.loads((Path(run["dir"]) / "metrics.json").read_text())
        assert metrics["robots"] == 4 and run["robot_oscillations"] == \
            [r["oscillations"] for r in metrics["per_robot"]]
    md = (out / "benchmark.md").read_text().splitlines()
    assert sum(line.startswith("| swap_pairs_4 |") for line in md) == 2
    assert sum(line.startswith("swap_pairs_4") for line in printed.splitlines()) == 2
    # The same directory again: refused, nothing overwritten.
    assert main(["benchmark", "--quick", "--families", "swap_pairs", "--max-cases", "1",
                 "--out", str(out)]) == ExitCode.BAD_INPUT


@pytest.mark.parametrize(("argv", "message"), [
    (["--planners", "rrt"], "--planners"),
    (["--families", "nope"], "--families"),
    (["--seeds", "lots"], "--seeds"),
    (["--jobs", "0"], "--jobs"),
])
def test_benchmark_rejects_bad_options(tmp_path, capsys, argv, message):
    assert main(["benchmark", "--quick", "--out", str(tmp_path / "b"), *argv]) == \
        ExitCode.BAD_INPUT
    assert message in capsys.readouterr().err


def test_benchmark_distributed_mode_takes_the_path_of_orchestrator_run(tmp_path, monkeypatch,
                                                                       capsys):
    from orchestrator.experiments import distributed
    from orchestrator.experiments.lockstep import run_lockstep
    from world.scenario_file import load_scenario

    calls = []

    def fake(scenario_path, out_dir, run_id, *, rate_hz, time_scale, on_progress, faults,
             live=None, tls=True, tls_ca=None, robot_launcher="spawn"):
        assert tls is True and tls_ca is None  # secure by default, as orchestrator run
        assert robot_launcher == "spawn"
        calls.append((Path(scenario_path), run_id, time_scale))
        run_lockstep(load_scenario(scenario_path), out_dir)
        (Path(out_dir) / "metrics.json").unlink()  # the world does not write metrics
        return 0

    monkeypatch.setattr(distributed, "run_distributed", fake)
    out = tmp_path / "bd"
    rc = main(["benchmark", "--quick", "--families", "setup_a", "--planners", "orca",
               "--mode", "distributed", "--time-scale", "3", "--out", str(out)])
    assert rc == 0
    ((path, run_id, scale),) = calls
    assert path.name == "scenario.input.yaml" and run_id.startswith("setup_a-0-")
    assert scale == 3.0
    saved = json.loads((out / "benchmark.json").read_text())
    assert saved["suite"]["mode"] == "distributed"
    (run,) = saved["runs"]
    assert run["mode"] == "distributed" and run["world_status"] == 0 and run["robots"] == 2
    info = json.loads((Path(run["dir"]) / "run.json").read_text())
    assert info["mode"] == "distributed" and info["versions"]["osqp"]
