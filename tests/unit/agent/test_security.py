"""Tests of `agent.security`: the run's certificate authority and its certificates."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.x509.oid import NameOID

from agent.security import make_run_pki
from eifp_wire.access import run_tag, scoped_cn
from eifp_wire.transport import TlsFiles


def test_relay_certificates_name_their_host(tmp_path) -> None:
    files = make_run_pki(tmp_path, "r1", [0], relays={"b": ["10.0.0.2", "host-b"]})
    cert = x509.load_pem_x509_certificate(Path(files["router-b"].cert).read_bytes())
    assert (cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value
            == scoped_cn("router-b", "r1"))
    sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert {str(n.value) for n in sans} == {"router-b", "localhost", "127.0.0.1", "10.0.0.2",
                                            "host-b"}
    robot = x509.load_pem_x509_certificate(Path(files["robot-0"].cert).read_bytes())
    with pytest.raises(x509.ExtensionNotFound):
        robot.extensions.get_extension_for_class(x509.SubjectAlternativeName)


def test_run_pki_files_modes_names_and_no_ca_key(tmp_path) -> None:
    files = make_run_pki(tmp_path / "tls", "r1", [0, 2], world_hosts=["127.0.0.2"])
    d = tmp_path / "tls"
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    assert set(files) == {"world", "orchestrator", "observer", "robot-0", "robot-2"}
    assert not (d / "ca.key").exists()
    for cn, f in files.items():
        assert stat.S_IMODE((tmp_path / "tls" / f"{cn}.key").stat().st_mode) == 0o600
        cert = x509.load_pem_x509_certificate(Path(f.cert).read_bytes())
        assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == (
            f"{cn}@{run_tag('r1')}")
    world = x509.load_pem_x509_certificate(Path(files["world"].cert).read_bytes())
    sans = world.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    names = {str(n.value) for n in sans}
    assert {"world", "localhost", "127.0.0.1", "127.0.0.2"} <= names


def test_split_pki_gives_each_identity_its_own_directory(tmp_path) -> None:
    files = make_run_pki(tmp_path, "r1", [1], split=True)
    assert files["robot-1"] == TlsFiles.in_dir(tmp_path / "robot-1", "robot-1")
    assert sorted(p.name for p in (tmp_path / "robot-1").iterdir()) == [
        "ca.pem", "robot-1.key", "robot-1.pem"]


def test_a_written_ca_signs_two_sets_of_one_run(tmp_path) -> None:
    """`RunCA.write` then `make_run_pki(ca_dir=...)` twice (a relay's certificate first, the
    run's own after, as orchestrator scale --router-link does): one CA issued both, and its
    key is 0600 and never copied into the sets."""
    from agent.security import RunCA

    ca_dir = tmp_path / "ca"
    ca_dir.mkdir(mode=0o700)
    RunCA("r1").write(ca_dir)
    assert stat.S_IMODE((ca_dir / "ca.key").stat().st_mode) == 0o600
    relay = make_run_pki(tmp_path / "b", "r1", (), relays={"b": ()}, ca_dir=ca_dir)
    run = make_run_pki(tmp_path / "a", "r1", [0], ca_dir=ca_dir)
    ca = x509.load_pem_x509_certificate((ca_dir / "ca.pem").read_bytes())
    for files in (relay["router-b"], run["world"], run["robot-0"]):
        cert = x509.load_pem_x509_certificate(Path(files.cert).read_bytes())
        assert cert.issuer == ca.subject
        cert.verify_directly_issued_by(ca)
    assert not (tmp_path / "a" / "ca.key").exists() and not (tmp_path / "b" / "ca.key").exists()
