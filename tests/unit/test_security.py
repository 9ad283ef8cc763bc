"""The security rules of the wire layer (`protocol`) and the run's certificates
(`agent.security`): access control, TLS settings, sequence and clock bounds."""

from __future__ import annotations

import json
import stat
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.x509.oid import NameOID
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.security import make_run_pki
from protocol import (
    ACL_MESSAGES,
    MAX_CMD_AHEAD_S,
    MAX_POSE_AHEAD_S,
    SEQ_PER_S,
    TlsFiles,
    access_control,
    check_pose_time,
    check_seq,
    max_seq,
    next_seq,
    relay_access_control,
    robot_cn,
    router_cn,
    run_tag,
    scoped_cn,
    session_settings,
    tls_endpoint,
)

# --- sequence numbers -----------------------------------------------------------------------


def test_a_robots_seq_follows_the_time_of_its_poses() -> None:
    assert next_seq(-1, 0.0) == 0
    assert next_seq(-1, 1.5) == 1500  # a robot's first plan, or a restarted robot's
    assert next_seq(1500, 1.5) == 1501  # a second plan on the same pose
    assert next_seq(1530, 1.5) == 1531
    assert next_seq(1501, 1.6) == 1600


def test_a_seq_is_bounded_by_the_worlds_time_not_by_its_step() -> None:
    assert max_seq(0.0) == MAX_CMD_AHEAD_S * SEQ_PER_S
    assert check_seq(max_seq(2.0), None, world_t_s=2.0) is None
    assert check_seq(max_seq(2.0) + 1, None, world_t_s=2.0) == "seq_jump"
    assert check_seq(max_seq(2.0) + 1, max_seq(2.0), world_t_s=2.0) == "seq_jump"
    assert check_seq(2**63 - 1, None, world_t_s=1e6) == "seq_jump"
    assert check_seq(11, 10, world_t_s=0.0) is None
    assert check_seq(10, 10, world_t_s=0.0) == "stale"
    assert check_seq(3, 10, world_t_s=0.0) == "stale"


def test_the_64_step_walk_is_stopped_and_the_robot_passes_it_a_second_later() -> None:
    """Issue 40: with robot 1's key, 300 commands stepping seq by 64 in 1.5 s took it from
    145 to 19 281, every one accepted, and the robot never caught up. Now the world accepts
    only what its time allows, and the genuine robot's next seq, taken from the time of its
    poses, is above every forged one within MAX_CMD_AHEAD_S of the walk's end."""
    t0_s, last, accepted = 14.5, 145, []
    for k in range(300):
        t_s = t0_s + 1.5 * k / 300
        seq = 145 + 64 * (k + 1)
        if check_seq(seq, last, world_t_s=t_s) is None:
            accepted.append(seq)
            last = seq
    assert len(accepted) < 300 and last <= max_seq(t0_s + 1.5)
    genuine = next_seq(145, t0_s + 1.5 + MAX_CMD_AHEAD_S + 0.02)  # its next pose
    assert check_seq(genuine, last, world_t_s=t0_s + 1.5 + MAX_CMD_AHEAD_S + 0.02) is None


@settings(max_examples=200, deadline=None)
@given(steps=st.lists(st.tuples(st.floats(0.0, 0.5), st.integers(1, 2**40)), max_size=60),
       t0_s=st.floats(0.0, 600.0))
def test_no_forged_walk_outruns_the_genuine_robot_by_more_than_the_bound(
        steps: list[tuple[float, int]], t0_s: float) -> None:
    """Whatever a forger sends (any step at any time), what the world accepted is passed by
    the genuine robot's seq on the first pose `MAX_CMD_AHEAD_S` after the forger stopped."""
    t_s, last = t0_s, next_seq(-1, t0_s)
    for dt_s, step in steps:
        t_s += dt_s
        if check_seq(last + step, last, world_t_s=t_s) is None:
            last += step
    later_s = t_s + MAX_CMD_AHEAD_S + 0.02
    assert check_seq(next_seq(next_seq(-1, t0_s), later_s), last, world_t_s=later_s) is None


