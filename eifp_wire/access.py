"""Who may do what in a run: certificate common names and the routers' access-control lists.

The world's router (and each relay router) tells the processes of a run apart by the common
name (CN) of the certificate each presented (mutual TLS, `eifp_wire.transport`); the lists
built here say which keys each CN may put, query, subscribe to or declare a token on
(docs/security.md). Each CN is scoped to its run (`scoped_cn`).
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterable, Mapping
from typing import Any

from eifp_wire.keys import KEY_ROOT, check_robot_id, validate_run_id

WORLD_CN = "world"
"""Certificate common name (CN) of the world process; the ACL tells identities apart by CN."""
ORCHESTRATOR_CN = "orchestrator"
"""CN of the orchestrator's watch session (compose): read-only, like `OBSERVER_CN`."""
OBSERVER_CN = "observer"
"""CN of a read-only tool (recorder, visualiser): may subscribe to everything, publish nothing."""
ROUTER_CN_PREFIX = "router-"
"""CNs of relay routers are ``router-<name>`` (`router_cn`)."""
_ROUTER_NAME_RE = re.compile(r"[a-z0-9][a-z0-9-]{0,31}")


def robot_cn(robot_id: int) -> str:
    """Certificate common name of robot `robot_id` (``robot-<id>``)."""
    return f"robot-{check_robot_id(robot_id)}"


RUN_TAG_HEX = 12
"""Hex digits of a run's tag (`run_tag`): 48 bits of SHA-256 of the run id."""


def run_tag(run_id: str) -> str:
    """A short, fixed-length tag of `run_id` (the first `RUN_TAG_HEX` hex digits of its
    SHA-256): a certificate's CN carries it, since a CN holds at most 64 characters and a run
    id alone may be 64."""
    return hashlib.sha256(validate_run_id(run_id).encode("ascii")).hexdigest()[:RUN_TAG_HEX]


def scoped_cn(cn: str, run_id: str) -> str:
    """The CN of identity `cn` (``world``, ``robot-3``, ...) in a certificate of run
    `run_id`: ``<cn>@<run tag>`` (`run_tag`). The access lists name these, so a certificate
    issued for another run, even by the same CA (``--tls-ca``), matches no subject and is
    refused everything. File names keep the plain `cn`."""
    return f"{cn}@{run_tag(run_id)}"


def router_cn(name: str) -> str:
    """Certificate common name of the relay router `name` (``router-<name>``): a router on
    another host through which some robots reach the world (`relay_access_control`)."""
    if not isinstance(name, str) or _ROUTER_NAME_RE.fullmatch(name) is None:
        raise ValueError(f"bad router name {name!r}: 1..32 chars of [a-z0-9-], starting with "
                         "a letter or digit")
    return f"{ROUTER_CN_PREFIX}{name}"


def _acl_rule(rid: str, messages: list[str], flows: list[str], keys: list[str]
              ) -> dict[str, Any]:
    return {"id": rid, "permission": "allow", "flows": flows, "messages": messages,
            "key_exprs": keys}


ACL_MESSAGES = ("put", "delete", "declare_subscriber", "declare_queryable", "query", "reply",
                "liveliness_token", "declare_liveliness_subscriber", "liveliness_query")
"""Every message kind Zenoh's access control filters."""
_ROBOT_SIDE_RULES = ("robot-sub", "robot-recv", "alive-watch", "alive-see", "robot-routes-sub",
                     "robot-routes-qbl")


def _robot_side_rules(p: str) -> list[dict[str, Any]]:
    """Rules shared by every robot and every relay (which carries robots): subscribe to and
    receive poses (any pose cell: a robot's cells follow it) and control, watch liveliness,
    see the world's declarations. Nobody but the world puts poses: no rule lets a remote."""
    return [
        _acl_rule("robot-sub", ["declare_subscriber"], ["ingress"],
                  [f"{p}/poses/**", f"{p}/control"]),
        _acl_rule("robot-recv", ["put"], ["egress"], [f"{p}/poses/**", f"{p}/control"]),
        _acl_rule("alive-watch", ["declare_liveliness_subscriber", "liveliness_query"],
                  ["ingress"], [f"{p}/alive/**"]),
        _acl_rule("alive-see", ["liveliness_token"], ["egress"], [f"{p}/alive/**"]),
        # Declarations toward robots: the world's subscriber on cmd/* (and whoever listens
        # to debug keys) and its queryable on config/*. Without them a robot's declared
        # Publisher / Querier never matches and drops every message, silently.
        _acl_rule("robot-routes-sub", ["declare_subscriber"], ["egress"], [f"{p}/**"]),
        _acl_rule("robot-routes-qbl", ["declare_queryable"], ["egress"], [f"{p}/config/*"]),
    ]


def _own_key_rules(p: str, tag: str, ids: Iterable[int]) -> list[dict[str, Any]]:
    """The keys only robots `ids` may use: put ``cmd/<i>`` and ``debug/<i>``, query
    ``config/<i>`` (and receive the reply), declare the token ``alive/robot/<i>``."""
    ids = list(ids)
    return [
        _acl_rule(f"cmd-{tag}", ["put"], ["ingress"],
                  [k for i in ids for k in (f"{p}/cmd/{i}", f"{p}/debug/{i}")]),
        _acl_rule(f"config-{tag}", ["query"], ["ingress"], [f"{p}/config/{i}" for i in ids]),
        _acl_rule(f"config-{tag}-reply", ["reply"], ["egress"],
                  [f"{p}/config/{i}" for i in ids]),
        _acl_rule(f"alive-{tag}", ["liveliness_token"], ["ingress"],
                  [f"{p}/alive/robot/{i}" for i in ids]),
    ]


