"""The wire protocol shared by the world, the robots and the orchestrator.

Every Zenoh key expression and every message schema lives here and nowhere else; nothing
else builds key strings or serialises messages. This module never imports zenoh.

Key expressions (all prefixed by the run id, so two runs on one machine never cross):

- ``eifp/<run>/poses/<slot>``      world -> robots, `PosesMsg`, once per world tick, on the
                                   slot ``tick mod K`` (`pose_slot_count`); a robot that
                                   plans on one slot of every control period subscribes
                                   to that slot only, anything else to ``poses/*``.
- ``eifp/<run>/cmd/<id>``          robot <id> -> world, `CommandMsg`.
- ``eifp/<run>/config/<id>``       queryable served by the world, replies `RunConfigMsg`.
- ``eifp/<run>/control``           world -> all, `ControlMsg` (run started / ended).
- ``eifp/<run>/debug/<id>``        robot <id> -> world (and viewers), `PlanDebugMsg`: the
                                   planner's internals, for viewing only; no robot
                                   subscribes to it.
- ``eifp/<run>/alive/world``       liveliness token of the world process.
- ``eifp/<run>/alive/robot/<id>``  liveliness token of robot process <id>.

Messages are msgpack maps with string keys. Every map carries ``"schema"`` (`SCHEMA_VERSION`)
and ``"type"`` (``"poses"``, ``"cmd"``, ``"config"``, ``"control"``, ``"debug"``), so a message
published on the wrong key is rejected too. Keys are checked strictly: a missing or an
extra key is an error. Numeric arrays travel as msgpack ``bin`` holding little-endian
``float64`` (``<f8``) or ``int32`` (``<i4``) values: a `PosesMsg` as one block of ids and one
block of disc rows (x, y, heading, radius), so a robot reads each with one `numpy.frombuffer`.

Decoding validates types, sizes, finiteness, ranges and the schema version, and every
malformation raises the one typed error `ProtocolError`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import sys
import types
import typing
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import msgpack
import numpy as np

from agent.core.config import PLANNER_NAMES, PlannerConfig
from agent.core.scenario import RobotSpec
from agent.core.types import PlanDebug, PlanResult, PlanStatus, PoseSnapshot, Side
from world.sim.schedule import LINK_LEASE_MS as LINK_LEASE_MS  # re-exported: the schedule
from world.sim.schedule import MAX_POSE_SLOTS as MAX_POSE_SLOTS  # is part of the wire
from world.sim.schedule import plan_pose_slot as plan_pose_slot  # contract
from world.sim.schedule import pose_slot_count as pose_slot_count
from world.sim.schedule import pose_slot_of_tick as pose_slot_of_tick

SCHEMA_VERSION = 4
"""Bumped on any incompatible change of a message schema."""

KEY_ROOT = "eifp"
MAX_MESSAGE_BYTES = 1 << 20
"""Largest payload accepted (1 MiB)."""
MAX_ROBOTS = 4096
MAX_OBSTACLES = 4096
MAX_ROBOT_ID = 2**31 - 1
MIN_OBSTACLE_ID = -(2**31)
MAX_COORD_M = 1.0e6
"""|x|, |y| larger than this (1000 km) is treated as garbage."""
MAX_RADIUS_M = 1.0e3
MAX_SPEED = 1.0e3
"""|v| [m/s] and |omega| [rad/s] larger than this are treated as garbage."""
MAX_HOLD_S = 60.0
MAX_TIME_S = 1.0e7
"""Largest sim time on the wire [s] (about 116 days): stamps, ticks' times, time limits."""
"""Longest a command may ask to be held [s]."""
MAX_REASON_CHARS = 256
MAX_SEQ = 2**63 - 1
MAX_RUN_ID_CHARS = 64
MAX_CLOCK_ID = 2**31 - 1
MAX_DEBUG_THREATS = 256
"""Most threat ids a `PlanDebugMsg` carries."""
MAX_DEBUG_POINTS = 512
"""Most points in each polyline of a `PlanDebugMsg` (via-points, reference, prediction)."""
"""Upper bound on `pose_slot_count` (a world ticking 1000 times per control period)."""

_RUN_ID_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_ROBOT_ID_RE = re.compile(r"0|[1-9][0-9]{0,9}")
_F8 = np.dtype("<f8")
_I4 = np.dtype("<i4")


class ProtocolError(ValueError):
    """A message, key expression or run id that does not follow this protocol."""


# ---------------------------------------------------------------------------------------------
# Key expressions
# ---------------------------------------------------------------------------------------------


def validate_run_id(run_id: object) -> str:
    """Return `run_id` if it is safe inside a key expression and a directory name.

    Allowed: 1..64 characters of ``[A-Za-z0-9_.-]``, starting with a letter or digit (no
    ``/``, wildcards, ``$``, ``?``, ``#`` or whitespace).
    """
    if not isinstance(run_id, str):
        raise ProtocolError(f"run id must be a string, got {type(run_id).__name__}")
    if not 0 < len(run_id) <= MAX_RUN_ID_CHARS or _RUN_ID_RE.fullmatch(run_id) is None:
        raise ProtocolError(
            f"bad run id {run_id!r}: 1..{MAX_RUN_ID_CHARS} chars of [A-Za-z0-9_.-], "
            "starting with a letter or digit"
        )
    return run_id


def _check_robot_id(robot_id: object) -> int:
    if isinstance(robot_id, bool) or not isinstance(robot_id, int | np.integer):
        raise ProtocolError(f"robot id must be an int, got {type(robot_id).__name__}")
    rid = int(robot_id)
    if not 0 <= rid <= MAX_ROBOT_ID:
        raise ProtocolError(f"robot id {rid} out of range [0, {MAX_ROBOT_ID}]")
    return rid


@dataclass(frozen=True)
class RunKeys:
    """Every key expression of one run.

    Args:
        run_id: validated with `validate_run_id`.
    """

    run_id: str

    def __post_init__(self) -> None:
        validate_run_id(self.run_id)

    @property
    def prefix(self) -> str:
        """``eifp/<run>``."""
        return f"{KEY_ROOT}/{self.run_id}"

    def poses_slot(self, slot: int) -> str:
        """World -> robots pose stream of the ticks ``tick mod K == slot`` (`pose_slot_count`)."""
        if isinstance(slot, bool) or not isinstance(slot, int) or not 0 <= slot < MAX_POSE_SLOTS:
            raise ProtocolError(f"pose slot must be an int in [0, {MAX_POSE_SLOTS}), got {slot!r}")
        return f"{self.prefix}/poses/{slot}"

    @property
    def poses_all(self) -> str:
        """Wildcard over every pose slot: every world tick's poses."""
        return f"{self.prefix}/poses/*"

    @property
    def control(self) -> str:
        """World -> all run start/end announcements."""
        return f"{self.prefix}/control"

    def cmd(self, robot_id: int) -> str:
        """Robot -> world command stream of one robot."""
        return f"{self.prefix}/cmd/{_check_robot_id(robot_id)}"

    @property
    def cmd_all(self) -> str:
        """Wildcard over every robot's command stream (the world subscribes to it)."""
        return f"{self.prefix}/cmd/*"

    def config(self, robot_id: int) -> str:
        """Selector a robot queries for its `RunConfigMsg`."""
        return f"{self.prefix}/config/{_check_robot_id(robot_id)}"

    @property
    def config_all(self) -> str:
        """Key expression of the world's configuration queryable."""
        return f"{self.prefix}/config/*"

    def debug(self, robot_id: int) -> str:
        """Robot -> viewers: one robot's planner internals (`PlanDebugMsg`)."""
        return f"{self.prefix}/debug/{_check_robot_id(robot_id)}"

    @property
    def debug_all(self) -> str:
        """Wildcard over every robot's debug stream (the world and live viewers)."""
        return f"{self.prefix}/debug/*"

    @property
    def alive_world(self) -> str:
        """Liveliness token of the world."""
        return f"{self.prefix}/alive/world"

    def alive_robot(self, robot_id: int) -> str:
        """Liveliness token of one robot process."""
        return f"{self.prefix}/alive/robot/{_check_robot_id(robot_id)}"

    @property
    def alive_robot_all(self) -> str:
        """Wildcard over every robot's liveliness token."""
        return f"{self.prefix}/alive/robot/*"

    def _id_after(self, key: object, middle: str) -> int:
        key = str(key)
        head = f"{self.prefix}/{middle}/"
        if not key.startswith(head):
            raise ProtocolError(f"key {key!r} is not under {head!r}")
        tail = key[len(head):]
        if _ROBOT_ID_RE.fullmatch(tail) is None:
            raise ProtocolError(f"key {key!r}: bad robot id {tail!r}")
        return _check_robot_id(int(tail))

    def robot_id_of_cmd(self, key: object) -> int:
        """Robot id in a ``cmd/<id>`` key (str or zenoh.KeyExpr)."""
        return self._id_after(key, "cmd")

    def robot_id_of_debug(self, key: object) -> int:
        """Robot id in a ``debug/<id>`` key."""
        return self._id_after(key, "debug")

    def robot_id_of_config(self, key: object) -> int:
        """Robot id in a ``config/<id>`` key."""
        return self._id_after(key, "config")

    def robot_id_of_alive(self, key: object) -> int:
        """Robot id in an ``alive/robot/<id>`` key."""
        return self._id_after(key, "alive/robot")


