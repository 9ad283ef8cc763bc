"""Certificates of a run: a per-run certificate authority and one certificate per process.

The orchestrator calls `make_run_pki` before it starts the world and the robots; each process
then opens its Zenoh session with its own files (`eifp_wire.transport.TlsFiles`,
`eifp_wire.transport.tls_settings`) and the world's router enforces
`eifp_wire.access.access_control`, which tells processes apart by the common name (CN) of
their certificate: ``world``, ``robot-<id>``, ``orchestrator``, ``observer``, each scoped to
the run (`eifp_wire.access.scoped_cn`: ``robot-3@<run tag>``), so a certificate of another
run, even from the same CA, holds no right in this one.

EC P-256 keys, SHA-256 signatures. The CA is made fresh for each run and, by default, its
key is never written: once every certificate is issued, nobody can mint another identity
for the run (the only "revocation" there is: a new run has a new CA). With a user-supplied
CA (``--tls-ca DIR`` holding ``ca.pem`` and ``ca.key``) the certificates are signed by it
instead, so that hosts which share that CA can join. Keys are written 0600 from the start
(never world-readable, not even for a moment), directories 0700, every file created new
without following symlinks (`agent.files`).

Only routers' certificates have subjectAltNames: the names they are dialled by. The world's:
``world`` in compose, ``localhost``, ``127.0.0.1``, and any ``--hosts``; a relay router's
(``router-<name>``, on another host, `eifp_wire.access.relay_access_control`): ``router-<name>``,
``localhost``, ``127.0.0.1`` and the names of its host. rustls checks the dialled name
against the SANs only, never the CN.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
from collections.abc import Iterable, Mapping
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from agent.files import PRIVATE_FILE_MODE, create_run_dir, replace_file, reuse_dir, write_new
from eifp_wire import (
    OBSERVER_CN,
    ORCHESTRATOR_CN,
    WORLD_CN,
    TlsFiles,
    robot_cn,
    router_cn,
    scoped_cn,
)

CA_CERT = "ca.pem"
CA_KEY = "ca.key"
DEFAULT_WORLD_HOSTS = ("world", "localhost", "127.0.0.1")
"""Names a client may dial the world by (SANs of the world's certificate)."""
VALID_DAYS = 2.0
"""Lifetime of a run's certificates (a run lasts minutes; the CA dies with it)."""
BACKDATE = dt.timedelta(minutes=5)
"""Certificates are valid from this long before now (small clock skew between hosts)."""


class PkiError(RuntimeError):
    """A CA directory that cannot be used (missing or unreadable files)."""


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _name(cn: str, run_id: str) -> x509.Name:
    return x509.Name([
        x509.NameAttribute(NameOID.ORGANIZATION_NAME, "eifp-swarm"),
        x509.NameAttribute(NameOID.ORGANIZATIONAL_UNIT_NAME, f"run {run_id}"),
        x509.NameAttribute(NameOID.COMMON_NAME, cn),  # scoped_cn for a leaf
    ])


def _key_usage(*, ca: bool) -> x509.KeyUsage:
    return x509.KeyUsage(
        digital_signature=True, key_cert_sign=ca, crl_sign=ca, content_commitment=False,
        key_encipherment=False, data_encipherment=False, key_agreement=False,
        encipher_only=False, decipher_only=False)


def _san(names: Iterable[str]) -> x509.SubjectAlternativeName:
    entries: list[x509.GeneralName] = []
    for n in dict.fromkeys(names):
        try:
            entries.append(x509.IPAddress(ipaddress.ip_address(n)))
        except ValueError:
            entries.append(x509.DNSName(n))
    return x509.SubjectAlternativeName(entries)


class RunCA:
    """A certificate authority that signs the certificates of one run.

    Args:
        run_id: goes into the subject (``OU=run <id>``).
        cert, key: an existing CA (`load`); None: a fresh one, valid `VALID_DAYS`.
    """

    def __init__(self, run_id: str, cert: x509.Certificate | None = None,
                 key: ec.EllipticCurvePrivateKey | None = None) -> None:
        self.run_id = run_id
        now = dt.datetime.now(dt.UTC)
        self.not_before = now - BACKDATE
        self.not_after = now + dt.timedelta(days=VALID_DAYS)
        if cert is not None and key is not None:
            self.cert, self.key = cert, key
            self.not_after = min(self.not_after, cert.not_valid_after_utc)
            return
        self.key = ec.generate_private_key(ec.SECP256R1())
        name = _name(f"eifp-run-ca {run_id}", run_id)
        self.cert = (
            x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(self.key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(self.not_before).not_valid_after(self.not_after)
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(_key_usage(ca=True), critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(self.key.public_key()),
                           critical=False)
            .sign(self.key, hashes.SHA256()))

    @classmethod
    def load(cls, directory: Path, run_id: str) -> RunCA:
        """The CA in `directory` (``ca.pem`` and ``ca.key``, PEM, unencrypted)."""
        d = Path(directory)
        try:
            cert = x509.load_pem_x509_certificate((d / CA_CERT).read_bytes())
            key = serialization.load_pem_private_key((d / CA_KEY).read_bytes(), password=None)
        except (OSError, ValueError, TypeError) as exc:
            raise PkiError(f"--tls-ca {d}: needs {CA_CERT} and an unencrypted {CA_KEY}: "
                           f"{exc}") from exc
        if not isinstance(key, ec.EllipticCurvePrivateKey):
            raise PkiError(f"--tls-ca {d}: {CA_KEY} must be an EC key")
        return cls(run_id, cert, key)

    @property
    def cert_pem(self) -> bytes:
        return self.cert.public_bytes(serialization.Encoding.PEM)

    def write(self, directory: Path) -> None:
        """Write ``ca.pem`` and ``ca.key`` (0600) into `directory`, as `load` reads them:
        for a tool that signs further certificates of the run (a relay's) besides
        `make_run_pki`'s. The key then lives as long as that directory."""
        write_new(Path(directory) / CA_CERT, self.cert_pem)
        write_new(Path(directory) / CA_KEY, _key_pem(self.key), file_mode=PRIVATE_FILE_MODE)

    def issue(self, cn: str, sans: Iterable[str] = ()) -> tuple[bytes, bytes]:
        """``(certificate PEM, private key PEM)`` of a leaf for `cn` (TLS server and client),
        whose CN is `cn` scoped to the run (`eifp_wire.access.scoped_cn`: ``robot-3@<run tag>``)."""
        key = ec.generate_private_key(ec.SECP256R1())
        builder = (
            x509.CertificateBuilder().subject_name(_name(scoped_cn(cn, self.run_id), self.run_id))
            .issuer_name(self.cert.subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(self.not_before).not_valid_after(self.not_after)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(_key_usage(ca=False), critical=True)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                                  ExtendedKeyUsageOID.CLIENT_AUTH]),
                           critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(
                self.key.public_key()), critical=False)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                           critical=False))
        sans = list(sans)
        if sans:
            builder = builder.add_extension(_san(sans), critical=False)
        return (builder.sign(self.key, hashes.SHA256()).public_bytes(serialization.Encoding.PEM),
                _key_pem(key))