# --- pose time --------------------------------------------------------------------------------


def pose_check(tick: int, t_s: float, clock_s: float | None, **kw) -> str | None:
    return check_pose_time(tick, t_s, world_rate_hz=50.0, time_limit_s=60.0, clock_s=clock_s,
                           **kw)


def test_a_genuine_pose_passes() -> None:
    assert pose_check(0, 0.0, None) is None
    assert pose_check(500, 10.0, 9.98) is None
    assert pose_check(500, 10.0, 10.5) is None  # older than the clock: the controller decides


def test_a_pose_whose_time_is_not_its_tick_is_refused() -> None:
    assert pose_check(500, 10.5, 10.0) == "tick_time"
    assert pose_check(2**40, 10.0, 10.0) == "tick_time"


def test_a_pose_beyond_the_time_limit_is_refused_even_before_the_clock_is_set() -> None:
    assert pose_check(50_000_000, 1.0e6, None) == "beyond_limit"
    assert pose_check(3050, 61.0, None) is None
    assert pose_check(3100, 62.0, None) == "beyond_limit"


def test_a_pose_far_ahead_of_the_clock_is_refused() -> None:
    assert pose_check(1500, 30.0, 10.0) == "ahead"
    assert pose_check(int((10.0 + MAX_POSE_AHEAD_S) * 50), 10.0 + MAX_POSE_AHEAD_S,
                      10.0) is None
    # A faster run gets a proportionally wider bound (wall jitter x time scale).
    assert pose_check(1000, 20.0, 16.0, time_scale=5.0) is None
    assert pose_check(1000, 20.0, 14.0, time_scale=5.0) == "ahead"


# --- access control ---------------------------------------------------------------------------


def rules_of(acl: dict, cn: str) -> list[dict]:
    """The rules of a certificate with CN `cn` (a plain identity: of run ``r1``)."""
    cn = cn if "@" in cn else scoped_cn(cn, "r1")
    subjects = {s["id"] for s in acl["subjects"] if cn in s["cert_common_names"]}
    names = {r for p in acl["policies"] if subjects & set(p["subjects"]) for r in p["rules"]}
    return [r for r in acl["rules"] if r["id"] in names]


def allowed(acl: dict, cn: str, message: str, flow: str, key: str) -> bool:
    """Allowed if a rule of `cn` names (message, flow) and a key expression that includes
    `key` (here: equal, or a ``/**`` or ``/*`` prefix of it)."""
    def includes(expr: str, k: str) -> bool:
        if expr == k:
            return True
        if expr.endswith("/**"):
            return k.startswith(expr[:-2]) or k == expr[:-3]
        if expr.endswith("/*"):
            head = expr[:-1]
            return k.startswith(head) and "/" not in k[len(head):] and k != head
        return False

    return any(message in r["messages"] and flow in r["flows"]
               and any(includes(e, key) for e in r["key_exprs"])
               for r in rules_of(acl, cn))


def test_only_robot_i_may_put_its_command_and_debug_keys() -> None:
    acl = access_control("r1", [0, 3])
    assert acl["enabled"] and acl["default_permission"] == "deny"
    assert allowed(acl, "robot-3", "put", "ingress", "eifp/r1/cmd/3")
    assert allowed(acl, "robot-3", "put", "ingress", "eifp/r1/debug/3")
    for cn in ("robot-0", "observer", "orchestrator", "world", "robot-9"):
        assert not allowed(acl, cn, "put", "ingress", "eifp/r1/cmd/3"), cn
        assert not allowed(acl, cn, "put", "ingress", "eifp/r1/debug/3"), cn
    assert not allowed(acl, "robot-3", "put", "ingress", "eifp/r1/cmd/*")


