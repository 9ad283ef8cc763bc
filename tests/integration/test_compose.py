"""`orchestrator compose`: the docker-compose demo's scenario step, its certificates and the
image's entrypoint. The watch-and-report step (`compose await`) runs against real world and
robot processes: tests/system/test_compose.py."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.experiments.compose import SCENARIO_FILE, set_aside
from world.scenario_file import load_scenario


def test_scenario_step_writes_the_worlds_file(tmp_path: Path) -> None:
    rc = main(["compose", "scenario", "--setup", "setup_d", "--robots", "4", "--run", "r1",
               "--runs-dir", str(tmp_path)])
    assert rc == 0
    scenario = load_scenario(tmp_path / "r1" / SCENARIO_FILE)
    assert scenario.name == "setup_d"
    assert [r.id for r in scenario.robots] == [0, 1, 2, 3]


def test_scenario_step_sets_an_earlier_run_aside(tmp_path: Path) -> None:
    args = ["compose", "scenario", "--setup", "setup_a", "--run", "r1", "--runs-dir",
            str(tmp_path)]
    assert main(args) == 0
    (tmp_path / "r1" / "trajectory.csv").write_text("t,robot,x,y,theta,v,omega\n")
    assert main(args) == 0
    assert (tmp_path / "r1.1" / "trajectory.csv").is_file()
    assert not (tmp_path / "r1" / "trajectory.csv").exists()
    assert (tmp_path / "r1" / SCENARIO_FILE).is_file()


def test_set_aside_leaves_missing_and_empty_directories(tmp_path: Path) -> None:
    assert set_aside(tmp_path / "absent") is None
    (tmp_path / "empty").mkdir()
    assert set_aside(tmp_path / "empty") is None
    assert (tmp_path / "empty").is_dir()
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    (tmp_path / "full.1").mkdir()
    assert set_aside(tmp_path / "full") == tmp_path / "full.2"


def test_robot_count_must_match_the_robot_services(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["compose", "scenario", "--setup", "setup_g", "--robots", "4", "--run", "r1",
               "--runs-dir", str(tmp_path)])
    assert rc == 2
    assert "has 16 robots but the compose file runs 4 robot services" in capsys.readouterr().err
    assert not (tmp_path / "r1").exists()


def test_bad_run_id_is_bad_input(tmp_path: Path) -> None:
    assert main(["compose", "scenario", "--setup", "setup_a", "--run", "a/b", "--runs-dir",
                 str(tmp_path)]) == 2


def test_compose_certs_writes_one_directory_per_service_with_only_its_key(tmp_path) -> None:
    assert main(["compose", "certs", "--run", "r1", "--robots", "2",
                     "--out", str(tmp_path / "tls")]) == 0
    for cn in ("world", "orchestrator", "observer", "robot-0", "robot-1"):
        names = sorted(p.name for p in (tmp_path / "tls" / cn).iterdir())
        assert names == sorted(["ca.pem", f"{cn}.pem", f"{cn}.key"]), (cn, names)
    assert not list((tmp_path / "tls").rglob("ca.key"))
    assert main(["compose", "certs", "--run", "r1", "--robots", "0",
                     "--out", str(tmp_path / "x")]) == 2


def test_compose_certs_makes_a_relay_certificate_for_its_hosts(tmp_path) -> None:
    from cryptography import x509

    assert main(["compose", "certs", "--run", "r1", "--robots", "4", "--out", str(tmp_path),
                 "--relay", "b", "--relay", "c=10.0.0.3,host-c"]) == 0
    for name, hosts in (("b", set()), ("c", {"10.0.0.3", "host-c"})):
        cn = f"router-{name}"
        assert sorted(p.name for p in (tmp_path / cn).iterdir()) == sorted(
            ["ca.pem", f"{cn}.pem", f"{cn}.key"])
        cert = x509.load_pem_x509_certificate((tmp_path / cn / f"{cn}.pem").read_bytes())
        sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        assert {str(n.value) for n in sans} == {cn, "localhost", "127.0.0.1", *hosts}
    assert main(["compose", "certs", "--run", "r1", "--robots", "4", "--out", str(tmp_path),
                 "--relay", "B"]) == 2


def test_entrypoint_runs_the_cli_for_a_subcommand_and_follows_the_run_without_one(tmp_path):
    # `docker run IMAGE orchestrator list` runs the CLI; `orchestrator` alone (compose.yaml)
    # or with options only (compose.live.yaml) is the demo's role, which first waits for its
    # certificate. A stand-in `orchestrator` on PATH records how it was called.
    import os

    repo = Path(__file__).resolve().parents[2]
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "orchestrator"
    fake.write_text('#!/bin/sh\necho "called: $*"\n')
    fake.chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}", "STARTUP_TIMEOUT_S": "0",
           "TLS_DIR": str(tmp_path / "no-tls")}
    entry = str(repo / "docker" / "entrypoint.sh")

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(["sh", entry, *args], env=env, capture_output=True, text=True,
                              timeout=30, check=False)

    listed = run("orchestrator", "list")
    assert listed.returncode == 0 and listed.stdout == "called: list\n", listed
    for args in ((), ("--live", "--live-port", "8765")):
        role = run("orchestrator", *args)
        assert role.returncode == 6, role  # TRANSPORT: no certificate within the deadline
        assert "no certificate" in role.stderr and "called" not in role.stdout, role
