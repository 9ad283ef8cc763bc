"""Tests of `eifp_wire.access`: the common names of a run's identities and the access-control
lists of the world's router and of relay routers."""

from __future__ import annotations

import pytest

from eifp_wire.access import (
    ACL_MESSAGES,
    access_control,
    relay_access_control,
    router_cn,
    run_tag,
    scoped_cn,
)
from eifp_wire.keys import RunKeys

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


def test_robots_subscribe_to_pose_cells_and_only_the_world_publishes_them() -> None:
    """The pose grid's keys (``poses/<slot>/<i>/<j>``, `RunKeys.poses_cell`) fall under the
    same rules: a robot, a relay and an observer may subscribe to and receive any cell,
    wildcards included; no client may put one. The world is the router's own session."""
    acl = access_control("r1", [0, 1], relays={"b": [1]})
    keys = RunKeys("r1")
    cells = [keys.poses_cell(3, (-2, 7)), keys.poses_cell(None, (0, 0)),
             keys.poses_every_cell(3), keys.poses_all]
    for key in cells:
        for cn in ("robot-0", "robot-1", "router-b", "observer"):
            assert allowed(acl, cn, "declare_subscriber", "ingress", key), (cn, key)
            assert allowed(acl, cn, "put", "egress", key), (cn, key)
            assert not allowed(acl, cn, "put", "ingress", key), (cn, key)
        assert not allowed(acl, "robot-9", "declare_subscriber", "ingress", key)
    assert not allowed(acl, "robot-0", "put", "ingress", "eifp/r1/poses/**")
    relay = relay_access_control("r1", [1])
    assert allowed(relay, "robot-1", "declare_subscriber", "ingress", cells[0])
    assert not allowed(relay, "robot-1", "put", "ingress", cells[0])
    assert not allowed(relay, "robot-0", "declare_subscriber", "ingress", cells[0])


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
    """Every subject is scoped to its run: robot 1's certificate of an earlier run, signed by
    the same ``--tls-ca``, must not put commands in a new run (as it could if the lists named
    bare CNs)."""
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