# ---------------------------------------------------------------------------------------------
# Shared transport settings (JSON5 values for zenoh.Config.insert_json5; no zenoh import)
# ---------------------------------------------------------------------------------------------

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
        acl: the router's ``access_control`` block (`access_control`,
            `relay_access_control`); router with `tls` only, since the rules name
            certificate CNs.
        zid: this session's Zenoh id (`validate_zid`); None: a random one. The world takes
            a fixed one when robots reach it through another router (they cannot learn it
            from the router they dial).
    """
    import json

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


# ---------------------------------------------------------------------------------------------
# Security: TLS files, the router's access control, and the bounds every receiver enforces
# ---------------------------------------------------------------------------------------------

WORLD_CN = "world"
"""Certificate common name (CN) of the world process; the ACL tells identities apart by CN."""
ORCHESTRATOR_CN = "orchestrator"
"""CN of the orchestrator's watch session (compose): read-only, like `OBSERVER_CN`."""
OBSERVER_CN = "observer"
"""CN of a read-only tool (recorder, visualiser): may subscribe to everything, publish nothing."""
ROUTER_CN_PREFIX = "router-"
"""CNs of relay routers are ``router-<name>`` (`router_cn`)."""
_ROUTER_NAME_RE = re.compile(r"[a-z0-9][a-z0-9-]{0,31}")
_ZID_RE = re.compile(r"[1-9a-f][0-9a-f]{0,31}")
SEQ_PER_S = 1000
"""A command's ``seq`` is on a clock: the sim time [ms] of the poses it was planned on, or one
more than the robot's previous seq if that is larger (`next_seq`). The world refuses a seq
beyond what its own time allows (`max_seq`), so no burst of forged commands can push a
robot's seq out of the genuine robot's reach: once a forger stops, the robot's seq, taken
from time, passes the forged ones within `MAX_CMD_AHEAD_S`."""
MAX_POSE_AHEAD_S = 1.0
"""A pose stamped more than this [sim s] (times the time scale, if > 1) ahead of the
receiving robot's clock is rejected: a forged far-future pose would otherwise move the clock
and make every genuine pose look out of date."""
MAX_CMD_AHEAD_S = 1.0
"""A command whose ``pose_stamp`` is more than this [sim s] ahead of the world's time is
rejected (no genuine plan is made from a pose of the future)."""
TICK_TIME_TOLERANCE_S = 1e-3
"""A pose's ``t`` must equal ``tick / world_rate`` within this [s] (the world ticks at a fixed
rate from 0)."""


def robot_cn(robot_id: int) -> str:
    """Certificate common name of robot `robot_id` (``robot-<id>``)."""
    return f"robot-{_check_robot_id(robot_id)}"


RUN_TAG_HEX = 12
"""Hex digits of a run's tag (`run_tag`): 48 bits of SHA-256 of the run id."""