def test_no_client_may_publish_poses_control_or_answer_config() -> None:
    acl = access_control("r1", [0, 1, 2, 3])
    for cn in ("robot-0", "robot-3", "observer", "orchestrator"):
        for key in ("eifp/r1/poses/0", "eifp/r1/control"):
            assert not allowed(acl, cn, "put", "ingress", key), (cn, key)
        assert not allowed(acl, cn, "declare_queryable", "ingress", "eifp/r1/config/*")
        assert not allowed(acl, cn, "reply", "ingress", "eifp/r1/config/3")
    # ... but robots receive poses and control.
    assert allowed(acl, "robot-0", "put", "egress", "eifp/r1/poses/3")
    assert allowed(acl, "robot-0", "put", "egress", "eifp/r1/control")


def test_a_robot_queries_and_declares_only_its_own_keys() -> None:
    acl = access_control("r1", [0, 3])
    assert allowed(acl, "robot-3", "query", "ingress", "eifp/r1/config/3")
    assert allowed(acl, "robot-3", "reply", "egress", "eifp/r1/config/3")
    assert not allowed(acl, "robot-3", "query", "ingress", "eifp/r1/config/0")
    assert allowed(acl, "robot-3", "liveliness_token", "ingress", "eifp/r1/alive/robot/3")
    assert not allowed(acl, "robot-3", "liveliness_token", "ingress", "eifp/r1/alive/robot/0")
    assert not allowed(acl, "robot-3", "liveliness_token", "ingress", "eifp/r1/alive/world")
    # Declared publishers and queriers match only once the world's declarations reach them.
    assert allowed(acl, "robot-3", "declare_subscriber", "egress", "eifp/r1/cmd/*")
    assert allowed(acl, "robot-3", "declare_queryable", "egress", "eifp/r1/config/*")


def test_the_observer_and_the_orchestrator_only_read() -> None:
    acl = access_control("r1", [0])
    for cn in ("observer", "orchestrator"):
        assert allowed(acl, cn, "declare_subscriber", "ingress", "eifp/r1/**")
        assert allowed(acl, cn, "put", "egress", "eifp/r1/cmd/0")
        assert allowed(acl, cn, "declare_liveliness_subscriber", "ingress", "eifp/r1/alive/**")
        for message in ("put", "query", "liveliness_token", "declare_queryable"):
            for key in ("eifp/r1/cmd/0", "eifp/r1/control", "eifp/r1/debug/0"):
                assert not allowed(acl, cn, message, "ingress", key), (cn, message, key)


def test_the_acl_names_only_this_run() -> None:
    acl = access_control("r1", [0])
    exprs = [e for r in acl["rules"] for e in r["key_exprs"]]
    assert exprs and all(e.startswith("eifp/r1/") for e in exprs)
    with pytest.raises(ValueError):
        access_control("bad/run", [0])


# --- relay routers (robots on another host) ---------------------------------------------------


def test_a_relay_may_speak_on_the_worlds_router_for_its_robots_only() -> None:
    acl = access_control("r1", [0, 1, 2, 3], relays={"b": [2, 3]})
    b = router_cn("b")
    assert b == "router-b"
    for i in (2, 3):
        assert allowed(acl, b, "put", "ingress", f"eifp/r1/cmd/{i}")
        assert allowed(acl, b, "put", "ingress", f"eifp/r1/debug/{i}")
        assert allowed(acl, b, "query", "ingress", f"eifp/r1/config/{i}")
        assert allowed(acl, b, "reply", "egress", f"eifp/r1/config/{i}")
        assert allowed(acl, b, "liveliness_token", "ingress", f"eifp/r1/alive/robot/{i}")
    for i in (0, 1):
        assert not allowed(acl, b, "put", "ingress", f"eifp/r1/cmd/{i}")
        assert not allowed(acl, b, "query", "ingress", f"eifp/r1/config/{i}")
        assert not allowed(acl, b, "liveliness_token", "ingress", f"eifp/r1/alive/robot/{i}")
    for key in ("eifp/r1/poses/0", "eifp/r1/control", "eifp/r1/alive/world"):
        assert not allowed(acl, b, "put", "ingress", key)
        assert not allowed(acl, b, "liveliness_token", "ingress", key)
    assert allowed(acl, b, "put", "egress", "eifp/r1/poses/4")  # poses for its robots
    assert allowed(acl, b, "declare_subscriber", "ingress", "eifp/r1/poses/4")
    assert allowed(acl, b, "declare_subscriber", "egress", "eifp/r1/cmd/*")
    assert allowed(acl, b, "declare_queryable", "egress", "eifp/r1/config/*")
    assert not allowed(acl, b, "declare_queryable", "ingress", "eifp/r1/config/*")
    assert not allowed(acl, b, "declare_subscriber", "ingress", "eifp/r1/cmd/*")
    # The robots keep their own rights, wherever they connect.
    assert allowed(acl, "robot-2", "put", "ingress", "eifp/r1/cmd/2")
    # Without relays, the block is the one-router ACL.
    assert access_control("r1", [0, 1]) == access_control("r1", [0, 1], relays={})


