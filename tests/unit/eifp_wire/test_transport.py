"""Tests of `eifp_wire.transport`: the Zenoh session settings of every process and their TLS
part."""

from __future__ import annotations

import json

import pytest

from eifp_wire.access import access_control, relay_access_control, robot_cn
from eifp_wire.transport import TlsFiles, session_settings, tls_endpoint, validate_zid
from world.sim.schedule import LINK_LEASE_MS


def test_session_settings() -> None:
    router = session_settings(mode="router", listen=["tcp/127.0.0.1:7447"])
    assert router["mode"] == '"router"' and router["scouting/multicast/enabled"] == "false"
    assert router["transport/link/tx/lease"] == str(LINK_LEASE_MS)
    assert router["transport/shared_memory/enabled"] == "false"
    assert "connect/endpoints" not in router
    client = session_settings(mode="client", connect=["tcp/127.0.0.1:1"], connect_timeout_ms=500)
    assert client["connect/endpoints"] == '["tcp/127.0.0.1:1"]'
    assert client["connect/timeout_ms"] == "500"
    with pytest.raises(ValueError):
        session_settings(mode="peer")  # type: ignore[arg-type]


def test_a_router_dials_with_its_certificate_and_may_take_a_fixed_id() -> None:
    relay = session_settings(mode="router", listen=["tls/0.0.0.0:7447"],
                             connect=["tls/world:7447"], tls=TlsFiles.in_dir("/t", "router-b"),
                             acl=relay_access_control("r1", [2]), zid="e1f0a5")
    assert json.loads(relay["transport/link/tls/connect_certificate"]) == "/t/router-b.pem"
    assert json.loads(relay["transport/link/tls/listen_certificate"]) == "/t/router-b.pem"
    assert relay["transport/link/tls/verify_name_on_connect"] == "true"
    assert json.loads(relay["connect/endpoints"]) == ["tls/world:7447"]
    assert json.loads(relay["id"]) == "e1f0a5"
    with pytest.raises(ValueError, match="Zenoh id"):
        session_settings(mode="router", listen=["tcp/127.0.0.1:1"], zid="0abc")


def test_tls_settings_of_router_and_client() -> None:
    files = TlsFiles.in_dir("/t", "world")
    assert files == TlsFiles("/t/ca.pem", "/t/world.pem", "/t/world.key")
    router = session_settings(mode="router", listen=["tls/127.0.0.1:1"], tls=files,
                              acl=access_control("r1", [0]))
    assert json.loads(router["transport/link/protocols"]) == ["tls"]
    assert router["transport/link/tls/enable_mtls"] == "true"
    assert json.loads(router["transport/link/tls/listen_private_key"]) == "/t/world.key"
    assert json.loads(router["access_control"])["default_permission"] == "deny"
    client = session_settings(mode="client", connect=["tls/world:7447"],
                              tls=TlsFiles.in_dir("/t", robot_cn(3)))
    assert client["transport/link/tls/enable_mtls"] == "true"  # else it sends no certificate
    assert client["transport/link/tls/verify_name_on_connect"] == "true"
    assert json.loads(client["transport/link/tls/connect_certificate"]) == "/t/robot-3.pem"


def test_tls_refuses_plain_endpoints_and_acl_needs_a_tls_router() -> None:
    files = TlsFiles.in_dir("/t", "world")
    with pytest.raises(ValueError, match="tls/"):
        session_settings(mode="router", listen=["tcp/0.0.0.0:1"], tls=files)
    with pytest.raises(ValueError):
        session_settings(mode="router", listen=["tcp/127.0.0.1:1"], acl={"enabled": True})
    assert tls_endpoint("tcp/127.0.0.1:7") == "tls/127.0.0.1:7"
    assert tls_endpoint("tls/world:7447") == "tls/world:7447"
    with pytest.raises(ValueError):
        tls_endpoint("udp/h:1")


def test_zenoh_ids_are_lowercase_hex_without_a_leading_zero() -> None:
    assert validate_zid("e1f0a5") == "e1f0a5" and validate_zid("f" * 32) == "f" * 32
    for bad in ("", "0abc", "E1F0", "g1", "f" * 33, 12, None):
        with pytest.raises(ValueError, match="Zenoh id"):
            validate_zid(bad)