def run_tag(run_id: str) -> str:
    """A short, fixed-length tag of `run_id` (the first `RUN_TAG_HEX` hex digits of its
    SHA-256): a certificate's CN carries it, since a CN holds at most 64 characters and a run
    id alone may be 64."""
    import hashlib

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
    receive poses and control, watch liveliness, see the world's declarations."""
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
      the reply); declare the token ``alive/robot/<i>``; subscribe to ``poses/**`` and
      ``control``; watch ``alive/**``. Robots see subscriber and queryable declarations
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
    ids = sorted({_check_robot_id(i) for i in robot_ids})
    rules, subjects, policies = _robots_acl(p, ids, run_id)
    rules += [
        _acl_rule("obs-sub", ["declare_subscriber"], ["ingress"], [f"{p}/**"]),
        _acl_rule("obs-recv", ["put", "delete"], ["egress"], [f"{p}/**"]),
    ]
    behind: dict[int, str] = {}
    for name, relay_ids in (relays or {}).items():
        cn = router_cn(name)
        mine = sorted({_check_robot_id(i) for i in relay_ids})
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
    ids = sorted({_check_robot_id(i) for i in robot_ids})
    if not ids:
        raise ValueError("a relay needs at least one robot behind it")
    rules, subjects, policies = _robots_acl(p, ids, run_id)
    rules.append(_acl_rule("upstream", list(ACL_MESSAGES), ["ingress", "egress"], [f"{p}/**"]))
    subjects.append({"id": "s-upstream", "cert_common_names": [scoped_cn(upstream_cn, run_id)]})
    policies.append({"id": "p-upstream", "subjects": ["s-upstream"], "rules": ["upstream"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


def tls_settings(mode: Literal["router", "client"], tls: TlsFiles) -> dict[str, str]:
    """The TLS part of a session's settings (`session_settings` adds it).

    Both sides require mutual TLS: a router lists only ``tls`` as a link protocol (no
    unauthenticated door), a client presents its certificate (``enable_mtls`` on the client
    too, else it sends none) and checks the router's name against its certificate's SANs. A
    router that dials another router (a relay dialling the world) presents the same
    certificate and checks the name the same way.
    """
    import json

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


def next_seq(previous: int, pose_stamp_s: float) -> int:
    """The ``seq`` of a robot's next command: the sim time [ms] of the poses it was planned
    on (`SEQ_PER_S`), or `previous` + 1 if that is larger (several plans on one pose).

    A robot whose commands were refused as stale because a forger pushed its seq up
    re-synchronises this way: its seq follows time, which the forger's could not outrun."""
    return max(int(previous) + 1, math.floor(pose_stamp_s * SEQ_PER_S))


def max_seq(world_t_s: float) -> int:
    """The largest ``seq`` the world accepts at its sim time `world_t_s`: the time of a pose
    `MAX_CMD_AHEAD_S` ahead of it (`SEQ_PER_S`). A genuine robot plans on poses the world
    already published, and at `SEQ_PER_S` plans per second it would still be below."""
    return math.floor((world_t_s + MAX_CMD_AHEAD_S) * SEQ_PER_S)


def check_seq(seq: int, last_seq: int | None, *, world_t_s: float) -> str | None:
    """Why a command's `seq` is refused (None: it is not), given the last one the world
    applied for that robot and the world's sim time.

    ``seq_jump``: beyond what the time allows (`max_seq`): how far a seq may advance is
    bounded by elapsed time, not by step, so a walk of small steps cannot carry it off;
    ``stale``: not above `last_seq`.
    """
    if seq > max_seq(world_t_s):
        return "seq_jump"
    if last_seq is not None and seq <= last_seq:
        return "stale"
    return None


def check_pose_time(tick: int, t_s: float, *, world_rate_hz: float, time_limit_s: float,
                    clock_s: float | None, time_scale: float = 1.0) -> str | None:
    """Why a (validated) pose's `tick` / `t_s` is refused by a robot (None: it is not).

    ``tick_time``: `t_s` is not ``tick / world_rate_hz``; ``beyond_limit``: later than the
    run's time limit (plus `MAX_POSE_AHEAD_S`); ``ahead``: more than `MAX_POSE_AHEAD_S`
    (times `time_scale` when > 1) ahead of the robot's clock `clock_s` (None: no clock yet).
    """
    if abs(tick / world_rate_hz - t_s) > TICK_TIME_TOLERANCE_S + 1e-9 * t_s:
        return "tick_time"
    if t_s > time_limit_s + MAX_POSE_AHEAD_S:
        return "beyond_limit"
    if clock_s is not None and t_s > clock_s + MAX_POSE_AHEAD_S * max(1.0, time_scale):
        return "ahead"
    return None


# ---------------------------------------------------------------------------------------------
# Decoding helpers: each raises ProtocolError naming the field
# ---------------------------------------------------------------------------------------------


def _no_duplicate_keys(pairs: list[tuple[Any, Any]]) -> dict[Any, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):
        raise ProtocolError("duplicate map key")
    return out


_BUFFER_TYPES = (memoryview, bytearray)
_UNPACK_FLAT: dict[str, Any] = {
    "raw": False, "strict_map_key": True, "max_str_len": MAX_MESSAGE_BYTES,
    "max_bin_len": MAX_MESSAGE_BYTES, "max_array_len": 2 * (MAX_ROBOTS + MAX_OBSTACLES),
    "max_map_len": 256, "max_ext_len": 0}
"""`msgpack.unpackb` options: strings are UTF-8, bounded sizes, no extension types."""
_UNPACK_CHECKED: dict[str, Any] = {**_UNPACK_FLAT, "object_pairs_hook": _no_duplicate_keys}
"""The same, every map checked for duplicate keys on the way."""


def _unpack(data: object, *, flat: bool = False) -> Any:
    """Parse a payload; every map is checked for duplicate keys.

    `flat`: the message is one map whose values hold no map (a `PosesMsg`): its duplicate
    keys are found by comparing its size with the count in its header, without calling a
    hook on every map (a nested map would go unchecked, and then fails the message's own
    type checks anyway)."""
    if isinstance(data, _BUFFER_TYPES):
        data = bytes(data)
    if not isinstance(data, bytes):
        raise ProtocolError(f"payload must be bytes, got {type(data).__name__}")
    if len(data) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"payload of {len(data)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        obj = msgpack.unpackb(data, **(_UNPACK_FLAT if flat else _UNPACK_CHECKED))
    except ProtocolError:
        raise
    except Exception as exc:  # msgpack raises many kinds (FormatError, StackError, ...)
        raise ProtocolError(f"not valid msgpack: {type(exc).__name__}: {exc}") from exc
    if flat and type(obj) is dict and len(obj) != _map_count(data):
        raise ProtocolError("duplicate map key")
    return obj


def _map_count(data: bytes) -> int:
    """The entry count in the header of the msgpack map `data` starts with."""
    head = data[0]
    if head == 0xDE:  # map 16
        return int.from_bytes(data[1:3], "big")
    if head == 0xDF:  # map 32
        return int.from_bytes(data[1:5], "big")
    return head & 0x0F  # fixmap


def _as_map(obj: object, where: str, keys: Collection[str]) -> dict[str, Any]:
    if not isinstance(obj, dict):
        raise ProtocolError(f"{where}: expected a map, got {type(obj).__name__}")
    want = keys if isinstance(keys, frozenset) else frozenset(keys)
    if obj.keys() != want:  # compared as sets
        got = set(obj)
        missing = sorted(map(str, want - got))
        extra = sorted(map(str, got - want))
        raise ProtocolError(f"{where}: missing keys {missing}, unknown keys {extra}")
    return obj


def _open_envelope(data: object, msg_type: str, keys: Collection[str], *,
                   flat: bool = False) -> dict[str, Any]:
    obj = _unpack(data, flat=flat)
    if not isinstance(obj, dict):
        raise ProtocolError(f"expected a map, got {type(obj).__name__}")
    version = obj.get("schema")
    if isinstance(version, bool) or not isinstance(version, int):
        raise ProtocolError(f"missing or non-integer schema version: {version!r}")
    if version != SCHEMA_VERSION:
        raise ProtocolError(f"schema version {version}, expected {SCHEMA_VERSION}")
    if obj.get("type") != msg_type:
        raise ProtocolError(f"message type {obj.get('type')!r}, expected {msg_type!r}")
    return _as_map(obj, msg_type, _envelope_keys(keys))


@functools.lru_cache(maxsize=64)
def _envelope_keys(keys: tuple[str, ...]) -> frozenset[str]:
    """Every key of a message's map: the envelope's and its body's `keys`."""
    return frozenset(("schema", "type", *keys))


def _pack(msg_type: str, body: Mapping[str, Any]) -> bytes:
    data = msgpack.packb({"schema": SCHEMA_VERSION, "type": msg_type, **body}, use_bin_type=True)
    if len(data) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"{msg_type}: encoded size {len(data)} exceeds {MAX_MESSAGE_BYTES}")
    return data


_NUMBER_TYPES = (int, float, np.integer, np.floating)
_INT_TYPES = (int, np.integer)


def _float(value: object, where: str, lo: float = -math.inf, hi: float = math.inf,
           *, lo_open: bool = False) -> float:
    if type(value) is float:  # the usual case, as msgpack decodes it
        out = value
    else:
        if isinstance(value, bool) or not isinstance(value, _NUMBER_TYPES):
            raise ProtocolError(f"{where}: expected a number, got {type(value).__name__}")
        try:
            out = float(value)
        except OverflowError as exc:
            raise ProtocolError(f"{where}: number too large") from exc
    if not math.isfinite(out):
        raise ProtocolError(f"{where}: non-finite value {out!r}")
    if out < lo or out > hi or (lo_open and out == lo):
        bracket = "(" if lo_open else "["
        raise ProtocolError(f"{where}: {out!r} outside {bracket}{lo}, {hi}]")
    return out


def _int(value: object, where: str, lo: int, hi: int) -> int:
    if type(value) is int:  # the usual case (not bool, a subclass)
        out = value
    else:
        if isinstance(value, bool) or not isinstance(value, _INT_TYPES):
            raise ProtocolError(f"{where}: expected an int, got {type(value).__name__}")
        out = int(value)
    if not lo <= out <= hi:
        raise ProtocolError(f"{where}: {out} outside [{lo}, {hi}]")
    return out


def _str(value: object, where: str, max_chars: int = MAX_REASON_CHARS) -> str:
    if not isinstance(value, str):
        raise ProtocolError(f"{where}: expected a string, got {type(value).__name__}")
    if len(value) > max_chars:
        raise ProtocolError(f"{where}: longer than {max_chars} characters")
    return value


def _column(value: object, where: str, dtype: np.dtype, n: int | None, max_n: int) -> np.ndarray:
    """One packed column: ``bin`` of n little-endian `dtype` items, returned read-only (n,)."""
    if not isinstance(value, bytes):
        raise ProtocolError(f"{where}: expected bin, got {type(value).__name__}")
    if len(value) % dtype.itemsize:
        raise ProtocolError(f"{where}: {len(value)} bytes is not a multiple of {dtype.itemsize}")
    count = len(value) // dtype.itemsize
    if count > max_n:
        raise ProtocolError(f"{where}: {count} items exceeds {max_n}")
    if n is not None and count != n:
        raise ProtocolError(f"{where}: {count} items, expected {n}")
    return np.frombuffer(value, dtype=dtype)


def _frozen(arr: object, dtype: type, shape: tuple[int, ...], where: str) -> np.ndarray:
    out = np.array(arr, dtype=dtype)
    if out.shape != shape:
        raise ProtocolError(f"{where}: shape {out.shape}, expected {shape}")
    out.flags.writeable = False
    return out


def _known_set(known_ids: Collection[int] | None) -> frozenset[int] | set[int] | None:
    """`known_ids` as a set of Python ints (kept as is if it already is a set)."""
    if known_ids is None or isinstance(known_ids, set | frozenset):
        return known_ids
    return frozenset(np.asarray(known_ids, dtype=np.int64).reshape(-1).tolist())


def _check_ids(ids: np.ndarray, where: str, lo: int, hi: int,
               known_ids: frozenset[int] | set[int] | None) -> None:
    if ids.size == 0:
        return
    values = ids.tolist()
    if min(values) < lo or max(values) > hi:
        raise ProtocolError(f"{where}: id outside [{lo}, {hi}]")
    unique = set(values)
    if len(unique) != len(values):
        raise ProtocolError(f"{where}: duplicate ids")
    if known_ids is not None and not unique <= known_ids:
        raise ProtocolError(f"{where}: unknown ids {sorted(unique - known_ids)[:8]}")


def _check_values(arr: np.ndarray, where: str, lo: float, hi: float,
                  *, lo_open: bool = False) -> None:
    if arr.size == 0:
        return
    # min/max propagate NaN, so one pass each checks finiteness and range.
    low, high = float(arr.min()), float(arr.max())
    if not (math.isfinite(low) and math.isfinite(high)):
        raise ProtocolError(f"{where}: non-finite value")
    if low < lo or high > hi or (lo_open and low <= lo):
        raise ProtocolError(f"{where}: value outside {'(' if lo_open else '['}{lo}, {hi}]")


# ---------------------------------------------------------------------------------------------
# Messages
# ---------------------------------------------------------------------------------------------


_DISC_FIELDS = 4
"""Values per disc in a `PosesMsg`'s ``discs`` block: x, y, heading, radius."""
_DISC_LO = (-MAX_COORD_M, -MAX_COORD_M, -1e3, 0.0)
_DISC_HI = (MAX_COORD_M, MAX_COORD_M, 1e3, MAX_RADIUS_M)
_DISC_NEAR = min(_DISC_HI)
"""Discs whose every value is within +-this (and radius > 0) pass every range at once."""
_DISC_NAMES = ("x", "y", "theta", "radius")
_POSES_KEYS = ("t", "tick", "pub_ns", "clock", "ids", "discs")
_POSES_MAP_KEYS = frozenset(("schema", "type", *_POSES_KEYS))
_POSES_MAP_HEAD = bytes([0x80 | len(_POSES_MAP_KEYS)])
"""A `PosesMsg` payload starts with this fixmap header (its count of entries)."""
_POSES_VIEWS = frozenset(("robot_ids", "robot_pose", "robot_radius_m", "obstacle_ids",
                          "obstacle_xy_m", "obstacle_radius_m"))


@dataclass(frozen=True, eq=False)
class PosesMsg:
    """World -> robots: every disc's pose at one world tick (the robots' only sensor).

    Wire body: ``t`` (float), ``tick``, ``pub_ns``, ``clock`` (ints), ``ids`` (bin: one
    ``<i4`` per disc, the robots' ids >= 0 first, then the obstacles' < 0), ``discs`` (bin:
    four ``<f8`` per disc in the order of ``ids``: x, y, heading, radius; an obstacle's
    heading is 0). One row per disc, so a receiver reads each block with one
    `numpy.frombuffer` (`PoseDecoder`).

    Args:
        t_s: sim time at which the poses were true (>= 0).
        tick: world tick that produced them (>= 0).
        robot_ids: (n,) ids >= 0, unique, n <= `MAX_ROBOTS`.
        robot_pose: (n, 3) x [m], y [m], heading [rad].
        robot_radius_m: (n,) radii > 0.
        obstacle_ids: (m,) ids < 0, unique, m <= `MAX_OBSTACLES`.
        obstacle_xy_m: (m, 2) obstacle centres.
        obstacle_radius_m: (m,) radii > 0.
        pub_ns: wall time the world published it, `time.monotonic_ns()` on its host (0:
            not stamped); `clock_id` names that clock.
        clock_id: the publishing host's monotonic clock (`WallStamps`); 0: unknown.

    Arrays are read-only (copies when constructed, views of the payload when decoded); an
    invalid message raises `ProtocolError`.
    """

    t_s: float
    tick: int
    robot_ids: np.ndarray
    robot_pose: np.ndarray
    robot_radius_m: np.ndarray
    obstacle_ids: np.ndarray
    obstacle_xy_m: np.ndarray
    obstacle_radius_m: np.ndarray
    pub_ns: int = 0
    clock_id: int = 0

    TYPE: typing.ClassVar[str] = "poses"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "t_s", _float(self.t_s, "poses.t", 0.0, MAX_TIME_S))
        set_(self, "tick", _int(self.tick, "poses.tick", 0, MAX_SEQ))
        set_(self, "pub_ns", _int(self.pub_ns, "poses.pub_ns", 0, MAX_SEQ))
        set_(self, "clock_id", _int(self.clock_id, "poses.clock", 0, MAX_CLOCK_ID))
        try:
            rid = np.asarray(self.robot_ids)
            oid = np.asarray(self.obstacle_ids)
            if rid.ndim != 1 or oid.ndim != 1:
                raise ProtocolError("poses: ids must be 1-d")
            n, m = rid.shape[0], oid.shape[0]
            if n > MAX_ROBOTS or m > MAX_OBSTACLES:
                raise ProtocolError(f"poses: {n} robots / {m} obstacles exceed the caps")
            if rid.size and not np.issubdtype(rid.dtype, np.integer):
                raise ProtocolError("poses.robots.id: ids must be integers")
            if oid.size and not np.issubdtype(oid.dtype, np.integer):
                raise ProtocolError("poses.obstacles.id: ids must be integers")
            fields = {
                "robot_ids": _frozen(rid, np.int64, (n,), "poses.robot_ids"),
                "robot_pose": _frozen(self.robot_pose, np.float64, (n, 3), "poses.robot_pose"),
                "robot_radius_m": _frozen(self.robot_radius_m, np.float64, (n,),
                                          "poses.robot_radius_m"),
                "obstacle_ids": _frozen(oid, np.int64, (m,), "poses.obstacle_ids"),
                "obstacle_xy_m": _frozen(self.obstacle_xy_m, np.float64, (m, 2),
                                         "poses.obstacle_xy_m"),
                "obstacle_radius_m": _frozen(self.obstacle_radius_m, np.float64, (m,),
                                             "poses.obstacle_radius_m"),
            }
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ProtocolError):
                raise
            raise ProtocolError(f"poses: bad array: {exc}") from exc
        _check_ids(fields["robot_ids"], "poses.robots.id", 0, MAX_ROBOT_ID, None)
        _check_ids(fields["obstacle_ids"], "poses.obstacles.id", MIN_OBSTACLE_ID, -1, None)
        _check_values(fields["robot_pose"][:, :2], "poses.robots.xy", -MAX_COORD_M, MAX_COORD_M)
        _check_values(fields["robot_pose"][:, 2], "poses.robots.theta", -1e3, 1e3)
        _check_values(fields["robot_radius_m"], "poses.robots.radius", 0.0, MAX_RADIUS_M,
                      lo_open=True)
        _check_values(fields["obstacle_xy_m"], "poses.obstacles.xy", -MAX_COORD_M, MAX_COORD_M)
        _check_values(fields["obstacle_radius_m"], "poses.obstacles.radius", 0.0, MAX_RADIUS_M,
                      lo_open=True)
        for name, value in fields.items():
            set_(self, name, value)

    def __getattr__(self, name: str) -> np.ndarray:
        """The per-kind arrays of a decoded message, as views of its disc blocks, made on
        first use (a robot reads the blocks whole, `to_snapshot`)."""
        both = self.__dict__.get("_discs")
        if both is None or name not in _POSES_VIEWS:
            raise AttributeError(name)
        ids, values = both
        n = self.__dict__["_n_robots"]
        views = {"robot_ids": ids[:n], "robot_pose": values[:n, :3],
                 "robot_radius_m": values[:n, 3], "obstacle_ids": ids[n:],
                 "obstacle_xy_m": values[n:, :2], "obstacle_radius_m": values[n:, 3]}
        self.__dict__.update(views)
        return views[name]

    @property
    def n_robots(self) -> int:
        """Number of robots in the message."""
        n = self.__dict__.get("_n_robots")
        return int(self.robot_ids.shape[0]) if n is None else n

    def discs(self) -> tuple[np.ndarray, np.ndarray]:
        """Every disc, robots then obstacles: ids (k,) int64 and (k, 4) x, y, heading, radius
        (heading 0 for obstacles), as on the wire."""
        both = self.__dict__.get("_discs")
        if both is not None:  # decoded: the payload's own arrays
            return both
        n, m = self.robot_ids.shape[0], self.obstacle_ids.shape[0]
        values = np.zeros((n + m, _DISC_FIELDS))
        values[:n, :3] = self.robot_pose
        values[:n, 3] = self.robot_radius_m
        values[n:, :2] = self.obstacle_xy_m
        values[n:, 3] = self.obstacle_radius_m
        return np.concatenate([self.robot_ids, self.obstacle_ids]), values

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        ids, values = self.discs()
        return _pack(self.TYPE, {
            "t": self.t_s,
            "tick": self.tick,
            "pub_ns": self.pub_ns,
            "clock": self.clock_id,
            "ids": ids.astype(_I4).tobytes(),
            "discs": values.astype(_F8).tobytes(),
        })

    @classmethod
    def decode(cls, data: object, *, known_ids: Collection[int] | None = None) -> PosesMsg:
        """Parse and validate; `known_ids` (robot and obstacle ids) rejects strangers.

        A receiver of a stream decodes with its own `PoseDecoder` (the same checks, each
        id block checked once)."""
        return PoseDecoder(known_ids).decode(data)

    @classmethod
    def from_snapshot(cls, snapshot: PoseSnapshot, *, pub_ns: int = 0,
                      clock_id: int = 0) -> PosesMsg:
        """Split a world snapshot into robots (ids >= 0) and obstacles (ids < 0)."""
        robots = snapshot.ids >= 0
        return cls(
            t_s=snapshot.stamp_s,
            tick=snapshot.tick,
            robot_ids=snapshot.ids[robots],
            robot_pose=snapshot.pose[robots],
            robot_radius_m=snapshot.radius_m[robots],
            obstacle_ids=snapshot.ids[~robots],
            obstacle_xy_m=snapshot.pose[~robots, :2],
            obstacle_radius_m=snapshot.radius_m[~robots],
            pub_ns=pub_ns,
            clock_id=clock_id,
        )

    def to_snapshot(self) -> PoseSnapshot:
        """Robots then obstacles in one `PoseSnapshot`; obstacles get heading 0.

        Of a decoded message, the snapshot's arrays are views of the payload (nothing is
        copied or checked again)."""
        ids, values = self.discs()
        return PoseSnapshot.trusted(stamp_s=self.t_s, tick=self.tick, ids=ids,
                                    pose=values[:, :3], radius_m=values[:, 3])


class PoseDecoder:
    """Decodes the `PosesMsg` stream of one receiver, every message checked in full.

    The world sends the same discs in the same order every tick, so a message's ``ids``
    block is nearly always the previous one's, byte for byte. Its checks (robots first, ids
    unique, in range, all in `known_ids`) then passed already: the decoder does not repeat
    them and hands out the same read-only int64 id array again (`NeighborTracker.update`
    recognises it). Everything else (the envelope, every key, the time fields, the size,
    finiteness and range of every value) is checked on every message.

    Args:
        known_ids: robot and obstacle ids of the run; None: any.
    """

    def __init__(self, known_ids: Collection[int] | None = None) -> None:
        self.known_ids = _known_set(known_ids)
        self._ids_bin: bytes | None = None
        self._ids = np.zeros(0, dtype=np.int64)
        self._n_robots = 0
        self._discs_bytes = 0
        self._discs_shape = (0, _DISC_FIELDS)

    def decode(self, data: object) -> PosesMsg:
        """Parse and validate one payload (`PosesMsg.decode`); raises `ProtocolError`.

        A message like the previous one (the same id block, every field of the usual type
        and in range) is accepted by one chain of comparisons (`_decode_usual`); anything
        else goes through the field-by-field checks, which name what is wrong."""
        if type(data) is bytes and self._ids_bin is not None:
            msg = self._decode_usual(data)
            if msg is not None:
                return msg
        return self._decode_checked(data)

    def _decode_usual(self, data: bytes) -> PosesMsg | None:
        """The message if it passes every check of `_decode_checked` with the previous id
        block, else None (then `_decode_checked` finds what is wrong)."""
        if len(data) > MAX_MESSAGE_BYTES or data[:1] != _POSES_MAP_HEAD:
            return None
        try:
            obj = msgpack.unpackb(data, **_UNPACK_FLAT)
        except Exception:  # noqa: BLE001 - the checked path reports it
            return None
        # A fixmap of 8 entries with these 8 keys has no duplicate key.
        if type(obj) is not dict or obj.keys() != _POSES_MAP_KEYS:
            return None
        schema, t_s, tick, pub_ns, clock_id = (obj["schema"], obj["t"], obj["tick"],
                                               obj["pub_ns"], obj["clock"])
        discs_bin = obj["discs"]
        if not (type(schema) is int and schema == SCHEMA_VERSION and obj["type"] == "poses"
                and type(t_s) is float and 0.0 <= t_s <= MAX_TIME_S
                and type(tick) is int and 0 <= tick <= MAX_SEQ
                and type(pub_ns) is int and 0 <= pub_ns <= MAX_SEQ
                and type(clock_id) is int and 0 <= clock_id <= MAX_CLOCK_ID
                and obj["ids"] == self._ids_bin
                and type(discs_bin) is bytes and len(discs_bin) == self._discs_bytes):
            return None
        ids, n = self._ids, self._n_robots
        values = np.ndarray(self._discs_shape, _F8, discs_bin)  # read-only view of the bytes
        if ids.shape[0] and not (float(np.abs(values).max()) <= _DISC_NEAR
                                 and float(values[:, 3].min()) > _DISC_LO[3]
                                 and (n == ids.shape[0] or not values[n:, 2].any())):
            return None
        msg = object.__new__(PosesMsg)  # the per-kind views come on first use (__getattr__)
        msg.__dict__.update(t_s=t_s, tick=tick, pub_ns=pub_ns, clock_id=clock_id,
                            _discs=(ids, values), _n_robots=n)
        return msg

    def _decode_checked(self, data: object) -> PosesMsg:
        body = _open_envelope(data, PosesMsg.TYPE, _POSES_KEYS, flat=True)
        t_s = _float(body["t"], "poses.t", 0.0, MAX_TIME_S)
        tick = _int(body["tick"], "poses.tick", 0, MAX_SEQ)
        pub_ns = _int(body["pub_ns"], "poses.pub_ns", 0, MAX_SEQ)
        clock_id = _int(body["clock"], "poses.clock", 0, MAX_CLOCK_ID)
        ids_bin, discs_bin = body["ids"], body["discs"]
        if type(ids_bin) is not bytes or ids_bin != self._ids_bin:
            self._ids, self._n_robots = self._check_ids(ids_bin)
            self._ids_bin = ids_bin
            k = self._ids.shape[0]
            self._discs_bytes, self._discs_shape = 8 * _DISC_FIELDS * k, (k, _DISC_FIELDS)
        ids, n = self._ids, self._n_robots
        k = ids.shape[0]
        if type(discs_bin) is not bytes:
            raise ProtocolError(f"poses.discs: expected bin, got {type(discs_bin).__name__}")
        if len(discs_bin) != 8 * _DISC_FIELDS * k:
            raise ProtocolError(f"poses.discs: {len(discs_bin)} bytes, expected "
                                f"{8 * _DISC_FIELDS * k} for {k} discs")
        values = np.frombuffer(discs_bin, dtype=_F8).reshape(k, _DISC_FIELDS)
        if k:
            # Every value within +-`_DISC_NEAR` and every radius > 0 passes every range
            # (max and min propagate NaN, which fails the comparison); else each column is
            # checked against its own range (`_check_discs`: far coordinates, or an error).
            if not (float(np.abs(values).max()) <= _DISC_NEAR
                    and float(values[:, 3].min()) > _DISC_LO[3]):
                _check_discs(values)
            if n < k and values[n:, 2].any():
                raise ProtocolError("poses.discs: an obstacle's heading is not 0")
        msg = object.__new__(PosesMsg)  # the per-kind views come on first use (__getattr__)
        msg.__dict__.update(t_s=t_s, tick=tick, pub_ns=pub_ns, clock_id=clock_id,
                            _discs=(ids, values), _n_robots=n)
        return msg

    def _check_ids(self, ids_bin: object) -> tuple[np.ndarray, int]:
        """The id block as a read-only int64 array and the number of robots; raises."""
        ids = _column(ids_bin, "poses.ids", _I4, None, MAX_ROBOTS + MAX_OBSTACLES)
        n = int(np.count_nonzero(ids >= 0))
        if n and ids[:n].min() < 0:
            raise ProtocolError("poses.ids: the robots' ids (>= 0) must come first")
        if n > MAX_ROBOTS or ids.shape[0] - n > MAX_OBSTACLES:
            raise ProtocolError(f"poses.ids: {n} robots / {ids.shape[0] - n} obstacles exceed "
                                "the caps")
        _check_ids(ids, "poses.ids", MIN_OBSTACLE_ID, MAX_ROBOT_ID, self.known_ids)
        out = ids.astype(np.int64)
        out.flags.writeable = False
        return out, n


def _check_discs(values: np.ndarray) -> None:
    """Check each column of a ``discs`` block against its range; the error names it."""
    for j, name in enumerate(_DISC_NAMES):
        _check_values(values[:, j], f"poses.discs.{name}", _DISC_LO[j], _DISC_HI[j],
                      lo_open=name == "radius")


_STATUS_VALUES = frozenset(s.value for s in PlanStatus)
_SIDE_MIN, _SIDE_MAX = int(Side.RIGHT), int(Side.LEFT)

TIMING_COLUMNS = ("robot_clock", "world_clock", "pose_pub_ns", "pose_rx_ns", "plan_start_ns",
                  "plan_end_ns", "cmd_pub_ns", "cmd_rx_ns", "applied_ns")
"""Wall stamps per applied command: the robot's and the world's clock ids, then the pose
published (world), received (robot), planning started and ended, the command published
(robot), received and applied (world)."""


@dataclass(frozen=True)
class WallStamps:
    """Wall-clock stamps of one command's way from a pose to the world, in integer ns.

    Each stamp is `time.monotonic_ns()` of the host that took it. Monotonic clocks agree
    between the processes of one Linux host (one boot); `clock_id` (robot) and
    `pose_clock_id` (world) name the clocks, so stages that cross processes are measured
    only when both ends share a clock (`orchestrator.analysis.metrics`). 0: not stamped.

    Args:
        clock_id: the robot's clock.
        pose_clock_id: the world's clock (echoed from the pose's `PosesMsg.clock_id`).
        pose_pub_ns: the world published the pose the plan used (echoed, world's clock).
        pose_rx_ns: the robot received that pose.
        plan_start_ns, plan_end_ns: the robot's planning cycle.
        pub_ns: the robot published the command.
    """

    clock_id: int = 0
    pose_clock_id: int = 0
    pose_pub_ns: int = 0
    pose_rx_ns: int = 0
    plan_start_ns: int = 0
    plan_end_ns: int = 0
    pub_ns: int = 0

    FIELDS: typing.ClassVar[tuple[str, ...]] = (
        "clock_id", "pose_clock_id", "pose_pub_ns", "pose_rx_ns", "plan_start_ns",
        "plan_end_ns", "pub_ns")
    _CHECKS: typing.ClassVar[tuple[tuple[str, str, int], ...]] = tuple(
        (name, f"cmd.wall.{name}", MAX_CLOCK_ID if name.endswith("clock_id") else MAX_SEQ)
        for name in FIELDS)

    def __post_init__(self) -> None:
        values = self.__dict__
        for name, where, hi in self._CHECKS:
            values[name] = _int(values[name], where, 0, hi)

    def as_list(self) -> list[int]:
        """The stamps in `FIELDS` order (the wire form)."""
        return [getattr(self, name) for name in self.FIELDS]

    @classmethod
    def from_list(cls, value: object) -> WallStamps:
        """Parse the wire form; `ProtocolError` unless a list of `len(FIELDS)` ints."""
        if not isinstance(value, list | tuple) or len(value) != len(cls.FIELDS):
            raise ProtocolError(f"cmd.wall: expected a list of {len(cls.FIELDS)} integers")
        return cls(*value)


@dataclass(frozen=True)
class CommandMsg:
    """Robot -> world: one velocity command.

    Wire body: ``robot`` (int), ``seq`` (int), ``pose_stamp`` (float), ``v``, ``omega``,
    ``plan_ms`` (float), ``status`` (str), ``side`` (-1|0|1), ``resolved`` (int or nil),
    ``hold`` (float or nil), ``wall`` (`WallStamps` as a list of ints).

    Args:
        robot_id: sender (must match the key's id; checked by `decode(expected_robot_id=)`).
        seq: per-process sequence number, strictly increasing (the world drops stale ones).
        pose_stamp_s: sim time of the pose the plan was made from.
        v_mps, omega_radps: the command (the world clamps it to the robot's limits).
        plan_ms: wall time the plan took.
        status: a `agent.core.types.PlanStatus` value.
        side: a `agent.core.types.Side` value.
        resolved_id: id of the threat the chosen via-point resolves, or None.
        hold_s: how long (sim s, in (0, `MAX_HOLD_S`]) the world may apply this command
            if no newer one arrives; after that it brakes the robot (a command is good for
            the period it was planned for, not until a lost link's time-out). None: until
            the world's own command time-out.
        wall: wall-clock stamps of the command's way (`WallStamps`).
    """

    robot_id: int
    seq: int
    pose_stamp_s: float
    v_mps: float
    omega_radps: float
    plan_ms: float
    status: str
    side: int = 0
    resolved_id: int | None = None
    hold_s: float | None = None
    wall: WallStamps = WallStamps()

    TYPE: typing.ClassVar[str] = "cmd"

    def __post_init__(self) -> None:
        d = self.__dict__  # frozen: fields are written through the instance dict
        d["robot_id"] = _int(d["robot_id"], "cmd.robot", 0, MAX_ROBOT_ID)
        d["seq"] = _int(d["seq"], "cmd.seq", 0, MAX_SEQ)
        d["pose_stamp_s"] = _float(d["pose_stamp_s"], "cmd.pose_stamp", 0.0, MAX_TIME_S)
        d["v_mps"] = _float(d["v_mps"], "cmd.v", -MAX_SPEED, MAX_SPEED)
        d["omega_radps"] = _float(d["omega_radps"], "cmd.omega", -MAX_SPEED, MAX_SPEED)
        d["plan_ms"] = _float(d["plan_ms"], "cmd.plan_ms", 0.0)
        status = _str(d["status"], "cmd.status", 32)
        if status not in _STATUS_VALUES:
            raise ProtocolError(f"cmd.status: unknown status {status!r}")
        d["status"] = str(status)
        d["side"] = _int(d["side"], "cmd.side", _SIDE_MIN, _SIDE_MAX)
        if d["resolved_id"] is not None:
            d["resolved_id"] = _int(d["resolved_id"], "cmd.resolved", MIN_OBSTACLE_ID,
                                    MAX_ROBOT_ID)
        if d["hold_s"] is not None:
            d["hold_s"] = _float(d["hold_s"], "cmd.hold", 0.0, MAX_HOLD_S, lo_open=True)
        if not isinstance(self.wall, WallStamps):
            raise ProtocolError(f"cmd.wall: expected WallStamps, got {type(self.wall).__name__}")

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        return _pack(self.TYPE, {
            "robot": self.robot_id,
            "seq": self.seq,
            "pose_stamp": self.pose_stamp_s,
            "v": self.v_mps,
            "omega": self.omega_radps,
            "plan_ms": self.plan_ms,
            "status": self.status,
            "side": self.side,
            "resolved": self.resolved_id,
            "hold": self.hold_s,
            "wall": self.wall.as_list(),
        })

    @classmethod
    def decode(cls, data: object, *, known_ids: Collection[int] | None = None,
               expected_robot_id: int | None = None) -> CommandMsg:
        """Parse and validate.

        Args:
            known_ids: if given, the robot id must be one of them.
            expected_robot_id: if given (the id in the key), the message must carry it.
        """
        body = _open_envelope(data, cls.TYPE, (
            "robot", "seq", "pose_stamp", "v", "omega", "plan_ms", "status", "side", "resolved",
            "hold", "wall",
        ))
        msg = cls(
            robot_id=body["robot"],
            seq=body["seq"],
            pose_stamp_s=body["pose_stamp"],
            v_mps=body["v"],
            omega_radps=body["omega"],
            plan_ms=body["plan_ms"],
            status=body["status"],
            side=body["side"],
            resolved_id=body["resolved"],
            hold_s=body["hold"],
            wall=WallStamps.from_list(body["wall"]),
        )
        if known_ids is not None and msg.robot_id not in known_ids:
            raise ProtocolError(f"cmd.robot: unknown robot id {msg.robot_id}")
        if expected_robot_id is not None and msg.robot_id != expected_robot_id:
            raise ProtocolError(
                f"cmd.robot: id {msg.robot_id} sent on the key of robot {expected_robot_id}"
            )
        return msg


def encode_command(robot_id: int, seq: int, pose_stamp_s: float, v_mps: float,
                   omega_radps: float, plan_ms: float, status: str, side: int,
                   resolved_id: int | None, hold_s: float | None, wall: list[int]) -> bytes:
    """``CommandMsg(...).encode()`` of these fields (`wall`: `WallStamps.as_list`), byte
    for byte, without building the message objects.

    A robot sends one command per control cycle. Values of the usual types in range are
    checked by one chain of comparisons and packed; anything else is built as a
    `CommandMsg`, whose checks raise `ProtocolError` naming the field.
    """
    if (type(robot_id) is int and 0 <= robot_id <= MAX_ROBOT_ID
            and type(seq) is int and 0 <= seq <= MAX_SEQ
            and type(pose_stamp_s) is float and 0.0 <= pose_stamp_s <= MAX_TIME_S
            and type(v_mps) is float and -MAX_SPEED <= v_mps <= MAX_SPEED
            and type(omega_radps) is float and -MAX_SPEED <= omega_radps <= MAX_SPEED
            and type(plan_ms) is float and 0.0 <= plan_ms <= _MAX_FLOAT
            and status in _STATUS_VALUES and type(side) is int and _SIDE_MIN <= side <= _SIDE_MAX
            and (resolved_id is None
                 or type(resolved_id) is int and MIN_OBSTACLE_ID <= resolved_id <= MAX_ROBOT_ID)
            and (hold_s is None or type(hold_s) is float and 0.0 < hold_s <= MAX_HOLD_S)
            and type(wall) is list and len(wall) == len(WallStamps.FIELDS)
            and all(type(x) is int and 0 <= x <= MAX_SEQ for x in wall)
            and wall[0] <= MAX_CLOCK_ID and wall[1] <= MAX_CLOCK_ID):
        return msgpack.packb({
            "schema": SCHEMA_VERSION, "type": CommandMsg.TYPE, "robot": robot_id, "seq": seq,
            "pose_stamp": pose_stamp_s, "v": v_mps, "omega": omega_radps, "plan_ms": plan_ms,
            "status": str(status), "side": side, "resolved": resolved_id, "hold": hold_s,
            "wall": wall}, use_bin_type=True)
    return CommandMsg(robot_id=robot_id, seq=seq, pose_stamp_s=pose_stamp_s, v_mps=v_mps,
                      omega_radps=omega_radps, plan_ms=plan_ms, status=status, side=side,
                      resolved_id=resolved_id, hold_s=hold_s,
                      wall=WallStamps.from_list(wall)).encode()


_MAX_FLOAT = sys.float_info.max


def _points(value: object, where: str, max_n: int) -> np.ndarray:
    """A packed polyline: ``bin`` of 2 k little-endian float64, returned read-only (k, 2)."""
    flat = _column(value, where, _F8, None, 2 * max_n)
    if flat.shape[0] % 2:
        raise ProtocolError(f"{where}: odd number of coordinates")
    _check_values(flat, where, -MAX_COORD_M, MAX_COORD_M)
    return flat.reshape(-1, 2)


def _pack_points(points: np.ndarray) -> bytes:
    return np.ascontiguousarray(points, dtype=_F8).reshape(-1).tobytes()


@dataclass(frozen=True, eq=False)
class PlanDebugMsg:
    """Robot -> viewers: one plan's internals (`agent.core.types.PlanDebug`), for viewing.

    Sent once per plan on ``debug/<id>`` with congestion control DROP: nothing waits for it
    and nothing decides on it. The world records it in ``run.mcap``.

    Wire body: ``robot`` (int), ``seq`` (the seq of the command it belongs to), ``t`` (sim
    time of the plan), ``v``, ``omega`` (the command), ``status`` (str), ``ego`` (bin, 3
    <f8: x, y, heading), ``threats`` (list of ids), ``via``, ``ref``, ``pred`` (bin of
    <f8 x, y pairs: via-points, reference path samples, MPC prediction).

    Args:
        robot_id: sender (must match the key's id; checked by `decode(expected_robot_id=)`).
        seq: the sequence number of the command this plan produced.
        t_s: sim time at which the robot planned.
        v_mps, omega_radps: the command.
        status: a `agent.core.types.PlanStatus` value.
        debug: the internals; arrays read-only, at most `MAX_DEBUG_POINTS` points each
            and `MAX_DEBUG_THREATS` threats.
    """

    robot_id: int
    seq: int
    t_s: float
    v_mps: float
    omega_radps: float
    status: str
    debug: PlanDebug

    TYPE: typing.ClassVar[str] = "debug"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "robot_id", _int(self.robot_id, "debug.robot", 0, MAX_ROBOT_ID))
        set_(self, "seq", _int(self.seq, "debug.seq", 0, MAX_SEQ))
        set_(self, "t_s", _float(self.t_s, "debug.t", 0.0))
        set_(self, "v_mps", _float(self.v_mps, "debug.v", -MAX_SPEED, MAX_SPEED))
        set_(self, "omega_radps", _float(self.omega_radps, "debug.omega", -MAX_SPEED, MAX_SPEED))
        status = _str(self.status, "debug.status", 32)
        if status not in _STATUS_VALUES:
            raise ProtocolError(f"debug.status: unknown status {status!r}")
        set_(self, "status", str(status))
        d = self.debug
        if not isinstance(d, PlanDebug):
            raise ProtocolError("debug: expected a PlanDebug")
        if len(d.threat_ids) > MAX_DEBUG_THREATS:
            raise ProtocolError(f"debug.threats: more than {MAX_DEBUG_THREATS}")
        for tid in d.threat_ids:
            _int(tid, "debug.threats[]", MIN_OBSTACLE_ID, MAX_ROBOT_ID)
        _check_values(d.ego[:2], "debug.ego.xy", -MAX_COORD_M, MAX_COORD_M)
        _check_values(d.ego[2:], "debug.ego.theta", -1e3, 1e3)
        for name, where in (("via_points_m", "debug.via"), ("reference_m", "debug.ref"),
                            ("predicted_m", "debug.pred")):
            points = getattr(d, name)
            if points.shape[0] > MAX_DEBUG_POINTS:
                raise ProtocolError(f"{where}: {points.shape[0]} points exceed "
                                    f"{MAX_DEBUG_POINTS}")
            _check_values(points, where, -MAX_COORD_M, MAX_COORD_M)

    @classmethod
    def from_result(cls, robot_id: int, seq: int, t_s: float,
                    result: PlanResult) -> PlanDebugMsg | None:
        """The message of one plan, or None if the plan has no `PlanDebug` (a brake).

        Polylines longer than `MAX_DEBUG_POINTS` are cut to their first points.
        """
        d = result.debug
        if d is None:
            return None
        if (len(d.threat_ids) > MAX_DEBUG_THREATS
                or max(len(d.via_points_m), len(d.reference_m), len(d.predicted_m))
                > MAX_DEBUG_POINTS):
            d = PlanDebug(ego=d.ego, threat_ids=d.threat_ids[:MAX_DEBUG_THREATS],
                          via_points_m=d.via_points_m[:MAX_DEBUG_POINTS],
                          reference_m=d.reference_m[:MAX_DEBUG_POINTS],
                          predicted_m=d.predicted_m[:MAX_DEBUG_POINTS])
        return cls(robot_id=robot_id, seq=seq, t_s=t_s, v_mps=result.v_mps,
                   omega_radps=result.omega_radps, status=str(result.status.value), debug=d)

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        d = self.debug
        return _pack(self.TYPE, {
            "robot": self.robot_id,
            "seq": self.seq,
            "t": self.t_s,
            "v": self.v_mps,
            "omega": self.omega_radps,
            "status": self.status,
            "ego": _pack_points(d.ego),
            "threats": list(d.threat_ids),
            "via": _pack_points(d.via_points_m),
            "ref": _pack_points(d.reference_m),
            "pred": _pack_points(d.predicted_m),
        })

    @classmethod
    def decode(cls, data: object, *, known_ids: Collection[int] | None = None,
               expected_robot_id: int | None = None) -> PlanDebugMsg:
        """Parse and validate.

        Args:
            known_ids: if given, the robot id and every threat id must be one of them.
            expected_robot_id: if given (the id in the key), the message must carry it.
        """
        body = _open_envelope(data, cls.TYPE, (
            "robot", "seq", "t", "v", "omega", "status", "ego", "threats", "via", "ref", "pred",
        ))
        ego = _column(body["ego"], "debug.ego", _F8, 3, 3)
        threats = body["threats"]
        if not isinstance(threats, list) or len(threats) > MAX_DEBUG_THREATS:
            raise ProtocolError(f"debug.threats: expected a list of at most "
                                f"{MAX_DEBUG_THREATS} ids")
        threat_ids = tuple(_int(i, "debug.threats[]", MIN_OBSTACLE_ID, MAX_ROBOT_ID)
                           for i in threats)
        _check_values(ego, "debug.ego", -MAX_COORD_M, MAX_COORD_M)
        try:
            debug = PlanDebug(ego=ego, threat_ids=threat_ids,
                              via_points_m=_points(body["via"], "debug.via", MAX_DEBUG_POINTS),
                              reference_m=_points(body["ref"], "debug.ref", MAX_DEBUG_POINTS),
                              predicted_m=_points(body["pred"], "debug.pred", MAX_DEBUG_POINTS))
        except ValueError as exc:
            if isinstance(exc, ProtocolError):
                raise
            raise ProtocolError(f"debug: {exc}") from exc
        msg = cls(robot_id=body["robot"], seq=body["seq"], t_s=body["t"], v_mps=body["v"],
                  omega_radps=body["omega"], status=body["status"], debug=debug)
        if known_ids is not None:
            known = _known_set(known_ids)
            if msg.robot_id not in known:
                raise ProtocolError(f"debug.robot: unknown robot id {msg.robot_id}")
            strangers = set(threat_ids) - known
            if strangers:
                raise ProtocolError(f"debug.threats: unknown ids {sorted(strangers)[:8]}")
        if expected_robot_id is not None and msg.robot_id != expected_robot_id:
            raise ProtocolError(
                f"debug.robot: id {msg.robot_id} sent on the key of robot {expected_robot_id}"
            )
        return msg


ControlKind = Literal["start", "end"]


@dataclass(frozen=True)
class ControlMsg:
    """World -> all: the run started or ended.

    Wire body: ``kind`` ("start"|"end"), ``t`` (float), ``reason`` (str).

    Args:
        kind: ``"start"`` or ``"end"``.
        t_s: sim time of the announcement.
        reason: why the run ended (``all_arrived``, ``time_limit``, ``signal``, ...), or "".
    """

    kind: ControlKind
    t_s: float
    reason: str = ""

    TYPE: typing.ClassVar[str] = "control"

    def __post_init__(self) -> None:
        if self.kind not in ("start", "end"):
            raise ProtocolError(f"control.kind: {self.kind!r} is not 'start' or 'end'")
        object.__setattr__(self, "t_s", _float(self.t_s, "control.t", 0.0, MAX_TIME_S))
        object.__setattr__(self, "reason", _str(self.reason, "control.reason"))

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        return _pack(self.TYPE, {"kind": self.kind, "t": self.t_s, "reason": self.reason})

    @classmethod
    def decode(cls, data: object) -> ControlMsg:
        """Parse and validate."""
        body = _open_envelope(data, cls.TYPE, ("kind", "t", "reason"))
        if not isinstance(body["kind"], str):
            raise ProtocolError("control.kind: expected a string")
        return cls(kind=body["kind"], t_s=body["t"], reason=body["reason"])


# --- Generic, strict (de)serialisation of the shared configuration dataclasses --------------


def _dump_value(value: object, hint: Any, where: str) -> Any:
    """A configuration value as plain msgpack-able data, following its type hint."""
    if value is None:
        return None
    if dataclasses.is_dataclass(hint):
        return _dump_dataclass(value, where)
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        (inner,) = [a for a in typing.get_args(hint) if a is not type(None)]
        return _dump_value(value, inner, where)
    if origin is tuple:
        args = typing.get_args(hint)
        return [_dump_value(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args))]
    if hint is float:
        return float(value)
    if hint is int:
        return int(value)
    if hint in (str, bool):
        return value
    raise TypeError(f"{where}: unsupported configuration type {hint!r}")


def _dump_dataclass(obj: object, where: str) -> dict[str, Any]:
    hints = typing.get_type_hints(type(obj))
    return {
        f.name: _dump_value(getattr(obj, f.name), hints[f.name], f"{where}.{f.name}")
        for f in dataclasses.fields(obj)
    }


def _load_value(value: object, hint: Any, where: str) -> Any:
    """Rebuild a configuration value from msgpack data, checking it against its type hint."""
    if dataclasses.is_dataclass(hint):
        return _load_dataclass(value, hint, where)
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _load_value(value, inner, where)
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, list) or len(value) != len(args):
            raise ProtocolError(f"{where}: expected a list of {len(args)} items")
        return tuple(
            _load_value(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args))
        )
    if hint is float:
        return _float(value, where)
    if hint is int:
        return _int(value, where, -MAX_SEQ - 1, MAX_SEQ)
    if hint is bool:
        if not isinstance(value, bool):
            raise ProtocolError(f"{where}: expected a bool")
        return value
    if hint is str:
        return _str(value, where)
    raise ProtocolError(f"{where}: unsupported configuration type {hint!r}")


def _load_dataclass(data: object, cls: type, where: str) -> Any:
    fields = dataclasses.fields(cls)
    body = _as_map(data, where, [f.name for f in fields])
    hints = typing.get_type_hints(cls)
    kwargs = {f.name: _load_value(body[f.name], hints[f.name], f"{where}.{f.name}")
              for f in fields}
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ProtocolError(f"{where}: {exc}") from exc


def _static_map(rows: object, known: frozenset[int]
                ) -> tuple[tuple[int, float, float, float], ...]:
    """`RunConfigMsg.static_map` checked: [id, x, y, radius] rows, ids known obstacles."""
    what = "config.static_map"
    if isinstance(rows, str | bytes) or not isinstance(rows, Iterable):
        raise ProtocolError(f"{what}: expected a sequence of [id, x, y, radius]")
    out = []
    for row in rows:
        if isinstance(row, str | bytes) or not isinstance(row, Iterable):
            raise ProtocolError(f"{what}[]: expected [id, x, y, radius]")
        values = tuple(row)
        if len(values) != 4:
            raise ProtocolError(f"{what}[]: expected [id, x, y, radius]")
        disc_id = _int(values[0], f"{what}[].id", MIN_OBSTACLE_ID, -1)
        if disc_id not in known:
            raise ProtocolError(f"{what}[].id: {disc_id} is not one of known_ids")
        out.append((disc_id,
                    _float(values[1], f"{what}[].x", -MAX_COORD_M, MAX_COORD_M),
                    _float(values[2], f"{what}[].y", -MAX_COORD_M, MAX_COORD_M),
                    _float(values[3], f"{what}[].radius", 0.0, MAX_RADIUS_M, lo_open=True)))
        if len(out) > MAX_OBSTACLES:
            raise ProtocolError(f"{what}: more than {MAX_OBSTACLES} discs")
    return tuple(out)


@dataclass(frozen=True)
class RunConfigMsg:
    """World -> one robot (query reply): everything the robot needs to plan in this run.

    Wire body: ``run`` (str), ``robot`` (map of every `RobotSpec` field, ``limits`` nested),
    ``planner`` (map of every `PlannerConfig` field, ``mpc`` nested), ``goal_tolerance``,
    ``control_rate``, ``world_rate``, ``time_scale``, ``time_limit``, ``cmd_timeout`` (floats),
    ``known_ids`` (list of every robot and obstacle id of the run), ``static_map`` (list of
    [id, x, y, radius] of the static obstacles, which every robot knows in advance).

    Args:
        run_id: the run this configuration belongs to.
        robot: the robot's spec (its id, start, goal, radius, limits, planner name).
        planner: the shared planner parameters.
        goal_tolerance_m: a robot has arrived when its centre is this close to its goal.
        control_rate_hz: planning rate in sim time.
        world_rate_hz: world tick rate in sim time (poses arrive at this rate).
        time_scale: sim seconds per wall second the world runs at.
        time_limit_s: sim time at which the world gives up.
        cmd_timeout_s: a command older than this (sim time) makes the world brake the robot.
        known_ids: every robot (>= 0) and obstacle (< 0) id of the run.
        static_map: (id, x [m], y [m], radius [m]) of every static obstacle (the robots
            route round them, `agent.planning.routing`); each id is one of `known_ids`.
    """

    run_id: str
    robot: RobotSpec
    planner: PlannerConfig
    goal_tolerance_m: float
    control_rate_hz: float
    world_rate_hz: float
    time_scale: float
    time_limit_s: float
    cmd_timeout_s: float
    known_ids: tuple[int, ...]
    static_map: tuple[tuple[int, float, float, float], ...] = ()

    TYPE: typing.ClassVar[str] = "config"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        validate_run_id(self.run_id)
        if not isinstance(self.robot, RobotSpec) or not isinstance(self.planner, PlannerConfig):
            raise ProtocolError("config: robot must be a RobotSpec, planner a PlannerConfig")
        # Round-trip the nested dataclasses through the strict loader: one set of checks.
        try:
            robot = _dump_dataclass(self.robot, "config.robot")
            planner = _dump_dataclass(self.planner, "config.planner")
        except (TypeError, ValueError, OverflowError) as exc:
            raise ProtocolError(f"config: {exc}") from exc
        set_(self, "robot", _load_dataclass(robot, RobotSpec, "config.robot"))
        set_(self, "planner", _load_dataclass(planner, PlannerConfig, "config.planner"))
        _check_robot_id(self.robot.id)
        if self.robot.planner not in PLANNER_NAMES:
            raise ProtocolError(f"config.robot.planner: unknown planner {self.robot.planner!r}")
        _float(self.robot.radius_m, "config.robot.radius_m", 0.0, MAX_RADIUS_M, lo_open=True)
        for i, c in enumerate((*self.robot.start[:2], *self.robot.goal)):
            _float(c, f"config.robot.coordinate[{i}]", -MAX_COORD_M, MAX_COORD_M)
        for name in ("goal_tolerance_m", "control_rate_hz", "world_rate_hz", "time_scale",
                     "time_limit_s", "cmd_timeout_s"):
            set_(self, name, _float(getattr(self, name), f"config.{name}", 0.0, lo_open=True))
        if isinstance(self.known_ids, str | bytes) or not isinstance(
                self.known_ids, Iterable):
            raise ProtocolError("config.known_ids: expected a sequence of ints")
        ids = tuple(_int(i, "config.known_ids[]", MIN_OBSTACLE_ID, MAX_ROBOT_ID)
                    for i in self.known_ids)
        if len(ids) > MAX_ROBOTS + MAX_OBSTACLES or len(set(ids)) != len(ids):
            raise ProtocolError("config.known_ids: too many or duplicate ids")
        if self.robot.id not in ids:
            raise ProtocolError("config.known_ids: does not contain the robot's own id")
        set_(self, "known_ids", ids)
        set_(self, "static_map", _static_map(self.static_map, frozenset(ids)))

    def encode(self) -> bytes:
        """Serialise to msgpack."""
        return _pack(self.TYPE, {
            "run": self.run_id,
            "robot": _dump_dataclass(self.robot, "robot"),
            "planner": _dump_dataclass(self.planner, "planner"),
            "goal_tolerance": self.goal_tolerance_m,
            "control_rate": self.control_rate_hz,
            "world_rate": self.world_rate_hz,
            "time_scale": self.time_scale,
            "time_limit": self.time_limit_s,
            "cmd_timeout": self.cmd_timeout_s,
            "known_ids": list(self.known_ids),
            "static_map": [list(d) for d in self.static_map],
        })

    @classmethod
    def decode(cls, data: object, *, expected_run_id: str | None = None,
               expected_robot_id: int | None = None) -> RunConfigMsg:
        """Parse and validate; optionally insist on this run and this robot."""
        body = _open_envelope(data, cls.TYPE, (
            "run", "robot", "planner", "goal_tolerance", "control_rate", "world_rate",
            "time_scale", "time_limit", "cmd_timeout", "known_ids", "static_map",
        ))
        if not isinstance(body["known_ids"], list):
            raise ProtocolError("config.known_ids: expected a list")
        if not isinstance(body["static_map"], list):
            raise ProtocolError("config.static_map: expected a list")
        msg = cls(
            run_id=_str(body["run"], "config.run", MAX_RUN_ID_CHARS),
            robot=_load_dataclass(body["robot"], RobotSpec, "config.robot"),
            planner=_load_dataclass(body["planner"], PlannerConfig, "config.planner"),
            goal_tolerance_m=body["goal_tolerance"],
            control_rate_hz=body["control_rate"],
            world_rate_hz=body["world_rate"],
            time_scale=body["time_scale"],
            time_limit_s=body["time_limit"],
            cmd_timeout_s=body["cmd_timeout"],
            known_ids=tuple(body["known_ids"]),
            static_map=tuple(body["static_map"]),
        )
        if expected_run_id is not None and msg.run_id != expected_run_id:
            raise ProtocolError(f"config.run: {msg.run_id!r}, expected {expected_run_id!r}")
        if expected_robot_id is not None and msg.robot.id != expected_robot_id:
            raise ProtocolError(f"config.robot.id: {msg.robot.id}, expected {expected_robot_id}")
        return msg