def run_identities(robot_ids: Iterable[int], relays: Iterable[str] = ()) -> list[str]:
    """Every CN of a run: the world, the orchestrator, the observer, each robot, each relay
    router (by name)."""
    return [WORLD_CN, ORCHESTRATOR_CN, OBSERVER_CN, *(robot_cn(int(i)) for i in robot_ids),
            *(router_cn(name) for name in relays)]


def make_run_pki(directory: Path, run_id: str, robot_ids: Iterable[int], *,
                 world_hosts: Iterable[str] = DEFAULT_WORLD_HOSTS,
                 relays: Mapping[str, Iterable[str]] | None = None,
                 ca_dir: Path | None = None, split: bool = False) -> dict[str, TlsFiles]:
    """Make (or, with `ca_dir`, sign with a given CA) every certificate of a run.

    Args:
        directory: where the files go: created 0700, or an empty directory of this user
            (`agent.files.create_run_dir`), every file new (`agent.files.write_new`); with
            `split`, existing directories are reused (`agent.files.reuse_dir`: compose
            volumes) and files replaced (`agent.files.replace_file`). Never through a
            symlink.
        run_id: the run.
        robot_ids: one ``robot-<id>`` certificate each.
        world_hosts: SANs of the world's certificate (every name clients and relays dial
            it by).
        relays: relay router name -> the names its host is dialled by (SANs of
            ``router-<name>``, besides ``router-<name>``, ``localhost`` and ``127.0.0.1``).
        ca_dir: a user's CA (``ca.pem``, ``ca.key``); None: a fresh CA whose key is never
            written.
        split: one subdirectory per identity (``<directory>/<cn>/``: ``ca.pem``,
            ``<cn>.pem``, ``<cn>.key``), so each can be handed to its process alone (compose
            volumes); else every file in `directory`.

    Returns:
        CN -> that process's `TlsFiles`.
    """
    # A run's own TLS directory is new (or empty and this user's); compose's volumes are
    # made by Docker and handed to the container's user, and may hold a previous run's files:
    # those are replaced, never written through a symlink.
    if split:
        d, write = reuse_dir(Path(directory), flag="TLS directory"), replace_file
    else:
        d, write = create_run_dir(Path(directory), flag="TLS directory"), write_new
    ca = RunCA.load(Path(ca_dir), run_id) if ca_dir is not None else RunCA(run_id)
    out: dict[str, TlsFiles] = {}
    relays = dict(relays or {})
    sans = {WORLD_CN: list(dict.fromkeys([*DEFAULT_WORLD_HOSTS, *world_hosts]))}
    for name, hosts in relays.items():
        cn = router_cn(name)
        sans[cn] = list(dict.fromkeys([cn, "localhost", "127.0.0.1", *hosts]))
    if not split:
        write(d / CA_CERT, ca.cert_pem)
    for cn in run_identities(robot_ids, relays):
        where = d
        if split:
            where = reuse_dir(d / cn, flag="TLS directory")
            write(where / CA_CERT, ca.cert_pem)
        cert_pem, key_pem = ca.issue(cn, sans.get(cn, ()))
        files = TlsFiles.in_dir(where, cn)
        write(files.cert, cert_pem)
        write(files.key, key_pem, file_mode=PRIVATE_FILE_MODE)
        out[cn] = files
    return out

