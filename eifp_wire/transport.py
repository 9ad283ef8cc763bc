"""Zenoh session settings shared by every process of a run, and their TLS part.

Values are JSON5 strings for ``zenoh.Config.insert_json5``: this module never imports
zenoh. The router's access-control block is built in `eifp_wire.access`.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from world.sim.schedule import LINK_LEASE_MS

_ZID_RE = re.compile(r"[1-9a-f][0-9a-f]{0,31}")


def session_settings(
    *,
    mode: Literal["router", "client"],
    listen: Iterable[str] = (),
    connect: Iterable[str] = (),
    connect_timeout_ms: int = -1,
    tls: TlsFiles | None = None,
    acl: Mapping[str, Any] | None = None,
    zid: str | None = None,
) -> dict[str, str]:
    """Zenoh configuration every process of a run uses, as ``key -> JSON5 value``.

    Multicast scouting is off and endpoints are explicit; the link lease is
    `LINK_LEASE_MS` on both sides so crashed or hung processes are noticed quickly; shared
    memory transport is off.

    Args:
        mode: ``"router"`` (the world) or ``"client"`` (robots, tools).
        listen: endpoints to listen on, e.g. ``tcp/127.0.0.1:7447``.
        connect: endpoints to connect to.
        connect_timeout_ms: how long `zenoh.open` waits for a connect endpoint (-1: forever).
        tls: this process's certificate, key and the run's CA (`tls_settings`); endpoints
            must then be ``tls/...``. None: plain TCP, no authentication.
        acl: the router's ``access_control`` block (`eifp_wire.access.access_control`,
            `eifp_wire.access.relay_access_control`); router with `tls` only, since the
            rules name certificate CNs.
        zid: this session's Zenoh id (`validate_zid`); None: a random one. The world takes
            a fixed one when robots reach it through another router (they cannot learn it
            from the router they dial).
    """
    if mode not in ("router", "client"):
        raise ValueError(f"mode must be 'router' or 'client', got {mode!r}")
    settings = {
        "mode": json.dumps(mode),
        "scouting/multicast/enabled": "false",
        "transport/link/tx/lease": str(LINK_LEASE_MS),
        # Messages travel as bytes over TCP; shared memory would only add a watchdog
        # thread per process (~0.05 % of a core each, 6.5 % of a core over 128 robots).
        "transport/shared_memory/enabled": "false",
    }
    listen = list(listen)
    connect = list(connect)
    if listen:
        settings["listen/endpoints"] = json.dumps(listen)
    if connect:
        settings["connect/endpoints"] = json.dumps(connect)
        settings["connect/timeout_ms"] = str(int(connect_timeout_ms))
    if tls is not None:
        plain = [e for e in (*listen, *connect) if not e.startswith("tls/")]
        if plain:
            raise ValueError(f"with TLS every endpoint must be tls/...: {plain}")
        settings.update(tls_settings(mode, tls))
    if acl is not None:
        if mode != "router" or tls is None:
            raise ValueError("access control is for the router, with TLS (rules name CNs)")
        settings["access_control"] = json.dumps(dict(acl))
    if zid is not None:
        settings["id"] = json.dumps(validate_zid(zid))
    return settings


def validate_zid(zid: object) -> str:
    """Return `zid` if Zenoh accepts it as a session id: 1..32 lowercase hex digits, no
    leading zero."""
    if not isinstance(zid, str) or _ZID_RE.fullmatch(zid) is None:
        raise ValueError(f"bad Zenoh id {zid!r}: 1..32 lowercase hex digits, no leading zero")
    return zid


@dataclass(frozen=True)
class TlsFiles:
    """One process's TLS material: the run's CA certificate, its own certificate and key.

    Paths as strings (PEM files). A process with these presents its certificate (mutual
    TLS) and trusts only peers signed by `ca`.
    """

    ca: str
    cert: str
    key: str

    @classmethod
    def in_dir(cls, directory: object, cn: str) -> TlsFiles:
        """The files of `cn` in a TLS directory: ``ca.pem``, ``<cn>.pem``, ``<cn>.key``."""
        d = str(directory).rstrip("/") or "/"
        return cls(ca=f"{d}/ca.pem", cert=f"{d}/{cn}.pem", key=f"{d}/{cn}.key")


def tls_endpoint(endpoint: str) -> str:
    """`endpoint` with its protocol replaced by ``tls`` (``tcp/h:p`` -> ``tls/h:p``)."""
    proto, sep, rest = endpoint.partition("/")
    if not sep or proto not in ("tcp", "tls"):
        raise ValueError(f"endpoint {endpoint!r} is not tcp/HOST:PORT or tls/HOST:PORT")
    return f"tls/{rest}"


def tls_settings(mode: Literal["router", "client"], tls: TlsFiles) -> dict[str, str]:
    """The TLS part of a session's settings (`session_settings` adds it).

    Both sides require mutual TLS: a router lists only ``tls`` as a link protocol (no
    unauthenticated door), a client presents its certificate (``enable_mtls`` on the client
    too, else it sends none) and checks the router's name against its certificate's SANs. A
    router that dials another router (a relay dialling the world) presents the same
    certificate and checks the name the same way.
    """
    prefix = "transport/link/tls"
    out = {f"{prefix}/root_ca_certificate": json.dumps(str(tls.ca)),
           f"{prefix}/enable_mtls": "true",
           f"{prefix}/connect_certificate": json.dumps(str(tls.cert)),
           f"{prefix}/connect_private_key": json.dumps(str(tls.key)),
           f"{prefix}/verify_name_on_connect": "true"}
    if mode == "router":
        out[f"{prefix}/listen_certificate"] = json.dumps(str(tls.cert))
        out[f"{prefix}/listen_private_key"] = json.dumps(str(tls.key))
        out["transport/link/protocols"] = json.dumps(["tls"])
    return out