def test_a_certificate_of_another_run_has_no_rights_even_from_the_same_ca() -> None:
    """Issue 40: the ACL named bare CNs, so robot 1's certificate of an earlier run, signed by
    the same ``--tls-ca``, put commands in a new run. Now every subject is scoped to its run."""
    acl = access_control("r1", [1], relays={"b": [1]})
    relay = relay_access_control("r1", [1])
    earlier = {cn: scoped_cn(cn, "r0") for cn in ("robot-1", "observer", "orchestrator",
                                                  "router-b", "world")}
    for which in (acl, relay):
        for cn in earlier.values():
            assert rules_of(which, cn) == []
    assert allowed(acl, "robot-1", "put", "ingress", "eifp/r1/cmd/1")
    assert run_tag("r1") != run_tag("r0") and len(scoped_cn("router-" + "a" * 32, "x" * 64)) <= 64
    every = [cn for s in acl["subjects"] + relay["subjects"] for cn in s["cert_common_names"]]
    assert every and all(cn.endswith("@" + run_tag("r1")) for cn in every)


def test_relays_must_carry_robots_of_the_run_each_behind_one_relay() -> None:
    with pytest.raises(ValueError, match="robots of the run"):
        access_control("r1", [0, 1], relays={"b": [2]})
    with pytest.raises(ValueError, match="robots of the run"):
        access_control("r1", [0, 1], relays={"b": []})
    with pytest.raises(ValueError, match="behind both"):
        access_control("r1", [0, 1, 2], relays={"b": [1, 2], "c": [2]})
    with pytest.raises(ValueError, match="router name"):
        access_control("r1", [0, 1], relays={"B": [1]})


def test_a_relay_enforces_its_robots_rights_and_trusts_only_the_worlds_router() -> None:
    acl = relay_access_control("r1", [2, 3])
    assert acl["enabled"] and acl["default_permission"] == "deny"
    assert allowed(acl, "robot-2", "put", "ingress", "eifp/r1/cmd/2")
    assert not allowed(acl, "robot-2", "put", "ingress", "eifp/r1/cmd/3")
    assert not allowed(acl, "robot-2", "put", "ingress", "eifp/r1/poses/0")
    assert allowed(acl, "robot-2", "put", "egress", "eifp/r1/poses/0")
    for cn in ("robot-0", "observer", "orchestrator", "router-c"):  # not served here
        for message in ACL_MESSAGES:
            for flow in ("ingress", "egress"):
                assert not allowed(acl, cn, message, flow, "eifp/r1/cmd/0"), (cn, message)
    for message in ACL_MESSAGES:
        for flow in ("ingress", "egress"):
            assert allowed(acl, "world", message, flow, "eifp/r1/poses/0")
    assert not allowed(acl, "world", "put", "ingress", "eifp/r2/poses/0")  # another run
    with pytest.raises(ValueError):
        relay_access_control("r1", [])


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


# --- TLS settings ---------------------------------------------------------------------------


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


# --- certificates -------------------------------------------------------------------------


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