def _robots_acl(p: str, ids: list[int], run_id: str
                ) -> tuple[list[dict[str, Any]], list[dict[str, Any]], list[dict[str, Any]]]:
    """(rules, subjects, policies) of robots `ids` of run `run_id`: each its own keys, all the
    shared rules."""
    rules = _robot_side_rules(p)
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for i in ids:
        own = _own_key_rules(p, str(i), [i])
        rules += own
        subjects.append({"id": f"s-robot-{i}",
                         "cert_common_names": [scoped_cn(robot_cn(i), run_id)]})
        policies.append({"id": f"p-robot-{i}", "subjects": [f"s-robot-{i}"],
                         "rules": [r["id"] for r in own]})
    if ids:
        subjects.append({"id": "s-robots",
                         "cert_common_names": [scoped_cn(robot_cn(i), run_id) for i in ids]})
        policies.append({"id": "p-robots", "subjects": ["s-robots"],
                         "rules": list(_ROBOT_SIDE_RULES)})
    return rules, subjects, policies


def access_control(run_id: str, robot_ids: Iterable[int],
                   relays: Mapping[str, Iterable[int]] | None = None) -> dict[str, Any]:
    """The ``access_control`` block of the world's router for one run (default deny).

    Rules are evaluated by the router against the remote end of each link, by the CN of
    the certificate it presented: ``ingress`` is what the remote sends, ``egress`` what the
    router sends to it. The world is the router's own session, not a subject: nobody but the
    world can publish poses or control, or answer configuration queries, because no remote
    is allowed to.

    - ``robot-<i>``: put ``cmd/<i>`` and ``debug/<i>``; query ``config/<i>`` (and receive
      the reply); declare the token ``alive/robot/<i>``; subscribe to ``poses/**`` (every
      cell of the pose grid, ``poses/<slot>/<i>/<j>``, and the wildcards over them: a robot
      changes its cells as it moves, `world.sim.cells`) and ``control``; watch
      ``alive/**``. Robots see subscriber and queryable declarations
      (a declared Publisher or Querier only sends once it has matched one); they cannot
      put, query or declare tokens anywhere else.
    - ``router-<name>`` (`relays`: name -> the robot ids behind that relay router, on
      another host): the union of those robots' rights and nothing more, so a relay's
      certificate can speak only for its own robots (`relay_access_control` is the
      relay's side).
    - ``observer``: subscribe to and receive everything under ``eifp/<run>/``; nothing else.
    - ``orchestrator``: the same read-only rights as the observer (its live view, compose
      ``await --live``, republishes the run); nothing else.
    """
    p = f"{KEY_ROOT}/{validate_run_id(run_id)}"
    ids = sorted({check_robot_id(i) for i in robot_ids})
    rules, subjects, policies = _robots_acl(p, ids, run_id)
    rules += [
        _acl_rule("obs-sub", ["declare_subscriber"], ["ingress"], [f"{p}/**"]),
        _acl_rule("obs-recv", ["put", "delete"], ["egress"], [f"{p}/**"]),
    ]
    behind: dict[int, str] = {}
    for name, relay_ids in (relays or {}).items():
        cn = router_cn(name)
        mine = sorted({check_robot_id(i) for i in relay_ids})
        if not mine or not set(mine) <= set(ids):
            raise ValueError(f"relay {cn}: robots {mine} must be robots of the run {ids}")
        for i in mine:
            if i in behind:
                raise ValueError(f"robot {i} is behind both {behind[i]} and {cn}")
            behind[i] = cn
        own = _own_key_rules(p, cn, mine)
        rules += own
        subjects.append({"id": f"s-{cn}", "cert_common_names": [scoped_cn(cn, run_id)]})
        policies.append({"id": f"p-{cn}", "subjects": [f"s-{cn}"],
                         "rules": [r["id"] for r in own] + list(_ROBOT_SIDE_RULES)})
    subjects += [{"id": "s-observer", "cert_common_names": [scoped_cn(OBSERVER_CN, run_id)]},
                 {"id": "s-orchestrator",
                  "cert_common_names": [scoped_cn(ORCHESTRATOR_CN, run_id)]}]
    policies += [
        {"id": "p-observer", "subjects": ["s-observer"],
         "rules": ["obs-sub", "obs-recv", "alive-watch", "alive-see"]},
        {"id": "p-orchestrator", "subjects": ["s-orchestrator"],
         "rules": ["obs-sub", "obs-recv", "alive-watch", "alive-see"]},
    ]
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


def relay_access_control(run_id: str, robot_ids: Iterable[int],
                         upstream_cn: str = WORLD_CN) -> dict[str, Any]:
    """The ``access_control`` block of a relay router: robots `robot_ids` reach the world
    through it (default deny).

    - ``robot-<i>`` for `robot_ids`: the same rights as on the world's router
      (`access_control`), enforced here, where their messages enter the router network.
      Any other identity of the run may connect and do nothing.
    - `upstream_cn` (the world's router, which this relay dials): everything under
      ``eifp/<run>/``, both ways. What comes from there was filtered by the world's router
      on its own links; what goes there was filtered here on the robots' links.
    """
    p = f"{KEY_ROOT}/{validate_run_id(run_id)}"
    ids = sorted({check_robot_id(i) for i in robot_ids})
    if not ids:
        raise ValueError("a relay needs at least one robot behind it")
    rules, subjects, policies = _robots_acl(p, ids, run_id)
    rules.append(_acl_rule("upstream", list(ACL_MESSAGES), ["ingress", "egress"], [f"{p}/**"]))
    subjects.append({"id": "s-upstream", "cert_common_names": [scoped_cn(upstream_cn, run_id)]})
    policies.append({"id": "p-upstream", "subjects": ["s-upstream"], "rules": ["upstream"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}
